"""Camera rays in two dispatches on llvmpipe (``SPLIT_PASS`` in backends/shared/options.h).

llvmpipe runs every branch of a shader masked for all the lanes of a SIMD vector, and a loop's body at least
once with none of them active, so every pixel of a frame with portals paid for a pass of the event loop. Where
a frame's camera rays search their first leg with the view tiles' instance lists apart from the loop, the
first dispatch (``SPLIT_PASS 1``) traces every pixel's first leg, writes the pixels it finishes and queues the
others with the event their first leg ended on; the second (``SPLIT_PASS 2``) runs one invocation per queued
ray, on from that event as the single dispatch would, so the frames are the single dispatch's to the bit.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from backends.glsl.tables import CAMERA_BINDING
from engine.camera_view import CameraView

if TYPE_CHECKING:  # moderngl is imported lazily: importing this module must not need it
    import moderngl

#: The storage buffer of the queued rays, after the AOV outputs' (backend.OUTPUT_BINDINGS).
QUEUE_BINDING = CAMERA_BINDING + 5
#: A split frame that queues more than this share of its pixels costs more than one dispatch (its first ran
#: their first legs' code for nothing: a view-filling box or portal, 1.6x the time); the frames after it take
#: one until the camera has been away from that view for SINGLE_FRAMES frames, then two are tried again.
SPLIT_QUEUED_MAX = 0.5
SINGLE_FRAMES = 15


class SplitDispatch:
    """A backend's queue buffer and the state that says whether its next frame may take two dispatches."""

    def __init__(self) -> None:
        self._queue: moderngl.Buffer | None = None
        #: Frames left to trace in one dispatch, counted down only while the camera is away from
        #: the view (position and axes) whose split frame queued most of its pixels.
        self.single_frames = 0
        self._single_view = b""

    @property
    def allowed(self) -> bool:
        return self.single_frames == 0

    def observe(self, camera: CameraView) -> None:
        """A frame of ``camera`` begins: one frame away from the view that stopped the split, if it is."""
        if self.single_frames and _view_key(camera) != self._single_view:
            self.single_frames -= 1

    def run(
        self,
        ctx: moderngl.Context,
        programs: tuple[moderngl.ComputeShader, moderngl.ComputeShader],
        camera: CameraView,
        size: tuple[int, int],
        workgroup: tuple[int, int],
    ) -> int:
        """The frame's two dispatches (``programs``: the SPLIT_PASS 1 and 2 variants): every pixel's first leg,
        then the rays it queued, their count read back in between (four bytes, the second dispatch's size).
        Returns that count."""
        width, height = size
        need = 16 + 4 * width * height
        if self._queue is None or self._queue.size < need:
            if self._queue is not None:
                self._queue.release()
            self._queue = ctx.buffer(reserve=need)
        self._queue.write(bytes(4))
        self._queue.bind_to_storage_buffer(QUEUE_BINDING)
        gx, gy = workgroup
        programs[0].run(math.ceil(width / gx), math.ceil(height / gy), 1)
        ctx.memory_barrier()
        queued = int(np.frombuffer(self._queue.read(4), np.uint32)[0])
        if queued:
            programs[1].run(math.ceil(queued / (gx * gy)), 1, 1)
        if queued > SPLIT_QUEUED_MAX * width * height:
            self.single_frames = SINGLE_FRAMES
            self._single_view = _view_key(camera)
        return queued

    def release(self) -> None:
        if self._queue is not None:
            self._queue.release()
        self._queue = None


def _view_key(camera: CameraView) -> bytes:
    return np.asarray(camera.position, np.float64).tobytes() + np.asarray(camera.rotation, np.float64).tobytes()
