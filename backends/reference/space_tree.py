"""Which portal quads and boxes each ray or point can meet, without testing every one against every ray.

A median-split tree over their world bounds (:func:`backends.reference.tlas.build_instance_tree`) gives,
breadth-first over (ray, node) pairs, the rows each ray's line can cross; the portal and box rules then
run row by row in ascending order, each over the rays that can meet that row, exactly as the loop over
every row runs them over every ray (the same arithmetic on a subset of the same rows): rays a row cannot
meet would have failed its test anyway, so the results are the loop's to the bit. The bounds are padded
far beyond the float64 rounding of the local-frame tests (:data:`PAD`).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from backends.reference.intersect import safe_inverse
from backends.reference.tlas import InstanceTree, build_instance_tree, instance_pairs

#: With more rows than this, rules run through the tree; fewer are looped over with every ray.
TREE_MIN = 8
#: Bounds grow by this fraction of (1 + their coordinates' size), and of (1 + the rays' origins' size).
PAD = 1e-7


@dataclass(frozen=True)
class SpaceTree:
    """Padded world bounds of every row and the tree over them."""

    lo: np.ndarray  # (K, 3)
    hi: np.ndarray
    tree: InstanceTree

    @staticmethod
    def over(world_to_local: np.ndarray, corners: np.ndarray) -> SpaceTree | None:
        """The tree over the solids with local ``corners`` (k, 3) of the maps ``world_to_local`` (K, 3, 4), or
        ``None`` for too few rows (or maps that cannot be inverted)."""
        if len(world_to_local) <= TREE_MIN:
            return None
        with np.errstate(all="ignore"):
            try:
                linear = np.linalg.inv(world_to_local[:, :, :3])
            except np.linalg.LinAlgError:
                return None
            centre = -np.einsum("nij,nj->ni", linear, world_to_local[:, :, 3])
            world = np.einsum("nij,kj->nki", linear, corners) + centre[:, None, :]
        lo, hi = world.min(axis=1), world.max(axis=1)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return None
        pad = PAD * (1.0 + np.maximum(np.abs(lo), np.abs(hi)).max(axis=1, keepdims=True))
        lo, hi = lo - pad, hi + pad
        return SpaceTree(lo, hi, build_instance_tree(lo, hi))

    def ray_rows(self, o: np.ndarray, r: np.ndarray, t_min: np.ndarray) -> Iterator[tuple[int, np.ndarray]]:
        """``(row, rays)`` in ascending row order: the rays whose line beyond ``t_min`` can cross the row."""
        pad = PAD * (1.0 + float(np.abs(o).max(initial=0.0)))
        ray, row, _ = instance_pairs(
            self.tree, self.lo - pad, self.hi + pad, o, safe_inverse(r), t_min, np.full(len(o), np.inf), pad
        )
        return _by_row(ray, row)

    def point_rows(self, points: np.ndarray) -> Iterator[tuple[int, np.ndarray]]:
        """``(row, points)`` in ascending row order: the points inside the row's padded bounds."""
        pad = PAD * (1.0 + float(np.abs(points).max(initial=0.0)))
        tree, lo, hi = self.tree, self.lo - pad, self.hi + pad
        f_point = np.arange(len(points))
        f_node = np.zeros(len(points), np.int64)
        found_point, found_row = [], []
        while f_point.size:
            inside = np.all((tree.lo[f_node] - pad <= points[f_point]) & (points[f_point] <= tree.hi[f_node] + pad), 1)
            f_point, f_node = f_point[inside], f_node[inside]
            leaf = tree.count[f_node] > 0
            for slot in range(int(tree.count[f_node[leaf]].max(initial=0))):
                has = tree.count[f_node[leaf]] > slot
                rows = tree.order[tree.first[f_node[leaf]][has] + slot]
                p = f_point[leaf][has]
                keep = np.all((lo[rows] <= points[p]) & (points[p] <= hi[rows]), axis=1)
                found_point.append(p[keep])
                found_row.append(rows[keep])
            kids = tree.first[f_node[~leaf]]
            f_point = np.repeat(f_point[~leaf], 2)
            f_node = np.stack([kids, kids + 1], axis=1).reshape(-1)
        if not found_point:
            return iter(())
        return _by_row(np.concatenate(found_point), np.concatenate(found_row))


def _by_row(items: np.ndarray, rows: np.ndarray) -> Iterator[tuple[int, np.ndarray]]:
    if not len(rows):
        return
    order = np.lexsort((items, rows))
    items, rows = items[order], rows[order]
    starts = np.flatnonzero(np.concatenate([[True], rows[1:] != rows[:-1]]))
    ends = np.concatenate([starts[1:], [len(rows)]])
    for start, end in zip(starts.tolist(), ends.tolist(), strict=True):
        yield int(rows[start]), items[start:end]
