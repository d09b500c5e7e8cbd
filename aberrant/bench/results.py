"""The bench's results document and its outputs: ``report.md``, ``results.json`` and ``speed_vs_error.png``
(and ``space_count.png`` when the run measured that sweep), rendered in memory and written through
temporary files and renames, so an interrupted or failed run never leaves a half-written report beside an
old plot; ``--rerender`` writes them again from earlier runs' ``results.json``.
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any

from aberrant.bench import embree
from aberrant.bench.merge import FORMAT, merge_results, read_results
from aberrant.bench.paired import SPACE_PLOT, has_space
from aberrant.bench.plot import plot_png, space_plot_png
from aberrant.bench.report import render_report
from aberrant.bench.sweeps import Setting
from engine.atomic_files import write_atomically

VERSION = 1
OUTPUTS: tuple[str, ...] = ("report.md", "results.json", "speed_vs_error.png")


def stamp(rows: list[dict[str, Any]], machine: dict[str, Any]) -> list[dict[str, Any]]:
    """Each row told the machine and the device it ran on (results from several machines stay apart)."""
    for row in rows:
        info = machine["backends"].get(row["backend"], {})
        row["machine"] = machine["name"]
        row["device"] = info.get("unavailable") or info.get("renderer") or info.get("device") or "?"
    return rows


def document(
    config: dict[str, Any],
    started: float,
    settings: list[Setting],
    scenes: dict[str, Any],
    anchors: dict[str, Any],
    rows: list[dict[str, Any]],
    overhead: list[dict[str, Any]],
    machines: dict[str, dict[str, Any]],
) -> dict[str, Any]:
    """The results document (``config``: the run's settings as :meth:`BenchConfig.as_dict` gives them);
    ``machine`` is the first machine's facts, ``machines`` every one's by name."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "started": time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(started)),
        "duration_s": time.time() - started,
        "config": config,
        "machine": next(iter(machines.values())),
        "machines": machines,
        "settings": [s.as_dict() for s in settings],
        "scenes": scenes,
        "embree": anchors,
        "rows": rows,
        "overhead": overhead,
    }


def embree_ratio(row: dict[str, Any], anchor: dict[str, Any]) -> None:
    """The row's rays/s as a multiple of Embree's on the same scene and size (or why there is none)."""
    if anchor.get("status") != "ok":
        row["embree_ratio"], row["embree_note"] = None, anchor.get("status")
        return
    entry = anchor["sizes"].get(f"{row['size'][0]}x{row['size'][1]}", {})
    if row.get("status") != "ok" or entry.get("status") != "ok":
        row["embree_ratio"], row["embree_note"] = None, entry.get("status", "no embree run at this size")
        return
    paired = row.get("embree_paired") or {}
    if paired.get("shadows_off"):  # paired on the frame without shadow rays: its median, not the lit one's
        width, height = row["size"]
        row["embree_ratio"] = embree.mrays(paired["frame_ms"], width * height) / entry["mrays_per_s"]
        row["embree_note"] = "shadows off for the pairing"
        return
    row["embree_ratio"] = row["mrays_per_s"] / entry["mrays_per_s"]
    row["embree_note"] = ""


def _clean(value: Any) -> Any:
    """Strict JSON: NaN and infinities become null."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


def write_outputs(results: dict[str, Any], out: Path) -> list[Path]:
    """Render the report and the plots, then write the files atomically.

    ``space_count.png`` is written when the run measured the space-count sweep; otherwise an earlier run's is
    removed, so the folder never holds a plot its report does not show.
    """
    out.mkdir(parents=True, exist_ok=True)
    png, plot_note = plot_png(results)
    results["plot_note"] = plot_note
    text = render_report(results)
    data = json.dumps(_clean(results), indent=1, allow_nan=False).encode()
    files = dict(zip([out / name for name in OUTPUTS], (text.encode(), data, png), strict=True))
    space_plot = out / SPACE_PLOT
    if has_space(results):
        files[space_plot] = space_plot_png(results)
    write_atomically(files)
    if not has_space(results):
        space_plot.unlink(missing_ok=True)
    return list(files)


def rerender(results_paths: Path | list[Path], out: Path) -> list[Path]:
    """Write the report and plot again from earlier runs' results.json (no measuring); several are merged."""
    paths = [Path(results_paths)] if isinstance(results_paths, str | os.PathLike) else [Path(p) for p in results_paths]
    return write_outputs(merge_results([(path, read_results(path)) for path in paths]), out)
