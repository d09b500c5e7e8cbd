"""The one interface every tracer backend implements, and the registry that picks one.

Systems talk to a backend only through :class:`Backend`. A backend imports
its heavy dependency lazily (inside ``probe``/``__init__``), so importing this
module never needs moderngl or pyopencl, and a backend that cannot run says
why instead of crashing its caller.
"""

from __future__ import annotations

import importlib
import os
import sys
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from engine.camera_view import CameraView
from engine.errors import AberrantError, BackendUnavailable
from engine.packed import PackedScene, TableUpdate
from engine.records import Precision

#: Outputs a backend can write (docs/semantics.md, "What a frame holds").
AOVS: tuple[str, ...] = ("color", "depth", "perceived", "instance", "events")
#: Each AOV's element type and per-pixel shape in a :class:`Frame` (17 bytes a pixel for all five).
AOV_DTYPES: dict[str, tuple[np.dtype, tuple[int, ...]]] = {
    "color": (np.dtype(np.uint8), (4,)),
    "depth": (np.dtype(np.float32), ()),
    "perceived": (np.dtype(np.float32), ()),
    "instance": (np.dtype(np.int32), ()),
    "events": (np.dtype(np.uint8), ()),
}


def aov_bytes(aovs: Sequence[str]) -> int:
    """Bytes one pixel of these AOVs takes in a frame."""
    return sum(AOV_DTYPES[name][0].itemsize * int(np.prod(AOV_DTYPES[name][1], dtype=np.int64)) for name in aovs)


#: Registered backends: name -> "module:Class", imported on first use.
BACKENDS: dict[str, str] = {
    "reference": "backends.reference.backend:ReferenceBackend",
    "glsl": "backends.glsl.backend:GlslBackend",
    "opencl": "backends.opencl.backend:OpenClBackend",
}

#: ``auto`` tries these in order: fastest first.
AUTO_ORDER: tuple[str, ...] = ("opencl", "glsl", "reference")


@dataclass
class Frame:
    """A rendered frame's AOVs (row 0 = top) and how long it took."""

    width: int
    height: int
    color: np.ndarray | None = None  # (H, W, 4) uint8
    depth: np.ndarray | None = None  # (H, W) float32, path length L, +inf on a miss
    perceived: np.ndarray | None = None  # (H, W) float32, perceived length
    instance: np.ndarray | None = None  # (H, W) int32, entity id, -1 on a miss
    events: np.ndarray | None = None  # (H, W) uint8
    timings_ms: dict[str, float] = field(default_factory=dict)

    def aov(self, name: str) -> np.ndarray:
        value = getattr(self, name, None) if name in AOVS else None
        if value is None:
            raise KeyError(f"this frame has no {name!r} AOV (rendered: {', '.join(self.present())})")
        return value

    def present(self) -> list[str]:
        return [name for name in AOVS if getattr(self, name) is not None]


