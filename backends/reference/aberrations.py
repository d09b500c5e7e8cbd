"""Aberration boxes (docs/semantics.md, "Aberrations" and rules 3-9), vectorised over rays.

One rule per function, so each ports to a kernel function one to one:

* :func:`nearest_box_faces` — the next box face a ray crosses (event search);
* :func:`containing_box` — the active box at points (last containing row);
* :func:`sigma`, :func:`bend` — the radial/additive entry rule;
* :func:`exit_rule` — restore / repeat / invert when leaving a bending box;
* :func:`world_direction` — the metric rule ``r = normalize(R (s ⊙ Rᵀ w))``;
* :func:`perceived_per_world` — perceived length per world length;
* :func:`transition` — what happens to ``w`` and ``r`` when the active box changes.

Boxes are iterated one at a time (rows in table order) with every ray at
once, as a kernel loops over them; among many, each with only the rays or
points that can reach it (:mod:`backends.reference.space_tree`: the same
results). Box rows are sorted by (priority, entity), so "the last row that
contains a point" is the highest-priority box, ties going to the later entity.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from backends.reference.directions import affine_points, linear_vectors, normalize_or_keep
from backends.reference.space_tree import SpaceTree

#: Mode codes (engine.layout.ABERRATION_MODES); NO_MODE is "no active box".
NO_MODE, METRIC, RADIAL, ADDITIVE = -1, 0, 1, 2
#: Exit codes (engine.layout.ABERRATION_EXITS).
RESTORE, REPEAT, INVERT = 0, 1, 2
#: The row of "no box".
NO_BOX = -1
#: Faces per box; face id = 6·row + 2·axis + (1 on the +½ side, 0 on the −½ side).
FACES = 6
#: Radial mode: an axis whose corner-ray range is narrower than this uses σ_k = sign(v_k).
COLLAPSED_RANGE = 1e-6
#: The unit box's corners in its local frame.
BOX_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])


@dataclass(frozen=True)
class Boxes:
    """The live rows of the ``aberrations`` table as float64 / int64 arrays."""

    world_to_local: np.ndarray  # (B, 3, 4): world -> the unit box [-1/2, 1/2]^3
    rotation: np.ndarray  # (B, 3, 3): R (scale ignored)
    deformation: np.ndarray  # (B, 3): D
    mode: np.ndarray  # (B,) METRIC / RADIAL / ADDITIVE
    exit: np.ndarray  # (B,) RESTORE / REPEAT / INVERT
    entity: np.ndarray  # (B,)
    tree: SpaceTree | None = None  # over the boxes, when there are many

    def __len__(self) -> int:
        return len(self.mode)

    @staticmethod
    def from_table(table: np.ndarray, count: int) -> Boxes:
        rows = table[:count]
        meta = rows["meta"].astype(np.int64).reshape(-1, 4)
        world_to_local = rows["world_to_local"].astype(np.float64).reshape(-1, 3, 4)
        return Boxes(
            world_to_local=world_to_local,
            rotation=rows["rotation"][:, :, :3].astype(np.float64).reshape(-1, 3, 3),
            deformation=rows["deformation"][:, :3].astype(np.float64).reshape(-1, 3),
            mode=meta[:, 0],
            exit=meta[:, 1],
            entity=meta[:, 3],
            tree=SpaceTree.over(world_to_local, BOX_CORNERS),
        )

    @staticmethod
    def empty() -> Boxes:
        i = np.zeros(0, np.int64)
        return Boxes(np.zeros((0, 3, 4)), np.zeros((0, 3, 3)), np.zeros((0, 3)), i, i, i)


@dataclass(frozen=True)
class SigmaBounds:
    """The radial mode's per-axis ``m_k`` (``lo``) and ``M_k`` (``hi``) from the camera's corner rays."""

    lo: np.ndarray  # (3,)
    hi: np.ndarray  # (3,)

    @staticmethod
    def default() -> SigmaBounds:
        """Used when no camera is given (``trace_rays``): the full range [-1, 1] on every axis."""
        return SigmaBounds(np.full(3, -1.0), np.full(3, 1.0))


def mode_of(boxes: Boxes, rows: np.ndarray) -> np.ndarray:
    """The mode of each row, NO_MODE for NO_BOX."""
    if len(boxes) == 0:
        return np.full(len(rows), NO_MODE, np.int64)
    return np.where(rows >= 0, boxes.mode[np.maximum(rows, 0)], NO_MODE)


def bends(mode: np.ndarray) -> np.ndarray:
    """Radial and additive boxes bend the perceived direction ``w`` (metric boxes never do)."""
    return (mode == RADIAL) | (mode == ADDITIVE)


# --- where the boxes are ------------------------------------------------------------------------


def slab_faces(a: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Entry and exit of local rays ``a + t·v`` through the unit box: ``(t_near, face, t_far, face)``.

    Face numbers are ``2·axis + (1 if +½ else 0)``. An axis with ``v_k == 0``
    is crossed nowhere: the ray lies inside its slab for every ``t`` when
    ``|a_k| <= ½`` (closed box), outside otherwise. Equal per-axis entries
    (a ray through an edge) go to the lowest axis. The ray crosses the box
    only where ``t_near <= t_far``; the faces are -1 where no axis moves.
    """
    n = len(a)
    t_near, t_far = np.full(n, -np.inf), np.full(n, np.inf)
    near_face, far_face = np.full(n, -1, np.int64), np.full(n, -1, np.int64)
    with np.errstate(all="ignore"):
        for k in range(3):
            ak, vk = a[:, k], v[:, k]
            moving = vk != 0.0
            inside = np.abs(ak) <= 0.5
            safe = np.where(moving, vk, 1.0)
            t_minus, t_plus = (-0.5 - ak) / safe, (0.5 - ak) / safe
            up = vk > 0.0
            tn = np.where(moving, np.where(up, t_minus, t_plus), np.where(inside, -np.inf, np.inf))
            tf = np.where(moving, np.where(up, t_plus, t_minus), np.where(inside, np.inf, -np.inf))
            take = tn > t_near
            t_near, near_face = np.where(take, tn, t_near), np.where(take, np.where(up, 2 * k, 2 * k + 1), near_face)
            take = tf < t_far
            t_far, far_face = np.where(take, tf, t_far), np.where(take, np.where(up, 2 * k + 1, 2 * k), far_face)
    return t_near, near_face, t_far, far_face


