"""Wide BVHs: a binary SAH tree collapsed into 4- or 8-wide nodes, leaves cut into blocks of 4 triangles.

A CPU tracer tests a wide node's children at once with 4- or 8-vector operations
(OpenCL: float4 / float8), the way Embree does, and a leaf's triangles four at a
time. Collapsing keeps the binary tree's leaves and triangle order, so a wide tree
finds exactly the hits the binary one does.
"""

from __future__ import annotations

import numpy as np

from engine.bvh import Bvh, frozen_bvh, half_area
from engine.layout import BVH_WIDTHS

__all__ = ["collapse", "collapse_slots", "leaf_blocks", "wide_nodes"]


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
    slots = collapse_slots(first, count, b["bounds_min"], b["bounds_max"], width)
    nodes = wide_nodes(slots, first, count, b["bounds_min"], b["bounds_max"], width)
    return frozen_bvh(nodes, bvh.triangle_order.copy(), bvh.params)


def collapse_slots(
    first: np.ndarray, count: np.ndarray, bounds_min: np.ndarray, bounds_max: np.ndarray, width: int
) -> np.ndarray:
    """The wide nodes of a binary tree (``first``/``count`` as :data:`engine.layout.BVH_NODE_DTYPE`: ``count
    == 0`` interior with children ``first`` and ``first + 1``; bounds (N, 3)) as (F, ``width``) binary node
    ids, -1 for an empty slot, in level order (row 0 the root's; see :func:`collapse`)."""
    inner = count == 0
    area = half_area(np.asarray(bounds_min).T, np.asarray(bounds_max).T)
    # A subtree of at most `width` leaves is opened whole (its inner nodes are pulled before any other),
    # so its leaves share one wide node: filling by area alone left most 8-wide nodes of the tori holding
    # 2 leaves (15408 of 25445 nodes at 200k triangles, now 4040 of 14509; SAH 24.1 -> 23.6; 0.5-1.5 %
    # less CPU per frame on the tori, PoCL 3.1, 800x800).
    leaves = _leaf_counts(first, inner)
    opened = np.zeros(len(first), bool)
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
    return np.concatenate(rows)


def wide_nodes(
    slots: np.ndarray,
    first: np.ndarray,
    count: np.ndarray,
    bounds_min: np.ndarray,
    bounds_max: np.ndarray,
    width: int,
) -> np.ndarray:
    """The ``width``-wide node table of :func:`collapse_slots`' ``slots``: each slot's box, its wide child
    (interior) or ``first`` (a leaf) and ``count`` (-1 for an empty slot)."""
    inner = count == 0
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
        put(f"lo_{axis}", np.where(empty, 0.0, bounds_min[safe, k]))
        put(f"hi_{axis}", np.where(empty, 0.0, bounds_max[safe, k]))
    put("child", np.where(empty, 0, np.where(wide_inner, wide_id, first[safe])))
    put("count", np.where(empty, -1, count[safe]))
    return nodes


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
