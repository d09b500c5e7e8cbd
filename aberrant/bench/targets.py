"""The report's targets table: each goal of the bench beside what the run measured."""

from __future__ import annotations

from typing import Any

from aberrant.bench.markdown import markdown_table, met_mark, millis, number, times

#: The goals: ratio to Embree at 800x800 (family -> minimum), overhead ratios, tick budget.
EMBREE_GOALS: dict[str, float] = {"opencl f32": 1.0, "glsl f32": 0.6}
TARGET_SCENES: tuple[str, ...] = ("mesh-10k", "mesh-200k")
TARGET_SIZE: tuple[int, int] = (800, 800)
OVERHEAD_SCENES: dict[str, tuple[str, float]] = {
    "aberrations": ("ten-boxes-aberration", 1.3),
    "portals": ("ten-boxes-portals", 1.2),
}
PLAIN_SCENE = "ten-boxes"
TICK_BUDGET_MS = 1.0


def base_rows(results: dict[str, Any]) -> dict[tuple[str, str], dict[str, Any]]:
    """(scene, family) -> the family's base row (no knob swept) on that scene."""
    return {(r["scene"], r["family"]): r for r in results["rows"] if r["setting"]["sweep"] in ("", "precision")}


def best_ratio(row: dict[str, Any]) -> float:
    """The row's ratio to Embree's rays/s: paired (same background load) when measured, and on the frame of
    Embree's own outputs (the hits, no shading) where that was timed."""
    paired = row.get("embree_trace_paired") or row.get("embree_paired")
    return float(paired["ratio"]) if paired else float(row["embree_ratio"])


def frame_ratio(row: dict[str, Any]) -> float | None:
    """The whole frame's (shaded, colour read back) paired ratio to Embree, where the trace's was timed apart."""
    paired = row.get("embree_paired")
    return float(paired["ratio"]) if paired and row.get("embree_trace_paired") else None


def targets_section(results: dict[str, Any]) -> list[str]:
    base = base_rows(results)
    rows: list[list[str]] = []
    for family, goal in EMBREE_GOALS.items():
        for scene in TARGET_SCENES:
            row = base.get((scene, family))
            if row is None or row.get("embree_ratio") is None:
                why = "not run" if row is None else (row["status"] if row["status"] != "ok" else row["embree_note"])
                rows.append([f"{family} / Embree rays/s, {scene}", why or "–", f">= {goal}x", met_mark(None)])
                continue
            at = tuple(row["size"])
            note = "" if at == TARGET_SIZE else f" (at {at[0]}x{at[1]}; the goal is at 800x800)"
            ratio = best_ratio(row)
            ok = ratio >= goal if at == TARGET_SIZE else None
            paired = row.get("embree_paired")
            shaded = frame_ratio(row)
            if shaded is not None:
                how = f"the hits alone, paired; the shaded frame {times(shaded)} paired, "
                how += f"{times(row['embree_ratio'])} from its medians, "
            else:
                how = f"paired; {times(row['embree_ratio'])} from the medians, " if paired else ""
            measured = f"{times(ratio)} ({how}{number(row['mrays_per_s'])} Mrays/s){note}"
            rows.append([f"{family} / Embree rays/s, {scene}", measured, f">= {goal}x", met_mark(ok)])
    families = sorted({r["family"] for r in results["rows"]})
    for kind, (scene, goal) in OVERHEAD_SCENES.items():
        for family in families:
            plain, deformed = base.get((PLAIN_SCENE, family)), base.get((scene, family))
            label = f"{family}: {kind} over the view / plain frame time"
            plain_ok = plain is not None and plain["status"] == "ok"
            if deformed is None or (plain is None and not deformed.get("baseline_paired")):
                rows.append([label, "not run", f"<= {goal}x", met_mark(None)])
            elif deformed["status"] != "ok" or not (deformed.get("baseline_paired") or plain_ok):
                why = deformed["status"] if deformed["status"] != "ok" or plain is None else plain["status"]
                rows.append([label, why, f"<= {goal}x", met_mark(None)])
            else:
                paired = deformed.get("baseline_paired")
                medians = (
                    deformed["frame"]["median_ms"] / plain["frame"]["median_ms"]
                    if plain is not None and plain_ok
                    else None
                )
                slower = paired["inverse"] if paired else medians
                assert slower is not None  # this branch has a paired run or an ok plain one
                how = "paired" + (f"; {times(medians)} from the medians" if medians else "") if paired else "medians"
                rows.append([label, f"{times(slower)} ({how})", f"<= {goal}x", met_mark(slower <= goal)])
    for entry in results.get("overhead", []):
        label = f"engine tick without render ({entry['backend']}, 1,000 entities, one moving)"
        if "median_ms" not in entry:
            rows.append([label, entry.get("status", "–"), f"< {TICK_BUDGET_MS} ms, one row", met_mark(None)])
            continue
        ok = entry["median_ms"] < TICK_BUDGET_MS and entry["one_row"]
        upload = f"{entry['upload_bytes']} B ({'one table row' if entry['one_row'] else 'more than one row'})"
        rows.append(
            [
                label,
                f"{millis(entry['median_ms'])} ms median, upload {upload}",
                f"< {TICK_BUDGET_MS} ms, one row",
                met_mark(ok),
            ]
        )
    return ["## Targets", "", *markdown_table(["target", "measured", "goal", "status"], rows), ""]
