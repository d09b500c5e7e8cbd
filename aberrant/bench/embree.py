"""The outside anchor: Embree (through ``embreex``) tracing the same primary rays, closest hit only.

Every Euclidean row of the report also reads as a ratio to Embree measured in
the same run on the same machine, so a number means something beyond this
project. The scene is flattened to one triangle mesh in world space *minus
the camera position* (float64, then float32), and the rays start at the
origin along ``CameraView.primary_directions`` (float32): the same rays the
backends trace, camera-relative as the float32 backends work (docs/semantics.md,
"Primary rays"), so a scene far from the origin is fair to Embree too. No
shading, no back-face culling: ``tfar``, ``primID`` and ``geomID`` only.

embreex's ``run`` holds the GIL, so two threads do not use two cores; the
split across both cores is two worker processes (spawned: Embree's TBB
threads do not survive a fork), each holding its own copy of the scene and
its half of the rays, which are sent once per scene and size so that a timed
trace is one short message each way. Every mode (one thread, two threads,
two processes) is timed and the best is the anchor, so the ratio is against
the best Embree this machine gets through embreex.
"""

from __future__ import annotations

import contextlib
import importlib.util
import math
import multiprocessing as mp
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from components import Mesh, Transform
from engine.camera_view import CameraView
from engine.maths import quat_to_matrix
from engine.scene import Scene

NOT_INSTALLED = "embree: not installed (pip install '.[bench]')"
#: Modes timed; the best is the anchor.
MODES: tuple[str, ...] = ("1 thread", "2 threads", "2 processes")


def available() -> str | None:
    """``None`` when embreex imports, else why not (the report's note)."""
    if importlib.util.find_spec("embreex") is None:
        return NOT_INSTALLED
    try:
        from embreex import mesh_construction, rtcore_scene  # noqa: F401
    except Exception as e:  # a broken wheel must not stop the bench
        return f"embree: cannot load embreex ({type(e).__name__}: {e})"
    return None


def version() -> str:
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("embreex")
    except PackageNotFoundError:
        return "unknown"


@dataclass
class FlatScene:
    """Every mesh instance baked into one camera-relative float32 mesh, and each triangle's entity id."""

    vertices: np.ndarray  # (N, 3) float32
    faces: np.ndarray  # (M, 3) int32
    entity_of_triangle: np.ndarray  # (M,) int32


def flatten(scene: Scene, camera: CameraView) -> FlatScene:
    """World-space triangles relative to the camera, in float64 until the final cast."""
    verts, faces, owners = [], [], []
    base = 0
    for entity, (transform, mesh) in scene.query(Transform, Mesh):
        assert isinstance(transform, Transform) and isinstance(mesh, Mesh)
        asset = scene.asset(mesh.asset)
        m = quat_to_matrix(transform.rotation) * np.asarray(transform.scale, np.float64)[None, :]
        offset = np.asarray(transform.position, np.float64) - camera.position
        verts.append(asset.vertices.astype(np.float64) @ m.T + offset)
        faces.append(asset.faces.astype(np.int64) + base)
        owners.append(np.full(len(asset.faces), entity, np.int32))
        base += len(asset.vertices)
    if not verts:
        return FlatScene(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32), np.zeros(0, np.int32))
    return FlatScene(
        np.concatenate(verts).astype(np.float32), np.concatenate(faces).astype(np.int32), np.concatenate(owners)
    )


def _build(flat: FlatScene) -> Any:
    from embreex import mesh_construction, rtcore_scene

    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene, flat.vertices, flat.faces)
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=1)  # commits (builds the BVH)
    return scene


def _trace(scene: Any, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    out = scene.run(np.zeros_like(directions), directions, output=1)
    return out["tfar"], out["primID"]


def _worker(conn: Any) -> None:
    """A worker process: holds one scene and one block of rays; traces on request."""
    scene = directions = origins = None
    while True:
        msg = conn.recv()
        kind = msg[0]
        if kind == "stop":
            return
        if kind == "scene":
            scene = _build(msg[1])
            conn.send(None)
        elif kind == "rays":
            directions = np.ascontiguousarray(msg[1], np.float32)
            origins = np.zeros_like(directions)
            conn.send(None)
        elif kind == "trace":
            start = time.perf_counter()
            assert scene is not None  # the parent sends "scene" and "rays" before any "trace"
            scene.run(origins, directions, output=1)
            conn.send((time.perf_counter() - start) * 1e3)


class _Pool:
    """Two spawned worker processes, each with half the rays."""

    def __init__(self, workers: int = 2) -> None:
        ctx = mp.get_context("spawn")
        self.conns, self.procs = [], []
        for _ in range(workers):
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child,), daemon=True)
            proc.start()
            child.close()
            self.conns.append(parent)
            self.procs.append(proc)

    def _all(self, messages: list[tuple[Any, ...]]) -> list[Any]:
        for conn, msg in zip(self.conns, messages, strict=True):
            conn.send(msg)
        return [conn.recv() for conn in self.conns]

    def scene(self, flat: FlatScene) -> None:
        self._all([("scene", flat)] * len(self.conns))

    def rays(self, directions: np.ndarray) -> None:
        self._all([("rays", part) for part in np.array_split(directions, len(self.conns))])

    def trace(self) -> None:
        self._all([("trace",)] * len(self.conns))

    def close(self) -> None:
        for conn, proc in zip(self.conns, self.procs, strict=True):
            with contextlib.suppress(OSError):
                conn.send(("stop",))
            proc.join(timeout=5)
            if proc.is_alive():
                proc.terminate()
            conn.close()


