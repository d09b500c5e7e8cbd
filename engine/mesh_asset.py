"""A mesh asset: object-space triangles, validated and frozen, identified by a content hash.

What a file parser (:mod:`engine.mesh_files`) or a primitive builder (:mod:`engine.assets`) hands over
becomes a :class:`MeshAsset` here or an :class:`AssetError` naming its source.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from engine.errors import AberrantError
from engine.textures import TextureImage


class AssetError(AberrantError, ValueError):
    """A mesh asset cannot be loaded or is unusable."""


@dataclass(frozen=True, eq=False)
class MeshAsset:
    """Object-space triangles: float32 vertices (N, 3), int32 faces (M, 3), optional float32 UVs (N, 2).

    ``normals`` are the file's unit vertex normals (N, 3), if it has them; ``image`` and ``base_color`` its
    material's colour texture and colour (OBJ ``.mtl`` ``map_Kd``/``Kd``, glTF ``baseColor``), which a
    mesh's own colour multiplies.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray | None
    source: str
    content_hash: str = field(default="")
    normals: np.ndarray | None = None
    image: TextureImage | None = None
    base_color: tuple[float, float, float] = (1.0, 1.0, 1.0)

    @property
    def triangle_count(self) -> int:
        return int(self.faces.shape[0])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.vertices.min(axis=0), self.vertices.max(axis=0)


def make_asset(
    vertices: np.ndarray,
    faces: np.ndarray,
    uvs: np.ndarray | None,
    source: str,
    *,
    normals: np.ndarray | None = None,
    image: TextureImage | None = None,
    base_color: tuple[float, float, float] = (1.0, 1.0, 1.0),
) -> MeshAsset:
    """Validate and freeze geometry; the content hash identifies it everywhere (BVH cache, packing).

    Whatever a file parser hands over (odd shapes, float or huge indices,
    values beyond float32) becomes an :class:`AssetError` naming ``source``,
    never a numpy exception or a silently wrapped index.
    """
    try:
        raw_v = np.asarray(vertices)
        raw_f = np.asarray(faces)
    except (TypeError, ValueError) as e:  # ragged nested lists
        raise AssetError(f"{source}: vertices or faces are not arrays ({e})") from None
    if raw_v.ndim != 2 or raw_v.shape[1] != 3 or not np.issubdtype(raw_v.dtype, np.number):
        raise AssetError(f"{source}: vertices must be (N, 3) numbers, got shape {raw_v.shape} of {raw_v.dtype}")
    if raw_f.ndim != 2 or raw_f.shape[1] != 3 or raw_f.shape[0] == 0:
        raise AssetError(f"{source}: holds no triangles (faces of shape {raw_f.shape}); export it as a triangle mesh")
    if not (np.issubdtype(raw_f.dtype, np.integer) or np.issubdtype(raw_f.dtype, np.floating)):
        raise AssetError(f"{source}: face indices must be integers, got {raw_f.dtype}")
    with np.errstate(over="ignore", invalid="ignore"):  # overflow to inf is reported just below
        v = np.ascontiguousarray(raw_v, dtype=np.float32)
    if not np.all(np.isfinite(v)):
        raise AssetError(f"{source}: vertex coordinates contain NaN or infinity (or exceed the float32 range)")
    if np.issubdtype(raw_f.dtype, np.floating) and not (
        np.all(np.isfinite(raw_f)) and np.array_equal(raw_f, np.round(raw_f))
    ):
        raise AssetError(f"{source}: face indices must be whole numbers")
    low, high = raw_f.min(), raw_f.max()
    if low < 0 or high >= len(v):  # checked before the int32 cast, which would wrap a huge index into range
        raise AssetError(f"{source}: face indices out of range [0, {len(v)}) (found {int(low)}..{int(high)})")
    f = np.ascontiguousarray(raw_f, dtype=np.int32)
    uv = None
    if uvs is not None:
        try:
            with np.errstate(over="ignore", invalid="ignore"):
                uv = np.ascontiguousarray(uvs, dtype=np.float32).reshape(-1, 2)
        except (TypeError, ValueError):
            uv = None
        if uv is not None and (len(uv) != len(v) or not np.all(np.isfinite(uv))):
            uv = None  # unusable UVs: fall back to triplanar texturing rather than failing the load
    n = None
    if normals is not None:
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            n = np.asarray(normals, dtype=np.float64).reshape(-1, 3) if np.size(normals) == v.size else None
            if n is not None:
                n = (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(np.float32)
        if n is not None and not np.all(np.isfinite(n)):
            n = None  # unusable normals: computed from the faces instead
    h = hashlib.sha256()
    arrays = tuple(a for a in (v, f, uv, n) if a is not None)
    for a in arrays:
        h.update(a.tobytes())
        a.setflags(write=False)
    if image is not None:
        h.update(image.content_hash.encode())
    h.update(repr(tuple(base_color)).encode())
    r, g, b = (float(c) for c in base_color)
    return MeshAsset(v, f, uv, source, h.hexdigest(), n, image, (r, g, b))
