"""Binned-SAH bounding volume hierarchy of one mesh asset, built fast.

The tree is stored in :data:`engine.layout.BVH_NODE_DTYPE`, the exact bytes the
kernels traverse. Indices are relative to the asset; the packer adds offsets.
:mod:`engine.bvh_wide` collapses it into 4- or 8-wide trees for tracers that test
several boxes at once with vector operations, :mod:`engine.bvh_compact` packs it as
compact records for GLSL, and :mod:`engine.bvh_cache` keeps built trees in memory
and on disk.

Python cannot afford a per-node loop (a 200k-triangle mesh has ~100k nodes), so
the builder is *level-synchronous*: every node of one tree level is binned,
evaluated and partitioned at once with flat NumPy operations over all of that
level's triangles. The cost is a few dozen array calls per level, whatever the
number of nodes in it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from engine.bvh_split import half_area, split_references
from engine.layout import BVH_NODE_DTYPE, BVH_WIDTHS

__all__ = [
    "BUILDER_VERSION",
    "Bvh",
    "BvhParams",
    "build_bvh",
    "frozen_bvh",
    "half_area",
    "validated_geometry",
]

log = logging.getLogger(__name__)

#: Bump whenever the builder's output changes, so stale disk caches are ignored.
BUILDER_VERSION = 3


@dataclass(frozen=True)
class BvhParams:
    """Knobs of the builder; part of the cache key, so a change rebuilds."""

    max_leaf_size: int = 4
    bins: int = 16
    traversal_cost: float = 1.0
    #: Pre-split triangles whose box's half area exceeds this many times their area (0: never).
    #: 8 leaves even, well-shaped meshes (a torus, a tessellated ground) exactly as they were.
    split_ratio: float = 8.0
    #: At most this fraction of the triangle count in extra references (an asset of long planks
    #: doubles; at +30 % its frames cost 0.88x the unsplit ones, at +100 % 0.55x).
    split_budget: float = 1.0

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
        for name in ("split_ratio", "split_budget"):
            x = getattr(self, name)
            if not isinstance(x, int | float) or isinstance(x, bool) or not 0 <= x < np.inf:
                raise ValueError(f"BvhParams.{name} must be a finite number >= 0, got {x!r}")


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

    With pre-splitting a triangle may appear more than once in ``triangle_order`` (one row per leaf
    that references it); every triangle appears at least once.

    ``eq=False``: field-wise ``==`` on arrays is ambiguous; trees compare (and hash) by identity.
    """

    nodes: np.ndarray
    triangle_order: np.ndarray
    params: BvhParams

    @property
    def width(self) -> int:
        """Children per node: 2 (:data:`engine.layout.BVH_NODE_DTYPE`), 4 or 8.

        The wide nodes' dtypes are those of :data:`engine.layout.BVH_WIDTHS`.
        """
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
            root = half_area(lo[:, : int(used[:w].sum())].min(axis=1), hi[:, : int(used[:w].sum())].max(axis=1))
            area = half_area(lo, hi)
            rel = area / root if np.isfinite(root) and root > 0 else np.ones_like(area)
            inner = count == 0
            inner_terms = 1.0 + rel[inner].sum()  # the root, then every wide child
            return float(self.params.traversal_cost * inner_terms + (count[~inner] * rel[~inner]).sum())
        area = half_area(self.nodes["bounds_min"].T, self.nodes["bounds_max"].T)
        rel = area / area[0] if np.isfinite(area[0]) and area[0] > 0 else np.ones_like(area)
        count = self.nodes["count"]
        inner = count == 0
        return float(self.params.traversal_cost * rel[inner].sum() + (count[~inner] * rel[~inner]).sum())


def validated_geometry(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    blo: np.ndarray = np.full((3, nkeys), np.inf, np.float32)
    bhi: np.ndarray = np.full((3, nkeys), -np.inf, np.float32)
    for j in range(3):  # 1-D ufunc.at is fast; one call per box component
        np.minimum.at(blo[j], key, np.repeat(lo[:, j], 3))
        np.maximum.at(bhi[j], key, np.repeat(hi[:, j], 3))
    blo, bhi = blo.reshape(3, bins, k, 3), bhi.reshape(3, bins, k, 3)
    plo, phi = _sweep(blo, np.minimum), _sweep(bhi, np.maximum)
    slo, shi = _sweep(blo, np.minimum, reverse=True), _sweep(bhi, np.maximum, reverse=True)
    nl = np.cumsum(cnt, axis=0)[:-1]  # candidate s = 1..bins-1: left = bins < s
    nr = size[:, None] - nl
    cost = half_area(plo[:, :-1], phi[:, :-1]) * nl + half_area(slo[:, 1:], shi[:, 1:]) * nr
    box_lo, box_hi = plo[:, -1, :, 0], phi[:, -1, :, 0]  # (xyz, node): the node's bounds
    area = half_area(box_lo, box_hi)
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
    verts, tris = validated_geometry(vertices, faces)
    corners = verts[tris]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    cent = corners.sum(axis=1, dtype=np.float64) / 3.0
    ref_tri = None
    if params.split_ratio > 0:
        ref_tri, lo, hi = split_references(corners, lo, hi, params.split_ratio, params.split_budget)
        if len(ref_tri) == len(tris):
            ref_tri = None  # nothing split: the same tree as without splitting
        else:
            split = np.bincount(ref_tri, minlength=len(tris)) > 1
            cent = np.where(split[ref_tri, None], 0.5 * (lo.astype(np.float64) + hi), cent[ref_tri])
    m = len(lo)
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
    if ref_tri is not None:
        order = ref_tri[order]
    return frozen_bvh(nodes, order.astype(np.int32), params)


def frozen_bvh(nodes: np.ndarray, order: np.ndarray, params: BvhParams) -> Bvh:
    """A Bvh whose arrays are read-only: cached trees are shared between callers."""
    nodes.flags.writeable = False
    order.flags.writeable = False
    return Bvh(nodes=nodes, triangle_order=order, params=params)