class Backend(ABC):
    """A tracer: uploads packed scene tables, renders frames."""

    name: ClassVar[str]
    #: Precisions this backend can trace at (the first is its default).
    precisions: ClassVar[tuple[Precision, ...]] = ("f32",)

    def __init__(self, precision: Precision | None = None) -> None:
        precision = precision or self.precisions[0]
        if precision not in self.precisions:
            raise BackendUnavailable(
                f"{self.name} backend cannot trace at precision {precision!r}; it offers {', '.join(self.precisions)}"
            )
        self.precision: Precision = precision

    #: Whether the packed tables should be relative to a floating origin near the camera (a wrapper backend
    #: sets it per instance, to the wrapped one's).
    camera_relative: bool = True
    #: The BVH width its packer should build (``ScenePacker(bvh_width=...)``): what it traverses fastest
    #: (a backend may set it per instance, e.g. by precision).
    bvh_width: int = 2
    #: Children per node of the top-level tree over instances its packer should build
    #: (``ScenePacker(tlas_width=...)``, :mod:`engine.tlas_wide`). Binary by default: on llvmpipe (GLSL) a
    #: 4-wide walk's per-lane tests and sorted pushes cost 30-56 % more CPU per frame than binary steps on
    #: the village, the hotel shut, the starter and the house (320x320, interleaved).
    tlas_width: int = 2
    #: Whether its packer should write binary trees as compact records (``ScenePacker(bvh_compact=...)``).
    bvh_compact: ClassVar[bool] = False
    #: Peak memory of a frame, as copies of its AOVs (device buffers, read-back, the written image) plus
    #: a working set: :meth:`frame_bytes`, which the CLI checks against the memory budget up front. The
    #: default is GLSL's, measured through ``aberrant render`` at 4096x4096 on llvmpipe: 12 bytes a
    #: pixel for the colour image, 48 for all AOVs.
    aov_copies: ClassVar[float] = 3.0
    working_bytes: ClassVar[int] = 256 * 2**20

    @classmethod
    def frame_bytes(cls, width: int, height: int, aovs: Sequence[str]) -> int:
        """About how much memory rendering (and writing out) a ``width`` x ``height`` frame of ``aovs`` takes."""
        return int(cls.aov_copies * aov_bytes(aovs) * width * height) + cls.working_bytes

    @classmethod
    @abstractmethod
    def probe(cls) -> str | None:
        """``None`` when this backend can run here, otherwise the reason and what to install."""

    def info(self) -> dict[str, str]:
        """Device, driver and version facts for ``aberrant backends``."""
        return {}

    @abstractmethod
    def upload(self, packed: PackedScene, updates: Sequence[TableUpdate]) -> int:
        """Upload the changed tables; returns the bytes transferred."""

    @abstractmethod
    def render(self, camera: CameraView, width: int, height: int, aovs: Sequence[str] = AOVS) -> Frame:
        """Trace one frame of the uploaded scene from ``camera``."""

    def check_request(self, width: int, height: int, aovs: Sequence[str], *, uploaded: bool) -> tuple[int, int]:
        """Validate a render request the same way in every backend; returns ``(width, height)`` as ints.

        Raises :class:`engine.errors.AberrantError` for a render before any upload, an unknown AOV name or a
        non-positive image size.
        """
        if not uploaded:
            raise AberrantError(f"{self.name} backend: render() before upload(); upload a packed scene first")
        unknown = [a for a in aovs if a not in AOVS]
        if unknown:
            raise AberrantError(f"unknown AOV(s) {', '.join(map(repr, unknown))}; AOVs are {', '.join(AOVS)}")
        width, height = int(width), int(height)
        if width <= 0 or height <= 0:
            raise AberrantError(f"image size must be positive, got {width}x{height}")
        return width, height

    def release(self) -> None:  # noqa: B027 - optional hook, most backends override it
        """Free device resources (idempotent)."""

    def __enter__(self) -> Backend:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def backend_class(name: str) -> type[Backend]:
    """The class registered under ``name`` (imports its module, not its heavy dependency)."""
    try:
        target = BACKENDS[name]
    except KeyError:
        raise AberrantError(f"unknown backend {name!r}; choose one of {', '.join([*BACKENDS, 'auto'])}") from None
    module_name, _, class_name = target.partition(":")
    return getattr(importlib.import_module(module_name), class_name)


def probe(name: str) -> str | None:
    """Why ``name`` cannot run here, or ``None``; never raises for a known name."""
    try:
        return backend_class(name).probe()
    except AberrantError:
        raise
    except Exception as e:  # a broken optional install must not crash the caller
        return f"{type(e).__name__}: {e}"


def default_backend_name() -> str:
    return os.environ.get("ABERRANT_BACKEND", "auto") or "auto"


def resolve_name(name: str | None = None, *, fallback: bool = True, log: object = None) -> str:
    """Turn ``name`` (or ``ABERRANT_BACKEND``, or ``auto``) into a backend that can run here.

    ``auto`` picks the fastest available and says which. A named backend that
    cannot run falls back to ``auto`` with a one-line message (why, and which
    backend instead) when ``fallback`` is true, and raises
    :class:`engine.errors.BackendUnavailable` otherwise.
    """
    say = log if callable(log) else (lambda message: print(message, file=sys.stderr))
    name = name or default_backend_name()
    failed = None  # why the named backend cannot run: the fallback is then said in one line
    if name != "auto":
        reason = probe(name)
        if reason is None:
            return name
        if not fallback:
            raise BackendUnavailable(f"{name} backend cannot run here: {reason}")
        failed = f"{name} backend cannot run here ({' '.join(reason.split())})"
    reasons = []
    for candidate in AUTO_ORDER:
        reason = probe(candidate)
        if reason is None:
            if failed is None:
                say(f"aberrant: auto chose the {candidate} backend")
            else:
                say(f"aberrant: {failed}; falling back to the {candidate} backend")
            return candidate
        reasons.append(f"{candidate}: {reason}")
    raise BackendUnavailable("no backend can run here: " + "; ".join(reasons))  # pragma: no cover


def create_backend(
    name: str | None = None, *, precision: Precision | None = None, fallback: bool = True, log: object = None
) -> Backend:
    """A ready backend, chosen as :func:`backends.base.resolve_name` does."""
    return backend_class(resolve_name(name, fallback=fallback, log=log))(precision=precision)
