"""``speed_vs_error.png``: frame time (log) against error, one marker per backend, a line per sweep, the Pareto front;
and ``space_count.png``: the space-count sweep's paired ratios against N.

Each point is one setting summarised over the scenes that every compared
setting traced (geometric mean of frame times, so no one big scene
dominates; mean of the errors), so points are comparable. Two panels: the
instance-id mismatch and the 99th-percentile relative depth error; a third,
the colour's mean absolute error against the reference's many-sample image,
when the cells measured it (the spp and shadows sweeps). Zero errors (the reference, most
f64 rows) sit on the panel's floor, labelled.
Without matplotlib (the ``bench`` extra) the PNG is a notice drawn with
Pillow, and the report says so.
"""

from __future__ import annotations

import io
import math
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from aberrant.bench.metrics import DEPTH_P99_MAX, MISMATCH_MAX_EUCLIDEAN, geometric_mean, pareto_front
from aberrant.bench.paired import SPACE_GOAL, WHERE, space_series
from aberrant.bench.space import COUNTS, KINDS

MARKERS: dict[str, str] = {"glsl": "o", "opencl": "s", "reference": "D", "embree": "*"}
SWEEP_COLORS: dict[str, str] = {
    "precision": "#444444",
    "max_events": "#1f77b4",
    "size": "#2ca02c",
    "leaf": "#d62728",
    "workgroup": "#9467bd",
    "tables": "#8c564b",
    "local_size": "#e377c2",
    "spp": "#17becf",
    "shadows": "#bcbd22",
}
MISMATCH_FLOOR_PCT = 1e-4
DEPTH_FLOOR = 1e-16
COLOR_FLOOR = 1e-2


def _value(x: float | None) -> float:
    """A plottable number: ``None`` (JSON's NaN or infinity) and non-finite values become NaN (not drawn)."""
    return float(x) if x is not None and math.isfinite(x) else math.nan


@dataclass
class Point:
    label: str
    backend: str
    family: str
    sweep: str
    time_ms: float
    mismatch_pct: float
    depth_p99: float
    color_mae: float = math.nan  # levels of 255 against the reference's many-sample image; NaN: not measured


def _color_mae(rows: list[dict[str, Any]]) -> float:
    """The mean of the rows' colour error against the reference's many-sample image (NaN if one lacks it)."""
    values = [_value((r.get("image_errors") or {}).get("ref_mae")) for r in rows]
    return sum(values) / len(values) if values else math.nan


def points(results: dict[str, Any]) -> tuple[list[Point], list[str]]:
    """One point per setting over the common scenes (and Embree's, when it traced all of them)."""
    ok: dict[str, dict[str, dict[str, Any]]] = defaultdict(dict)  # label -> scene -> row
    meta: dict[str, dict[str, Any]] = {}
    for row in results["rows"]:
        meta.setdefault(row["label"], row)
        if row["status"] == "ok":
            ok[row["label"]][row["scene"]] = row
    # A fixed-size scene skips the size sweep, a scene without a shadowing light the shadows sweep: its base
    # frame (the same frame) stands in for those points.
    base_label = {m["family"]: label for label, m in meta.items() if m["setting"]["sweep"] in ("", "precision")}
    skips: dict[str, Callable[[dict[str, Any]], bool]] = {
        "size": lambda info: bool(info.get("fixed_size")),
        "shadows": lambda info: "shadows" in info.get("skipped_sweeps", []),
    }
    for label, m in meta.items():
        base = ok.get(base_label.get(m["family"], ""), {})
        skipped = skips.get(m["setting"]["sweep"])
        if skipped is not None:
            for scene, row in base.items():
                if skipped(results["scenes"].get(scene, {})):
                    ok[label].setdefault(scene, row)
    sets = [set(ok[label]) for label in meta]
    common = set.intersection(*sets) if sets and all(sets) else set()
    if not common:  # no scene every setting traced: each point over its own scenes
        common = set().union(*(set(v) for v in ok.values())) if ok else set()
    out = []
    for label, rows in ok.items():
        chosen = [rows[s] for s in sorted(common) if s in rows]
        if not chosen:
            continue
        m = meta[label]
        out.append(
            Point(
                label,
                m["backend"],
                m["family"],
                m["setting"]["sweep"],
                geometric_mean([r["frame"]["median_ms"] for r in chosen]),
                100 * sum(_value(r["errors"]["mismatch"]) for r in chosen) / len(chosen),
                sum(_value(r["errors"]["depth_p99"]) for r in chosen) / len(chosen),
                _color_mae(chosen),
            )
        )
    anchors = []
    for scene in sorted(common):
        info = results["scenes"].get(scene, {})
        size = "x".join(map(str, info.get("fixed_size") or results["config"]["size"]))
        entry = results["embree"].get(scene, {}).get("sizes", {}).get(size, {})
        if entry.get("status") == "ok":
            anchors.append(entry)
    if common and len(anchors) == len(common):
        out.append(
            Point(
                "embree",
                "embree",
                "embree",
                "",
                geometric_mean([a["frame"]["median_ms"] for a in anchors]),
                100 * sum(_value(a["errors"]["mismatch"]) for a in anchors) / len(anchors),
                sum(_value(a["errors"]["depth_p99"]) for a in anchors) / len(anchors),
            )
        )
    return out, sorted(common)


