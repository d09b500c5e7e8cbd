"""BVHs cached in memory and on disk, keyed by mesh content, build parameters and width.

Building a 200,000-triangle tree takes about a second; loading it back takes
milliseconds, so every scene load after the first is quick. A corrupt or foreign
cache file is only a miss (the tree is rebuilt and the file rewritten whole).
"""

from __future__ import annotations

import hashlib
import io
import logging
import os
import tempfile
from pathlib import Path

import numpy as np

from engine.atomic_files import read_regular
from engine.bvh import BUILDER_VERSION, Bvh, BvhParams, build_bvh, frozen_bvh, validated_geometry
from engine.bvh_wide import collapse
from engine.layout import BVH_WIDTHS

__all__ = ["cached_bvh", "clear_memory_cache", "default_cache_dir"]

log = logging.getLogger(__name__)

_MEMORY_CACHE: dict[str, Bvh] = {}


def clear_memory_cache() -> None:
    """Forget the in-process trees (tests, or to free memory); disk caches stay."""
    _MEMORY_CACHE.clear()


def default_cache_dir() -> Path:
    """``$ABERRANT_CACHE_DIR`` or ``~/.cache/aberrant``."""
    env = os.environ.get("ABERRANT_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "aberrant"


def _cache_key(verts: np.ndarray, tris: np.ndarray, params: BvhParams, width: int = 2) -> str:
    """Content hash of the geometry, the parameters, the width and the builder version."""
    h = hashlib.sha256()
    h.update(f"bvh-v{BUILDER_VERSION};w{width};{verts.shape};{tris.shape};{params!r};".encode())
    h.update(verts.tobytes())
    h.update(tris.tobytes())
    return h.hexdigest()


def _load(path: Path, key: str, m: int, params: BvhParams, width: int = 2) -> Bvh:
    """Read a cached tree, checking it is whole; raises on anything suspicious (a FIFO there too, at once)."""
    with np.load(io.BytesIO(read_regular(path)), allow_pickle=False) as data:
        if str(data["key"]) != key:
            raise ValueError("cache key mismatch")
        raw = np.ascontiguousarray(data["nodes"], dtype=np.int32)
        order = np.ascontiguousarray(data["triangle_order"], dtype=np.int32)
    dtype = BVH_WIDTHS[width]
    columns = dtype.itemsize // 4
    refs = len(order) if order.ndim == 1 else 0
    if raw.ndim != 2 or raw.shape[1] != columns or not 1 <= len(raw) <= 2 * refs - 1 or refs < m:
        raise ValueError("cached arrays have the wrong shape")
    nodes = raw.view(dtype).reshape(-1).copy()
    if order.min() < 0 or order.max() >= m or (np.bincount(order, minlength=m) == 0).any():
        raise ValueError("cached triangle_order misses a triangle or names one out of range")
    if refs > (m * (1 + params.split_budget) + 1 if params.split_ratio > 0 else m):
        raise ValueError("cached triangle_order has more references than the split budget allows")
    return frozen_bvh(nodes, order, params)


def _save(path: Path, key: str, bvh: Bvh) -> None:
    """Write atomically: a temp file in the same folder, then os.replace."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            raw = np.ascontiguousarray(bvh.nodes).view(np.int32).reshape(len(bvh.nodes), -1)
            np.savez(fh, key=np.array(key), nodes=raw, triangle_order=bvh.triangle_order)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def cached_bvh(
    vertices: np.ndarray,
    faces: np.ndarray,
    params: BvhParams | None = None,
    cache_dir: Path | None = None,
    width: int = 2,
) -> Bvh:
    """:func:`engine.bvh.build_bvh` (then :func:`engine.bvh_wide.collapse` for ``width`` 4 or 8) behind
    an in-process and an on-disk cache keyed by content, parameters and width."""
    params = params if params is not None else BvhParams()
    if width not in BVH_WIDTHS:
        raise ValueError(f"BVH width must be one of {sorted(BVH_WIDTHS)}, got {width!r}")
    verts, tris = validated_geometry(vertices, faces)
    key = _cache_key(verts, tris, params, width)
    hit = _MEMORY_CACHE.get(key)
    if hit is not None:
        return hit
    path = Path(cache_dir if cache_dir is not None else default_cache_dir()) / "bvh" / f"{key}.npz"
    bvh: Bvh | None = None
    if path.exists():
        try:
            bvh = _load(path, key, len(tris), params, width)
        except Exception as exc:  # a corrupt or foreign file is only a cache miss
            log.debug("rebuilding BVH: cannot use cache file %s (%s)", path, exc)
    if bvh is None:
        if width == 2:
            bvh = build_bvh(verts, tris, params)
        else:
            bvh = collapse(cached_bvh(verts, tris, params, cache_dir), width)
        try:
            _save(path, key, bvh)
        except OSError as exc:
            log.debug("cannot write BVH cache file %s (%s)", path, exc)
    _MEMORY_CACHE[key] = bvh
    return bvh
