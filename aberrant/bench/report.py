"""``report.md``: the results as tables a reader can act on.

Targets first (each measured figure beside its goal), then the headline
matrix (scene x backend, Mrays/s and the ratio to Embree), the plot, the
engine and non-Euclidean overheads, the Embree anchor, the image error of
samples a pixel and of shadows off, what the image features cost, every cell in detail,
what could not run and why, and what was swept.
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import Any

from aberrant.bench.embree import MODES
from aberrant.bench.images import image_section
from aberrant.bench.markdown import markdown_table
from aberrant.bench.paired import features_section, hotel_section, space_section
from aberrant.bench.sweeps import SWEEPS
from engine.errors import AberrantError

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


def _num(value: float | None, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    if value == 0:
        return "0"
    if abs(value) >= 1e4 or abs(value) < 1e-3:
        return f"{value:.2e}"
    return f"{value:.{digits}g}"


def _ms(value: float | None) -> str:
    return "–" if value is None else f"{value:.1f}" if value >= 10 else f"{value:.2f}"


def _pct(fraction: float | None) -> str:
    return "–" if fraction is None else "0" if fraction == 0 else f"{100 * fraction:.3g} %"


def _ratio(value: float | None) -> str:
    return "–" if value is None else f"{value:.2f}x"


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


def _mark(ok: bool | None) -> str:
    return "not measured" if ok is None else ("**met**" if ok else "**not met**")


def _targets(results: dict[str, Any]) -> list[str]:
    base = base_rows(results)
    rows: list[list[str]] = []
    for family, goal in EMBREE_GOALS.items():
        for scene in TARGET_SCENES:
            row = base.get((scene, family))
            if row is None or row.get("embree_ratio") is None:
                why = "not run" if row is None else (row["status"] if row["status"] != "ok" else row["embree_note"])
                rows.append([f"{family} / Embree rays/s, {scene}", why or "–", f">= {goal}x", _mark(None)])
                continue
            at = tuple(row["size"])
            note = "" if at == TARGET_SIZE else f" (at {at[0]}x{at[1]}; the goal is at 800x800)"
            ratio = best_ratio(row)
            ok = ratio >= goal if at == TARGET_SIZE else None
            paired = row.get("embree_paired")
            shaded = frame_ratio(row)
            if shaded is not None:
                how = f"the hits alone, paired; the shaded frame {_ratio(shaded)} paired, "
                how += f"{_ratio(row['embree_ratio'])} from its medians, "
            else:
                how = f"paired; {_ratio(row['embree_ratio'])} from the medians, " if paired else ""
            measured = f"{_ratio(ratio)} ({how}{_num(row['mrays_per_s'])} Mrays/s){note}"
            rows.append([f"{family} / Embree rays/s, {scene}", measured, f">= {goal}x", _mark(ok)])
    families = sorted({r["family"] for r in results["rows"]})
    for kind, (scene, goal) in OVERHEAD_SCENES.items():
        for family in families:
            plain, deformed = base.get((PLAIN_SCENE, family)), base.get((scene, family))
            label = f"{family}: {kind} over the view / plain frame time"
            plain_ok = plain is not None and plain["status"] == "ok"
            if deformed is None or (plain is None and not deformed.get("baseline_paired")):
                rows.append([label, "not run", f"<= {goal}x", _mark(None)])
            elif deformed["status"] != "ok" or not (deformed.get("baseline_paired") or plain_ok):
                why = deformed["status"] if deformed["status"] != "ok" or plain is None else plain["status"]
                rows.append([label, why, f"<= {goal}x", _mark(None)])
            else:
                paired = deformed.get("baseline_paired")
                medians = (
                    deformed["frame"]["median_ms"] / plain["frame"]["median_ms"]
                    if plain is not None and plain_ok
                    else None
                )
                slower = paired["inverse"] if paired else medians
                assert slower is not None  # this branch has a paired run or an ok plain one
                how = "paired" + (f"; {_ratio(medians)} from the medians" if medians else "") if paired else "medians"
                rows.append([label, f"{_ratio(slower)} ({how})", f"<= {goal}x", _mark(slower <= goal)])
    for entry in results.get("overhead", []):
        label = f"engine tick without render ({entry['backend']}, 1,000 entities, one moving)"
        if "median_ms" not in entry:
            rows.append([label, entry.get("status", "–"), f"< {TICK_BUDGET_MS} ms, one row", _mark(None)])
            continue
        ok = entry["median_ms"] < TICK_BUDGET_MS and entry["one_row"]
        upload = f"{entry['upload_bytes']} B ({'one table row' if entry['one_row'] else 'more than one row'})"
        rows.append(
            [
                label,
                f"{_ms(entry['median_ms'])} ms median, upload {upload}",
                f"< {TICK_BUDGET_MS} ms, one row",
                _mark(ok),
            ]
        )
    return ["## Targets", "", *markdown_table(["target", "measured", "goal", "status"], rows), ""]


def _headline(results: dict[str, Any]) -> list[str]:
    base = base_rows(results)
    families = list(dict.fromkeys(r["family"] for r in results["rows"]))
    rows = []
    for scene, info in results["scenes"].items():
        cells = []
        for family in families:
            row = base.get((scene, family))
            if row is None:
                cells.append("–")
            elif row["status"] != "ok":
                cells.append(row["status"].split(":")[0])  # unsupported, error or skipped
            else:
                unlit = "*" if (row.get("embree_paired") or {}).get("shadows_off") else ""
                ratio = f" ({_ratio(best_ratio(row))}{unlit})" if row.get("embree_ratio") is not None else ""
                cells.append(f"{_num(row['mrays_per_s'])}{ratio}")
        size = "x".join(map(str, info["fixed_size"] or results["config"]["size"]))
        entry = results["embree"].get(scene, {}).get("sizes", {}).get(size, {})
        cells.append(_num(entry["mrays_per_s"]) if entry.get("status") == "ok" else "–")
        rows.append([scene, f"{info['triangles']:,}", size, *cells])
    header = ["scene", "triangles", "size", *[f"{f} Mrays/s (x Embree)" for f in families], "Embree Mrays/s"]
    return [
        "## Headline: base settings, Mrays/s (ratio to Embree's rays/s)",
        "",
        "Ratios are *paired*: Embree's trace of the same rays alternates with the backend's frames, so both see "
        "the same background load; the median of the per-pair ratios. Embree traces the primary rays to their "
        "closest hit and returns the hits, so the ratio pairs it with the backend's frame of the same outputs "
        "(depth and instance, the shading compiled out) where that was timed; the shaded frame's own ratio is in "
        "the scene's table. A scene whose lights cast shadows (marked *) is paired with them off; its Mrays/s "
        "are those of the shaded frame with them.",
        "",
        *markdown_table(header, rows),
        "",
    ]


def _overhead(results: dict[str, Any]) -> list[str]:
    entries = [e for e in results.get("overhead", []) if "median_ms" in e]
    if not entries:
        return []
    systems = list(dict.fromkeys(name for e in entries for name in e["systems_ms"]))
    rows = [
        [
            e["backend"],
            f"{_ms(e['median_ms'])} ({_ms(e['min_ms'])}–{_ms(e['max_ms'])})",
            *[_ms(e["systems_ms"].get(s)) for s in systems],
            f"{e['upload_bytes']} B",
            f"{e['tlas_upload_ticks']} of {e['ticks']}" if "tlas_upload_ticks" in e else "–",
            ", ".join(
                f"{u['table']}[{'all' if u['rows'] is None else '{}:{}'.format(*u['rows'])}]" for u in e["updates"]
            ),
        ]
        for e in entries
    ]
    header = [
        "backend",
        "tick ms median (min–max)",
        *[f"{s} ms" for s in systems],
        "upload",
        "ticks uploading TLAS rows",
        "tables",
    ]
    return [
        "## Engine overhead per tick (render skipped)",
        "",
        f"{entries[0]['entities']:,} box entities, one moved before each tick; {entries[0]['ticks']} ticks "
        "after 5 warm-up ticks; the backend's render is replaced by a no-op, everything else is the real "
        "App (the render system's own work included).",
        "",
        *markdown_table(header, rows),
        "",
    ]


def _embree(results: dict[str, Any]) -> list[str]:
    rows = []
    for scene, anchor in results["embree"].items():
        if anchor.get("status") != "ok":
            continue
        for size, e in anchor["sizes"].items():
            if e.get("status") != "ok":
                rows.append([scene, size, e.get("status", "–"), *["–"] * (len(MODES) + 3)])
                continue
            err = e["errors"]
            rows.append(
                [
                    scene,
                    size,
                    e["best"],
                    *[_num(e["modes"][m]["mrays_per_s"]) for m in MODES],
                    _ms(e["build_ms"]),
                    _pct(err["mismatch"]),
                    _num(err["depth_p99"]),
                ]
            )
    notes = sorted({a["status"] for a in results["embree"].values() if a.get("status", "ok") != "ok"})
    out = ["## Embree anchor (embreex, closest hit only, same primary rays)", ""]
    if rows:
        header = [
            "scene",
            "size",
            "best mode",
            *[f"{m} Mrays/s" for m in MODES],
            "build ms",
            "mismatch vs reference",
            "depth p99 vs reference",
        ]
        out += [*markdown_table(header, rows), ""]
    out += [f"- {n}" for n in notes] + ([""] if notes else [])
    return out


def _detail(results: dict[str, Any]) -> list[str]:
    out = ["## Every cell", ""]
    header = [
        "setting",
        "size",
        "frame ms median (min–max)",
        "Mrays/s",
        "x Embree",
        "first frame ms",
        "init / pack / upload ms",
        "BVH build ms",
        "upload B first / static / moved",
        "mismatch",
        "depth err median / p99",
        "perceived err p99",
        "NaN",
    ]
    several = len({r.get("machine") for r in results["rows"]}) > 1
    if several:
        header.insert(1, "machine")
    by_scene: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for row in results["rows"]:
        by_scene[row["scene"]].append(row)
    for scene, rows in by_scene.items():
        ok = [r for r in rows if r["status"] == "ok"]
        info = results["scenes"][scene]
        out.append(
            f"### {scene}: {info['description']} ({info['triangles']:,} triangles, max_events "
            f"{info['max_events']}{'' if info['euclidean'] else ', non-Euclidean'})"
        )
        out.append("")
        if not ok:
            out += ["No setting could trace this scene (see below).", ""]
            continue
        table = []
        for r in ok:
            f, e = r["frame"], r["errors"]
            table.append(
                [
                    r["label"],
                    "x".join(map(str, r["size"])),
                    f"{_ms(f['median_ms'])} ({_ms(f['min_ms'])}–{_ms(f['max_ms'])})",
                    _num(r["mrays_per_s"]),
                    _ratio(r.get("embree_ratio"))
                    + (f" (paired {_ratio(r['embree_paired']['ratio'])})" if r.get("embree_paired") else "")
                    + (
                        f" (hits only {_ratio(r['embree_trace_paired']['ratio'])})"
                        if r.get("embree_trace_paired")
                        else ""
                    ),
                    _ms(r["first_frame_ms"]),
                    f"{_ms(r['init_ms'])} / {_ms(r['pack_ms'])} / {_ms(r['upload_ms'])}",
                    _ms(r["bvh_build_ms"]),
                    f"{r['upload_bytes']:,} / {r['tick_static_bytes']} / {r.get('tick_moved_bytes')}",
                    _pct(e["mismatch"]),
                    f"{_num(e['depth_median'])} / {_num(e['depth_p99'])}",
                    _num(e["perceived_p99"]),
                    str(e["nan_count"]),
                ]
            )
            if several:
                table[-1].insert(1, f"{r['machine']} ({r.get('device', '?')})")
        out += [*markdown_table(header, table), ""]
    return out


def _problems(results: dict[str, Any]) -> list[str]:
    groups: dict[tuple[str, str, str], list[str]] = defaultdict(list)
    for r in results["rows"]:
        if r["status"] != "ok":
            groups[(r["scene"], r["backend"], r["status"])].append(r["label"])
    if not groups:
        return []
    rows = [
        [scene, backend, f"{len(labels)} ({', '.join(labels[:3])}{', …' if len(labels) > 3 else ''})", status]
        for (scene, backend, status), labels in groups.items()
    ]
    return ["## Cells that did not run", "", *markdown_table(["scene", "backend", "settings", "status"], rows), ""]


def _swept(results: dict[str, Any]) -> list[str]:
    config = results["config"]
    values: dict[str, list[str]] = defaultdict(list)
    for s in results["settings"]:
        if s["sweep"]:
            values[f"{s['backend']} {s['sweep']}"].append(s["value"])
    lines = ["## What was swept and how it was measured", ""]
    lines += [f"- **{name}**: {SWEEPS[name]}" for name in config["sweeps"]]
    lines += [
        "",
        "Values (beside each backend's base: f32, the scene's max_events, full size, leaf 4, "
        "GLSL work group 8x8 with auto tables, OpenCL local size 16x16): "
        + "; ".join(f"{k}: {', '.join(v)}" for k, v in values.items())
        + ".",
        "",
    ]
    lines += [
        f"- Frame time: median and min–max of {config['repeat']} frames after a warm-up frame, reading back the "
        "colour image as the app does (the reference backend: one frame). Each cell starts a fresh backend; "
        "its start-up, packing (BVH from the cache), first upload, first frame (all AOVs; kernel compile "
        "included: GLSL compiles in each new context, OpenCL reads PoCL's disk cache after a first build) and "
        "an uncached BVH build of the scene's meshes are reported apart.",
        "- Mrays/s: primary rays (width x height) per second at the median frame time.",
        "- Upload: bytes of the first upload, of a static tick (should be 0) and of a tick after one entity moved.",
        "- Errors: against the float64 reference at the same scene, camera, size and max_events, cached on disk "
        f"({results['reference_cache']['folder']}; this run: {results['reference_cache']['hits']} hits, "
        f"{results['reference_cache']['misses']} renders). Mismatch: pixels whose instance id differs; depth and "
        "perceived: relative error where both hit the same instance; NaN: in depth and perceived.",
        "- Embree: every mode timed (one thread; two threads over halves of the rays; two spawned processes, each "
        "with its own scene and half the rays, sent once); ratios use the best. For base settings the ratio is "
        "also measured *paired*: Embree's best trace alternates with the backend's frame, repeat times, and the "
        "median of the per-pair ratios is reported (this machine is shared; pairing cancels most background "
        "load), once against the shaded frame and once against the frame of the hits alone (depth and "
        "instance, no shading: Embree's outputs), which is the ratio the targets read. Geometry is "
        "camera-relative float32 like the float32 backends' and rays start at the origin.",
        "",
    ]
    return lines


def _devices(machine: dict[str, Any]) -> str:
    return "; ".join(
        f"{name}: {info.get('unavailable') or info.get('renderer') or info.get('device') or '?'}"
        for name, info in machine["backends"].items()
    )


def render_report(results: dict[str, Any]) -> str:
    """The Markdown report of a results document."""
    if results.get("format") != "aberrant-bench":
        raise AberrantError("not an aberrant bench results document")
    m, c = results["machine"], results["config"]
    devices = _devices(m)
    load = m.get("load_average", {})
    lines = [
        "# aberrant bench: speed against error",
        "",
        f"**Machine:** {m['cpu']}, {m['cores']} cores; {m['platform']}; Python {m['python']}, NumPy {m['numpy']}.  ",
        f"**Devices:** {devices}; {m['embree']}.  ",
        f"**Run:** `{c['command'] or 'aberrant bench'}` on {results['started']}, took "
        f"{results['duration_s']:.0f} s; size {c['size'][0]}x{c['size'][1]}, repeat {c['repeat']}"
        f"{', quick' if c['quick'] else ''}. Load average {_num(load.get('start'))} at the start, "
        f"{_num(load.get('end'))} at the end (other work on the machine slows frames; ratios less so).",
        "",
    ]
    machines = results.get("machines", {})
    if len(machines) > 1:
        lines[3:5] = [f"**Machines:** {len(machines)}, each cell's named in its label (`@ machine`).  "]
        for name, info in machines.items():
            facts = f"{info['cpu']}, {info['cores']} cores; {info['platform']}; {_devices(info)}"
            lines.insert(-1, f"- **{name}:** {facts}.")
        lines.insert(-1, "")
    lines += _targets(results) + _headline(results)
    lines += ["## Speed against error", "", "![frame time against error](speed_vs_error.png)", ""]
    lines += [
        results.get("plot_note", ""),
        "",
        *space_section(results),
        *hotel_section(results),
        *_overhead(results),
        *_embree(results),
        *image_section(results),
        *features_section(results),
    ]
    lines += _detail(results) + _problems(results) + _swept(results)
    return "\n".join(lines).rstrip() + "\n"
