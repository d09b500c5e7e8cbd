"""Image textures: read once, packed with every other texture of a scene into one texel table.

A texture is an 8-bit image; the packer stores each as ``width * height``
consecutive rows of ``texels`` (linear RGBA in [0, 1], top image row first)
and names its first row and size in the material (docs/semantics.md,
"Meshes and shading"). A missing or unreadable file is no error: one warning
line names it and the mesh is drawn in its base colour.
"""

from __future__ import annotations

import hashlib
import io
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from engine import layout
from engine.atomic_files import read_regular
from engine.errors import AberrantError, shorten

#: Default texel budget of a scene, in MiB of packed texels (16 bytes a texel): 16M texels, a 4096^2 image.
DEFAULT_BUDGET_MIB = 256.0

_log = logging.getLogger(__name__)


class TextureBudgetError(AberrantError, ValueError):
    """A scene's textures do not fit its texel budget."""


@dataclass(frozen=True, eq=False)
class TextureImage:
    """An image as (H, W, 4) uint8 RGBA, row 0 the image's top row."""

    pixels: np.ndarray
    source: str
    content_hash: str = field(default="")

    @property
    def texel_bytes(self) -> int:
        return int(self.pixels.shape[0] * self.pixels.shape[1]) * layout.TEXEL_DTYPE.itemsize


def texture_image(pixels: np.ndarray, source: str) -> TextureImage:
    """Freeze an (H, W, 3 or 4) uint8 image; its hash identifies it in the atlas."""
    p = np.asarray(pixels)
    if p.ndim == 2:
        p = np.repeat(p[:, :, None], 3, axis=2)
    if p.shape[2] == 3:
        p = np.concatenate([p, np.full((*p.shape[:2], 1), 255, p.dtype)], axis=2)
    p = np.ascontiguousarray(p, dtype=np.uint8)
    p.setflags(write=False)
    return TextureImage(p, source, hashlib.sha256(p.tobytes() + repr(p.shape).encode()).hexdigest())


def decode_image(data: bytes, source: str) -> TextureImage:
    """An image file's bytes (any format Pillow reads) as a texture; raises ``OSError``/``ValueError``."""
    from PIL import Image

    with Image.open(io.BytesIO(data)) as image:
        rgba = image.convert("RGBA")
        if rgba.width == 0 or rgba.height == 0:
            raise ValueError("an empty image")
        return texture_image(np.asarray(rgba), source)


class TextureLibrary:
    """Reads each image file once (by resolved path, modification time and size); warns once per missing file."""

    def __init__(self) -> None:
        self._by_stat: dict[tuple[str, int, int], TextureImage] = {}
        self._warned: set[str] = set()

    def load(self, path: str | Path) -> TextureImage | None:
        """The image at ``path``, or None (after one warning line naming it) when it cannot be read."""
        p = Path(path).expanduser()
        name = shorten(p)
        try:
            resolved = p.resolve(strict=True)
            st = resolved.stat()
            key = (str(resolved), st.st_mtime_ns, st.st_size)
            if key in self._by_stat:
                return self._by_stat[key]
            image = decode_image(read_regular(resolved), name)
        except FileNotFoundError:
            self._warn(name, "texture file not found")
            return None
        except (OSError, ValueError, RuntimeError) as e:  # unreadable, not an image, a symlink loop
            self._warn(name, f"cannot read the texture ({type(e).__name__}: {e})")
            return None
        except Exception as e:  # Pillow raises many types on malformed images
            self._warn(name, f"cannot decode the texture ({type(e).__name__}: {e})")
            return None
        self._by_stat[key] = image
        self._warned.discard(name)
        return image

    def _warn(self, name: str, why: str) -> None:
        if name not in self._warned:
            self._warned.add(name)
            warn_unreadable(name, why)


def warn_unreadable(name: str, why: str) -> None:
    """The one warning line of a texture that cannot be used."""
    _log.warning("%s: %s; the mesh is drawn in its base colour", name, why)


def pack_atlas(images: list[tuple[str, TextureImage]], budget_mib: float) -> tuple[np.ndarray, dict[str, int]]:
    """The ``texels`` table of distinct images (by hash) and each one's first row.

    ``images`` pairs each with the name it is used by (an entity's field), for the error naming the texture
    that takes the scene past ``budget_mib``.
    """
    budget = int(budget_mib * 2**20)
    first: dict[str, int] = {}
    chunks: list[np.ndarray] = []
    rows = 0
    for user, image in images:
        if image.content_hash in first:
            continue
        h, w = image.pixels.shape[:2]
        if (rows + h * w) * layout.TEXEL_DTYPE.itemsize > budget:
            mib = (rows + h * w) * layout.TEXEL_DTYPE.itemsize / 2**20
            raise TextureBudgetError(
                f"{user}: texture {image.source} ({w}x{h}) takes the scene's texels to {mib:.1f} MiB, past the "
                f"{budget_mib:g} MiB texture budget (ScenePacker texture_budget_mib; use a smaller image)"
            )
        t = np.zeros(h * w, dtype=layout.TEXEL_DTYPE)
        t["rgba"] = image.pixels.reshape(-1, 4).astype(np.float32) / np.float32(255.0)
        first[image.content_hash] = rows
        chunks.append(t)
        rows += h * w
    table = np.concatenate(chunks) if chunks else np.zeros(0, dtype=layout.TEXEL_DTYPE)
    return table, first