def _order(setting: dict[str, Any], sweep: str) -> float:
    """Where a setting sits on a sweep's axis, so each line runs in order of the knob (base included)."""
    options = setting["options"]
    if sweep == "leaf":
        return float(setting["leaf"])
    if sweep == "max_events":
        return float(setting["max_events"] or 16)
    if sweep == "size":
        return -float(setting["size_divisor"])
    if sweep in ("workgroup", "local_size"):
        shape = options.get(sweep, (8, 8) if sweep == "workgroup" else (16, 16))
        return math.inf if shape is None else float(shape[0] * shape[1])
    if sweep == "tables":
        return float(options.get("tables", "auto") != "auto")
    if sweep == "spp":
        return float(setting.get("spp", 1))
    if sweep == "shadows":
        return float(not setting.get("shadows", True))
    return float(setting["precision"] != "f32")


def _lines(results: dict[str, Any], pts: list[Point]) -> list[tuple[str, list[Point]]]:
    """(sweep, points in the knob's order) for each backend's sweeps, each through the base point."""
    by_label = {p.label: p for p in pts}
    groups: dict[tuple[str, str], list[tuple[float, Point]]] = defaultdict(list)
    base_of: dict[str, tuple[dict[str, Any], Point]] = {}
    for s in results["settings"]:
        p = by_label.get(s["label"])
        if p is None:
            continue
        if s["sweep"] == "":
            base_of[s["backend"]] = (s, p)
        else:
            groups[(s["backend"], s["sweep"])].append((_order(s, s["sweep"]), p))
    out = []
    for (backend, sweep), members in groups.items():
        if backend in base_of:
            base, point = base_of[backend]
            members = [*members, (_order(base, sweep), point)]
        out.append((sweep, [p for _, p in sorted(members, key=lambda m: m[0])]))
    return out


def note(results: dict[str, Any]) -> str:
    pts, common = points(results)
    if not pts:
        return "No setting traced any scene, so the plot is empty."
    return (
        f"Each point is one setting: the geometric mean of its median frame times and the mean of its errors "
        f"over the {len(common)} scene(s) every setting traced ({', '.join(common)}); on the size sweep a "
        f"fixed-size scene counts its base frame, and on the shadows sweep a scene without a shadowing light. "
        f"Zero errors are drawn on each panel's floor; Embree is drawn only when it traced every one of those "
        f"scenes (it traces Euclidean scenes only)."
    )


