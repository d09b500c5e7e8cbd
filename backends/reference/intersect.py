"""Float64 ray–box and watertight ray–triangle tests, vectorised over (ray, primitive) pairs.

The triangle test is Woop, Benthin & Wald (2013), "Watertight Ray/Triangle
Intersection": each ray gets a permutation that makes its dominant direction
axis z and a shear that makes the direction (0, 0, 1); the vertices are
transformed *per vertex*, so a vertex shared by two triangles lands on the
same 2D point in both, and the edge functions ``U, V, W`` of a shared edge
are computed from the same two products in swapped order (exactly negated).

The paper recomputes an edge function in higher precision when it is exactly
zero. Here the sign of every edge function whose float64 value lies within
its rounding error bound (zero included) is recomputed *exactly* (error-free
products and sums), so the inside test is an exact point-in-triangle test
on the sheared 2D vertices: a ray through a shared edge or vertex of a
closed mesh hits one of the triangles (or several at the same ``t``), never
none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Relative bound under which the float64 sign of ``a*b - c*d`` is not trusted
#: (about 9 units of roundoff; the true error bound is 3).
_SIGN_TRUST = 1e-15
#: Veltkamp's splitter for float64 (2^27 + 1).
_SPLITTER = 134217729.0


# --- error-free transformations ------------------------------------------------


def _two_sum(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a + b = s + e`` exactly (Knuth)."""
    s = a + b
    bb = s - a
    e = (a - (s - bb)) + (b - bb)
    return s, e


