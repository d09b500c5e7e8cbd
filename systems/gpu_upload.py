"""GPU upload: re-pack only what changed since the last tick and hand it to the backend.

The third system of a tick (docs/design.md section 6). The packer follows the scene's change journal, so a
static tick uploads nothing and a moved entity re-uploads its instance row,
not its mesh.
"""

from __future__ import annotations

import esper

from backends.base import Backend
from engine.camera_view import scene_camera
from engine.packed import PackedScene
from engine.packing import ScenePacker
from engine.scene import Scene
from systems.state import UploadStats


class GpuUploadProcessor(esper.Processor):
    """Owns the scene's packer (configured from the backend) and uploads each tick's changes."""

    def __init__(self, scene: Scene, backend: Backend, stats: UploadStats) -> None:
        self.scene = scene
        self.backend = backend
        self.stats = stats
        self.packer = ScenePacker(
            precision=backend.precision,
            camera_relative=backend.camera_relative,
            bvh_width=backend.bvh_width,
            bvh_compact=backend.bvh_compact,
        )

    @property
    def packed(self) -> PackedScene | None:
        return self.packer.packed

    def process(self, dt: float) -> None:
        updates = self.packer.sync(self.scene, scene_camera(self.scene).position)
        nbytes = 0
        if updates:  # a static tick does not call the backend at all
            assert self.packer.packed is not None
            nbytes = int(self.backend.upload(self.packer.packed, updates))
            self.stats.uploads += 1
        self.stats.bytes = nbytes
        self.stats.updates = updates
        self.stats.total_bytes += nbytes
