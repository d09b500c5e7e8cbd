"""``report.md``: the results as tables a reader can act on.

Targets first (each measured figure beside its goal), then the headline
matrix (scene x backend, Mrays/s and the ratio to Embree), the plot, the
engine and non-Euclidean overheads, the Embree anchor, the image error of
samples a pixel and of shadows off, what the image features cost, every cell in detail,
what could not run and why, and what was swept.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from aberrant.bench.embree import MODES
from aberrant.bench.images import image_section
from aberrant.bench.markdown import markdown_table, millis, number, percent, times
from aberrant.bench.paired import features_section, hotel_section, space_section
from aberrant.bench.sweeps import SWEEPS
from aberrant.bench.targets import base_rows, best_ratio, targets_section
from engine.errors import AberrantError


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
                ratio = f" ({times(best_ratio(row))}{unlit})" if row.get("embree_ratio") is not None else ""
                cells.append(f"{number(row['mrays_per_s'])}{ratio}")
        size = "x".join(map(str, info["fixed_size"] or results["config"]["size"]))
        entry = results["embree"].get(scene, {}).get("sizes", {}).get(size, {})
        cells.append(number(entry["mrays_per_s"]) if entry.get("status") == "ok" else "–")
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
            f"{millis(e['median_ms'])} ({millis(e['min_ms'])}–{millis(e['max_ms'])})",
            *[millis(e["systems_ms"].get(s)) for s in systems],
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
                    *[number(e["modes"][m]["mrays_per_s"]) for m in MODES],
                    millis(e["build_ms"]),
                    percent(err["mismatch"]),
                    number(err["depth_p99"]),
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
                    f"{millis(f['median_ms'])} ({millis(f['min_ms'])}–{millis(f['max_ms'])})",
                    number(r["mrays_per_s"]),
                    times(r.get("embree_ratio"))
                    + (f" (paired {times(r['embree_paired']['ratio'])})" if r.get("embree_paired") else "")
                    + (
                        f" (hits only {times(r['embree_trace_paired']['ratio'])})"
                        if r.get("embree_trace_paired")
                        else ""
                    ),
                    millis(r["first_frame_ms"]),
                    f"{millis(r['init_ms'])} / {millis(r['pack_ms'])} / {millis(r['upload_ms'])}",
                    millis(r["bvh_build_ms"]),
                    f"{r['upload_bytes']:,} / {r['tick_static_bytes']} / {r.get('tick_moved_bytes')}",
                    percent(e["mismatch"]),
                    f"{number(e['depth_median'])} / {number(e['depth_p99'])}",
                    number(e["perceived_p99"]),
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
        f"{', quick' if c['quick'] else ''}. Load average {number(load.get('start'))} at the start, "
        f"{number(load.get('end'))} at the end (other work on the machine slows frames; ratios less so).",
        "",
    ]
    machines = results.get("machines", {})
    if len(machines) > 1:
        lines[3:5] = [f"**Machines:** {len(machines)}, each cell's named in its label (`@ machine`).  "]
        for name, info in machines.items():
            facts = f"{info['cpu']}, {info['cores']} cores; {info['platform']}; {_devices(info)}"
            lines.insert(-1, f"- **{name}:** {facts}.")
        lines.insert(-1, "")
    lines += targets_section(results) + _headline(results)
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