def _two_product(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a * b = p + e`` exactly (Dekker; no FMA needed)."""
    p = a * b
    ca = _SPLITTER * a
    ah = ca - (ca - a)
    al = a - ah
    cb = _SPLITTER * b
    bh = cb - (cb - b)
    bl = b - bh
    e = al * bl - (((p - ah * bh) - al * bh) - ah * bl)
    return p, e


def _grow(expansion: list[np.ndarray], b: np.ndarray) -> list[np.ndarray]:
    """Shewchuk's Grow-Expansion: add ``b`` to a nonoverlapping expansion (smallest first)."""
    out = []
    q = b
    for component in expansion:
        q, h = _two_sum(q, component)
        out.append(h)
    out.append(q)
    return out


def exact_sign_of_difference(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The exact sign (-1, 0, 1 as float64) of ``a*b - c*d`` for finite float64 inputs."""
    p1, e1 = _two_product(a, b)
    p2, e2 = _two_product(c, d)
    s, t = _two_sum(p1, -p2)
    expansion = _grow(_grow([t, s], e1), -e2)
    sign = np.zeros_like(a)
    for component in expansion:  # smallest first: the largest nonzero component decides
        sign = np.where(component != 0.0, np.sign(component), sign)
    return sign


def edge_function(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a*b - c*d`` in float64 and its exact sign (recomputed only where rounding could flip it)."""
    ab = a * b
    cd = c * d
    value = ab - cd
    sign = np.sign(value)
    unsure = np.abs(value) <= _SIGN_TRUST * (np.abs(ab) + np.abs(cd))
    if np.any(unsure):
        idx = np.flatnonzero(unsure)
        sign[idx] = exact_sign_of_difference(a[idx], b[idx], c[idx], d[idx])
    return value, sign


# --- rays ----------------------------------------------------------------------


@dataclass(frozen=True)
class ShearedRays:
    """Per-ray set-up of the watertight test: axis permutation (kx, ky, kz) and shear (Sx, Sy, Sz)."""

    perm: np.ndarray  # (N, 3) int64
    shear: np.ndarray  # (N, 3) float64


def shear_rays(direction: np.ndarray) -> ShearedRays:
    """Permute so the largest |direction| component is z; swap x/y when it is negative (keeps winding)."""
    n = len(direction)
    kz = np.argmax(np.abs(direction), axis=1)
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    dz = direction[np.arange(n), kz]
    flip = dz < 0.0
    kx, ky = np.where(flip, ky, kx), np.where(flip, kx, ky)
    perm = np.stack([kx, ky, kz], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        sz = 1.0 / dz
        sx = direction[np.arange(n), kx] * sz
        sy = direction[np.arange(n), ky] * sz
    return ShearedRays(perm, np.stack([sx, sy, sz], axis=1))


@dataclass(frozen=True)
class TriangleHits:
    """Per pair: ``t`` (+inf where there is no hit) and barycentric weights of v0, v1, v2."""

    t: np.ndarray
    bary: np.ndarray  # (P, 3)


def intersect_triangles(
    origin: np.ndarray,
    perm: np.ndarray,
    shear: np.ndarray,
    v0: np.ndarray,
    v1: np.ndarray,
    v2: np.ndarray,
    cull: np.ndarray,
) -> TriangleHits:
    """Watertight test of P (ray, triangle) pairs; every argument has one row per pair.

    ``t`` is in units of the (unnormalised) direction that built ``perm``/``shear``.
    Front faces (counter-clockwise v0, v1, v2 seen from the ray) have positive
    edge functions; with ``cull`` only those count. Triangles seen edge-on and
    degenerate triangles never hit. No NaN leaves this function.
    """
    sx, sy, sz = shear[:, 0], shear[:, 1], shear[:, 2]
    sheared = []
    for vertex in (v0, v1, v2):
        rel = np.take_along_axis(vertex - origin, perm, axis=1)
        sheared.append((rel[:, 0] - sx * rel[:, 2], rel[:, 1] - sy * rel[:, 2], sz * rel[:, 2]))
    (ax, ay, az), (bx, by, bz), (cx, cy, cz) = sheared
    u, su = edge_function(cx, by, cy, bx)
    v, sv = edge_function(ax, cy, ay, cx)
    w, sw = edge_function(bx, ay, by, ax)
    front = (su >= 0) & (sv >= 0) & (sw >= 0)
    back = (su <= 0) & (sv <= 0) & (sw <= 0)
    inside = (front | (back & ~cull)) & ((su != 0) | (sv != 0) | (sw != 0))
    # Keep float values only where their sign agrees with the exact one.
    u = np.where(np.sign(u) == su, u, 0.0)
    v = np.where(np.sign(v) == sv, v, 0.0)
    w = np.where(np.sign(w) == sw, w, 0.0)
    det = u + v + w
    ok = inside & (det != 0.0) & np.isfinite(det)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        t = (u * az + v * bz + w * cz) * inv
        bary = np.stack([u * inv, v * inv, w * inv], axis=1)
    ok &= np.isfinite(t) & np.all(np.isfinite(bary), axis=1)
    t = np.where(ok, t, np.inf)
    bary = np.where(ok[:, None], bary, 0.0)
    return TriangleHits(t, bary)


# --- boxes -----------------------------------------------------------------------


def safe_inverse(direction: np.ndarray) -> np.ndarray:
    """``1 / direction`` with zero components replaced by a huge finite value (no inf * 0 = NaN)."""
    tiny = np.where(direction == 0.0, 1e-300, direction)
    with np.errstate(over="ignore"):
        return 1.0 / tiny


def slab(origin: np.ndarray, inverse: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit ``t`` of rays against axis-aligned boxes (pairs broadcast row-wise).

    The exit is widened by a few ulps so a hit on a box face is never lost to
    rounding (a conservative test; the triangle test decides).
    """
    with np.errstate(over="ignore", invalid="ignore"):
        t0 = (lo - origin) * inverse
        t1 = (hi - origin) * inverse
    near_axis = np.minimum(t0, t1)
    far_axis = np.maximum(t0, t1)
    # Component-wise rather than ``.max(axis=-1)``: a reduction over 3 elements is slow in NumPy.
    near = np.maximum(np.maximum(near_axis[..., 0], near_axis[..., 1]), near_axis[..., 2])
    far = np.minimum(np.minimum(far_axis[..., 0], far_axis[..., 1]), far_axis[..., 2])
    far = far + np.abs(far) * 4e-16
    return near, far
