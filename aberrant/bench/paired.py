"""What the cells timed against a plain twin measured: the ``space-count`` sweep, the hotel's views and the
image features' costs, their lines, goals and report sections.

Every such cell holds ``baseline_paired``: its frames alternated with the
plain scene's on a second backend of the same setting, ``inverse`` being
the median of the per-pair ratios (this scene's frame over the plain one's).
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from aberrant.bench.features import FEATURES
from aberrant.bench.markdown import markdown_table
from aberrant.bench.space import COUNTS, KINDS, PLACEMENTS, PLAIN, parse_space_name

#: Out of view, 1,024 portals or boxes cost at most this much over the plain frame; in view, the ratio at
#: 1,024 over the ratio at 4 (the cost grows with what a ray passes, which stays the same, not with N).
SPACE_GOAL = 1.15
SPACE_PLOT = "space_count.png"
WHERE = {"out": "out of view", "in": "in view"}


def paired_ratio(row: dict[str, Any]) -> float | None:
    """The cell's frame time over its plain twin's (median of paired ratios), or ``None`` when not measured."""
    paired = row.get("baseline_paired")
    return float(paired["inverse"]) if row.get("status") == "ok" and paired else None


def space_series(results: dict[str, Any]) -> dict[tuple[str, str, str], dict[int, float]]:
    """(kind, placement, family) -> {N: paired ratio} over the measured space-count cells."""
    out: dict[tuple[str, str, str], dict[int, float]] = defaultdict(dict)
    for row in results["rows"]:
        parsed = parse_space_name(row["scene"])
        ratio = paired_ratio(row)
        if parsed is not None and ratio is not None:
            kind, placement, count = parsed
            out[(kind, placement, row["family"])][count] = ratio
    return dict(out)


def has_space(results: dict[str, Any]) -> bool:
    return any(parse_space_name(r["scene"]) is not None for r in results["rows"])


def _goal(placement: str, series: dict[int, float]) -> tuple[str, str]:
    """The goal's text and whether this line meets it (at N = 1,024, the sweep's top)."""
    top = max(COUNTS)
    if placement == "out":
        text = f"<= {SPACE_GOAL}x at {top:,}"
        value = series.get(top)
    else:
        text = f"{top:,} / {min(COUNTS)} <= {SPACE_GOAL}"
        low = series.get(min(COUNTS))
        value = series[top] / low if top in series and low else None
    if value is None:
        return text, "not measured"
    return text, f"{value:.2f}: " + ("**met**" if value <= SPACE_GOAL else "**not met**")


def space_table(results: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    """The sweep's table: a line per kind, placement and backend, N across, the goal and whether it is met."""
    series = space_series(results)
    plain = {r["family"]: r for r in results["rows"] if r["scene"] == PLAIN and r.get("status") == "ok"}
    families = list(dict.fromkeys(r["family"] for r in results["rows"] if parse_space_name(r["scene"])))
    header = ["kind", "placement", "backend", "N = 0 ms", *[f"{n:,}" for n in COUNTS], "goal", "measured"]
    lines = []
    for kind in KINDS:
        for placement in PLACEMENTS:
            for family in families:
                line = series.get((kind, placement, family), {})
                base = plain.get(family)
                goal, status = _goal(placement, line)
                cells = [f"{line[n]:.2f}x" if n in line else "–" for n in COUNTS]
                ms = f"{base['frame']['median_ms']:.1f}" if base else "–"
                lines.append([kind, WHERE[placement], family, ms, *cells, goal, status])
    return header, lines


#: The hotel's goal per view: its frame over the same level with every portal shut.
HOTEL_GOAL = 1.3
HOTEL_PREFIX = "hotel-view-"


