"""Render: one frame of the uploaded scene from the scene's camera, left where readers look.

The last system of a tick (docs/design.md section 6). The app, the editor and tests read the frame from the
shared :class:`systems.state.FrameSlot`.
"""

from __future__ import annotations

from collections.abc import Sequence

import esper

from backends.base import AOVS, Backend
from backends.samples import check_spp, render_samples
from engine.camera_view import scene_camera
from engine.scene import Scene
from systems.state import FrameSlot


class RenderProcessor(esper.Processor):
    """Renders once per tick; ``size``, ``aovs`` and ``spp`` (samples a pixel) may change between ticks."""

    def __init__(
        self,
        scene: Scene,
        backend: Backend,
        slot: FrameSlot,
        size: tuple[int, int],
        aovs: Sequence[str] = AOVS,
        spp: int = 1,
    ) -> None:
        self.scene = scene
        self.backend = backend
        self.slot = slot
        self.size = size
        self.aovs = tuple(aovs)
        self.spp = check_spp(spp)

    def process(self, dt: float) -> None:
        width, height = self.size
        self.slot.frame = render_samples(self.backend, scene_camera(self.scene), width, height, self.aovs, self.spp)
        self.slot.frames += 1
