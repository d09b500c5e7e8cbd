"""Binned-SAH bounding volume hierarchy of one mesh asset, built fast and cached.

The tree is stored in :data:`engine.layout.BVH_NODE_DTYPE`, the exact bytes the
kernels traverse. Indices are relative to the asset; the packer adds offsets.
:func:`collapse` turns it into a 4- or 8-wide tree (:data:`engine.layout.BVH4_NODE_DTYPE`,
:data:`engine.layout.BVH8_NODE_DTYPE`) for tracers that test four or eight boxes at once with
vector operations; a wide tree has the same leaves, so the triangles' order is the binary tree's. :func:`compact`
packs a binary tree as :data:`engine.layout.BVH_COMPACT_NODE_DTYPE` records (both
children's boxes on a 16-bit grid, conservative) for GLSL, where texel loads bound
the traversal.

Python cannot afford a per-node loop (a 200k-triangle mesh has ~100k nodes), so
the builder is *level-synchronous*: every node of one tree level is binned,
evaluated and partitioned at once with flat NumPy operations over all of that
level's triangles. The cost is a few dozen array calls per level, whatever the
number of nodes in it.
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.layout import BVH_COMPACT_NODE_DTYPE, BVH_LINK_SHIFT, BVH_NODE_DTYPE, BVH_WIDTHS

__all__ = [
    "BUILDER_VERSION",
    "Bvh",
    "BvhParams",
    "build_bvh",
    "cached_bvh",
    "clear_memory_cache",
    "collapse",
    "compact",
    "compact_boxes",
    "compact_frame",
    "leaf_blocks",
    "offset_compact",
]

log = logging.getLogger(__name__)

#: Bump whenever the builder's output changes, so stale disk caches are ignored.
BUILDER_VERSION = 2


@dataclass(frozen=True)
class BvhParams:
    """Knobs of the builder; part of the cache key, so a change rebuilds."""

    max_leaf_size: int = 4
    bins: int = 16
    traversal_cost: float = 1.0

    def __post_init__(self) -> None:
        """Reject values the builder cannot honour, naming the field."""

        def is_int(x: object) -> bool:
            return isinstance(x, int | np.integer) and not isinstance(x, bool)

        if not is_int(self.max_leaf_size) or not 1 <= self.max_leaf_size <= 64:
            raise ValueError(f"BvhParams.max_leaf_size must be an int in 1..64, got {self.max_leaf_size!r}")
        if not is_int(self.bins) or not 2 <= self.bins <= 256:
            raise ValueError(f"BvhParams.bins must be an int in 2..256, got {self.bins!r}")
        cost = self.traversal_cost
        if not isinstance(cost, int | float) or isinstance(cost, bool) or not 0 < cost < np.inf:
            raise ValueError(f"BvhParams.traversal_cost must be a finite number > 0, got {cost!r}")


def _half_area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Half the surface area of boxes, xyz on the FIRST axis; empty boxes (lo > hi) give 0."""
    d = np.maximum(hi.astype(np.float64) - lo, 0.0)
    return d[0] * d[1] + d[1] * d[2] + d[2] * d[0]


def _sweep(a: np.ndarray, op: np.ufunc, reverse: bool = False) -> np.ndarray:
    """Running ``op`` along axis 1; a loop over rows is ~10x faster than ``op.accumulate`` here."""
    out = a.copy()
    rows = range(out.shape[1] - 2, -1, -1) if reverse else range(1, out.shape[1])
    step = 1 if reverse else -1
    for i in rows:
        op(out[:, i + step], out[:, i], out=out[:, i])
    return out