def _paired_line(row: dict[str, Any], goal: float | None) -> list[str]:
    """Both frame times, the paired ratio, the goal and whether it is met (``–`` where there is no goal)."""
    limit = "–" if goal is None else f"<= {goal}x"
    ratio = paired_ratio(row)
    if ratio is None:
        return ["–", "–", row["status"] if row["status"] != "ok" else "not paired", limit, "not measured"]
    paired = row["baseline_paired"]
    met = "–" if goal is None else "**met**" if ratio <= goal else "**not met**"
    return [f"{paired['frame_ms']:.1f}", f"{paired['other_ms']:.1f}", f"{ratio:.2f}x", limit, met]


def hotel_table(results: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    """A line per hotel view and backend: frame times of both, the paired ratio, the goal and whether it is met."""
    header = ["view", "backend", "hotel ms", "doors shut ms", "paired ratio", "goal", "status"]
    lines = []
    for row in results["rows"]:
        if row["scene"].startswith(HOTEL_PREFIX) and row["setting"]["sweep"] == "":
            lines.append([row["scene"][len(HOTEL_PREFIX) :], row["family"], *_paired_line(row, HOTEL_GOAL)])
    return header, lines


def features_table(results: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    """A line per feature and fast backend: with and without it, the paired ratio, the goal, whether it is met."""
    header = ["feature", "backend", "with ms", "without ms", "paired ratio", "goal", "status"]
    lines = []
    for feature in FEATURES:
        for row in results["rows"]:
            if row["scene"] == feature.name and row["setting"]["sweep"] == "" and row["backend"] != "reference":
                lines.append([feature.what, row["family"], *_paired_line(row, feature.goal)])
    return header, lines


def space_section(results: dict[str, Any]) -> list[str]:
    """The report's space-count section: what was measured, the table and the plot (none without the sweep)."""
    if not has_space(results):
        return []
    header, rows = space_table(results)
    return [
        "## Space count: frame time against the number of portals and boxes",
        "",
        "A floor and 30 boxes in view, plus N portals (N / 2 linked pairs) or N metric aberration boxes, placed "
        "behind the camera (*out of view*: no ray reaches them) or on a grid across the view that covers a "
        "quarter of it whatever N is (*in view*: a ray passes at most one). Each figure is the frame time over "
        "the same frame without them (N = 0; its time in the fourth column), the two scenes' frames alternated "
        "so both see the same load: the median of the per-pair ratios. Goals: out of view, 1,024 of them cost "
        f"at most {SPACE_GOAL}x; in view, the ratio at 1,024 is at most {SPACE_GOAL} times the ratio at 4.",
        "",
        *markdown_table(header, rows),
        "",
        f"![paired frame-time ratio against N]({SPACE_PLOT})",
        "",
    ]


def hotel_section(results: dict[str, Any]) -> list[str]:
    """The report's hotel section: each view against its doors shut (none when no view was measured)."""
    header, rows = hotel_table(results)
    if not rows:
        return []
    return [
        "## The hotel against its doors shut",
        "",
        "The `hotel` demo (104 portals) from each of its views, against the same level with every portal "
        "replaced by a quad of its shape (the doors shut: the same geometry, Euclidean), frames alternated: "
        f"the median of the per-pair ratios. Goal: at most {HOTEL_GOAL}x per view.",
        "",
        *markdown_table(header, rows),
        "",
    ]


def features_section(results: dict[str, Any]) -> list[str]:
    """The report's image-feature costs (none when no ``features`` scene was measured on a fast backend)."""
    header, rows = features_table(results)
    if not rows:
        return []
    return [
        "## What the image features cost",
        "",
        "The `starter` demo with each feature against the same scene without it, on two backends of the same "
        "setting, frames alternated: the median of the per-pair ratios. *Flat*: every mesh untextured and "
        "without smooth normals; *no lights*: no Light entity (the implicit sun, which casts no shadows), so the "
        "two sun lines part the shadow rays' cost from the light's; *4 samples a pixel* against 1 of the same "
        "scene.",
        "",
        *markdown_table(header, rows),
        "",
    ]
