"""Feeding a backend: a packer configured the way the backend reads its tables, and the upload of each sync.

Every driver (the upload system, the editor's viewport, the bench, the
reference frames, the tests) packs through :class:`SceneUploader`, so each
one uploads the layout the backend asks for (its precision, floating origin,
BVH width and compact records) and none can drift from the others.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from backends.base import Backend
from engine.bvh import BvhParams
from engine.packed import PackedScene, TableUpdate
from engine.packing import ScenePacker
from engine.scene import Scene


@dataclass(frozen=True)
class Upload:
    """What one sync sent: the table updates, their bytes, and the milliseconds packing and uploading took."""

    updates: list[TableUpdate]
    nbytes: int
    pack_ms: float
    upload_ms: float


class SceneUploader:
    """Keeps ``backend``'s tables in step with a scene: re-packs what changed and uploads only that."""

    def __init__(
        self,
        backend: Backend,
        *,
        bvh_params: BvhParams | None = None,
        bvh_width: int | None = None,
        bvh_compact: bool | None = None,
    ) -> None:
        """``bvh_width``/``bvh_compact`` override the backend's tree layout (tests that compare layouts);
        compact records are binary-only, so the backend's compactness applies only at width 2."""
        self.backend = backend
        width = backend.bvh_width if bvh_width is None else bvh_width
        compact = (backend.bvh_compact and width == 2) if bvh_compact is None else bvh_compact
        self.packer = ScenePacker(
            precision=backend.precision,
            camera_relative=backend.camera_relative,
            bvh_params=bvh_params,
            bvh_width=width,
            bvh_compact=compact,
            tlas_width=backend.tlas_width,
        )

    @property
    def packed(self) -> PackedScene | None:
        return self.packer.packed

    def sync(self, scene: Scene, camera_position: np.ndarray | None = None) -> Upload:
        """Bring the backend up to date with ``scene`` (its floating origin near ``camera_position``, else
        near the scene's camera); a sync that changed nothing does not call the backend."""
        start = time.perf_counter()
        updates = self.packer.sync(scene, camera_position)
        pack_ms = (time.perf_counter() - start) * 1e3
        if not updates:
            return Upload(updates, 0, pack_ms, 0.0)
        assert self.packer.packed is not None
        start = time.perf_counter()
        nbytes = int(self.backend.upload(self.packer.packed, updates))
        return Upload(updates, nbytes, pack_ms, (time.perf_counter() - start) * 1e3)
