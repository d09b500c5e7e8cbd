"""The trees over portals and boxes collapsed into 4-wide nodes, for the kernels' ray walks.

A binary node visit loads and slabs two children; a 4-wide one slabs four at once with 4-vector
operations (backends/shared/space.h, SPACE_WIDE), so a ray crosses about half the levels. The binary
:class:`engine.tlas.AabbTree` stays the tree that is refit and queried on the host; this keeps, per wide node,
which binary nodes fill its slots, so a refit that changed some binary nodes rewrites only the wide nodes
holding them (the path of a moved leaf).

A wide node is stored as four ``space_nodes`` rows (:data:`ROWS`): the children's ``lo.x``, ``lo.y`` |
``lo.z``, ``hi.x`` | ``hi.y``, ``hi.z`` | ``child`` as int bits, lane i = slot i. ``child`` is the row of an
inner child's wide node (> 0), ``~row`` of a leaf's portal or box row (< 0), or 0 for an empty slot.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from engine import layout

#: Slots of a wide node, and the ``space_nodes`` rows it takes.
WIDTH = 4
ROWS = 4


def reserved_rows(leaves: int) -> int:
    """The rows kept for the wide tree over ``leaves`` rows: one wide node per binary inner node at most (a lone
    leaf gets one), so a rebuild of the same set never moves what comes after it."""
    return ROWS * max(1, leaves - 1) if leaves else 0


class WideTree:
    """The 4-wide shape of a binary space tree: which binary node fills each slot of each wide node."""

    def __init__(self, nodes: np.ndarray, count: int) -> None:
        """Collapse the binary tree ``nodes`` (TLAS layout, ``count`` live rows, root 0): each wide node takes a
        binary node's two children, then opens its largest-area inner child until it has :data:`WIDTH`."""
        first = nodes["first"][:count].astype(np.int64)
        inner = nodes["count"][:count] == 0
        size = nodes["bounds_max"][:count].astype(np.float64) - nodes["bounds_min"][:count].astype(np.float64)
        area = size[:, 0] * size[:, 1] + size[:, 1] * size[:, 2] + size[:, 2] * size[:, 0]
        order: list[int] = [0] if count else []  # binary node of each wide node (the root first)
        rows: list[list[int]] = []
        for node in order:  # grows while it runs: breadth-first
            slots = [int(first[node]), int(first[node]) + 1] if inner[node] else [node]
            while len(slots) < WIDTH:
                opened = [i for i, s in enumerate(slots) if inner[s]]
                if not opened:
                    break
                i = max(opened, key=lambda k: area[slots[k]])
                child = int(first[slots[i]])
                slots[i : i + 1] = [child, child + 1]
            order += [s for s in slots if inner[s]]
            rows.append(slots + [-1] * (WIDTH - len(slots)))
        #: (W, WIDTH) binary node in each slot, -1 empty; the wide node of each inner slot's binary node.
        self.slots = np.array(rows, np.int64).reshape(-1, WIDTH)
        self.wide_of = np.full(count, -1, np.int64)  # the wide node whose slot holds each binary node
        filled = self.slots >= 0
        self.wide_of[self.slots[filled]] = np.nonzero(filled)[0]
        self._child_wide = np.full(count, 0, np.int64)  # the wide node each inner binary node opens
        self._child_wide[np.array(order, np.int64)] = np.arange(len(order))
        self.depth = self._depth()

    def _depth(self) -> int:
        """Levels of wide nodes from the root."""
        depth, frontier = 0, np.zeros(min(1, len(self.slots)), np.int64)
        while frontier.size:
            depth += 1
            slots = self.slots[frontier].ravel()
            slots = slots[slots >= 0]
            frontier = self._child_wide[slots[self._inner(slots)]]
        return depth

    def _inner(self, binary: np.ndarray) -> np.ndarray:
        return self._child_wide[binary] > 0

    def rows(self, nodes: np.ndarray, base: int, wide: Sequence[int] | np.ndarray | None = None) -> np.ndarray:
        """The ``space_nodes`` rows of wide nodes ``wide`` (all by default), the tree stored from row ``base``."""
        wide = np.arange(len(self.slots)) if wide is None else np.asarray(wide, np.int64)
        slots = self.slots[wide]
        empty = slots < 0
        safe = np.maximum(slots, 0)
        lo = np.where(empty[..., None], 0.0, nodes["bounds_min"][safe]).astype(np.float32)
        hi = np.where(empty[..., None], 0.0, nodes["bounds_max"][safe]).astype(np.float32)
        leaf_row = nodes["first"][safe].astype(np.int64)
        child = np.where(self._inner(safe), base + ROWS * self._child_wide[safe], ~leaf_row)
        child = np.where(empty, 0, child).astype(np.int32)
        out = np.zeros((len(wide), ROWS * 8), np.float32)
        for k in range(3):
            out[:, 4 * k : 4 * k + 4] = lo[:, :, k]
            out[:, 12 + 4 * k : 16 + 4 * k] = hi[:, :, k]
        out[:, 24:28] = child.view(np.float32)
        return out.reshape(-1, 8).view(layout.SPACE_NODE_DTYPE).reshape(-1)

    def changed(self, binary: list[int]) -> list[int]:
        """The wide nodes whose slots hold any of the ``binary`` nodes (those a refit changed)."""
        wide = self.wide_of[np.asarray(binary, np.int64)] if binary else np.zeros(0, np.int64)
        return sorted(set(wide[wide >= 0].tolist()))
