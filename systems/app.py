"""The tick loop: the four systems registered in a scene's esper world, and the state they share.

An :class:`App` is what runs a scene, headless (tests, the CLI) or in the
editor's play mode. Without a backend only movement and teleport run, so
movement tests need no tracer.
"""

from __future__ import annotations

from collections.abc import Sequence

import esper

from backends.base import AOVS, Backend, Frame
from engine.errors import AberrantError
from engine.input import InputSource, NoInput
from engine.packed import PackedScene, TableUpdate
from engine.scene import Scene
from engine.space_index import SpaceIndex
from systems.camera_movement import SPRINT_MULTIPLIER, CameraMovementProcessor
from systems.gpu_upload import GpuUploadProcessor
from systems.portal_teleport import PortalTeleportProcessor
from systems.priorities import Priority
from systems.render import RenderProcessor
from systems.state import FrameSlot, MotionRecord, UploadStats

#: Frame size when none is given.
DEFAULT_SIZE: tuple[int, int] = (640, 480)


def _size(size: Sequence[int]) -> tuple[int, int]:
    width, height = (int(c) for c in size)
    if width <= 0 or height <= 0:
        raise AberrantError(f"frame size must be positive, got {width}x{height}")
    return width, height


class App:
    """Runs a scene tick by tick; ``close()`` takes its systems out of the scene's world again."""

    def __init__(
        self,
        scene: Scene,
        backend: Backend | None = None,
        *,
        size: Sequence[int] = DEFAULT_SIZE,
        aovs: Sequence[str] = AOVS,
        input_source: InputSource | None = None,
        sprint_multiplier: float = SPRINT_MULTIPLIER,
        spp: int = 1,
    ) -> None:
        self.scene = scene
        self.backend = backend
        self.motion = MotionRecord()
        self.upload_stats = UploadStats()
        self.frame_slot = FrameSlot()
        self.ticks = 0
        #: Where the portals and boxes are, for the camera's walk and teleport (one index for both).
        self.space = SpaceIndex()
        self.movement = CameraMovementProcessor(
            scene, input_source or NoInput(), self.motion, sprint_multiplier, index=self.space
        )
        self.teleport = PortalTeleportProcessor(scene, self.motion, index=self.space)
        self.upload: GpuUploadProcessor | None = None
        self.render: RenderProcessor | None = None
        registered: list[tuple[esper.Processor, Priority]] = [
            (self.movement, Priority.CAMERA_MOVEMENT),
            (self.teleport, Priority.PORTAL_TELEPORT),
        ]
        if backend is not None:
            self.upload = GpuUploadProcessor(scene, backend, self.upload_stats)
            self.render = RenderProcessor(scene, backend, self.frame_slot, _size(size), aovs, spp)
            registered += [(self.upload, Priority.GPU_UPLOAD), (self.render, Priority.RENDER)]
        scene.activate()
        for processor, _ in registered:
            if esper.get_processor(type(processor)) is not None:
                raise AberrantError(
                    f"scene {scene.name!r} already runs a {type(processor).__name__}; close() the other App first"
                )
        for processor, priority in registered:
            esper.add_processor(processor, priority)
        self._registered = [processor for processor, _ in registered]
        self._closed = False

    # --- running ----------------------------------------------------------------

    def tick(self, dt: float) -> Frame | None:
        """Run every system once, in priority order; the frame rendered (``None`` without a backend)."""
        if self._closed:
            raise AberrantError("this App is closed")
        if not dt >= 0.0:
            raise AberrantError(f"a tick's dt must be >= 0 seconds, got {dt}")
        self.scene.activate()
        esper.process(float(dt))
        self.ticks += 1
        return self.frame_slot.frame if self.backend is not None else None

    def run(self, ticks: int, dt: float) -> Frame | None:
        """``ticks`` ticks of ``dt`` seconds; the last frame."""
        frame = None
        for _ in range(ticks):
            frame = self.tick(dt)
        return frame

    def close(self) -> None:
        """Remove this app's processors from the scene's world (idempotent; the backend stays open)."""
        if self._closed:
            return
        self._closed = True
        if self.scene.world not in esper.list_worlds():
            return
        self.scene.activate()
        for processor in self._registered:
            if esper.get_processor(type(processor)) is processor:
                esper.remove_processor(type(processor))

    def __enter__(self) -> App:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- what the systems produced ---------------------------------------------

    @property
    def processors(self) -> tuple[esper.Processor, ...]:
        """This app's processors in the order they run each tick."""
        return tuple(sorted(self._registered, key=lambda p: p.priority, reverse=True))

    @property
    def frame(self) -> Frame | None:
        """The latest rendered frame."""
        return self.frame_slot.frame

    @property
    def last_upload_bytes(self) -> int:
        """Bytes the last tick uploaded (0 on a static tick)."""
        return self.upload_stats.bytes

    @property
    def last_updates(self) -> list[TableUpdate]:
        """The table updates the last tick uploaded (empty on a static tick)."""
        return self.upload_stats.updates

    @property
    def packed(self) -> PackedScene | None:
        """The packed tables the backend holds (``None`` without a backend or before the first tick)."""
        return None if self.upload is None else self.upload.packed

    # --- settings that may change between ticks ---------------------------------------

    @property
    def input_source(self) -> InputSource:
        return self.movement.input_source

    @input_source.setter
    def input_source(self, source: InputSource) -> None:
        self.movement.input_source = source

    @property
    def size(self) -> tuple[int, int] | None:
        """The frame size (``None`` without a backend); settable, e.g. on a window resize."""
        return None if self.render is None else self.render.size

    @size.setter
    def size(self, size: Sequence[int]) -> None:
        if self.render is None:
            raise AberrantError("this App has no backend, so it renders no frames")
        self.render.size = _size(size)


def render_once(
    scene: Scene, backend: Backend, size: Sequence[int] = DEFAULT_SIZE, aovs: Sequence[str] = AOVS, *, spp: int = 1
) -> Frame:
    """Upload and render one frame of ``scene`` as it stands (one tick, ``dt = 0``, no input), ``spp``
    samples a pixel."""
    with App(scene, backend, size=size, aovs=aovs, input_source=NoInput(), spp=spp) as app:
        frame = app.tick(0.0)
    assert frame is not None
    return frame
