"""Portal quads (docs/semantics.md, "Portals" and rules 3 and 10), vectorised over rays.

* :func:`nearest_portal_hits` — the next linked quad a ray passes through;
* :func:`teleport` — origin and the three directions mapped through ``X``.

A portal is the quad [-1, 1]² at z = 0 of its local space, two-sided. Only
linked portals (target row >= 0) are ever hit: an unlinked portal is inert
and invisible. Portals are iterated one at a time with every ray at once, as
a kernel loops over them; among many, each with only the rays that can reach
it (:mod:`backends.reference.space_tree`: the same results).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from backends.reference.directions import affine_points, linear_vectors, normalize_or_keep
from backends.reference.space_tree import SpaceTree

#: A portal's quad in its local frame: [-1, 1]^2 at z = 0.
QUAD_CORNERS = np.array([[x, y, 0.0] for x in (-1.0, 1.0) for y in (-1.0, 1.0)])

#: The row of "no portal"; also the target of an unlinked portal.
NO_PORTAL = -1


@dataclass(frozen=True)
class Portals:
    """The live rows of the ``portals`` table as float64 / int64 arrays."""

    world_to_local: np.ndarray  # (P, 3, 4): world -> quad space
    transfer: np.ndarray  # (P, 3, 4): X = M_target · M_self⁻¹
    target: np.ndarray  # (P,) target row, NO_PORTAL when unlinked
    entity: np.ndarray  # (P,)
    tree: SpaceTree | None = None  # over the quads, when there are many

    def __len__(self) -> int:
        return len(self.target)

    @staticmethod
    def from_table(table: np.ndarray, count: int) -> Portals:
        rows = table[:count]
        meta = rows["meta"].astype(np.int64).reshape(-1, 4)
        world_to_local = rows["world_to_local"].astype(np.float64).reshape(-1, 3, 4)
        return Portals(
            world_to_local=world_to_local,
            transfer=rows["transfer"].astype(np.float64).reshape(-1, 3, 4),
            target=meta[:, 0],
            entity=meta[:, 1],
            tree=SpaceTree.over(world_to_local, QUAD_CORNERS),
        )

    @staticmethod
    def empty() -> Portals:
        i = np.zeros(0, np.int64)
        return Portals(np.zeros((0, 3, 4)), np.zeros((0, 3, 4)), i, i)


def nearest_portal_hits(
    portals: Portals, o: np.ndarray, r: np.ndarray, t_min: np.ndarray, skip: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The nearest linked quad each ray passes through with ``t > t_min``: ``(t, row)``, ``(inf, -1)`` for none.

    ``skip`` is the portal row the ray is leaving (the one it arrived on).
    The quad is closed (its border counts); a ray parallel to its plane
    never hits it. Ties: the lower row.
    """
    n = len(o)
    best_t, best_row = np.full(n, np.inf), np.full(n, NO_PORTAL, np.int64)
    every = slice(None)
    rows = ((row, every) for row in range(len(portals))) if portals.tree is None else portals.tree.ray_rows(o, r, t_min)
    with np.errstate(all="ignore"):
        for row, rays in rows:
            if portals.target[row] < 0:
                continue
            m = portals.world_to_local[row]
            a, v = affine_points(m, o[rays]), linear_vectors(m, r[rays])
            crossing = v[:, 2] != 0.0
            t = -a[:, 2] / np.where(crossing, v[:, 2], 1.0)
            x, y = a[:, 0] + t * v[:, 0], a[:, 1] + t * v[:, 1]
            on_quad = (np.abs(x) <= 1.0) & (np.abs(y) <= 1.0)
            ok = crossing & np.isfinite(t) & (t > t_min[rays]) & on_quad & (t < best_t[rays]) & (skip[rays] != row)
            best_t[rays], best_row[rays] = np.where(ok, t, best_t[rays]), np.where(ok, row, best_row[rays])
    return best_t, best_row


def teleport(
    portals: Portals, rows: np.ndarray, p: np.ndarray, r: np.ndarray, w: np.ndarray, d0: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rays at ``p`` on quads ``rows`` continue from ``X p`` with ``normalize(L ·)`` of ``r``, ``w``, ``d0``.

    Returns ``(o, r, w, d0, arrival row)``; the arrival row is the target
    portal, which the ray is then leaving. A direction whose map degenerates
    keeps its previous value (no NaN).
    """
    transfer = portals.transfer[rows]
    with np.errstate(all="ignore"):
        o = affine_points(transfer, p)
        mapped = [normalize_or_keep(linear_vectors(transfer, v), v) for v in (r, w, d0)]
    return o, mapped[0], mapped[1], mapped[2], portals.target[rows]
