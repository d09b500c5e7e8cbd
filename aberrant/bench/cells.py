"""One cell of the bench: one setting of one backend on one scene, measured and compared with the reference.

A cell never raises for a backend's sake: a backend that cannot trace the
scene (``BackendUnavailable``, e.g. aberrations not yet in its kernels) gives
``unsupported: <reason>``, anything else ``error: <what>``, and the run goes
on. The scene is shared by every cell of it and comes back exactly as it was
(``max_events``, the lights' shadows and the moved entity are restored).
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from aberrant.bench.metrics import Timing, color_error, compare
from aberrant.bench.reference import ReferenceCache, scene_key
from aberrant.bench.sweeps import IMAGE_SWEEPS, TARGET_SPP, Setting
from backends.base import AOVS, Backend, Frame, backend_class, probe
from backends.samples import render_samples
from backends.upload import SceneUploader
from components import Light, Mesh, Transform
from engine.bvh import BvhParams, build_bvh
from engine.camera_view import CameraView, scene_camera
from engine.errors import BackendUnavailable
from engine.packed import PackedScene, TableUpdate
from engine.scene import Scene

#: What the timed frames read back: the colour image, as the app and the CLI do.
TIMED_AOVS: tuple[str, ...] = ("color",)
#: What Embree's pairing also times: the hits alone (depth and instance, no shading), as Embree returns them.
HIT_AOVS: tuple[str, ...] = ("depth", "instance")


def _ms(start: float) -> float:
    return (time.perf_counter() - start) * 1e3


def shadows_off(scene: Scene) -> list[tuple[int, Light]]:
    """Every shadowing light of the scene switched to cast none; returns the lights as they were."""
    before = [(entity, light) for entity, light in scene.query(Light) if light.shadows]
    for entity, light in before:
        scene.set(entity, replace(light, shadows=False))
    return before


def describe_updates(packed: PackedScene, updates: list[TableUpdate]) -> list[str]:
    """``["instances[3:4] 96 B"]``: which rows of which tables an upload sends."""
    out = []
    for u in updates:
        rows = "all" if u.rows is None else f"{u.rows.start}:{u.rows.stop}"
        out.append(f"{u.table}[{rows}] {packed.update_bytes([u])} B")
    return out


def image_error_row(color: np.ndarray, own: np.ndarray, truth: np.ndarray) -> dict[str, float | int]:
    """The colour's error against the backend's own many-sample image and the reference's."""
    own_error, ref_error = color_error(color, own), color_error(color, truth)
    return {
        "target_spp": TARGET_SPP,
        "own_mae": own_error["mae"],
        "own_psnr": own_error["psnr"],
        "ref_mae": ref_error["mae"],
        "ref_psnr": ref_error["psnr"],
    }