@dataclass(frozen=True, eq=False)
class Bvh:
    """A built tree: ``nodes`` (root at 0) over triangles reordered by ``triangle_order``.

    ``eq=False``: field-wise ``==`` on arrays is ambiguous; trees compare (and hash) by identity.
    """

    nodes: np.ndarray
    triangle_order: np.ndarray
    params: BvhParams

    @property
    def width(self) -> int:
        """Children per node: 2 (:data:`BVH_NODE_DTYPE`), 4 or 8 (the wide dtypes of :data:`BVH_WIDTHS`)."""
        return next(w for w, dtype in BVH_WIDTHS.items() if self.nodes.dtype == dtype)

    def depth(self) -> int:
        """Number of nodes on the longest root-to-leaf path (a lone binary leaf has depth 1).

        A wide tree counts wide nodes only (its leaves live in its nodes' slots).
        """
        if self.width > 2:
            child, count = self.nodes["child"], self.nodes["count"]
            frontier, depth = np.zeros(1, np.int64), 0
            while frontier.size:
                depth += 1
                frontier = child[frontier][count[frontier] == 0].astype(np.int64)
            return depth
        first, count = self.nodes["first"], self.nodes["count"]
        frontier, depth = np.zeros(1, np.int64), 0
        while frontier.size:
            depth += 1
            inner = frontier[count[frontier] == 0]
            frontier = np.concatenate([first[inner], first[inner] + 1]).astype(np.int64)
        return depth

    def sah_cost(self) -> float:
        """SAH cost relative to the root's area: traversal_cost per inner node, 1 per triangle test.

        The same formula for every width (a wide node costs what a binary one does), so collapsing
        can only lower it: each binary node pulled into its parent takes its term away.
        """
        if self.width > 2:
            n, w = self.nodes, self.width
            lo = np.stack([n["lo_x"], n["lo_y"], n["lo_z"]]).reshape(3, -1)
            hi = np.stack([n["hi_x"], n["hi_y"], n["hi_z"]]).reshape(3, -1)
            count = n["count"].reshape(-1)
            used = count >= 0
            lo, hi, count = lo[:, used], hi[:, used], count[used]
            root = _half_area(lo[:, : int(used[:w].sum())].min(axis=1), hi[:, : int(used[:w].sum())].max(axis=1))
            area = _half_area(lo, hi)
            rel = area / root if np.isfinite(root) and root > 0 else np.ones_like(area)
            inner = count == 0
            inner_terms = 1.0 + rel[inner].sum()  # the root, then every wide child
            return float(self.params.traversal_cost * inner_terms + (count[~inner] * rel[~inner]).sum())
        area = _half_area(self.nodes["bounds_min"].T, self.nodes["bounds_max"].T)
        rel = area / area[0] if np.isfinite(area[0]) and area[0] > 0 else np.ones_like(area)
        count = self.nodes["count"]
        inner = count == 0
        return float(self.params.traversal_cost * rel[inner].sum() + (count[~inner] * rel[~inner]).sum())


