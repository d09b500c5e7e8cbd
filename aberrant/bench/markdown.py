"""Markdown for the bench's report: one table format and one way to write each kind of figure, for every
section."""

from __future__ import annotations

import math


def markdown_table(header: list[str], rows: list[list[str]]) -> list[str]:
    """The lines of a Markdown table (a ``|`` inside a cell becomes ``/``)."""
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(cell.replace("|", "/") for cell in row) + " |" for row in rows]
    return out


def number(value: float | None, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    if value == 0:
        return "0"
    if abs(value) >= 1e4 or abs(value) < 1e-3:
        return f"{value:.2e}"
    return f"{value:.{digits}g}"


def millis(value: float | None) -> str:
    return "–" if value is None else f"{value:.1f}" if value >= 10 else f"{value:.2f}"


def percent(fraction: float | None) -> str:
    return "–" if fraction is None else "0" if fraction == 0 else f"{100 * fraction:.3g} %"


def times(value: float | None) -> str:
    return "–" if value is None else f"{value:.2f}x"


def met_mark(ok: bool | None) -> str:
    return "not measured" if ok is None else ("**met**" if ok else "**not met**")
