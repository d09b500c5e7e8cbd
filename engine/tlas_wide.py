"""The top-level tree as the kernels walk it (``tlas_nodes``): the binary instance tree
(:class:`engine.tlas.AabbTree`) collapsed into 4- or 8-wide nodes, as the asset trees are
(:func:`engine.bvh_wide.collapse_slots`), so that a visit tests up to 4 or 8 children's boxes at once.

Layout: :data:`engine.layout.BVH_WIDTHS` of the width, root at row 0. A lane with ``count == 1`` is a leaf
over instance row ``child``, ``count == 0`` an interior child (wide row ``child``), ``count == -1`` empty.
Every binary node but the root and those the collapse pulled up has one lane, so a refit of the binary
tree (an instance's path) rewrites the lanes of its changed nodes: a few wide rows, about a half or a
third of the binary path.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.bvh_wide import collapse_slots, wide_nodes
from engine.layout import BVH_WIDTHS, bvh_width
from engine.tlas import AabbTree

#: The top-level tree's widths: binary (the :class:`engine.tlas.AabbTree`'s own table), 4- or 8-wide.
TLAS_WIDTHS = (2, 4, 8)


@dataclass
class WideTlas:
    """An :class:`engine.tlas.AabbTree` packed at ``width``, and where each binary node's box lies in it."""

    width: int
    nodes: np.ndarray
    #: Per binary node: its lane as ``row * width + lane`` in :attr:`nodes`, -1 where it has none.
    lane: np.ndarray

    @classmethod
    def of(cls, tree: AabbTree, width: int) -> WideTlas:
        """The ``width``-wide table of ``tree`` (width 2: the tree's own nodes)."""
        if width not in TLAS_WIDTHS:
            raise ValueError(f"tlas_width must be one of {list(TLAS_WIDTHS)}, got {width!r}")
        b = tree.nodes
        if width == 2:
            return cls(2, b, np.arange(len(b)), tree.count)
        if not len(tree.leaf):  # no instances: one row of empty lanes
            nodes = np.zeros(1, BVH_WIDTHS[width])
            nodes["count"] = -1
            return cls(width, nodes, np.full(len(b), -1, np.int64), 0)
        first, count = b["first"].astype(np.int64), b["count"].astype(np.int64)
        lo, hi = b["bounds_min"][:, :3], b["bounds_max"][:, :3]
        slots = collapse_slots(first, count, lo, hi, width)
        lane = np.full(len(b), -1, np.int64)
        used = np.flatnonzero(slots.ravel() >= 0)
        lane[slots.ravel()[used]] = used
        return cls(width, wide_nodes(slots, first, count, lo, hi, width), lane, len(slots))

    #: Live rows: the binary tree's count at width 2, else every row; none without instances (the table then
    #: keeps one padding row of empty lanes, as the binary one its padding row).
    count: int

    def refit(self, tree: AabbTree, changed: list[int]) -> list[int]:
        """The rows whose lanes hold binary nodes ``changed`` (refitted in ``tree``), rewritten (sorted)."""
        if self.width == 2:
            return changed
        rows: set[int] = set()
        for node in changed:
            slot = int(self.lane[node])
            if slot < 0:
                continue  # the root, or a node the collapse pulled up: no box of its own here
            row, k = divmod(slot, self.width)
            for axis, name in enumerate("xyz"):
                self.nodes[f"lo_{name}"][row].reshape(-1)[k] = tree.nodes["bounds_min"][node, axis]
                self.nodes[f"hi_{name}"][row].reshape(-1)[k] = tree.nodes["bounds_max"][node, axis]
            rows.add(row)
        return sorted(rows)


@dataclass(frozen=True)
class TlasLanes:
    """A ``tlas_nodes`` table (binary or wide) as rows of ``width`` lanes, each a child's box, for walks on
    the host (:func:`engine.camera_view.seen_instances`): lane ``row * width + k`` of ``lo``/``hi`` (float64),
    ``kind`` 1 a leaf over instance row ``child``, 0 an interior child (row ``child``), -1 none. Row 0 is the
    root's."""

    width: int
    lo: np.ndarray
    hi: np.ndarray
    child: np.ndarray
    kind: np.ndarray

    @classmethod
    def of(cls, nodes: np.ndarray) -> TlasLanes:
        """The lanes of a ``tlas_nodes`` table. A binary node's lanes are its grandchildren's boxes (a leaf child's
        own): a walk takes two levels a step, as a 4-wide tree's."""
        width = bvh_width(nodes)
        if width == 2:
            n = len(nodes)
            first, count = nodes["first"].astype(np.int64), nodes["count"].astype(np.int64)
            interior = (count == 0) & (first + 1 < n)
            kids = np.where(interior, first, 0)[:, None] + np.arange(2)  # (n, 2)
            kids = np.minimum(kids, n - 1)
            kid_leaf = (count[kids] > 0) | ~interior[kids]
            grand = np.where(
                kid_leaf[..., None],
                np.stack([kids, np.full_like(kids, -1)], axis=-1),
                np.stack([first[kids], first[kids] + 1], axis=-1),
            ).reshape(n, 4)
            valid = interior[:, None] & (grand >= 0) & (grand < n)
            if count[0] > 0:  # a root leaf: its own lane
                valid[0], grand[0] = (True, False, False, False), 0
            lane = np.where(valid, grand, 0)
            kind = np.where(valid, np.where(count[lane] > 0, 1, 0), -1)
            child = np.where(kind == 1, first[lane], lane)
            lo = nodes["bounds_min"][lane.ravel(), :3].astype(np.float64)
            hi = nodes["bounds_max"][lane.ravel(), :3].astype(np.float64)
            return cls(4, lo, hi, child.ravel(), kind.ravel())
        lo = np.stack([nodes[f"lo_{a}"].reshape(-1) for a in "xyz"], axis=1).astype(np.float64)
        hi = np.stack([nodes[f"hi_{a}"].reshape(-1) for a in "xyz"], axis=1).astype(np.float64)
        return cls(
            width, lo, hi, nodes["child"].reshape(-1).astype(np.int64), nodes["count"].reshape(-1).astype(np.int64)
        )