def nearest_box_faces(
    boxes: Boxes, o: np.ndarray, r: np.ndarray, t_min: np.ndarray, skip_face: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The nearest box face each ray crosses with ``t > t_min``: ``(t, face id)``, ``(inf, -1)`` for none.

    ``skip_face`` is the face id the ray is leaving (-1: none); it never
    counts. ``t`` is in units of ``r`` (unit: world length), since the local
    direction is not normalised. Ties: the lower row, then the entry face.
    """
    n = len(o)
    best_t, best_face = np.full(n, np.inf), np.full(n, -1, np.int64)
    every = slice(None)
    rows = ((row, every) for row in range(len(boxes))) if boxes.tree is None else boxes.tree.ray_rows(o, r, t_min)
    for row, rays in rows:
        m = boxes.world_to_local[row]
        t_near, near_face, t_far, far_face = slab_faces(affine_points(m, o[rays]), linear_vectors(m, r[rays]))
        crosses = t_near <= t_far
        for t, face in ((t_near, near_face), (t_far, far_face)):
            face_id = FACES * row + face
            ok = crosses & (face >= 0) & np.isfinite(t) & (t > t_min[rays]) & (t < best_t[rays])
            ok &= face_id != skip_face[rays]
            best_t[rays], best_face[rays] = np.where(ok, t, best_t[rays]), np.where(ok, face_id, best_face[rays])
    return best_t, best_face


def containing_box(boxes: Boxes, points: np.ndarray) -> np.ndarray:
    """The active box at each point: the last row whose closed unit box contains it, NO_BOX for none."""
    found = np.full(len(points), NO_BOX, np.int64)
    every = slice(None)
    rows = ((row, every) for row in range(len(boxes))) if boxes.tree is None else boxes.tree.point_rows(points)
    with np.errstate(invalid="ignore"):
        for row, at in rows:
            local = affine_points(boxes.world_to_local[row], points[at])
            found[at] = np.where(np.all(np.abs(local) <= 0.5, axis=1), row, found[at])
    return found


# --- how they deform rays -------------------------------------------------------------------------


def sigma(v: np.ndarray, bounds: SigmaBounds) -> np.ndarray:
    """Radial weights ``σ_k(v) = 2·smoothstep(m_k, M_k, v_k) − 1``; ``sign(v_k)`` on a collapsed axis."""
    span = bounds.hi - bounds.lo
    collapsed = span < COLLAPSED_RANGE
    x = np.clip((v - bounds.lo) / np.where(collapsed, 1.0, span), 0.0, 1.0)
    smooth = x * x * (3.0 - 2.0 * x)
    return np.where(collapsed, np.sign(v), 2.0 * smooth - 1.0)


def bend(boxes: Boxes, bounds: SigmaBounds, rows: np.ndarray, w: np.ndarray, sign: float) -> np.ndarray:
    """The entry rule of radial/additive ``rows`` (with ``sign·D``) applied to ``w``.

    radial: ``normalize(w + D ⊙ σ(w))``; additive: ``normalize(w + D)``; a
    (near) zero or overflowing sum keeps ``w``.
    """
    d = sign * boxes.deformation[rows]
    offset = np.where((boxes.mode[rows] == RADIAL)[:, None], d * sigma(w, bounds), d)
    with np.errstate(all="ignore"):
        return normalize_or_keep(w + offset, w)


def exit_rule(boxes: Boxes, bounds: SigmaBounds, rows: np.ndarray, w: np.ndarray, d0: np.ndarray) -> np.ndarray:
    """``w`` after leaving radial/additive ``rows``: restore → ``d0``; repeat → entry again; invert → entry with −D."""
    rule = boxes.exit[rows]
    out = np.where((rule == RESTORE)[:, None], d0, w)
    for code, sign in ((REPEAT, 1.0), (INVERT, -1.0)):
        idx = np.flatnonzero(rule == code)
        if idx.size:
            out[idx] = bend(boxes, bounds, rows[idx], w[idx], sign)
    return out


def _metric_local(boxes: Boxes, rows: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``s ⊙ (Rᵀ w)`` in box axes (``s = 1 + D``) and ``R`` of metric ``rows``."""
    rotation = boxes.rotation[rows]
    local = np.einsum("nji,nj->ni", rotation, w)
    return (1.0 + boxes.deformation[rows]) * local, rotation


def world_direction(boxes: Boxes, rows: np.ndarray, w: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """``r`` from ``w``: ``normalize(R (s ⊙ Rᵀ w))`` in a metric box, ``w`` elsewhere (``previous`` if degenerate)."""
    r = w.copy()
    idx = np.flatnonzero(mode_of(boxes, rows) == METRIC)
    if idx.size:
        scaled, rotation = _metric_local(boxes, rows[idx], w[idx])
        with np.errstate(all="ignore"):
            r[idx] = normalize_or_keep(np.einsum("nij,nj->ni", rotation, scaled), previous[idx])
    return r


def perceived_per_world(boxes: Boxes, rows: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Perceived length per world length: ``1 / |s ⊙ Rᵀ w|`` in a metric box, 1 elsewhere.

    Radial and additive boxes bend rays but do not rescale length. An
    overflowing norm (huge D) gives 0, never NaN.
    """
    factor = np.ones(len(rows))
    idx = np.flatnonzero(mode_of(boxes, rows) == METRIC)
    if idx.size:
        scaled, _ = _metric_local(boxes, rows[idx], w[idx])
        with np.errstate(all="ignore"):
            norm = np.linalg.norm(scaled, axis=1)
            factor[idx] = np.where(norm > 0.0, 1.0 / np.where(norm > 0.0, norm, 1.0), 1.0)
    return factor


def transition(
    boxes: Boxes,
    bounds: SigmaBounds,
    old: np.ndarray,
    new: np.ndarray,
    w: np.ndarray,
    r: np.ndarray,
    d0: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """New ``(w, r)`` when the active box goes from ``old`` to ``new`` (rows, NO_BOX for none).

    1. leaving a bending box (``old ≠ new``): its exit rule changes ``w``;
    2. entering a bending box (``old ≠ new``): its entry rule changes ``w``;
    3. always: ``r`` is recomputed from ``w`` by the new box (metric) or is ``w``.
    """
    w = w.copy()
    changed = old != new
    leaving = np.flatnonzero(changed & bends(mode_of(boxes, old)))
    if leaving.size:
        w[leaving] = exit_rule(boxes, bounds, old[leaving], w[leaving], d0[leaving])
    entering = np.flatnonzero(changed & bends(mode_of(boxes, new)))
    if entering.size:
        w[entering] = bend(boxes, bounds, new[entering], w[entering], 1.0)
    return w, world_direction(boxes, new, w, r)
