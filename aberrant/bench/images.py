"""The report's image-error section: what more samples a pixel, or shadows off, cost and how far the colour
moves.

Each cell that measured it (the spp and shadows sweeps', and the base cells alongside) compares its colour
with TARGET_SPP samples a pixel of its own backend (the aliasing left) and of the float64 reference (aliasing
plus any difference of backend), as mean absolute error in levels of 255 and PSNR. The targets are always
the scene as built, shadows on: a shadows-off cell's error is what switching them off loses.
"""

from __future__ import annotations

import math
from typing import Any

from aberrant.bench.markdown import markdown_table


def _db(value: float | None) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    return "∞" if math.isinf(value) else f"{value:.1f} dB"


def _levels(value: float | None) -> str:
    return "–" if value is None else f"{value:.2f}"


def _shadows(row: dict[str, Any], results: dict[str, Any]) -> str:
    if not results["scenes"].get(row["scene"], {}).get("shadows"):
        return "none"
    return "on" if row["setting"].get("shadows", True) else "off"


def image_section(results: dict[str, Any]) -> list[str]:
    """The table of every cell with image errors, by scene and setting; nothing when none measured them."""
    rows = [r for r in results["rows"] if r["status"] == "ok" and r.get("image_errors")]
    if not rows:
        return []
    one_sample = {(r["scene"], r["family"]): r["frame"]["median_ms"] for r in rows
                  if r["setting"].get("spp", 1) == 1 and r["setting"].get("shadows", True)}  # fmt: skip
    target = rows[0]["image_errors"]["target_spp"]
    header = ["scene", "setting", "spp", "shadows", "frame ms", "x base", "vs own: MAE / PSNR",
              "vs reference: MAE / PSNR"]  # fmt: skip
    table = []
    order = sorted(rows, key=lambda r: (r["scene"], r["family"], not r["setting"].get("shadows", True),
                                        r["setting"].get("spp", 1)))  # fmt: skip
    for r in order:
        e, ms = r["image_errors"], r["frame"]["median_ms"]
        base = one_sample.get((r["scene"], r["family"]))
        table.append(
            [
                r["scene"],
                r["family"],
                str(r["setting"].get("spp", 1)),
                _shadows(r, results),
                f"{ms:.2f}",
                "–" if not base else f"{ms / base:.2f}x",
                f"{_levels(e['own_mae'])} / {_db(e['own_psnr'])}",
                f"{_levels(e['ref_mae'])} / {_db(e['ref_psnr'])}",
            ]
        )
    lines = [
        "## Image error: samples per pixel and shadows",
        "",
        f"Colour against {target} samples a pixel of the same backend (*own*: the aliasing left) and of the "
        "float64 reference (*reference*: aliasing and backend together), both of the scene with its shadows; "
        "MAE in levels of 255 over RGB, PSNR in dB (∞: identical). *Shadows off*: every light of the scene "
        "without its shadow rays, at the base spp, so its error is what switching them off loses and its "
        "*x base* (frame time over the 1-spp, shadows-on cell's; separate cells) what it saves. Depth and "
        "instance come from the pixel centre at every spp, so the geometric errors above do not change with it.",
        "",
        *markdown_table(header, table),
        "",
    ]
    unshadowed = [name for name, info in results["scenes"].items() if "shadows" in info.get("skipped_sweeps", [])]
    if unshadowed:
        lines += [f"The shadows sweep skipped {', '.join(unshadowed)}: no light there casts shadows.", ""]
    return lines