def _matplotlib_png(results: dict[str, Any]) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter

    pts, common = points(results)
    panels = [
        ("mismatch_pct", "instance-id mismatch (% of pixels, symlog)", MISMATCH_FLOOR_PCT),
        ("depth_p99", "depth relative error, 99th percentile (log)", DEPTH_FLOOR),
    ]
    if any(math.isfinite(p.color_mae) for p in pts):
        panels.append(("color_mae", "colour error vs the reference's 64-spp image (MAE, levels; log)", COLOR_FLOOR))
    fig, axes = plt.subplots(1, len(panels), figsize=(7 * len(panels), 6), dpi=110)
    for ax, (attr, ylabel, floor) in zip(axes, panels, strict=True):

        def y_of(p: Point, attr: str = attr, floor: float = floor) -> float:
            return getattr(p, attr) if attr == "mismatch_pct" else max(getattr(p, attr), floor)

        for sweep, members in _lines(results, pts):
            members = [m for m in members if math.isfinite(m.time_ms)]
            ax.plot(
                [m.time_ms for m in members],
                [y_of(m) for m in members],
                "-",
                lw=1.2,
                alpha=0.7,
                color=SWEEP_COLORS.get(sweep, "#999999"),
            )
        for p in pts:
            color = "#ff7f0e" if p.backend == "embree" else SWEEP_COLORS.get(p.sweep, "#111111")
            ax.scatter(
                p.time_ms,
                y_of(p),
                marker=MARKERS.get(p.backend.split(" @ ")[0], "x"),  # merged runs label backends "name @ machine"
                s=150 if p.backend == "embree" else 45,
                color=color,
                edgecolor="black",
                linewidth=0.5,
                zorder=3,
            )
        front = sorted(
            (pts[i] for i in pareto_front([(p.time_ms, getattr(p, attr)) for p in pts])), key=lambda p: p.time_ms
        )
        if front:
            ax.step(
                [p.time_ms for p in front],
                [y_of(p) for p in front],
                where="post",
                color="black",
                lw=1.5,
                ls="--",
                zorder=2,
            )
            ax.scatter(
                [p.time_ms for p in front],
                [y_of(p) for p in front],
                s=220,
                facecolors="none",
                edgecolors="black",
                linewidths=1.5,
                zorder=4,
            )
            for p in front:
                ax.annotate(p.label, (p.time_ms, y_of(p)), textcoords="offset points", xytext=(6, 6), fontsize=8)
        ax.set_xscale("log")
        if attr == "mismatch_pct":
            ax.set_yscale("symlog", linthresh=1e-2, linscale=0.5)
            ax.set_ylim(-1e-3, max(1.0, 2 * max((p.mismatch_pct for p in pts), default=0.0)))
            ax.axhline(100 * MISMATCH_MAX_EUCLIDEAN, color="#d62728", ls=":", lw=1)
            ax.text(
                0.0,
                100 * MISMATCH_MAX_EUCLIDEAN,
                " parity threshold (Euclidean)",
                fontsize=8,
                color="#d62728",
                va="bottom",
                transform=ax.get_yaxis_transform(),  # x in axes units: at the left edge whatever the data
            )
        elif attr == "color_mae":
            ax.set_yscale("log")
            top = max((p.color_mae for p in pts if math.isfinite(p.color_mae)), default=1.0)
            ax.set_ylim(floor / 3, max(1.0, 3 * top))
        else:
            ax.set_yscale("log")
            # Limits before the threshold line: with no points, autoscaling to the line alone would collapse.
            ax.set_ylim(floor / 3, max(1e-2, 10 * max((p.depth_p99 for p in pts), default=0.0)))
            ax.axhline(DEPTH_P99_MAX, color="#d62728", ls=":", lw=1)
            ax.text(
                0.0,
                DEPTH_P99_MAX,
                " parity threshold",
                fontsize=8,
                color="#d62728",
                va="bottom",
                transform=ax.get_yaxis_transform(),
            )
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.xaxis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}" if str(f"{v:g}")[0] in "25" else ""))
        ax.set_xlabel("frame time, ms (log; geometric mean over the scenes)")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.25)
    size = results["config"]["size"]
    fig.suptitle(
        f"aberrant bench: speed against error at {size[0]}x{size[1]} ({len(common)} scenes; dashed: Pareto front)",
        fontsize=12,
    )
    backends = sorted({p.backend for p in pts})
    sweeps = sorted({p.sweep for p in pts if p.sweep})
    handles = [
        Line2D(
            [],
            [],
            marker=MARKERS.get(b, "x"),
            ls="",
            color="#777777",
            markeredgecolor="black",
            markersize=12 if b == "embree" else 8,
            label=b,
        )
        for b in backends
    ]
    handles += [Line2D([], [], color=SWEEP_COLORS.get(s, "#999999"), lw=2, label=f"sweep: {s}") for s in sweeps]
    handles.append(Line2D([], [], color="black", ls="--", marker="o", mfc="none", label="Pareto front"))
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 7), fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.08, 1, 0.95))
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    plt.close(fig)
    return buffer.getvalue()


