"""Every aberration box's clearance to the instances and gap to the other boxes (:mod:`engine.box_clearance`
defines them), found through trees and kept when boxes or instances move.

Each value is a minimum over pairs, so it is found by branch and bound over a tree of the partners, and
stays valid while neither the box nor its nearest partner moves: a tick that moves a few boxes or
instances searches again only the boxes whose partner moved, and compares the others with the movers
near them. The pairs are computed as the brute force computes them: the values are the same to the bit.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from engine.box_clearance import CLEARANCE_SLACK, box_solids, separation, solid_slack
from engine.tlas import FAT_MARGIN, AabbTree


def box_clearances(
    world_to_local: np.ndarray, bounds_min: np.ndarray, bounds_max: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per box: (world distance to the nearest instance's bounds, to the nearest other box), lower bounds
    less the rounding slack, never negative; +inf-free (a scene without instances or other boxes gets 1e30).

    ``world_to_local`` (n, 3, 4) are the packed rows (camera-relative), ``bounds_*`` (m, 3) the instances'
    world bounds as packed (camera-relative too: distances do not depend on the origin). Near-linear: the
    nearest instance and box of each box come from trees over both (:class:`BoxClearances`).
    """
    clearances = BoxClearances()
    clearances.full(world_to_local, bounds_min, bounds_max)
    return clearances.instance.copy(), clearances.box.copy()


#: A pair function: (query rows, partner rows) -> each pair's gap less the partner's slack.
Pairs = Callable[[np.ndarray, np.ndarray], np.ndarray]
#: The value of a box with no partner (no instances, no other box).
_FAR = 1e30
#: Up to this many box pairs a search among the boxes evaluates every pair at once, not the tree's branch and
#: bound: one vector pass costs less than the tree's Python steps (a sync after one portal or box of 1,024
#: moved: 0.74x and 0.79x the time).
BRUTE_PAIRS = 1 << 14
#: Coordinates beyond this (or not finite) make every clearance they touch 0, as an overflowing pair would.
_HUGE = 1e100


def _usable(*arrays: np.ndarray) -> np.ndarray:
    """Rows (of the first axis) whose values are all finite and below :data:`_HUGE`."""
    ok = np.ones(len(arrays[0]), bool)
    for a in arrays:
        flat = a.reshape(len(a), -1) if len(a) else np.zeros((0, 1))
        with np.errstate(invalid="ignore"):
            ok &= np.all(np.isfinite(flat) & (np.abs(flat) < _HUGE), axis=1)
    return ok


