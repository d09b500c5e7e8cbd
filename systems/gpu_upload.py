"""GPU upload: re-pack only what changed since the last tick and hand it to the backend.

The third system of a tick (docs/design.md section 6). The packer follows the scene's change journal, so a
static tick uploads nothing and a moved entity re-uploads its instance row,
not its mesh.
"""

from __future__ import annotations

import esper

from backends.base import Backend
from backends.upload import SceneUploader
from engine.camera_view import scene_camera
from engine.packed import PackedScene
from engine.scene import Scene
from systems.state import UploadStats


class GpuUploadProcessor(esper.Processor):
    """Owns the scene's uploader (its packer configured from the backend) and uploads each tick's changes."""

    def __init__(self, scene: Scene, backend: Backend, stats: UploadStats) -> None:
        self.scene = scene
        self.backend = backend
        self.stats = stats
        self.uploader = SceneUploader(backend)

    @property
    def packed(self) -> PackedScene | None:
        return self.uploader.packed

    def process(self, dt: float) -> None:
        sent = self.uploader.sync(self.scene, scene_camera(self.scene).position)  # a static tick sends nothing
        if sent.updates:
            self.stats.uploads += 1
        self.stats.bytes = sent.nbytes
        self.stats.updates = sent.updates
        self.stats.total_bytes += sent.nbytes
