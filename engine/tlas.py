"""Dynamic AABB trees: over instances (``tlas_nodes``), which instances a ray can reach, without a loop over
all; over portal quads and aberration boxes (``space_nodes``, :mod:`engine.packing_space`), which of them a ray
or a point can meet; and, in world space, the same for the camera's walk (:mod:`engine.space_index`).

The kernels used to test every instance's world bounds for every search; a
ray taking several events (aberration faces, portals) searched the meshes
several times, each a loop over the whole instance table. This tree replaces
the loop (``nearest_mesh`` in ``backends/shared/instances.h``).

Layout: :data:`engine.layout.TLAS_NODE_DTYPE` (the 32-byte BVH node), root at
row 0. A leaf (``count == 1``) holds one instance row (``first``); an interior
node (``count == 0``) has children ``first`` and ``first + 1``. Leaves hold a
single instance so that each instance row has exactly one leaf, which an
incremental update can find without a search.

It is a *dynamic AABB tree* (as in Box2D): a leaf's bounds start as the
instance's exact world bounds; an instance that moves out of them gets a fat
box, its bounds grown by a margin (:data:`FAT_MARGIN` of its extent on every
side, see :func:`fatten`), and its path to the root is refitted (a few rows).
A moving instance whose exact bounds stay inside its fat box changes nothing
here (its exact bounds are on its instance row, which the kernel tests after
the leaf); when many leave at once, or the instance set changes, the tree is
rebuilt. Static instances keep tight leaves, so a ray walks no more of the
tree than their boxes need. Built with a full-sweep SAH over the leaves'
boxes, so a floor that spans the scene ends up alone near the root.
Node bounds are float32 rounded outward (and a parent's are the union of its
children's stored bounds), so every precision may traverse them.

A space tree's leaves stand for quads and boxes that the kernels test in their own
local frames, with rounding of their own: its fat boxes are grown further by
``slack`` times the size of their coordinates (:data:`SPACE_SLACK`), so a ray or a
point that such a test accepts is always inside the leaf's box.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from engine.layout import TLAS_NODE_DTYPE

#: A leaf's fat box: the exact bounds grown by this fraction of their largest extent on every side.
FAT_MARGIN = 0.1
#: Rebuild instead of refitting when more than this fraction of the instances left their fat boxes at once.
REBUILD_FRACTION = 0.125
#: A space tree's fat boxes also grow by this fraction of (1 + their largest coordinate): far above the float32
#: rounding of a portal's or a box's local coordinates (a few 1e-7 of their size), which the kernel's own
#: per-ray padding (SPACE_PAD in backends/shared/core.h) complements for the ray's origin.
SPACE_SLACK = 1e-5


def _round_out(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    lo32 = np.where(lo32.astype(np.float64) > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32.astype(np.float64) < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    return lo32, hi32


def fatten(
    lo: np.ndarray, hi: np.ndarray, margin: float = FAT_MARGIN, slack: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Fat boxes (float64) of exact bounds ``lo``/``hi`` (n, 3): each axis grown by ``margin`` times its
    extent, or a tenth of the largest extent where the axis is thinner (a floor plane gets a thin fat box,
    not one as tall as it is wide: a tall one would be entered by most rays); and by ``slack`` times
    (1 + the largest coordinate)."""
    extent = hi - lo
    grow = margin * np.maximum(extent, 0.1 * np.max(extent, axis=-1, keepdims=True))
    if slack:
        size = 1.0 + np.maximum(np.abs(lo), np.abs(hi)).max(axis=-1, keepdims=True)
        grow = grow + slack * size
    return lo - grow, hi + grow


def _half_area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    d = np.maximum(hi - lo, 0.0)
    return d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0]


def _sah_split(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, int]:
    """An order of boxes ``lo``/``hi`` (n >= 2) and k: the split into [:k], [k:] of least surface-area cost.

    The three axes' sweeps run as one array operation (a node's cost is then a few NumPy calls, whatever its
    size), so every node gets the SAH split: a median split of small nodes made the walk 3-15 % slower."""
    n = len(lo)
    orders = np.argsort(lo + hi, axis=0, kind="stable").T  # (3, n): the boxes by centre along each axis
    slo, shi = lo[orders], hi[orders]
    left = _half_area(np.minimum.accumulate(slo, axis=1), np.maximum.accumulate(shi, axis=1))[:, :-1]
    right = _half_area(
        np.minimum.accumulate(slo[:, ::-1], axis=1)[:, ::-1], np.maximum.accumulate(shi[:, ::-1], axis=1)[:, ::-1]
    )[:, 1:]
    k = np.arange(1, n)
    cost = left * k + right * (n - k)
    axis, i = divmod(int(np.argmin(cost)), n - 1)  # the first least cost, axes in order x, y, z
    best_cost, best_order, best_k = float(cost[axis, i]), orders[axis], i + 1
    # One more candidate a centroid sweep cannot make: the largest box alone (a floor whose centre lies
    # among the others' centres on every axis would otherwise stay in a subtree with small boxes).
    big = int(np.argmax(_half_area(lo, hi)))
    rest = np.delete(np.arange(n), big)
    alone = float(_half_area(lo[big], hi[big]) + _half_area(lo[rest].min(axis=0), hi[rest].max(axis=0)) * (n - 1))
    if alone < best_cost:
        best_order, best_k = np.concatenate([[big], rest]), 1
    return best_order, best_k


