"""Where the GLSL backend's tables live on the device: one std430 storage buffer each, or, on a CPU
rasteriser (llvmpipe), one RGBA32UI image each, the same bytes a texel per 4-vector. llvmpipe reads
storage buffers one SIMD lane at a time and images with vector gathers, about 13 times faster. The
shader reaches either through ``bindings.glsl``; the bindings and image units are numbered here."""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

import numpy as np

from engine import layout

if TYPE_CHECKING:  # moderngl is imported lazily: importing this module must not need it
    import moderngl

TableStore = Literal["auto", "ssbo", "image"]

#: Storage-buffer bindings after the scene tables.
CAMERA_BINDING = len(layout.TABLES)
#: Image-mode tables: texels per image row (a power of two; llvmpipe allows 16384).
TABLE_WIDTH = 4096
#: Image units: 0 the colour output, k + 1 table k, then the camera.
CAMERA_IMAGE = len(layout.TABLES) + 1
#: ... and the frame's view tiles (engine/view_tiles.py; the image store only).
VIEW_TILES_IMAGE = CAMERA_IMAGE + 1
#: Tables held in images under either store (bindings.glsl): with storage buffers, the rest already take the
#: 16 storage blocks a compute shader may have.
IMAGE_TABLES: tuple[str, ...] = ("triangle_normals", "texels")


def image_of(store: moderngl.Buffer | moderngl.Texture) -> moderngl.Texture:
    """A table store known to be an image."""
    import moderngl

    assert isinstance(store, moderngl.Texture)
    return store


def buffer_of(store: moderngl.Buffer | moderngl.Texture) -> moderngl.Buffer:
    """A table store known to be a storage buffer."""
    import moderngl

    assert isinstance(store, moderngl.Buffer)
    return store


def write_texels(image: moderngl.Texture, first: int, texels: np.ndarray) -> None:
    """Write consecutive texels from index ``first`` (row-major, TABLE_WIDTH per row): at most three writes."""
    width = image.size[0]
    pos, end = first, first + len(texels)
    while pos < end:
        x, y = pos % width, pos // width
        if x == 0 and end - pos >= width:
            count = (end - pos) // width * width
            viewport = (0, y, width, count // width)
        else:
            count = min(width - x, end - pos)
            viewport = (x, y, count, 1)
        image.write(texels[pos - first : pos - first + count], viewport=viewport, alignment=1)
        pos += count


def new_image(ctx: moderngl.Context, texels: int) -> moderngl.Texture:
    """An RGBA32UI image of TABLE_WIDTH-texel rows holding at least ``texels`` texels."""
    import moderngl

    rows = max(1, -(-texels // TABLE_WIDTH))
    texture = ctx.texture((TABLE_WIDTH, rows), 4, dtype="u4")
    texture.filter = (moderngl.NEAREST, moderngl.NEAREST)  # integer textures are complete only so
    return texture


class DeviceTables:
    """The packed tables and the camera row on the device, in buffers or images (``store``); the caller makes
    the context current around every call."""

    def __init__(self, ctx: moderngl.Context, store: str, camera_bytes: int) -> None:
        self._ctx = ctx
        #: ``"ssbo"`` or ``"image"``.
        self.store = store
        #: Each uploaded table's buffer or image, and its size in bytes.
        self.stores: dict[str, moderngl.Buffer | moderngl.Texture] = {}
        self.nbytes: dict[str, int] = {}
        self._camera: moderngl.Buffer | moderngl.Texture = (
            new_image(ctx, camera_bytes // 16) if store == "image" else ctx.buffer(reserve=camera_bytes)
        )
        self._view_tiles: moderngl.Texture | None = None

    def in_image(self, name: str) -> bool:
        """Whether a table lives in an image (every table with the image store; :data:`IMAGE_TABLES` always)."""
        return self.store == "image" or name in IMAGE_TABLES

    def write_whole(self, name: str, table: np.ndarray) -> None:
        """Write a whole table, in place when its size is unchanged, else into a new buffer or image."""
        old = self.stores.get(name)
        same = old is not None and self.nbytes.get(name) == table.nbytes
        if self.in_image(name):
            texels = table.nbytes // 16
            if not same:
                if old is not None:
                    old.release()
                old = self.stores[name] = new_image(self._ctx, texels)
            assert old is not None
            image = image_of(old)
            width, rows = image.size
            data = np.zeros((rows * width, 4), np.uint32)
            data[:texels] = table.view(np.uint32).reshape(-1, 4)
            image.write(data)
        elif same:
            assert old is not None
            old.write(table)
        else:
            if old is not None:
                old.release()
            self.stores[name] = self._ctx.buffer(table)
        self.nbytes[name] = table.nbytes

    def write_rows(self, name: str, table: np.ndarray, rows: range) -> int:
        """Write rows ``[start, stop)`` only; returns the bytes written."""
        part = table[rows.start : rows.stop]
        target = self.stores[name]
        if not self.in_image(name):
            buffer_of(target).write(part, offset=rows.start * table.dtype.itemsize)
            return part.nbytes
        stride = table.dtype.itemsize // 16
        write_texels(image_of(target), rows.start * stride, part.view(np.uint32).reshape(-1, 4))
        return part.nbytes

    def read(self, name: str) -> bytes:
        """The bytes of an uploaded table as the device holds them."""
        store = self.stores[name]
        data = image_of(store).read(alignment=1) if self.in_image(name) else store.read()
        return data[: self.nbytes[name]]

    def bind(self, camera_row: np.ndarray) -> None:
        """Write the frame's camera row and bind every table and the camera where the shader reads them."""
        if self.store == "image":
            camera_image = image_of(self._camera)
            write_texels(camera_image, 0, camera_row.view(np.uint32).reshape(-1, 4))
            for unit, name in enumerate(layout.TABLES, start=1):
                image_of(self.stores[name]).bind_to_image(unit, read=True, write=False)
            camera_image.bind_to_image(CAMERA_IMAGE, read=True, write=False)
        else:
            camera_buffer = buffer_of(self._camera)
            camera_buffer.write(camera_row)
            for binding, name in enumerate(layout.TABLES):
                if name in IMAGE_TABLES:
                    image_of(self.stores[name]).bind_to_image(binding + 1, read=True, write=False)
                else:
                    buffer_of(self.stores[name]).bind_to_storage_buffer(binding)
            camera_buffer.bind_to_storage_buffer(CAMERA_BINDING)

    def bind_view_tiles(self, tiles: np.ndarray) -> None:
        """Write the frame's view tiles into their image (grown when too small) and bind it (image store only)."""
        if self._view_tiles is None or self._view_tiles.size[0] * self._view_tiles.size[1] < len(tiles):
            if self._view_tiles is not None:
                self._view_tiles.release()
            self._view_tiles = new_image(self._ctx, 2 * len(tiles))
        write_texels(self._view_tiles, 0, tiles.view(np.uint32).reshape(-1, 4))
        self._view_tiles.bind_to_image(VIEW_TILES_IMAGE, read=True, write=False)

    def release(self) -> None:
        """Free every buffer and image."""
        for resource in [*self.stores.values(), self._camera]:
            resource.release()
        if self._view_tiles is not None:
            self._view_tiles.release()
            self._view_tiles = None
        self.stores.clear()
        self.nbytes.clear()