def notice_png(text: str) -> bytes:
    from PIL import Image, ImageDraw

    image = Image.new("RGB", (900, 120), "white")
    ImageDraw.Draw(image).text((20, 50), text, fill="black")
    buffer = io.BytesIO()
    image.save(buffer, "PNG")
    return buffer.getvalue()


def plot_png(results: dict[str, Any]) -> tuple[bytes, str]:
    """The PNG and a sentence for the report saying what it shows (or why it is only a notice)."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        text = "plot: matplotlib is not installed (pip install '.[bench]'); see the tables instead"
        return notice_png(text), text
    return _matplotlib_png(results), note(results)


def space_plot_png(results: dict[str, Any]) -> bytes:
    """``space_count.png``: paired ratio to N = 0 against N (both log), a panel per kind, a line per backend and
    placement (a notice without matplotlib)."""
    try:
        import matplotlib
    except ImportError:
        return notice_png("plot: matplotlib is not installed (pip install '.[bench]'); see the table instead")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, NullFormatter

    series = space_series(results)
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.5), dpi=110, sharey=True)
    colors = {"out": "#1f77b4", "in": "#d62728"}
    values = [v for line in series.values() for v in line.values() if math.isfinite(v) and v > 0]
    low, top = min([0.8, *[0.9 * v for v in values]]), max([1.5, *[1.3 * v for v in values]])
    ticks = [t for t in (0.25, 0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500) if low <= t <= top]
    for ax, kind in zip(axes, KINDS, strict=True):
        for (k, placement, family), line in sorted(series.items()):
            if k != kind:
                continue
            counts = sorted(line)
            ax.plot(counts, [line[n] for n in counts], ls="-" if family.startswith("opencl") else "--",
                    marker=MARKERS.get(family.split()[0], "x"), color=colors[placement],
                    label=f"{family}, {WHERE[placement]}")  # fmt: skip
        ax.axhline(1.0, color="black", lw=0.8)
        ax.axhline(SPACE_GOAL, color="#2ca02c", ls=":", lw=1.2)
        ax.text(max(COUNTS), SPACE_GOAL, f"goal out of view: {SPACE_GOAL}x ", fontsize=8, color="#2ca02c", va="top",
                ha="right")  # fmt: skip
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_ylim(low, top)
        ax.set_xlim(0.75 * min(COUNTS), 1.33 * max(COUNTS))
        ax.set_xticks(list(COUNTS))
        ax.set_yticks(ticks)
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}x"))
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(f"N: {kind} in the scene (log)")
        ax.set_title(f"{kind}: frame time over the frame without them")
        ax.grid(True, which="both", alpha=0.25)
        if any(k == kind for k, _, _ in series):
            ax.legend(fontsize=8)
    axes[0].set_ylabel("paired frame-time ratio to N = 0 (log)")
    size = results["config"]["size"]
    fig.suptitle(f"aberrant bench: space count at {size[0]}x{size[1]} (a floor and 30 boxes in view)", fontsize=12)
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    plt.close(fig)
    return buffer.getvalue()