class BoxClearances:
    """Each box's clearance to the instances (``instance``) and gap to the other boxes (``box``), as
    :func:`box_clearances` defines them, kept in step when boxes or instances move: only the boxes whose
    nearest partner moved are searched again, and only those near a moved one compare against it.

    Each value is a minimum over pairs of a separating-axis gap less the partner's slack, so it is found
    by branch and bound over a tree of the partners (:class:`engine.tlas.AabbTree`): a node is skipped
    when a lower bound of every gap in it (the query box's projection on its own face normals against the
    node's box, and for instances the world axes too) exceeds the best so far. The pairs it does evaluate
    are computed as the brute force computes them, so the values are the same to the bit.
    """

    def __init__(self) -> None:
        self.instance = np.zeros(0)
        self.box = np.zeros(0)
        self._raw_instance = np.zeros(0)
        self._raw_box = np.zeros(0)
        self._partner_instance = np.zeros(0, np.int64)
        self._partner_box = np.zeros(0, np.int64)
        self._boxes: AabbTree | None = None
        self._instances: AabbTree | None = None
        self._order_of = -1
        self._order = (np.zeros(0, np.int64), np.zeros(0, np.int64))

    # --- whole sets -----------------------------------------------------------------------------

    def full(self, world_to_local: np.ndarray, bounds_min: np.ndarray, bounds_max: np.ndarray) -> list[int]:
        """Every box's values from scratch; returns every row."""
        self._set_solids(world_to_local, bounds_min, bounds_max)
        n = len(self._centre)
        # The trees only guide the branch and bound: split at the median, a tenth of the SAH's build time.
        self._boxes = AabbTree.build(*self._box_bounds(np.arange(n)), margin=FAT_MARGIN, split="median")
        self._order_of = -1
        self._instances = AabbTree.build(self._lo, self._hi, margin=FAT_MARGIN, split="median")
        self._raw_instance = np.full(n, _FAR)
        self._raw_box = np.full(n, _FAR)
        self._partner_instance = np.full(n, -1, np.int64)
        self._partner_box = np.full(n, -1, np.int64)
        rows = np.arange(n)
        self._search_instances(rows)
        self._search_boxes(rows)
        self._finish(rows)
        return list(range(n))

    def moved(
        self,
        world_to_local: np.ndarray,
        bounds_min: np.ndarray,
        bounds_max: np.ndarray,
        boxes: list[int],
        instances: list[int],
    ) -> list[int]:
        """The values after box rows ``boxes`` and instance rows ``instances`` moved (same row sets as
        before; ``world_to_local`` and ``bounds_*`` are the new tables). Returns the rows that were
        recomputed (a superset of those that changed)."""
        if self._boxes is None or len(world_to_local) != len(self._centre) or len(bounds_min) != len(self._lo):
            return self.full(world_to_local, bounds_min, bounds_max)
        moved_boxes = np.asarray(sorted(boxes), np.int64)
        moved_instances = np.asarray(sorted(instances), np.int64)
        self._update_solids(world_to_local, bounds_min, bounds_max, moved_boxes, moved_instances)
        if not (self._good_boxes.all() and self._good_instances.all()):
            return self.full(world_to_local, bounds_min, bounds_max)
        touched: set[int] = set(moved_boxes.tolist())
        if moved_boxes.size:
            assert self._boxes is not None
            if self._boxes.update(moved_boxes, *self._box_bounds(moved_boxes)) is None:
                pass  # rebuilt: the same rows, a new shape
            again = np.flatnonzero(np.isin(self._partner_box, moved_boxes))
            fresh = np.union1d(moved_boxes, again)
            self._raw_box[fresh] = _FAR
            self._partner_box[fresh] = -1
            self._search_boxes(fresh)
            others = self._near_moved_boxes(moved_boxes, exclude=fresh)
            touched.update(again.tolist())
            touched.update(others)
        if moved_instances.size:
            assert self._instances is not None
            self._instances.update(moved_instances, self._lo[moved_instances], self._hi[moved_instances])
            again = np.flatnonzero(np.isin(self._partner_instance, moved_instances))
            touched.update(again.tolist())
            touched.update(self._near_moved_instances(moved_instances, exclude=np.union1d(again, moved_boxes)))
        else:
            again = np.zeros(0, np.int64)
        fresh = np.union1d(moved_boxes, again)
        self._raw_instance[fresh] = _FAR
        self._partner_instance[fresh] = -1
        self._search_instances(fresh)
        rows = np.asarray(sorted(touched), np.int64)
        self._finish(rows)
        return rows.tolist()

    # --- the solids --------------------------------------------------------------------------------

    def _set_solids(self, world_to_local: np.ndarray, bounds_min: np.ndarray, bounds_max: np.ndarray) -> None:
        m = np.asarray(world_to_local, dtype=np.float64).reshape(-1, 3, 4)
        with np.errstate(all="ignore"):
            if len(m):
                self._centre, self._half, self._normals = box_solids(m)
            else:
                self._centre, self._half, self._normals = np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3, 3))
            self._slack = solid_slack(self._centre, self._half)
            lo = np.asarray(bounds_min, dtype=np.float64).reshape(-1, 3)
            hi = np.asarray(bounds_max, dtype=np.float64).reshape(-1, 3)
            self._lo, self._hi = lo, hi
            self._c2 = 0.5 * (lo + hi)
            self._h2 = np.einsum("mj,jk->mjk", 0.5 * (hi - lo), np.eye(3))
            self._slack_i = CLEARANCE_SLACK * (np.linalg.norm(self._c2, axis=1) + np.linalg.norm(hi - lo, axis=1))
        self._good_boxes = _usable(self._centre, self._half, self._normals, self._slack)
        self._good_instances = _usable(self._c2, self._h2, self._slack_i)
        self._max_slack_i = float(self._slack_i.max()) if len(self._slack_i) and self._good_instances.all() else 0.0
        self._max_slack = float(self._slack.max()) if len(self._slack) and self._good_boxes.all() else 0.0

    def _update_solids(
        self, world_to_local: np.ndarray, lo: np.ndarray, hi: np.ndarray, boxes: np.ndarray, instances: np.ndarray
    ) -> None:
        """The solids of the moved rows only (each row's values do not depend on the others')."""
        with np.errstate(all="ignore"):
            if boxes.size:
                m = np.asarray(world_to_local[boxes], dtype=np.float64).reshape(-1, 3, 4)
                centre, half, normals = box_solids(m)
                self._centre[boxes], self._half[boxes], self._normals[boxes] = centre, half, normals
                self._slack[boxes] = solid_slack(centre, half)
                self._good_boxes[boxes] = _usable(centre, half, normals, self._slack[boxes])
                if self._good_boxes.all():
                    self._max_slack = max(self._max_slack, float(self._slack[boxes].max()))
            if instances.size:
                self._lo, self._hi = self._lo.copy(), self._hi.copy()
                self._lo[instances] = np.asarray(lo, dtype=np.float64)[instances]
                self._hi[instances] = np.asarray(hi, dtype=np.float64)[instances]
                ilo, ihi = self._lo[instances], self._hi[instances]
                self._c2[instances] = 0.5 * (ilo + ihi)
                self._h2[instances] = np.einsum("mj,jk->mjk", 0.5 * (ihi - ilo), np.eye(3))
                c2 = self._c2[instances]
                self._slack_i[instances] = CLEARANCE_SLACK * (
                    np.linalg.norm(c2, axis=1) + np.linalg.norm(ihi - ilo, axis=1)
                )
                self._good_instances[instances] = _usable(c2, self._h2[instances], self._slack_i[instances])
                if self._good_instances.all():
                    self._max_slack_i = max(self._max_slack_i, float(self._slack_i[instances].max()))

    def _box_bounds(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World bounds of box ``rows``: centre plus or minus the sum of the half edges' magnitudes."""
        reach = np.abs(self._half[rows]).sum(axis=1)
        reach = np.where(np.isfinite(reach), reach, 0.0)
        centre = np.where(np.isfinite(self._centre[rows]), self._centre[rows], 0.0)
        return centre - reach, centre + reach

    def _box_pairs(self, b: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Gap of box b to box c less c's slack (0 where not finite), as the brute force computes it."""
        axes = np.concatenate([self._normals[b], self._normals[c]], axis=1)
        with np.errstate(all="ignore"):
            gap = separation(self._centre[b], self._half[b], self._centre[c], self._half[c], axes) - self._slack[c]
        gap = np.where(np.isfinite(gap), gap, 0.0)
        return np.where(b == c, np.inf, gap)

    def _instance_pairs(self, b: np.ndarray, i: np.ndarray) -> np.ndarray:
        """Gap of box b to instance i less i's slack, as the brute force computes it."""
        axes = np.empty((len(b), 6, 3))
        axes[:, :3] = self._normals[b]
        axes[:, 3:] = np.eye(3)
        with np.errstate(all="ignore"):
            return separation(self._centre[b], self._half[b], self._c2[i], self._h2[i], axes) - self._slack_i[i]

    # --- branch and bound --------------------------------------------------------------------------

    def _lower_bound(self, q: np.ndarray, lo: np.ndarray, hi: np.ndarray, world: bool) -> np.ndarray:
        """A lower bound of the gap from box q to anything inside the box lo/hi: along q's face normals,
        and (``world``) the world axes; less a rounding allowance."""
        centre, extent = 0.5 * (lo + hi), 0.5 * (hi - lo)
        normals, cq = self._normals[q], self._centre[q]
        with np.errstate(all="ignore"):
            along = np.abs(np.einsum("pkj,pj->pk", normals, centre - cq))
            r1 = np.abs(np.einsum("pkj,pej->pke", normals, self._half[q])).sum(axis=-1)
            r2 = np.einsum("pkj,pj->pk", np.abs(normals), extent)
            bound = (along - r1 - r2).max(axis=-1)
            if world:
                reach = np.abs(self._half[q]).sum(axis=1)
                bound = np.maximum(bound, (np.abs(centre - cq) - reach - extent).max(axis=-1))
            size = 1.0 + np.abs(cq).sum(axis=1) + np.abs(self._half[q]).sum(axis=(1, 2)) + np.abs(centre).sum(axis=1)
            size += np.abs(extent).sum(axis=1)
        return bound - 1e-9 * size

    def _search(
        self, tree: AabbTree, queries: np.ndarray, raw: np.ndarray, partner: np.ndarray, world: bool, slack: float,
        pairs: Pairs,
    ) -> None:  # fmt: skip
        """Lower ``raw[q]`` (and set ``partner[q]``) to the least pair value of each query over ``tree``'s rows."""
        if not len(queries) or not len(tree.leaf):
            return
        nodes = tree.nodes
        count, first = nodes["count"], nodes["first"].astype(np.int64)
        self._seed(tree, queries, raw, partner, pairs)
        fq, fn = queries.copy(), np.zeros(len(queries), np.int64)
        while fq.size:
            lo, hi = nodes["bounds_min"][fn].astype(np.float64), nodes["bounds_max"][fn].astype(np.float64)
            bound = self._lower_bound(fq, lo, hi, world) - slack
            keep = bound <= raw[fq]
            fq, fn = fq[keep], fn[keep]
            leaf = count[fn] > 0
            if np.any(leaf):
                self._take(fq[leaf], first[fn[leaf]], raw, partner, pairs)
            inner = ~leaf
            kids = first[fn[inner]]
            fq = np.repeat(fq[inner], 2)
            fn = np.stack([kids, kids + 1], axis=1).reshape(-1)

    @staticmethod
    def _take(q: np.ndarray, rows: np.ndarray, raw: np.ndarray, partner: np.ndarray, pairs: Pairs) -> None:
        values = pairs(q, rows)
        better = values < raw[q]
        q, rows, values = q[better], rows[better], values[better]
        if not q.size:
            return
        order = np.lexsort((values, q))
        q, rows, values = q[order], rows[order], values[order]
        first = np.concatenate([[True], q[1:] != q[:-1]])
        raw[q[first]] = values[first]
        partner[q[first]] = rows[first]

    def _seed(self, tree: AabbTree, queries: np.ndarray, raw: np.ndarray, partner: np.ndarray, pairs: Pairs) -> None:
        """A first upper bound per query: the leaf reached by always stepping to the child nearer its centre."""
        nodes = tree.nodes
        count, first = nodes["count"], nodes["first"].astype(np.int64)
        node = np.zeros(len(queries), np.int64)
        centre = np.where(np.isfinite(self._centre[queries]), self._centre[queries], 0.0)
        for _ in range(tree.depth + 1):
            inner = np.flatnonzero(count[node] == 0)
            if not inner.size:
                break
            kids = first[node[inner]]
            mid = [0.5 * (nodes["bounds_min"][k] + nodes["bounds_max"][k]).astype(np.float64) for k in (kids, kids + 1)]
            d = [np.abs(m - centre[inner]).sum(axis=1) for m in mid]
            node[inner] = np.where(d[1] < d[0], kids + 1, kids)
        self._take(queries, first[node], raw, partner, pairs)

    def _leaf_order(self) -> tuple[np.ndarray, np.ndarray]:
        """The boxes in their tree's leaf order and each box's place in it (kept until the tree is rebuilt)."""
        assert self._boxes is not None
        if self._order_of != self._boxes.rebuilds:
            order = np.argsort(self._boxes.leaf)
            position = np.empty_like(order)
            position[order] = np.arange(len(order))
            self._order = (order, position)
            self._order_of = self._boxes.rebuilds
        return self._order

    def _search_boxes(self, rows: np.ndarray) -> None:
        assert self._boxes is not None
        if len(self._centre) < 2:
            return
        if not self._good_boxes.all():
            self._raw_box[:] = 0.0
            return
        n = len(self._centre)
        if len(rows) * n <= BRUTE_PAIRS:
            self._take(np.repeat(rows, n), np.tile(np.arange(n), len(rows)), self._raw_box, self._partner_box,
                       self._box_pairs)  # fmt: skip
            return
        # The neighbours in the tree's leaf order first: near in space, and never the box itself.
        order, position = self._leaf_order()
        for step in (-1, 1):
            other = order[np.clip(position[rows] + step, 0, len(order) - 1)]
            self._take(rows, other, self._raw_box, self._partner_box, self._box_pairs)
        self._search(self._boxes, rows, self._raw_box, self._partner_box, False, self._max_slack, self._box_pairs)

    def _search_instances(self, rows: np.ndarray) -> None:
        assert self._instances is not None
        if not len(self._lo) or not len(rows):
            return
        if not self._good_instances.all():
            self._raw_instance[rows] = 0.0
            return
        good = rows[self._good_boxes[rows]]
        self._raw_instance[rows[~self._good_boxes[rows]]] = 0.0
        self._search(
            self._instances, good, self._raw_instance, self._partner_instance, True, self._max_slack_i,
            self._instance_pairs,
        )  # fmt: skip

    def _near_moved_boxes(self, moved: np.ndarray, exclude: np.ndarray) -> list[int]:
        """Boxes (not ``exclude``) to which a moved box is now nearer than their gap: lowered to it. The gap
        from b to a moved box m is at least m's projection gap on m's own face normals, so the search
        descends the boxes' tree with m as the query, down to the nodes that could hold such a b."""
        assert self._boxes is not None
        n = len(self._centre)
        if len(moved) * n <= BRUTE_PAIRS:
            b, m = np.tile(np.arange(n), len(moved)), np.repeat(moved, n)
            wanted = ~np.isin(b, exclude)
            return self._lower(b[wanted], m[wanted], self._raw_box, self._partner_box, self._box_pairs)
        largest = float(self._raw_box.max()) if len(self._raw_box) else 0.0
        nodes = self._boxes.nodes
        count, first = nodes["count"], nodes["first"].astype(np.int64)
        hits: set[int] = set()
        fq, fn = moved.copy(), np.zeros(len(moved), np.int64)
        while fq.size:
            lo, hi = nodes["bounds_min"][fn].astype(np.float64), nodes["bounds_max"][fn].astype(np.float64)
            keep = self._lower_bound(fq, lo, hi, False) - self._slack[fq] <= largest
            fq, fn = fq[keep], fn[keep]
            leaf = count[fn] > 0
            b, m = first[fn[leaf]], fq[leaf]
            wanted = ~np.isin(b, exclude)
            if np.any(wanted):
                hits.update(self._lower(b[wanted], m[wanted], self._raw_box, self._partner_box, self._box_pairs))
            inner = ~leaf
            kids = first[fn[inner]]
            fq = np.repeat(fq[inner], 2)
            fn = np.stack([kids, kids + 1], axis=1).reshape(-1)
        return sorted(hits)

    def _near_moved_instances(self, moved: np.ndarray, exclude: np.ndarray) -> list[int]:
        """Boxes (not ``exclude``) to which a moved instance is now nearer than their clearance: the gap is
        at least the world-axis gap of their bounds, so only boxes within the largest clearance can be."""
        assert self._boxes is not None
        largest = float(self._raw_instance.max()) if len(self._raw_instance) else 0.0
        hits: set[int] = set()
        for i in moved.tolist():
            size = 1.0 + float(np.abs(self._lo[i]).sum() + np.abs(self._hi[i]).sum())
            reach = largest + float(self._slack_i[i]) + 1e-9 * size
            near = np.asarray(self._boxes.rows_in_box(self._lo[i] - reach, self._hi[i] + reach), np.int64)
            near = near[~np.isin(near, exclude)]
            if near.size:
                hits.update(
                    self._lower(near, np.full(len(near), i), self._raw_instance, self._partner_instance,
                                self._instance_pairs)
                )  # fmt: skip
        return sorted(hits)

    @classmethod
    def _lower(cls, q: np.ndarray, rows: np.ndarray, raw: np.ndarray, partner: np.ndarray, pairs: Pairs) -> list[int]:
        """Lower each query's value to its pair with ``rows`` where smaller; returns the queries lowered."""
        before = raw[q].copy()
        cls._take(q, rows, raw, partner, pairs)
        return np.unique(q[raw[q] < before]).tolist()

    def _finish(self, rows: np.ndarray) -> None:
        """The stored values of ``rows`` from their raw minima: less their own slack, never negative."""
        n = len(self._centre)
        if len(self.instance) != n:
            self.instance, self.box = np.zeros(n), np.zeros(n)
        with np.errstate(all="ignore"):
            inst = self._raw_instance[rows] - self._slack[rows]
            box = self._raw_box[rows] - self._slack[rows]
        self.instance[rows] = np.maximum(np.where(np.isfinite(inst), inst, 0.0), 0.0)
        self.box[rows] = np.maximum(np.where(np.isfinite(box), box, 0.0), 0.0)
