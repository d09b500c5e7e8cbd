"""What ``aberrant bench`` sweeps: per backend, a base setting and one-knob-at-a-time variations of it.

A *setting* is everything that decides a frame besides the scene: backend,
precision, ``max_events``, frame size, the BVH's leaf size and each
backend's own knobs (GLSL work-group shape and table store, OpenCL local
size). Sweeping one knob at a time around the base keeps the count linear in
the knobs; each sweep becomes one line on the plot.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

from engine.errors import AberrantError
from engine.records import Precision

#: Every sweep, with what it varies (the report lists these).
SWEEPS: dict[str, str] = {
    "precision": "tracing precision: f32, f64 where the backend offers it",
    "max_events": "the event limit (kernel variant MAX_EVENTS); the reference is rendered with the same limit",
    "size": "frame size: a quarter, half and all of --size on each side",
    "leaf": "BVH leaf size (BvhParams.max_leaf_size): build time and tree size against trace speed",
    "workgroup": "GLSL compute work-group shape (local_size_x x local_size_y)",
    "tables": "GLSL table store: RGBA32UI images (the llvmpipe default) or storage buffers",
    "local_size": "OpenCL work-group (local) size; 'driver' lets the OpenCL driver choose",
    "spp": "samples per pixel (anti-aliasing): frame time against the colour's error to a many-sample image",
    "shadows": "every light's shadows off: the time saved against the colour's error to the shadowed many-sample "
    "image (scenes with a shadowing light only)",
}
#: Which sweeps apply to which backend (the reference has no knobs but the frame's size).
BACKEND_SWEEPS: dict[str, tuple[str, ...]] = {
    "glsl": ("precision", "max_events", "size", "leaf", "workgroup", "tables", "spp", "shadows"),
    "opencl": ("precision", "max_events", "size", "leaf", "local_size", "spp", "shadows"),
    "reference": ("spp", "shadows"),
}
#: The sweeps whose cells measure the colour's error to the many-sample images (the base cells alongside).
IMAGE_SWEEPS: tuple[str, ...] = ("spp", "shadows")
QUICK_SWEEPS: tuple[str, ...] = ("precision", "max_events", "leaf")
#: Values swept. Where a tuple lists the base value (first, or BASE_LEAF), it is the base setting itself; the
#: base ``max_events`` is the scene's own.
LEAF_SIZES: tuple[int, ...] = (1, 2, 4, 8, 16)
QUICK_LEAF_SIZES: tuple[int, ...] = (4, 8)
MAX_EVENTS: tuple[int, ...] = (4, 64)
QUICK_MAX_EVENTS: tuple[int, ...] = (4,)
WORKGROUPS: tuple[tuple[int, int], ...] = ((8, 8), (16, 16), (4, 4), (32, 4))
TABLE_STORES: tuple[str, ...] = ("auto", "ssbo")
LOCAL_SIZES: tuple[tuple[int, int] | None, ...] = ((16, 16), (8, 8), (32, 8), None)
SAMPLE_COUNTS: tuple[int, ...] = (1, 2, 4, 8, 16)
#: The many-sample images colour errors are measured against (the backend's own, and the reference's).
TARGET_SPP = 64
BASE_LEAF = 4


@dataclass(frozen=True)
class Setting:
    """One point of a sweep: a backend configured one way (``sweep`` names the knob varied, '' for the base)."""

    backend: str
    precision: Precision = "f32"
    options: tuple[tuple[str, Any], ...] = ()  # backend constructor keywords
    leaf: int = BASE_LEAF
    max_events: int | None = None  # None: the scene's own
    size_divisor: int = 1  # the frame is --size divided by this on each side
    spp: int = 1  # samples a pixel
    shadows: bool = True  # False: every light of the scene traced without its shadow rays
    sweep: str = ""
    value: str = "base"

    @property
    def kwargs(self) -> dict[str, Any]:
        return dict(self.options)

    @property
    def family(self) -> str:
        """The backend and precision: one marker, one Embree ratio line in the report."""
        return f"{self.backend} {self.precision}"

    @property
    def label(self) -> str:
        """A short unique name, e.g. ``glsl f32``, ``opencl f32 leaf=8``."""
        return (
            self.family if not self.sweep or self.sweep == "precision" else f"{self.family} {self.sweep}={self.value}"
        )

    @property
    def is_base(self) -> bool:
        return self.sweep in ("", "precision")

    def size_for(self, size: tuple[int, int]) -> tuple[int, int]:
        return (max(8, size[0] // self.size_divisor), max(8, size[1] // self.size_divisor))

    def as_dict(self) -> dict[str, Any]:
        return {
            "backend": self.backend,
            "precision": self.precision,
            "options": {k: _jsonable(v) for k, v in self.options},
            "leaf": self.leaf,
            "max_events": self.max_events,
            "size_divisor": self.size_divisor,
            "spp": self.spp,
            "shadows": self.shadows,
            "sweep": self.sweep,
            "value": self.value,
            "label": self.label,
        }


def _jsonable(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def _fmt(value: Any) -> str:
    if value is None:
        return "driver"
    if isinstance(value, tuple):
        return "x".join(str(v) for v in value)
    return str(value)


def settings_for(
    backend: str, precisions: Sequence[Precision], sweeps: Sequence[str], quick: bool, spp: int = 1
) -> list[Setting]:
    """The base setting of ``backend`` (``spp`` samples a pixel), its other precisions, then each applicable
    sweep's other points."""
    allowed = BACKEND_SWEEPS.get(backend, ())
    base_precision = precisions[0]
    base = Setting(backend, base_precision, spp=spp)
    out = [base]
    if "precision" in sweeps and "precision" in allowed:
        out += [replace(base, precision=p, sweep="precision", value=p) for p in precisions[1:]]
    chosen = [s for s in sweeps if s in allowed and s != "precision"]
    for sweep in chosen:
        if sweep == "max_events":
            out += [
                replace(base, max_events=m, sweep=sweep, value=str(m))
                for m in (QUICK_MAX_EVENTS if quick else MAX_EVENTS)
            ]
        elif sweep == "spp":
            out += [replace(base, spp=n, sweep=sweep, value=str(n)) for n in SAMPLE_COUNTS if n != spp]
        elif sweep == "shadows":
            out.append(replace(base, shadows=False, sweep=sweep, value="off"))
        elif sweep == "size":
            out += [replace(base, size_divisor=d, sweep=sweep, value=f"1/{d}") for d in (4, 2)]
        elif sweep == "leaf":
            leaves = QUICK_LEAF_SIZES if quick else LEAF_SIZES
            out += [replace(base, leaf=n, sweep=sweep, value=str(n)) for n in leaves if n != BASE_LEAF]
        elif sweep == "workgroup":
            out += [replace(base, options=(("workgroup", w),), sweep=sweep, value=_fmt(w)) for w in WORKGROUPS[1:]]
        elif sweep == "tables":
            out += [replace(base, options=(("tables", t),), sweep=sweep, value=t) for t in TABLE_STORES[1:]]
        elif sweep == "local_size":
            out += [replace(base, options=(("local_size", s),), sweep=sweep, value=_fmt(s)) for s in LOCAL_SIZES[1:]]
    return out


def check_sweeps(names: Sequence[str]) -> list[str]:
    """Validated sweep names (``all`` for every one)."""
    out: list[str] = []
    for name in names:
        if name == "all":
            out += [s for s in SWEEPS if s not in out]
        elif name in SWEEPS:
            out += [name] if name not in out else []
        elif name != "none":
            raise AberrantError(f"unknown sweep {name!r}; choose from all, none, {', '.join(SWEEPS)}")
    return out