class CellRunner:
    """Measures cells; remembers per run what is costly to learn twice (probes, BVH build times)."""

    def __init__(self, references: ReferenceCache, repeat: int, image_errors: bool = False) -> None:
        self.references = references
        self.repeat = repeat
        #: Whether base cells measure their colour's error too (the spp and shadows sweeps' cells always do).
        self.image_errors = image_errors
        self._probes: dict[str, str | None] = {}
        self._bvh_ms: dict[tuple[str, int], float] = {}
        self._targets_cache: dict[tuple[str, str], np.ndarray] = {}

    def probe(self, backend: str) -> str | None:
        if backend not in self._probes:
            self._probes[backend] = probe(backend)
        return self._probes[backend]

    def bvh_build_ms(self, scene: Scene, leaf: int) -> float:
        """Uncached build time of every distinct asset's BVH at this leaf size (memoised per run)."""
        total = 0.0
        seen: set[str] = set()
        for _, mesh in scene.query(Mesh):
            asset = scene.asset(mesh.asset)
            if asset.content_hash in seen:
                continue
            seen.add(asset.content_hash)
            key = (asset.content_hash, leaf)
            if key not in self._bvh_ms:
                start = time.perf_counter()
                build_bvh(asset.vertices, asset.faces, BvhParams(max_leaf_size=leaf))
                self._bvh_ms[key] = _ms(start)
            total += self._bvh_ms[key]
        return total

    def run(
        self,
        scene: Scene,
        camera: CameraView,
        setting: Setting,
        size: tuple[int, int],
        pair: Callable[[], object] | None = None,
        baseline: Scene | None = None,
        baseline_spp: int | None = None,
        image_errors: bool = True,
    ) -> dict[str, Any]:
        """Measure one cell; the row's ``status`` is ``ok``, ``unsupported: ...`` or ``error: ...``.

        ``pair``: one Embree trace of the same rays; ``baseline``: the plain scene this one deforms (or
        whose feature it adds), its frames taking ``baseline_spp`` samples a pixel (``None``: the setting's).
        ``image_errors``: False keeps a base cell from measuring its colour's error whatever the run does.
        Either is timed alternately with extra frames, so the ratio sees the same background load
        (the machine is shared).
        """
        row: dict[str, Any] = {
            "setting": setting.as_dict(),
            "label": setting.label,
            "family": setting.family,
            "backend": setting.backend,
            "precision": setting.precision,
            "size": list(size),
        }
        original = scene.settings
        if setting.max_events is not None:
            scene.settings = replace(original, max_events=setting.max_events)
        row["max_events"] = scene.settings.max_events
        try:
            reason = self.probe(setting.backend)
            if reason is not None:
                raise BackendUnavailable(reason)
            errors = setting.sweep in IMAGE_SWEEPS or (setting.sweep == "" and self.image_errors and image_errors)
            self._measure(scene, camera, setting, size, row, pair, baseline, baseline_spp or setting.spp, errors)
            row["status"] = "ok"
        except BackendUnavailable as e:
            row["status"] = f"unsupported: {' '.join(str(e).split())}"
        except Exception as e:  # recorded, never fatal: one broken cell must not lose the run
            row["status"] = f"error: {type(e).__name__}: {' '.join(str(e).split())}"
            row["traceback"] = traceback.format_exc(limit=6)
        finally:
            scene.settings = original
        return row

    def _measure(
        self,
        scene: Scene,
        camera: CameraView,
        setting: Setting,
        size: tuple[int, int],
        row: dict,
        pair: Callable[[], object] | None,
        baseline: Scene | None,
        baseline_spp: int,
        measure_image: bool,
    ) -> None:
        width, height = size
        restore: list[tuple[int, Light]] = []
        row["bvh_build_ms"] = self.bvh_build_ms(scene, setting.leaf)
        start = time.perf_counter()
        backend: Backend = backend_class(setting.backend)(precision=setting.precision, **setting.kwargs)
        row["init_ms"] = _ms(start)
        try:
            uploader = SceneUploader(backend, bvh_params=BvhParams(max_leaf_size=setting.leaf))
            sent = uploader.sync(scene, camera.position)
            row["pack_ms"] = sent.pack_ms
            row["upload_bytes"] = sent.nbytes
            row["upload_ms"] = sent.upload_ms
            # The reference frame and the colour's targets are the scene's as it is, shadows and all: a
            # shadows-off cell is measured against what switching them off loses.
            reference = self.references.get(scene, camera, size)
            row["reference_ms"] = reference.render_ms
            row["reference_cached"] = reference.cached
            targets = self._targets(backend, scene, camera, setting, size) if measure_image else None
            if not setting.shadows:
                restore += shadows_off(scene)
                uploader.sync(scene, camera.position)
            start = time.perf_counter()
            spp = setting.spp
            frame = render_samples(backend, camera, width, height, AOVS, spp)  # compiles the variant: apart
            row["first_frame_ms"] = _ms(start)
            errors = compare(frame.aov("instance"), frame.aov("depth"), frame.aov("perceived"), reference.aovs)
            row["errors"] = errors.as_dict()
            row["coverage"] = float((reference.aovs["instance"] >= 0).mean())
            if targets is not None:
                row["image_errors"] = image_error_row(frame.aov("color"), *targets)
            reference_backend = setting.backend == "reference"
            if not reference_backend:  # the timed variant (colour only) compiles here, not in a timed frame
                backend.render(camera, width, height, TIMED_AOVS)
            samples = []
            for _ in range(1 if reference_backend else self.repeat):
                start = time.perf_counter()
                render_samples(backend, camera, width, height, TIMED_AOVS, spp)
                samples.append(_ms(start))
            timing = Timing.of(samples)
            row["frame"] = timing.as_dict()
            row["mrays_per_s"] = timing.mrays_per_s(width * height)

            def timed_frame() -> object:
                return render_samples(backend, camera, width, height, TIMED_AOVS, spp)

            if pair is not None:
                # Embree traces the primary rays only: a scene whose lights cast shadows is paired on its
                # frame without them, so that both trace the same rays.
                lit = shadows_off(scene) if setting.shadows else []
                restore += lit
                if lit:
                    uploader.sync(scene, camera.position)
                    timed_frame()  # the shadow-free variant compiles apart
                row["embree_paired"] = {**self._paired(pair, timed_frame), "shadows_off": bool(lit)}
                if not reference_backend:
                    # Embree's side is a closest-hit trace: our frame of the same outputs skips the shading.
                    def hit_frame() -> Frame:
                        return backend.render(camera, width, height, HIT_AOVS)

                    hits = hit_frame()  # its variant (no shading) compiles apart
                    same = all(np.array_equal(hits.aov(n), frame.aov(n)) for n in HIT_AOVS)
                    row["embree_trace_paired"] = {**self._paired(pair, hit_frame), "same_hits": same}
                for entity, light in lit:
                    scene.set(entity, light)
                    restore.remove((entity, light))
                if lit:
                    uploader.sync(scene, camera.position)
            if baseline is not None:
                row["baseline_paired"] = self._baseline(setting, baseline, size, baseline_spp, timed_frame)
            self._ticks(scene, camera, uploader, row)
        finally:
            for entity, light in restore:
                scene.set(entity, light)
            backend.release()

    def _targets(
        self, backend: Backend, scene: Scene, camera: CameraView, setting: Setting, size: tuple[int, int]
    ) -> tuple[np.ndarray, np.ndarray]:
        """TARGET_SPP samples a pixel of this backend (uploaded with ``scene`` as it is) and of the reference.

        The backend's own is rendered once per scene and backend family in a run (it is the same for every
        point of the spp and shadows sweeps); the reference's is cached on disk like every reference frame.
        """
        key = (scene_key(scene, camera, size), f"{setting.family} leaf={setting.leaf} {setting.options}")
        if key not in self._targets_cache:
            own = render_samples(backend, camera, size[0], size[1], ("color",), TARGET_SPP)
            self._targets_cache[key] = own.aov("color")
        return self._targets_cache[key], self.references.get(scene, camera, size, TARGET_SPP).aovs["color"]

    def _paired(self, other: Callable[[], object], frame: Callable[[], object]) -> dict[str, float]:
        """``other``'s time over the frame's (``ratio``) and its inverse: medians of per-pair ratios."""
        other_ms, frame_ms = [], []
        for _ in range(self.repeat):
            start = time.perf_counter()
            other()
            other_ms.append(_ms(start))
            start = time.perf_counter()
            frame()
            frame_ms.append(_ms(start))
        pairs = list(zip(other_ms, frame_ms, strict=True))
        return {
            "ratio": float(np.median([o / f for o, f in pairs])),
            "inverse": float(np.median([f / o for o, f in pairs])),
            "other_ms": float(np.median(other_ms)),
            "frame_ms": float(np.median(frame_ms)),
            "pairs": len(pairs),
        }

    def _baseline(
        self, setting: Setting, baseline: Scene, size: tuple[int, int], spp: int, frame: Callable[[], object]
    ) -> dict[str, float]:
        """The plain scene on a second backend of the same setting (``spp`` samples a pixel), its frames
        alternating with this scene's."""
        other: Backend = backend_class(setting.backend)(precision=setting.precision, **setting.kwargs)
        try:
            camera = scene_camera(baseline)
            SceneUploader(other, bvh_params=BvhParams(max_leaf_size=setting.leaf)).sync(baseline, camera.position)

            def plain() -> object:
                return render_samples(other, camera, size[0], size[1], TIMED_AOVS, spp)

            plain()  # compiles its variant
            return self._paired(plain, frame)
        finally:
            other.release()

    @staticmethod
    def _ticks(scene: Scene, camera: CameraView, uploader: SceneUploader, row: dict) -> None:
        """Bytes a static tick and a one-entity-moved tick upload (the static one should be 0)."""
        row["tick_static_bytes"] = uploader.sync(scene, camera.position).nbytes
        meshes = scene.query(Transform, Mesh)
        if not meshes:
            row["tick_moved_bytes"] = None
            return
        entity, (transform, _) = meshes[0]
        moved = replace(transform, position=(transform.position[0] + 0.01, *transform.position[1:]))
        scene.set(entity, moved)
        try:
            sent = uploader.sync(scene, camera.position)
            assert uploader.packed is not None
            row["tick_moved_bytes"] = sent.nbytes
            row["tick_moved_updates"] = describe_updates(uploader.packed, sent.updates)
        finally:
            scene.set(entity, transform)
