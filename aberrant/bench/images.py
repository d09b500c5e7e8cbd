"""The report's image-error section: what more samples a pixel cost and how much closer the colour gets.

Each cell that measured it (the spp sweep's, and the base cells alongside) compares its colour with
TARGET_SPP samples a pixel of its own backend (the aliasing left) and of the float64 reference (aliasing
plus any difference of backend), as mean absolute error in levels of 255 and PSNR.
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


def image_section(results: dict[str, Any]) -> list[str]:
    """The table of every cell with image errors, by scene and setting; nothing when none measured them."""
    rows = [r for r in results["rows"] if r["status"] == "ok" and r.get("image_errors")]
    if not rows:
        return []
    one_sample = {(r["scene"], r["family"]): r["frame"]["median_ms"] for r in rows if r["setting"].get("spp", 1) == 1}
    target = rows[0]["image_errors"]["target_spp"]
    header = ["scene", "setting", "spp", "frame ms", "x 1 spp", "vs own: MAE / PSNR", "vs reference: MAE / PSNR"]
    table = []
    for r in sorted(rows, key=lambda r: (r["scene"], r["family"], r["setting"].get("spp", 1))):
        e, ms = r["image_errors"], r["frame"]["median_ms"]
        base = one_sample.get((r["scene"], r["family"]))
        table.append(
            [
                r["scene"],
                r["family"],
                str(r["setting"].get("spp", 1)),
                f"{ms:.2f}",
                "–" if not base else f"{ms / base:.2f}x",
                f"{_levels(e['own_mae'])} / {_db(e['own_psnr'])}",
                f"{_levels(e['ref_mae'])} / {_db(e['ref_psnr'])}",
            ]
        )
    return [
        "## Image error: samples per pixel",
        "",
        f"Colour against {target} samples a pixel of the same backend (*own*: the aliasing left) and of the "
        "float64 reference (*reference*: aliasing and backend together); MAE in levels of 255 over RGB, PSNR "
        "in dB (∞: identical). Depth and instance come from the pixel centre at every spp, so the geometric "
        "errors above do not change with it.",
        "",
        *markdown_table(header, table),
        "",
    ]