def _median_split(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, int]:
    """An order of boxes ``lo``/``hi`` (n >= 2) and k = n // 2: halves along the axis their centres spread most
    on. A few NumPy calls a node instead of the SAH's sweeps: for trees that only guide a branch and bound
    (:mod:`engine.clearances`), whose answers do not depend on the tree's shape."""
    centres = lo + hi
    axis = int(np.argmax(centres.max(axis=0) - centres.min(axis=0)))
    return np.argsort(centres[:, axis], kind="stable"), len(lo) // 2


#: How a tree's nodes are split: the surface-area heuristic (trees the rays walk) or at the median.
SPLITS = {"sah": _sah_split, "median": _median_split}


@dataclass
class AabbTree:
    """The packed node table and what an incremental update needs (host only)."""

    nodes: np.ndarray
    #: Fat box of each instance row (float64, camera-relative like the instance table).
    fat_lo: np.ndarray
    fat_hi: np.ndarray
    #: Parent of each node (-1 for the root) and the leaf of each instance row.
    parent: np.ndarray
    leaf: np.ndarray
    margin: float = FAT_MARGIN
    #: Growth of the fat boxes relative to their coordinates' size (space trees: :data:`SPACE_SLACK`).
    slack: float = 0.0
    #: How many rebuilds and refits this tree has had (benchmarks report them).
    rebuilds: int = 0
    refits: int = 0
    depth: int = 0
    #: Depth of each node (root 0).
    level: np.ndarray = field(default_factory=lambda: np.zeros(1, np.int64))
    #: How its nodes are split when it is built or rebuilt (:data:`SPLITS`).
    split: str = "sah"

    @property
    def count(self) -> int:
        """Live node rows (the table keeps one padding row when there are no instances)."""
        return 0 if len(self.leaf) == 0 else 2 * len(self.leaf) - 1

    # --- building ----------------------------------------------------------------------------

    @classmethod
    def build(
        cls, lo: np.ndarray, hi: np.ndarray, margin: float = FAT_MARGIN, slack: float = 0.0, split: str = "sah"
    ) -> AabbTree:
        """A tree over rows with exact world bounds ``lo``/``hi`` (n, 3), n >= 0, its nodes split by ``split``.

        The leaves start tight (grown by ``slack`` only): fat boxes of every instance overlap their neighbours'
        and made the walk over a level of many small instances a quarter slower; an instance gets its fat
        box (``margin``) the first time it moves out of its leaf (:meth:`update`)."""
        lo = np.asarray(lo, np.float64).reshape(-1, 3)
        hi = np.asarray(hi, np.float64).reshape(-1, 3)
        fat_lo, fat_hi = fatten(lo, hi, 0.0, slack)
        empty = np.zeros(0, np.int64)
        tree = cls(np.zeros(1, TLAS_NODE_DTYPE), fat_lo, fat_hi, empty, empty, margin, slack, split=split)
        tree._build()
        return tree

    def _build(self) -> None:
        n = len(self.fat_lo)
        self.leaf = np.zeros(n, np.int64)
        if n == 0:
            self.nodes = np.zeros(1, TLAS_NODE_DTYPE)
            self.parent = np.full(1, -1, np.int64)
            self.level = np.zeros(1, np.int64)
            self.depth = 0
            return
        nodes = np.zeros(2 * n - 1, TLAS_NODE_DTYPE)
        parent = np.full(2 * n - 1, -1, np.int64)
        level = np.zeros(2 * n - 1, np.int64)
        next_free = 1
        stack: list[tuple[int, np.ndarray]] = [(0, np.arange(n))]
        while stack:
            node, rows = stack.pop()
            if len(rows) == 1:
                nodes["first"][node] = rows[0]
                nodes["count"][node] = 1
                self.leaf[rows[0]] = node
                continue
            order, k = SPLITS[self.split](self.fat_lo[rows], self.fat_hi[rows])
            child = next_free
            next_free += 2
            nodes["first"][node] = child
            nodes["count"][node] = 0
            parent[child : child + 2] = node
            level[child : child + 2] = level[node] + 1
            stack.append((child, rows[order[:k]]))
            stack.append((child + 1, rows[order[k:]]))
        self.nodes = nodes
        self.parent = parent
        self.level = level
        self.depth = int(level.max()) + 1
        self._refit_all()
        self.rebuilds += 1

    def _refit_all(self) -> None:
        """Every node's bounds from the fat boxes, deepest level first (one vectorised step per level)."""
        nodes = self.nodes
        leaves = np.flatnonzero(nodes["count"] > 0)
        rows = nodes["first"][leaves]
        nodes["bounds_min"][leaves], nodes["bounds_max"][leaves] = _round_out(self.fat_lo[rows], self.fat_hi[rows])
        inner = nodes["count"] == 0
        level = self.level
        for depth in range(int(level.max()) - 1, -1, -1):
            at = np.flatnonzero(inner & (level == depth))
            kids = nodes["first"][at]
            nodes["bounds_min"][at] = np.minimum(nodes["bounds_min"][kids], nodes["bounds_min"][kids + 1])
            nodes["bounds_max"][at] = np.maximum(nodes["bounds_max"][kids], nodes["bounds_max"][kids + 1])

    # --- incremental updates -------------------------------------------------------------------

    def _outside(self, rows: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Which of ``rows`` no longer fit their fat box with exact bounds ``lo``/``hi`` (grown by the slack)."""
        lo, hi = fatten(lo, hi, 0.0, self.slack) if self.slack else (lo, hi)
        return np.any(lo < self.fat_lo[rows], axis=1) | np.any(hi > self.fat_hi[rows], axis=1)

    def update(self, rows: np.ndarray | list[int], lo: np.ndarray, hi: np.ndarray) -> list[int] | None:
        """Instance ``rows`` now have exact bounds ``lo``/``hi`` (len(rows), 3).

        Returns the node rows that changed (empty when every instance stayed in
        its fat box), or ``None`` when the whole tree was rebuilt.
        """
        rows = np.asarray(rows, np.int64).reshape(-1)
        lo = np.asarray(lo, np.float64).reshape(-1, 3)
        hi = np.asarray(hi, np.float64).reshape(-1, 3)
        out = self._outside(rows, lo, hi)
        if not np.any(out):
            return []
        escaped, lo, hi = rows[out], lo[out], hi[out]
        self.fat_lo[escaped], self.fat_hi[escaped] = fatten(lo, hi, self.margin, self.slack)
        if len(escaped) > max(1, int(REBUILD_FRACTION * len(self.leaf))):
            self._build()
            return None
        self.refits += 1
        nodes = self.nodes
        changed: set[int] = set()
        for row in escaped:
            node = int(self.leaf[row])
            nodes["bounds_min"][node], nodes["bounds_max"][node] = _round_out(self.fat_lo[row], self.fat_hi[row])
            changed.add(node)
            node = int(self.parent[node])
            while node >= 0:
                kid = int(nodes["first"][node])
                new_lo = np.minimum(nodes["bounds_min"][kid], nodes["bounds_min"][kid + 1])
                new_hi = np.maximum(nodes["bounds_max"][kid], nodes["bounds_max"][kid + 1])
                if np.array_equal(new_lo, nodes["bounds_min"][node]) and np.array_equal(
                    new_hi, nodes["bounds_max"][node]
                ):
                    break  # the ancestors' unions are unchanged too
                nodes["bounds_min"][node], nodes["bounds_max"][node] = new_lo, new_hi
                changed.add(node)
                node = int(self.parent[node])
        return sorted(changed)

    def translate(self, delta: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        """The packed origin moved by ``delta`` (every coordinate minus ``delta``); ``lo``/``hi`` are the new
        exact bounds of every row. Keeps the tree's shape; boxes that no longer hold their instance (rounding)
        grow just enough to hold it again, so tight leaves stay tight."""
        self.fat_lo = self.fat_lo - delta
        self.fat_hi = self.fat_hi - delta
        out = self._outside(np.arange(len(self.fat_lo)), lo, hi)
        need_lo, need_hi = fatten(lo[out], hi[out], 0.0, self.slack)
        self.fat_lo[out] = np.minimum(self.fat_lo[out], need_lo)
        self.fat_hi[out] = np.maximum(self.fat_hi[out], need_hi)
        if len(self.leaf):
            self._refit_all()

    # --- queries (host side) ---------------------------------------------------------------------

    def rows_on_segment(self, start: np.ndarray, end: np.ndarray, pad: float = 0.0) -> list[int]:
        """Rows whose fat box, grown by ``pad``, the segment from ``start`` to ``end`` meets (sorted)."""
        a = np.asarray(start, np.float64)
        return self.rows_on_ray(a, np.asarray(end, np.float64) - a, 1.0, pad)

    def rows_on_ray(
        self, origin: np.ndarray, direction: np.ndarray, t_max: float = np.inf, pad: float = 0.0
    ) -> list[int]:
        """Rows whose fat box, grown by ``pad``, the ray ``origin + t * direction`` meets for some ``t`` in
        ``[0, t_max]`` (sorted); ``t_max`` may be infinite (an editor's pick ray)."""
        if not len(self.leaf):
            return []
        a = np.asarray(origin, np.float64)
        d = np.asarray(direction, np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):  # an infinite ray: inf * 0 where it does not move
            end = np.where(d == 0.0, a, a + t_max * d)
            inv = 1.0 / d
        seg_lo, seg_hi = np.minimum(a, end) - pad, np.maximum(a, end) + pad

        def meets(lo: np.ndarray, hi: np.ndarray) -> bool:
            if np.any(hi < seg_lo) or np.any(lo > seg_hi):
                return False
            lo, hi = lo - pad, hi + pad
            t_in, t_out = 0.0, t_max
            for k in range(3):
                if d[k] == 0.0:
                    if a[k] < lo[k] or a[k] > hi[k]:
                        return False
                    continue
                t0, t1 = (lo[k] - a[k]) * inv[k], (hi[k] - a[k]) * inv[k]
                t_in, t_out = max(t_in, min(t0, t1)), min(t_out, max(t0, t1))
            return t_in <= t_out * (1.0 + 1e-12) + 1e-12

        return self._collect(meets)

    def rows_at(self, point: np.ndarray, pad: float = 0.0) -> list[int]:
        """Rows whose fat box, grown by ``pad``, holds ``point`` (sorted)."""
        return rows_at(self.nodes, 0, point, pad) if len(self.leaf) else []

    def rows_in_box(self, lo: np.ndarray, hi: np.ndarray) -> list[int]:
        """Rows whose fat box overlaps the closed box ``lo``/``hi`` (sorted)."""
        qlo, qhi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        return self._collect(lambda nlo, nhi: bool(np.all(nlo <= qhi) and np.all(qlo <= nhi)))

    def rows_in_planes(self, planes: np.ndarray) -> list[int]:
        """Rows whose fat box is not wholly on the negative side of any plane ``(a, b, c, d)``: ``a x + b y +
        c z + d >= 0`` inside (a view frustum's six planes, sorted)."""
        planes = np.asarray(planes, np.float64).reshape(-1, 4)
        normals, offsets = planes[:, :3], planes[:, 3]
        positive = normals >= 0.0

        def keep(lo: np.ndarray, hi: np.ndarray) -> bool:
            corner = np.where(positive, hi, lo)  # per plane, the box's corner furthest along its normal
            return bool(np.all(np.einsum("ij,ij->i", normals, corner) + offsets >= 0.0))

        return self._collect(keep)

    def _collect(self, keep: Callable[[np.ndarray, np.ndarray], bool]) -> list[int]:
        return collect(self.nodes, 0, keep) if len(self.leaf) else []


def collect(nodes: np.ndarray, root: int, keep: Callable[[np.ndarray, np.ndarray], bool]) -> list[int]:
    """The rows of every leaf of the tree in ``nodes`` from ``root`` reached through nodes whose (float64)
    bounds ``keep`` accepts, sorted."""
    found: list[int] = []
    stack = [root]
    while stack:
        node = stack.pop()
        if not keep(nodes["bounds_min"][node].astype(np.float64), nodes["bounds_max"][node].astype(np.float64)):
            continue
        first = int(nodes["first"][node])
        if nodes["count"][node] > 0:
            found.append(first)
        else:
            stack += [first, first + 1]
    return sorted(found)


def rows_at(nodes: np.ndarray, root: int, point: np.ndarray, pad: float = 0.0) -> list[int]:
    """Rows whose leaf in the tree of ``nodes`` from ``root``, grown by ``pad``, holds ``point`` (sorted)."""
    p = np.asarray(point, np.float64)
    return collect(nodes, root, lambda lo, hi: bool(np.all(lo - pad <= p) and np.all(p <= hi + pad)))