def _validated(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Contiguous float32 (N, 3) vertices and int32 (M, 3) faces, or a ValueError saying what is wrong."""
    v = np.asarray(vertices)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (N, 3), got {v.shape}")
    if not (np.issubdtype(v.dtype, np.floating) or np.issubdtype(v.dtype, np.integer)):
        raise ValueError(f"vertices must be numeric, got dtype {v.dtype}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (M, 3), got {f.shape}")
    if f.shape[0] < 1:
        raise ValueError("faces is empty: a BVH needs at least one triangle")
    if not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"faces must be integer indices, got dtype {f.dtype}")
    with np.errstate(over="ignore"):
        v = np.ascontiguousarray(v, dtype=np.float32)
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        raise ValueError(
            f"vertices contain non-finite values (NaN or inf, or too large for float32): "
            f"{int(bad.sum())} vertices, first at index {int(np.argmax(bad))}"
        )
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(
            f"faces index out of range: indices span [{int(f.min())}, {int(f.max())}] but there are {len(v)} vertices"
        )
    return v, np.ascontiguousarray(f, dtype=np.int32)


def _plan_level(
    cent: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    local: np.ndarray,
    seg: np.ndarray,
    size: np.ndarray,
    p: BvhParams,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Decide every node of one level at once.

    Inputs are per element (a triangle in a node, grouped by node): centroid,
    box, node index ``local``; and per node: ``seg`` (first element), ``size``.
    Returns per node whether it splits and its left size, and per element its
    new offset inside its node (left part first; identity for leaves).
    """
    k, n, bins = size.size, local.size, p.bins
    cmin = np.minimum.reduceat(cent, seg, axis=0)
    cmax = np.maximum.reduceat(cent, seg, axis=0)
    ext = cmax - cmin
    scale = np.where(ext > 0, bins / np.where(ext > 0, ext, 1.0), 0.0)
    b = ((cent - cmin[local]) * scale[local]).astype(np.int64)
    np.clip(b, 0, bins - 1, out=b)
    # Layout (xyz, bin, node, axis): sweeps and areas then run over contiguous blocks.
    key = (b * (k * 3) + (local[:, None] * 3 + np.arange(3))).ravel()  # element-major, axis-minor
    nkeys = bins * k * 3
    cnt = np.bincount(key, minlength=nkeys).reshape(bins, k, 3)
    blo = np.full((3, nkeys), np.inf, np.float32)
    bhi = np.full((3, nkeys), -np.inf, np.float32)
    for j in range(3):  # 1-D ufunc.at is fast; one call per box component
        np.minimum.at(blo[j], key, np.repeat(lo[:, j], 3))
        np.maximum.at(bhi[j], key, np.repeat(hi[:, j], 3))
    blo, bhi = blo.reshape(3, bins, k, 3), bhi.reshape(3, bins, k, 3)
    plo, phi = _sweep(blo, np.minimum), _sweep(bhi, np.maximum)
    slo, shi = _sweep(blo, np.minimum, reverse=True), _sweep(bhi, np.maximum, reverse=True)
    nl = np.cumsum(cnt, axis=0)[:-1]  # candidate s = 1..bins-1: left = bins < s
    nr = size[:, None] - nl
    cost = _half_area(plo[:, :-1], phi[:, :-1]) * nl + _half_area(slo[:, 1:], shi[:, 1:]) * nr
    box_lo, box_hi = plo[:, -1, :, 0], phi[:, -1, :, 0]  # (xyz, node): the node's bounds
    area = _half_area(box_lo, box_hi)
    flat = area <= 0  # a point or a segment: SAH is blind, prefer balanced splits
    cost = np.where(flat[:, None], np.abs(nl - nr).astype(np.float64), cost)
    cost = np.where((nl > 0) & (nr > 0), cost, np.inf).transpose(1, 2, 0).reshape(k, -1)
    best = np.argmin(cost, axis=1)  # over (axis, cut) pairs
    best_cost = cost[np.arange(k), best]
    axis, cut = best // (bins - 1), best % (bins - 1) + 1
    has_cut = np.isfinite(best_cost)
    cheaper = p.traversal_cost * area + best_cost < size * area
    sah_leaf = has_cut & ~flat & ~cheaper & (size <= 4 * p.max_leaf_size)
    split = ~sah_leaf
    # Partition: a stable in-node partition by the chosen bin, with segmented cumsums.
    is_left = np.where(split[local], b[np.arange(n), axis[local]] < cut[local], True)
    cs = np.concatenate([[0], np.cumsum(is_left)])
    before = cs[seg]
    nleft = cs[seg + size] - before
    lrank = cs[1:] - before[local]
    j = np.arange(n) - seg[local]
    newoff = np.where(is_left, lrank - 1, nleft[local] + j - lrank)
    fallback = ~has_cut  # all centroids identical: median of box centres on the longest axis
    if fallback.any():
        idx = np.flatnonzero(fallback[local])
        longest = np.argmax(box_hi.astype(np.float64) - box_lo, axis=0)
        centre = lo[idx, longest[local[idx]]].astype(np.float64) + hi[idx, longest[local[idx]]]
        perm = idx[np.lexsort((centre, local[idx]))]
        fsize = np.where(fallback, size, 0)
        sub_start = np.cumsum(fsize) - fsize
        newoff[perm] = np.arange(idx.size) - sub_start[local[perm]]
        nleft[fallback] = size[fallback] // 2
    return split, nleft, newoff


def build_bvh(vertices: np.ndarray, faces: np.ndarray, params: BvhParams = BvhParams()) -> Bvh:
    """Build a binned-SAH BVH; degenerate triangles are kept, non-finite vertices are refused."""
    verts, tris = _validated(vertices, faces)
    corners = verts[tris]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    cent = corners.sum(axis=1, dtype=np.float64) / 3.0
    m = len(tris)
    leaf_max = params.max_leaf_size
    order = np.arange(m, dtype=np.int64)
    first = np.zeros(2 * m - 1, np.int64)
    count = np.zeros(2 * m - 1, np.int64)
    levels: list[np.ndarray] = []  # inner node ids, one array per level
    ids, start, size = (np.zeros(1, np.int64), np.zeros(1, np.int64), np.full(1, m, np.int64))
    if m <= leaf_max:
        count[0] = m
        ids = ids[:0]
    next_id = 1
    chunk = max(1, (1 << 22) // (9 * params.bins))
    while ids.size:
        seg = np.cumsum(size) - size
        local = np.repeat(np.arange(ids.size), size)
        base = np.repeat(start, size)
        t = order[np.arange(local.size) - seg[local] + base]
        ct, lt, ht = cent[t], lo[t], hi[t]
        plans = []
        for a in range(0, ids.size, chunk):  # chunks of nodes bound the (node, bin) arrays' memory
            z, e = seg[a], seg[a] + size[a : a + chunk].sum()
            args = (ct[z:e], lt[z:e], ht[z:e], local[z:e] - a, seg[a : a + chunk] - z, size[a : a + chunk])
            plans.append(_plan_level(*args, params))
        split, nleft, newoff = (np.concatenate(parts) for parts in zip(*plans, strict=True))
        order[base + newoff] = t
        leaves = ~split
        first[ids[leaves]], count[ids[leaves]] = start[leaves], size[leaves]
        parents = ids[split]
        children = next_id + 2 * np.arange(parents.size)
        next_id += 2 * parents.size
        first[parents] = children
        levels.append(parents)
        cid = np.stack([children, children + 1], axis=1).ravel()
        nl = nleft[split]
        cstart = np.stack([start[split], start[split] + nl], axis=1).ravel()
        csize = np.stack([nl, size[split] - nl], axis=1).ravel()
        small = csize <= leaf_max
        first[cid[small]], count[cid[small]] = cstart[small], csize[small]
        ids, start, size = cid[~small], cstart[~small], csize[~small]
    first, count = first[:next_id], count[:next_id]
    # Exact bounds: leaves by one segmented reduction, inner nodes bottom-up.
    bmin = np.empty((next_id, 3), np.float32)
    bmax = np.empty((next_id, 3), np.float32)
    leaf_ids = np.flatnonzero(count > 0)
    leaf_ids = leaf_ids[np.argsort(first[leaf_ids])]
    bmin[leaf_ids] = np.minimum.reduceat(lo[order].T, first[leaf_ids], axis=1).T
    bmax[leaf_ids] = np.maximum.reduceat(hi[order].T, first[leaf_ids], axis=1).T
    for parents in reversed(levels):
        c = first[parents]
        bmin[parents] = np.minimum(bmin[c], bmin[c + 1])
        bmax[parents] = np.maximum(bmax[c], bmax[c + 1])
    nodes = np.zeros(next_id, BVH_NODE_DTYPE)
    # Round outward so a tracer of any precision never misses because of the bounds.
    nodes["bounds_min"] = np.nextafter(bmin, np.float32(-np.inf))
    nodes["bounds_max"] = np.nextafter(bmax, np.float32(np.inf))
    nodes["first"], nodes["count"] = first, count
    return _frozen(nodes, order.astype(np.int32), params)


def _leaf_counts(first: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """Leaves under each node of a binary tree (1 for a leaf), level by level from the bottom."""
    levels = [np.zeros(1, np.int64)] if inner[0] else []
    while levels and levels[-1].size:
        kids = first[levels[-1]]
        kids = np.concatenate([kids, kids + 1])
        levels.append(kids[inner[kids]])
    leaves = np.ones(len(first), np.int64)
    for level in reversed(levels):
        leaves[level] = leaves[first[level]] + leaves[first[level] + 1]
    return leaves


def collapse(bvh: Bvh, width: int = 4) -> Bvh:
    """The ``width``-wide tree (4 or 8) of a binary one: each wide node takes a binary node's two
    children, then pulls up inner children until it has ``width`` (or only leaves): first those inside a
    subtree of at most ``width`` leaves (so such a subtree's leaves share one wide node), then the
    largest-area one.

    Every pull removes one binary node and its SAH term (largest area first: the dearest to visit);
    leaves and the triangles' order are unchanged. Level-synchronous like the builder: a few array
    operations per level of the wide tree.
    """
    if bvh.width != 2:
        raise ValueError(f"collapse takes a binary tree, got width {bvh.width}")
    if width not in BVH_WIDTHS or width == 2:
        raise ValueError(f"collapse builds widths {sorted(w for w in BVH_WIDTHS if w > 2)}, got {width!r}")
    b = bvh.nodes
    first, count = b["first"].astype(np.int64), b["count"].astype(np.int64)
    inner = count == 0
    area = _half_area(b["bounds_min"].T, b["bounds_max"].T)
    # A subtree of at most `width` leaves is opened whole (its inner nodes are pulled before any other),
    # so its leaves share one wide node: filling by area alone left most 8-wide nodes of the tori holding
    # 2 leaves (15408 of 25445 nodes at 200k triangles, now 4040 of 14509; SAH 24.1 -> 23.6; 0.5-1.5 %
    # less CPU per frame on the tori, PoCL 3.1, 800x800).
    leaves = _leaf_counts(first, inner)
    opened = np.zeros(len(b), bool)
    small = np.flatnonzero(inner & (leaves <= width))
    opened[first[small]] = opened[first[small] + 1] = True
    boost = area.max() + 1.0
    rows: list[np.ndarray] = []  # per level: (F, width) binary node ids in the slots, -1 empty
    frontier = np.zeros(1, np.int64)
    if not inner[0]:  # a lone leaf: one wide node holding it
        lone = np.full((1, width), -1, np.int64)
        lone[0, 0] = 0
        rows.append(lone)
        frontier = frontier[:0]
    col = np.arange(width)
    while frontier.size:
        f = frontier.size
        slots = np.full((f, width), -1, np.int64)
        slots[:, 0], slots[:, 1] = first[frontier], first[frontier] + 1
        r = np.arange(f)
        for used in range(2, width):
            safe = np.maximum(slots, 0)
            pullable = (slots >= 0) & inner[safe]
            pick = np.argmax(np.where(pullable, area[safe] + opened[safe] * boost, -1.0), axis=1)
            can = pullable[r, pick]
            picked = slots[r, pick]
            # Insert the picked node's two children in its place: the left-to-right order stays.
            src = np.where(col[None, :] <= pick[:, None], col[None, :], col[None, :] - 1)
            grown = slots[r[:, None], src]
            grown[r, pick] = first[np.maximum(picked, 0)]
            grown[r, np.minimum(pick + 1, used)] = first[np.maximum(picked, 0)] + 1
            slots = np.where(can[:, None], grown, slots)
        rows.append(slots)
        flat = slots.ravel()
        frontier = flat[(flat >= 0) & inner[np.maximum(flat, 0)]]
    slots = np.concatenate(rows)
    wide_inner = (slots >= 0) & inner[np.maximum(slots, 0)]
    # Wide nodes are numbered in level order, and inner slots in row-major order are exactly that order.
    wide_id = np.zeros(slots.shape, np.int64)
    wide_id[wide_inner] = np.arange(1, int(wide_inner.sum()) + 1)
    safe = np.maximum(slots, 0)
    nodes = np.zeros(len(slots), BVH_WIDTHS[width])
    empty = slots < 0

    def put(field: str, values: np.ndarray) -> None:
        # Width 8 stores each 8-lane field as two 4-vector rows (the bytes of a float8 / int8).
        nodes[field] = values.reshape(nodes[field].shape)

    for k, axis in enumerate("xyz"):
        put(f"lo_{axis}", np.where(empty, 0.0, b["bounds_min"][safe, k]))
        put(f"hi_{axis}", np.where(empty, 0.0, b["bounds_max"][safe, k]))
    put("child", np.where(empty, 0, np.where(wide_inner, wide_id, first[safe])))
    put("count", np.where(empty, -1, count[safe]))
    return _frozen(nodes, bvh.triangle_order.copy(), bvh.params)


def leaf_blocks(bvh: Bvh, block: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Blocks of ``block`` triangles for a wide tree's leaves: ``(lanes, child)``.

    ``lanes`` (B, block): each block's triangle rows (relative to the asset, -1 for padding), a leaf's
    blocks consecutive, leaves in node order; ``child``: the nodes' ``child`` with each leaf slot
    pointing at its first block instead of its first triangle (counts unchanged).
    """
    if bvh.width == 2:
        raise ValueError("triangle blocks are for wide trees (width 4 or 8)")
    count = bvh.nodes["count"].reshape(-1).astype(np.int64)
    first = bvh.nodes["child"].reshape(-1).astype(np.int64)
    leaf = count > 0
    nblocks = (count[leaf] + block - 1) // block
    start = np.cumsum(nblocks) - nblocks
    child = first.copy()
    child[leaf] = start
    owner = np.repeat(np.arange(nblocks.size), nblocks)  # the leaf of each block
    j = np.arange(owner.size) - start[owner]  # block number inside its leaf
    offset = block * j[:, None] + np.arange(block)[None, :]
    lanes = np.where(offset < count[leaf][owner][:, None], first[leaf][owner][:, None] + offset, -1)
    return lanes.astype(np.int32), child.reshape(bvh.nodes["child"].shape).astype(np.int32)


# --- compact records (GLSL) --------------------------------------------------------

#: Largest grid coordinate of a compact record (16 bits).
GRID_MAX = 65535
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
    GRID_MAX * scale >= hi`` however it is rounded; scale is normal (no flush to zero on a GPU)."""
    origin = lo.astype(np.float32)
    # no subnormal origin (a GPU may flush it to 0): 0 below a positive one, -tiny below a negative one
    origin = np.where(np.abs(origin) < _F32_NORMAL, np.where(origin > 0, 0.0, -_F32_NORMAL), origin)
    origin = np.where(lo.astype(np.float32) == 0, lo.astype(np.float32), origin).astype(np.float32)
    extent = hi.astype(np.float64) - origin.astype(np.float64)
    scale = np.maximum(np.float32(extent / GRID_MAX), _F32_NORMAL).astype(np.float32)
    top = np.full(3, GRID_MAX)
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
    qlo = np.clip(np.nan_to_num(np.floor(rel_lo), nan=0.0), 0, GRID_MAX).astype(np.int64)
    qhi = np.clip(np.nan_to_num(np.ceil(rel_hi), nan=GRID_MAX), 0, GRID_MAX).astype(np.int64)
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
        qhi = np.where(bad, np.minimum(qhi + 1, GRID_MAX), qhi)
    qhi = np.where(_at_least(qhi, origin, scale, hi32), qhi, GRID_MAX)
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


def _frozen(nodes: np.ndarray, order: np.ndarray, params: BvhParams) -> Bvh:
    """A Bvh whose arrays are read-only: cached trees are shared between callers."""
    nodes.flags.writeable = False
    order.flags.writeable = False
    return Bvh(nodes=nodes, triangle_order=order, params=params)


# --- caching -------------------------------------------------------------------

_MEMORY_CACHE: dict[str, Bvh] = {}


def clear_memory_cache() -> None:
    """Forget the in-process trees (tests, or to free memory); disk caches stay."""
    _MEMORY_CACHE.clear()


def _default_cache_dir() -> Path:
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
    """Read a cached tree, checking it is whole; raises on anything suspicious."""
    with np.load(path, allow_pickle=False) as data:
        if str(data["key"]) != key:
            raise ValueError("cache key mismatch")
        raw = np.ascontiguousarray(data["nodes"], dtype=np.int32)
        order = np.ascontiguousarray(data["triangle_order"], dtype=np.int32)
    dtype = BVH_WIDTHS[width]
    columns = dtype.itemsize // 4
    if raw.ndim != 2 or raw.shape[1] != columns or not 1 <= len(raw) <= 2 * m - 1 or order.shape != (m,):
        raise ValueError("cached arrays have the wrong shape")
    nodes = raw.view(dtype).reshape(-1).copy()
    if not (np.sort(order) == np.arange(m)).all():
        raise ValueError("cached triangle_order is not a permutation")
    return _frozen(nodes, order, params)


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
    params: BvhParams = BvhParams(),
    cache_dir: Path | None = None,
    width: int = 2,
) -> Bvh:
    """:func:`build_bvh` (then :func:`collapse` for ``width`` 4 or 8) behind an in-process and an on-disk
    cache keyed by content, parameters and width."""
    if width not in BVH_WIDTHS:
        raise ValueError(f"BVH width must be one of {sorted(BVH_WIDTHS)}, got {width!r}")
    verts, tris = _validated(vertices, faces)
    key = _cache_key(verts, tris, params, width)
    hit = _MEMORY_CACHE.get(key)
    if hit is not None:
        return hit
    path = Path(cache_dir if cache_dir is not None else _default_cache_dir()) / "bvh" / f"{key}.npz"
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
