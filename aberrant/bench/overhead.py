"""Engine overhead per tick: every system but the backend's render, 1,000 entities, one moving.

The real :class:`systems.app.App` runs the real systems (camera movement,
portal teleport, GPU upload into a real backend, the render system) over a
scene of 1,000 boxes; only the backend's ``render`` is skipped, by a thin
wrapper that forwards ``upload`` and returns an empty frame. Before each
tick one box moves (the game's doing, not timed); the tick is timed with
``perf_counter`` around ``App.tick`` and around each system (esper's own
``timed_process`` rounds to whole milliseconds, too coarse for this). It also
counts the ticks that re-uploaded rows of the top-level tree (``tlas_nodes``):
none while the mover stays inside its fat leaf (:mod:`engine.tlas`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any, ClassVar

import numpy as np

from backends.base import AOVS, Backend, Frame, backend_class
from components import Transform
from engine.camera_view import CameraView
from engine.input import NoInput
from engine.packed import PackedScene, TableUpdate
from engine.records import Precision
from engine.scene import Scene
from systems.app import App

ENTITIES = 1000
TICKS = 60
WARMUP_TICKS = 5


class SkipRender(Backend):
    """Forwards uploads to a real backend and renders nothing: what is left of a tick is the engine's."""

    name: ClassVar[str] = "skip-render"

    def __init__(self, inner: Backend) -> None:  # no super().__init__: precision is the inner backend's
        self.inner = inner
        self.precision = inner.precision
        self.camera_relative = inner.camera_relative

    @classmethod
    def probe(cls) -> str | None:
        return None

    def upload(self, packed: PackedScene, updates: Sequence[TableUpdate]) -> int:
        return self.inner.upload(packed, updates)

    def render(self, camera: CameraView, width: int, height: int, aovs: Sequence[str] = AOVS) -> Frame:
        return Frame(width, height)


def thousand_boxes(count: int = ENTITIES) -> Scene:
    """``count`` small boxes in a grid on the ground, the camera above looking over them."""
    scene = Scene(f"{count}-boxes")
    side = int(np.ceil(np.sqrt(count)))
    for k in range(count):
        i, j = divmod(k, side)
        scene.add_mesh(f"box{k}", "box", position=(i - side / 2, 0.5, -j), scale=0.6, color=(0.8, 0.6, 0.4))
    scene.set_camera((0.0, 12.0, 10.0), look_at=(0.0, 0.0, -side / 2), fov_deg=60.0)
    return scene


def _timed_processors(app: App, samples: dict[str, list[float]]) -> None:
    """Wrap each processor's ``process`` to record its wall time (milliseconds)."""
    for processor in app.processors:
        name = type(processor).__name__
        samples[name] = []
        original: Callable[[float], Any] = processor.process

        def timed(dt: float, _original: Callable[[float], Any] = original, _name: str = name) -> None:
            start = time.perf_counter()
            _original(dt)
            samples[_name].append((time.perf_counter() - start) * 1e3)

        # An instance attribute: shadows the class's method for this processor only (esper.process calls it).
        vars(processor)["process"] = timed


def measure_overhead(backend_name: str, precision: Precision | None = None, ticks: int = TICKS) -> dict[str, Any]:
    """Median tick time without the render, per-system medians, and what the measured ticks uploaded."""
    inner = backend_class(backend_name)(precision=precision)
    scene = thousand_boxes()
    try:
        mover = scene.entity("box0")
        start = scene.get(mover, Transform)
        with App(scene, SkipRender(inner), size=(64, 64), input_source=NoInput()) as app:
            samples: dict[str, list[float]] = {}
            ticks_ms: list[float] = []
            uploads: list[int] = []
            updates: list[TableUpdate] = []
            tlas_ticks = 0  # measured ticks that uploaded top-level tree rows (the mover left its fat leaf)
            for k in range(WARMUP_TICKS + ticks):
                if k == WARMUP_TICKS:
                    _timed_processors(app, samples)
                offset = 0.01 * (1 + k % 2)  # differs from the previous tick's: every tick moves it
                scene.set(mover, replace(start, position=(start.position[0] + offset, *start.position[1:])))
                t0 = time.perf_counter()
                app.tick(1.0 / 60.0)
                if k >= WARMUP_TICKS:
                    ticks_ms.append((time.perf_counter() - t0) * 1e3)
                    uploads.append(app.last_upload_bytes)
                    tlas_ticks += any(u.table == "tlas_nodes" for u in app.last_updates)
                    updates = list(app.last_updates)
            packed = app.packed
            assert packed is not None
            row_bytes = int(packed.tables["instances"].dtype.itemsize)
        one_row = len(updates) == 1 and updates[0].rows is not None and len(updates[0].rows) == 1
        return {
            "backend": inner.name,
            "precision": inner.precision,
            "entities": ENTITIES,
            "ticks": ticks,
            "median_ms": float(np.median(ticks_ms)),
            "min_ms": float(np.min(ticks_ms)),
            "max_ms": float(np.max(ticks_ms)),
            "systems_ms": {name: float(np.median(v)) for name, v in samples.items() if v},
            "upload_bytes": int(np.median(uploads)),
            "instance_row_bytes": row_bytes,
            "updates": [
                {"table": u.table, "rows": None if u.rows is None else [u.rows.start, u.rows.stop]} for u in updates
            ],
            "one_row": bool(one_row),
            "tlas_upload_ticks": int(tlas_ticks),
        }
    finally:
        scene.close()
        inner.release()
