"""Click to select: the nearest mesh, aberration box or portal quad under the mouse.

Picking uses straight rays in undeformed space, like the preview lines, so
what you click is where the entity really is (not where an aberration makes
it appear). Pure NumPy: it needs no GL context and is tested headless.
"""

from __future__ import annotations

import numpy as np

from components import Mesh, Transform
from engine.errors import AberrantError
from engine.maths import trs_inverse
from engine.scene import Scene
from engine.space_index import SpaceIndex


def _to_local(transform: Transform, origin: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    inv = trs_inverse(transform.position, transform.rotation, transform.scale)
    return inv[:3, :3] @ origin + inv[:3, 3], inv[:3, :3] @ direction


def ray_triangles(origin: np.ndarray, direction: np.ndarray, v0: np.ndarray, v1: np.ndarray, v2: np.ndarray) -> float:
    """Nearest positive ``t`` where the ray meets one of the triangles (Möller-Trumbore, two-sided), or inf."""
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - v0
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ direction) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9)
    return float(t[hit].min()) if np.any(hit) else np.inf


def ray_box(origin: np.ndarray, direction: np.ndarray) -> tuple[float, float]:
    """Where the ray enters and leaves the unit box [-1/2, 1/2]^3 (``(inf, inf)`` when it misses)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / direction
        t0 = (-0.5 - origin) * inv
        t1 = (0.5 - origin) * inv
    lo = float(np.nanmax(np.minimum(t0, t1)))
    hi = float(np.nanmin(np.maximum(t0, t1)))
    if hi < max(lo, 0.0):
        return np.inf, np.inf
    return lo, hi


def ray_quad(origin: np.ndarray, direction: np.ndarray) -> float:
    """Positive ``t`` where the ray crosses the quad [-1, 1]^2 in the local XY plane, or inf."""
    if abs(direction[2]) < 1e-12:
        return np.inf
    t = -origin[2] / direction[2]
    if t <= 1e-9:
        return np.inf
    x, y = origin[:2] + t * direction[:2]
    return float(t) if abs(x) <= 1.0 and abs(y) <= 1.0 else np.inf


def pick(scene: Scene, origin: np.ndarray, direction: np.ndarray, index: SpaceIndex | None = None) -> int | None:
    """The entity under the ray.

    Meshes and portal quads: the nearest surface. An aberration box wins
    only when whatever surface the ray meets lies behind the whole box, so
    a mesh inside a box is still clicked through it; boxes around the view
    are picked from the hierarchy instead.

    Portals and boxes are found through ``index`` (synced here; the editor keeps one so that a click costs
    what the ray passes, not the scene's count), only up to the nearest surface found so far: nothing
    further can win. Without one, a fresh index is built.
    """
    origin = np.asarray(origin, dtype=np.float64)
    direction = np.asarray(direction, dtype=np.float64)
    index = (index or SpaceIndex()).sync(scene)
    best_t, best = np.inf, None
    for entity, (transform, mesh) in scene.query(Transform, Mesh):
        try:
            asset = scene.asset(mesh.asset)
        except AberrantError:
            continue
        o, d = _to_local(transform, origin, direction)
        v = asset.vertices.astype(np.float64)
        f = asset.faces
        t = ray_triangles(o, d, v[f[:, 0]], v[f[:, 1]], v[f[:, 2]])
        if t < best_t:  # the same t in both spaces: the local direction is the mapped world one
            best_t, best = t, entity
    for entity in index.portals_on_ray(origin, direction, best_t):
        t = ray_quad(*_to_local(scene.get(entity, Transform), origin, direction))
        if t < best_t:
            best_t, best = t, entity
    box_t, box = np.inf, None
    for entity in index.boxes_on_ray(origin, direction, best_t):  # a winner leaves the box before best_t
        enter, leave = ray_box(*_to_local(scene.get(entity, Transform), origin, direction))
        if 0.0 < enter < box_t and leave < best_t:
            box_t, box = enter, entity
    return box if box is not None else best