@dataclass
class EmbreeRun:
    """Embree on one scene at one size: timings per mode, the best mode, and its AOVs."""

    build_ms: float
    modes: dict[str, dict[str, float]] = field(default_factory=dict)  # mode -> median/min/max ms
    best: str = ""
    instance: np.ndarray | None = None  # (H, W) entity ids, -1 on a miss
    depth: np.ndarray | None = None  # (H, W) float32, +inf on a miss


def _timed(call: Callable[[], object], repeat: int) -> dict[str, float]:
    call()  # warm-up
    samples = []
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        samples.append((time.perf_counter() - start) * 1e3)
    return {"median_ms": float(np.median(samples)), "min_ms": min(samples), "max_ms": max(samples)}


class EmbreeAnchor:
    """Embree on one scene at a time (``load``), timed per size (``run``) or one trace at a time (``tracer``).

    The worker pool starts on first use and stops on ``close``.
    """

    def __init__(self, repeat: int) -> None:
        self.repeat = max(1, repeat)
        self._pool: _Pool | None = None
        self._pool_size: tuple[int, int] | None = None
        self._flat: FlatScene | None = None
        self._local: Any = None
        self._camera: CameraView | None = None
        self._rays: dict[tuple[int, int], np.ndarray] = {}
        self.build_ms = 0.0

    def load(self, scene: Scene, camera: CameraView) -> None:
        """Flatten and build ``scene`` here and in the workers (the build time is Embree's, here)."""
        self._flat, self._camera, self._rays, self._pool_size = flatten(scene, camera), camera, {}, None
        start = time.perf_counter()
        self._local = _build(self._flat)
        self.build_ms = (time.perf_counter() - start) * 1e3
        if self._pool is None:
            self._pool = _Pool(2)
        self._pool.scene(self._flat)

    def _directions(self, size: tuple[int, int]) -> np.ndarray:
        if size not in self._rays:
            assert self._camera is not None
            self._rays[size] = self._camera.primary_directions(*size).reshape(-1, 3).astype(np.float32)
        return self._rays[size]

    def tracer(self, size: tuple[int, int], mode: str) -> Callable[[], object]:
        """One trace of the loaded scene's primary rays at ``size`` in ``mode`` (rays sent to the workers once)."""
        directions, local = self._directions(size), self._local
        if mode == "1 thread":
            return lambda: _trace(local, directions)
        if mode == "2 threads":
            halves = np.array_split(directions, 2)

            def two_threads() -> None:
                threads = [threading.Thread(target=_trace, args=(local, half)) for half in halves]
                for t in threads:
                    t.start()
                for t in threads:
                    t.join()

            return two_threads
        pool = self._pool
        assert pool is not None
        if self._pool_size != size:
            pool.rays(directions)
            self._pool_size = size
        return pool.trace

    def run(self, size: tuple[int, int]) -> EmbreeRun:
        """Every mode timed at ``size``, the best named, and the AOVs Embree found."""
        assert self._flat is not None
        result = EmbreeRun(build_ms=self.build_ms)
        for mode in MODES:
            result.modes[mode] = _timed(self.tracer(size, mode), self.repeat)
        result.best = min(result.modes, key=lambda m: result.modes[m]["median_ms"])
        tfar, prim = _trace(self._local, self._directions(size))
        hit = prim >= 0
        owner = self._flat.entity_of_triangle
        result.instance = np.where(hit, owner[np.where(hit, prim, 0)], -1).reshape(size[1], size[0])
        result.depth = np.where(hit, tfar, np.float32(np.inf)).astype(np.float32).reshape(size[1], size[0])
        return result

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool = None


def mrays(ms: float, rays: int) -> float:
    return rays / (ms * 1e-3) / 1e6 if ms > 0 else math.inf
