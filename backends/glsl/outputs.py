"""A GLSL frame's outputs: the colour texture (drawable by the editor without a read-back) and one storage
buffer per other AOV, allocated once per size and read back only where the frame asks for them."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from backends.base import Frame
from backends.glsl.tables import CAMERA_BINDING

if TYPE_CHECKING:  # moderngl is imported lazily: importing this module must not need it
    import moderngl

#: Storage-buffer bindings of the AOV outputs, after the scene tables' and the camera's.
OUTPUT_BINDINGS: dict[str, int] = {
    "depth": CAMERA_BINDING + 1,
    "perceived": CAMERA_BINDING + 2,
    "instance": CAMERA_BINDING + 3,
    "events": CAMERA_BINDING + 4,
}
#: Bytes per pixel and read-back dtype of each storage-buffer AOV.
OUTPUT_DTYPES: dict[str, np.dtype] = {
    "depth": np.dtype(np.float32),
    "perceived": np.dtype(np.float32),
    "instance": np.dtype(np.int32),
    "events": np.dtype(np.uint32),
}


class FrameOutputs:
    """The colour texture and the AOV buffers of a backend's frames."""

    def __init__(self) -> None:
        self.texture: moderngl.Texture | None = None
        self._buffers: dict[str, moderngl.Buffer] = {}
        self._size: tuple[int, int] = (0, 0)

    @property
    def buffers(self) -> dict[str, moderngl.Buffer]:
        """The AOV buffers allocated so far, by name."""
        return self._buffers

    def bind(self, ctx: moderngl.Context, width: int, height: int, aovs: Sequence[str]) -> None:
        """Bind the outputs of a frame of ``aovs``, (re)allocated only when the size changes or an AOV is new."""
        if self._size != (width, height):
            self.release()
            self.texture = ctx.texture((width, height), 4, dtype="f1")
            self._size = (width, height)
        for name in aovs:
            if name in OUTPUT_BINDINGS:
                if name not in self._buffers:
                    self._buffers[name] = ctx.buffer(reserve=width * height * OUTPUT_DTYPES[name].itemsize)
                self._buffers[name].bind_to_storage_buffer(OUTPUT_BINDINGS[name])
        assert self.texture is not None
        self.texture.bind_to_image(0, read=False, write=True)

    def read(self, width: int, height: int, aovs: Sequence[str]) -> Frame:
        """The frame's requested AOVs, read back."""
        frame = Frame(width, height)
        if "color" in aovs:
            assert self.texture is not None
            data = self.texture.read(alignment=1)
            frame.color = np.frombuffer(data, np.uint8).reshape(height, width, 4).copy()
        for name in aovs:
            if name not in OUTPUT_BINDINGS:
                continue
            raw = np.frombuffer(self._buffers[name].read(), OUTPUT_DTYPES[name]).reshape(height, width)
            value: Any = raw.astype(np.uint8) if name == "events" else raw.copy()
            setattr(frame, name, value)
        return frame

    def release(self) -> None:
        for buffer in self._buffers.values():
            buffer.release()
        self._buffers.clear()
        if self.texture is not None:
            self.texture.release()
        self.texture = None
        self._size = (0, 0)
