"""Compact binary BVH records for GLSL: both children's boxes on a 16-bit grid in one 32-byte record.

On llvmpipe texel loads bound the traversal: a compact record gives both children's
boxes in 2 texels where two :data:`engine.layout.BVH_NODE_DTYPE` rows take 4. Boxes
are quantised outward over the asset's box and checked for every way a kernel may
round the decoding (unfused, fused, subnormals flushed), so they stay conservative.
"""

from __future__ import annotations

import numpy as np

from engine.bvh import Bvh
from engine.layout import BVH_COMPACT_NODE_DTYPE, BVH_GRID_MAX, BVH_LINK_SHIFT

__all__ = ["compact", "compact_boxes", "compact_frame", "offset_compact"]

_F32_NORMAL = np.float32(np.finfo(np.float32).tiny)


def _decoded(q: np.ndarray, origin: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What a kernel may compute for ``origin + q * scale`` in float32: unfused (rounded twice), and
    the fused value's exact ``(sum, error)`` pair (TwoSum: the product is exact in float64)."""
    q32, o32, s32 = q.astype(np.float32), origin.astype(np.float32), scale.astype(np.float32)
    with np.errstate(over="ignore", invalid="ignore"):
        unfused = q32 * s32 + o32
        a, b = q.astype(np.float64) * s32.astype(np.float64), o32.astype(np.float64)
        total = a + b
        bb = total - a
        err = (a - (total - bb)) + (b - bb)
    return unfused, total, err


def _at_most(q: np.ndarray, origin: np.ndarray, scale: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """Whether every float32 decoding of grid coordinate ``q`` is <= ``bound`` (float32)."""
    unfused, total, err = _decoded(q, origin, scale)
    b = bound.astype(np.float64)
    flushed = np.where(np.abs(total) < _F32_NORMAL, 0.0, total)  # a GPU may flush a subnormal result to 0
    return (unfused <= bound) & ((total < b) | ((total == b) & (err <= 0))) & (flushed <= b)


def _at_least(q: np.ndarray, origin: np.ndarray, scale: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """Whether every float32 decoding of grid coordinate ``q`` is >= ``bound`` (float32)."""
    unfused, total, err = _decoded(q, origin, scale)
    b = bound.astype(np.float64)
    flushed = np.where(np.abs(total) < _F32_NORMAL, 0.0, total)
    return (unfused >= bound) & ((total > b) | ((total == b) & (err >= 0))) & (flushed >= b)


def compact_frame(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(origin, scale)`` float32 of the grid over a root box: ``origin = lo``, and ``origin +
    BVH_GRID_MAX * scale >= hi`` however it is rounded; scale is normal (no flush to zero on a GPU)."""
    origin = lo.astype(np.float32)
    # no subnormal origin (a GPU may flush it to 0): 0 below a positive one, -tiny below a negative one
    origin = np.where(np.abs(origin) < _F32_NORMAL, np.where(origin > 0, 0.0, -_F32_NORMAL), origin)
    origin = np.where(lo.astype(np.float32) == 0, lo.astype(np.float32), origin).astype(np.float32)
    extent = hi.astype(np.float64) - origin.astype(np.float64)
    scale = np.maximum(np.float32(extent / BVH_GRID_MAX), _F32_NORMAL).astype(np.float32)
    top = np.full(3, BVH_GRID_MAX)
    for step in range(80):  # a few ulps, then doubling (where the top lands on a subnormal)
        short = ~_at_least(top, origin, scale, hi.astype(np.float32))
        if not short.any():
            break
        grown = np.nextafter(scale, np.float32(np.inf)) if step < 16 else scale * np.float32(2)
        scale = np.where(short, grown, scale).astype(np.float32)
    return origin, scale


def compact_boxes(
    lo: np.ndarray, hi: np.ndarray, origin: np.ndarray, scale: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Grid coordinates ``(qlo, qhi)`` (N, 3) of float32 boxes (N, 3) inside the frame's root box:
    every float32 decoding of ``qlo`` is <= lo and of ``qhi`` >= hi (conservative; the grid's ends
    always are, so a coordinate that resists rounding falls back to them)."""
    lo32, hi32 = lo.astype(np.float32), hi.astype(np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel_lo = (lo32.astype(np.float64) - origin) / scale.astype(np.float64)
        rel_hi = (hi32.astype(np.float64) - origin) / scale.astype(np.float64)
    qlo = np.clip(np.nan_to_num(np.floor(rel_lo), nan=0.0), 0, BVH_GRID_MAX).astype(np.int64)
    qhi = np.clip(np.nan_to_num(np.ceil(rel_hi), nan=BVH_GRID_MAX), 0, BVH_GRID_MAX).astype(np.int64)
    for _ in range(4):
        bad = ~_at_most(qlo, origin, scale, lo32)
        if not bad.any():
            break
        qlo = np.where(bad, np.maximum(qlo - 1, 0), qlo)
    qlo = np.where(_at_most(qlo, origin, scale, lo32), qlo, 0)
    for _ in range(4):
        bad = ~_at_least(qhi, origin, scale, hi32)
        if not bad.any():
            break
        qhi = np.where(bad, np.minimum(qhi + 1, BVH_GRID_MAX), qhi)
    qhi = np.where(_at_least(qhi, origin, scale, hi32), qhi, BVH_GRID_MAX)
    return qlo, qhi


def compact(bvh: Bvh) -> np.ndarray:
    """A binary tree as compact records (:data:`engine.layout.BVH_COMPACT_NODE_DTYPE`): the header,
    then one record per interior node in node order. Links are relative to the asset (records from
    the header, triangles from its first); :func:`offset_compact` makes them absolute."""
    if bvh.width != 2:
        raise ValueError("compact records are for binary trees")
    nodes = bvh.nodes
    first, count = nodes["first"].astype(np.int64), nodes["count"].astype(np.int64)
    inner = count == 0
    if count.max(initial=0) >= 1 << BVH_LINK_SHIFT:
        raise ValueError(f"a leaf of {count.max()} triangles does not fit a compact link")
    record = np.cumsum(inner) - 1 + 1  # record of each interior node (after the header)
    links = np.where(inner, record << BVH_LINK_SHIFT, (first << BVH_LINK_SHIFT) | count)
    if links.max(initial=0) >= 1 << 31:
        raise ValueError("too many nodes or triangles for compact links")
    origin, scale = compact_frame(nodes["bounds_min"][0], nodes["bounds_max"][0])
    qlo, qhi = compact_boxes(nodes["bounds_min"], nodes["bounds_max"], origin, scale)
    # child.xyz words: (lo.x | lo.y << 16, lo.z | hi.x << 16, hi.y | hi.z << 16) as int32 bits
    words = (
        np.stack([qlo[:, 0] | qlo[:, 1] << 16, qlo[:, 2] | qhi[:, 0] << 16, qhi[:, 1] | qhi[:, 2] << 16], axis=1)
        .astype(np.uint32)
        .view(np.int32)
    )
    out = np.zeros(1 + int(inner.sum()), BVH_COMPACT_NODE_DTYPE)
    out["child0"][0, :3] = origin.view(np.int32)
    out["child0"][0, 3] = links[0]
    out["child1"][0, :3] = scale.view(np.int32)
    out["child1"][0, 3] = -1
    kids = first[inner]
    for field, child in (("child0", kids), ("child1", kids + 1)):
        out[field][1:, :3] = words[child]
        out[field][1:, 3] = links[child]
    return out


def offset_compact(records: np.ndarray, node_base: int, tri_base: int) -> np.ndarray:
    """Compact records of one asset with absolute links: records after ``node_base``, triangles after
    ``tri_base`` (the header's -1 stays)."""
    out = records.copy()
    mask = (1 << BVH_LINK_SHIFT) - 1
    for field in ("child0", "child1"):
        link = out[field][:, 3].astype(np.int64)
        shifted = link + (np.where(link & mask == 0, node_base, tri_base) << BVH_LINK_SHIFT)
        shifted = np.where(link < 0, link, shifted)
        if shifted.max(initial=0) >= 1 << 31:
            raise ValueError("too many nodes or triangles for compact links")
        out[field][:, 3] = shifted
    return out
