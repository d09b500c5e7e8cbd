"""A small top-level tree over instance world bounds, so many instances are not tested per ray.

Built on the host whenever the instance table changes (median split along
the widest centroid axis, a Python loop over nodes: instances number in the
thousands at most). Its layout mirrors the BVH table: ``count > 0`` is a leaf
over ``order[first : first + count]``, ``count == 0`` an interior node whose
children are ``first`` and ``first + 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from backends.reference.intersect import slab

#: Instances per leaf.
LEAF_SIZE = 2


@dataclass(frozen=True)
class InstanceTree:
    """Nodes (root at 0) over instance rows reordered by ``order``."""

    lo: np.ndarray  # (K, 3)
    hi: np.ndarray
    first: np.ndarray  # (K,) int64
    count: np.ndarray
    order: np.ndarray  # (I,) int64


def build_instance_tree(lo: np.ndarray, hi: np.ndarray) -> InstanceTree:
    """Median-split tree over boxes ``lo``/``hi`` (I, 3); I may be 0 (then one empty leaf)."""
    n = len(lo)
    order = np.arange(n, dtype=np.int64)
    centre = (lo + hi) * 0.5
    node_lo, node_hi = [np.zeros(3)], [np.zeros(3)]
    first, count = [0], [0]
    stack = [(0, 0, n)]
    while stack:
        node, start, end = stack.pop()
        rows = order[start:end]
        if rows.size:
            node_lo[node], node_hi[node] = lo[rows].min(axis=0), hi[rows].max(axis=0)
        else:
            node_lo[node], node_hi[node] = np.full(3, np.inf), np.full(3, -np.inf)
        if end - start <= LEAF_SIZE:
            first[node], count[node] = start, end - start
            continue
        c = centre[rows]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order[start:end] = rows[np.argsort(c[:, axis], kind="stable")]
        mid = (start + end) // 2
        child = len(first)
        node_lo += [np.zeros(3), np.zeros(3)]
        node_hi += [np.zeros(3), np.zeros(3)]
        first += [0, 0]
        count += [0, 0]
        first[node], count[node] = child, 0
        stack += [(child, start, mid), (child + 1, mid, end)]
    return InstanceTree(
        np.array(node_lo), np.array(node_hi), np.array(first, np.int64), np.array(count, np.int64), order
    )


def instance_pairs(
    tree: InstanceTree,
    inst_lo: np.ndarray,
    inst_hi: np.ndarray,
    origin: np.ndarray,
    inverse: np.ndarray,
    t_min: np.ndarray,
    t_max: np.ndarray,
    pad: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ray, instance, entry t) for every instance box each ray crosses within (t_min, t_max); the tree's
    nodes grown by ``pad`` (the instance boxes given are tested as they are)."""
    f_ray = np.arange(len(origin))
    f_node = np.zeros(len(origin), np.int64)
    rays, insts = [], []
    while f_ray.size:
        near, far = slab(origin[f_ray], inverse[f_ray], tree.lo[f_node] - pad, tree.hi[f_node] + pad)
        keep = (far >= np.maximum(near, t_min[f_ray])) & (near <= t_max[f_ray])
        f_ray, f_node = f_ray[keep], f_node[keep]
        leaf = tree.count[f_node] > 0
        if np.any(leaf):
            l_count = tree.count[f_node[leaf]]
            p_ray = np.repeat(f_ray[leaf], l_count)
            starts = np.cumsum(l_count) - l_count
            slot = np.repeat(tree.first[f_node[leaf]] - starts, l_count) + np.arange(len(p_ray))
            rays.append(p_ray)
            insts.append(tree.order[slot])
        inner = ~leaf
        children = tree.first[f_node[inner]]
        f_ray = np.repeat(f_ray[inner], 2)
        f_node = np.stack([children, children + 1], axis=1).reshape(-1)
    if not rays:
        empty = np.zeros(0, np.int64)
        return empty, empty, np.zeros(0)
    ray, inst = np.concatenate(rays), np.concatenate(insts)
    near, far = slab(origin[ray], inverse[ray], inst_lo[inst], inst_hi[inst])
    keep = (far >= np.maximum(near, t_min[ray])) & (near <= t_max[ray])
    return ray[keep], inst[keep], np.maximum(near[keep], t_min[ray[keep]])
