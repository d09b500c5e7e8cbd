"""Per-frame instance lists for the leg after a camera ray's first portal (the view tiles' portal-leg section).

A primary ray that crosses portal p on its first leg goes on, from p's exit quad, as the primary ray of a
*virtual camera* at the same pixel: the camera moved by p's transfer X (a rotation and a uniform scale; another
map has no such camera, and its portal no lists). So the instances that leg can meet are listed per tile as
the first leg's are (:func:`engine.view_tiles.leaf_tiles`, :func:`engine.camera_view.seen_instances`), for the
virtual camera, over the tiles p's quad covers, without the instances wholly behind the exit quad's plane (the
leg starts on it and goes away from the virtual camera's side).

A listed row's bound is in the leg's own parameter t (from the exit quad along the unit direction): a hit at
virtual distance s lies at t >= s - D, D the exit quad's farthest corner from the virtual camera, so the
virtual distance less D (grown for rounding) bounds it below and the kernels' break stays exact.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from engine.camera_view import CameraView, boxes_seen, seen_instances, view_planes
from engine.tlas_wide import TlasLanes
from engine.view_tiles import CORNER_PICK, KERNEL_PAD, PortalLegs, leaf_tiles, tile_rows

#: Relative growth of the exit quad's farthest corner, on top of :data:`engine.view_tiles.KERNEL_PAD`'s.
FAR_MARGIN = 1e-3
#: A box counts as in front of an exit plane unless all its corners lie behind it by this (times
#: max(1, the corners' distance from the packed origin)): far above the rounding of a teleported point.
PLANE_MARGIN = 1e-4
#: A view-filling portal hides the portals beyond its plane from the first legs: its corner rays must meet the
#: quad this far inside its edges (local units), and the others lie beyond its plane by this, times
#: max(1, the camera's distance from the packed origin plus theirs).
HIDE_MARGIN = 1e-3
#: How far from a rotation a transfer's 3x3 part, over its scale, may be and still count as one.
ROTATION_TOLERANCE = 1e-5

_QUAD = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
#: Which of a box's 8 corners take hi, per axis.
_PICK = CORNER_PICK > 0.0


def quad_corners(w2l: np.ndarray) -> np.ndarray:
    """The corners (n, 4, 3) of portal quads, camera-relative, from their ``world_to_local`` rows (n, 3, 4)."""
    inverse = np.linalg.inv(w2l[:, :, :3])
    return np.einsum("nij,nkj->nki", inverse, _QUAD[None] - w2l[:, None, :, 3])


def virtual_view(view: CameraView, origin: np.ndarray, transfer: np.ndarray) -> CameraView | None:
    """The camera moved by a portal's transfer rows (3, 4, camera-relative), or None where its 3x3 part is no
    rotation times a scale (rays through the portal are then no camera's primary rays)."""
    linear = transfer[:, :3]
    scale = abs(float(np.linalg.det(linear))) ** (1.0 / 3.0)
    if not scale > 0.0:
        return None
    rotation = linear / scale
    if not np.allclose(rotation.T @ rotation, np.eye(3), atol=ROTATION_TOLERANCE):
        return None
    apex = np.asarray(view.position, dtype=np.float64) - origin
    return replace(view, position=origin + linear @ apex + transfer[:, 3], rotation=rotation @ view.rotation)


def _away(quad: np.ndarray, apex: np.ndarray) -> np.ndarray:
    """The unit normal of the plane of ``quad``'s corners (4, 3) that points away from the apex's side."""
    normal = np.cross(quad[1] - quad[0], quad[3] - quad[0])
    normal = normal / np.linalg.norm(normal)
    return -normal if normal @ (apex - quad[0]) > 0.0 else normal


def _in_front(corners: np.ndarray, quad: np.ndarray, apex: np.ndarray) -> np.ndarray:
    """Which boxes, by corners (n, k, 3), are not wholly on the apex's side of the plane of ``quad``'s corners
    (4, 3), less :data:`PLANE_MARGIN`: only those can a leg from the quad away from the apex's side meet."""
    signed = (corners - quad[0]) @ _away(quad, apex)
    reach = np.maximum(1.0, np.abs(corners).max(axis=(1, 2)))
    return signed.max(axis=1) > -PLANE_MARGIN * reach


def portal_legs(
    view: CameraView,
    width: int,
    height: int,
    origin: np.ndarray,
    portals: np.ndarray,
    instances: tuple[TlasLanes, np.ndarray, np.ndarray],
    log2: int,
) -> PortalLegs:
    """The portal legs' lists of a frame (see the module): ``portals`` the packed portal rows in use, float64 as
    the kernels read them; ``instances`` the ``tlas_nodes`` lanes and the instances' exact bounds. Every tile of a
    slot lists all its instances (:func:`engine.view_tiles.cut_long` leaves the long ones to the tree)."""
    aspect = width / height
    w2l = portals["world_to_local"].astype(np.float64)
    transfer = portals["transfer"].astype(np.float64)
    target = portals["meta"][:, 0].astype(np.int64)
    corners = quad_corners(w2l)
    rects, _ = leaf_tiles(view, width, height, origin, corners.min(axis=1), corners.max(axis=1), log2)
    lanes, lo, hi = instances
    box_corners = np.where(_PICK[None], hi[:, None], lo[:, None])  # (n, 8, 3)
    linked = _reachable(view, aspect, origin, w2l, corners, (target >= 0) & (rects[:, 2] >= rects[:, 0]))
    rows, kept, lists = [], [], []
    complete = True
    for p in linked:
        virtual = virtual_view(view, origin, transfer[p])
        if virtual is None:
            complete = False
            continue
        exit_row = int(target[p])
        apex = virtual.position - origin
        x0, y0, x1, y1 = (int(v) for v in rects[p])
        seen = seen_instances(virtual, aspect, origin, lanes)
        seen = seen[_in_front(box_corners[seen], corners[exit_row], apex)]
        ranges, near = leaf_tiles(virtual, width, height, origin, lo[seen], hi[seen], log2)
        # Clip to the portal's rect, as tiles of a grid of its own.
        ranges = ranges - np.array([x0, y0, x0, y0])
        ranges[:, 2] = np.minimum(ranges[:, 2], x1 - x0)
        ranges[:, 3] = np.minimum(ranges[:, 3], y1 - y0)
        ranges[:, :2] = np.maximum(ranges[:, :2], 0)
        far = float(np.linalg.norm(corners[exit_row] - apex, axis=1).max())
        far = far * (1.0 + FAR_MARGIN) + 2.0 * KERNEL_PAD * max(1.0, float(np.linalg.norm(apex)), far)
        listed, bound, counts = tile_rows(ranges, seen, near - far, x1 - x0 + 1, (x1 - x0 + 1) * (y1 - y0 + 1))
        rows.append(p)
        kept.append((x0, y0, x1, y1))
        lists.append((listed, bound, counts))
        if complete:
            complete = not _meets_portal(virtual, width, height, origin, corners, target, exit_row, rects[p], log2)
    return PortalLegs(np.array(rows, np.int64), np.array(kept, np.int64).reshape(-1, 4), lists, complete)


def _reachable(
    view: CameraView, aspect: float, origin: np.ndarray, w2l: np.ndarray, corners: np.ndarray, seen: np.ndarray
) -> np.ndarray:
    """The portal rows among ``seen`` a first leg may cross: all of them, or only a view-filling one (every corner
    ray of the camera's pyramid meets its quad) where the others lie wholly beyond its plane (it comes first)."""
    rows = np.flatnonzero(seen)
    apex = np.asarray(view.position, dtype=np.float64) - origin
    t = np.tan(np.radians(view.fov_deg) / 2.0)
    local = np.array([[-aspect * t, -t, -1.0], [aspect * t, -t, -1.0], [aspect * t, t, -1.0], [-aspect * t, t, -1.0]])
    rays = local @ view.rotation.T  # (4, 3) world directions of the pyramid's edges
    for p in rows:
        linear, shift = w2l[p, :, :3], w2l[p, :, 3]
        o, d = linear @ apex + shift, rays @ linear.T  # quad space: z = 0 the quad's plane
        # Towards the plane, and far enough from it that no first leg starts past it (t_min).
        if not np.all(d[:, 2] * o[2] < 0.0) or abs(o[2]) / np.linalg.norm(linear[2]) <= HIDE_MARGIN * max(
            1.0, float(np.linalg.norm(apex))
        ):
            continue
        hit = o[None, :2] - d[:, :2] * (o[2] / d[:, 2])[:, None]
        if np.abs(hit).max() > 1.0 - HIDE_MARGIN:
            continue
        others = rows[rows != p]
        if not others.size:
            return rows[rows == p]
        beyond = ((corners[others] - corners[p, 0]) @ _away(corners[p], apex)).min()
        margin = HIDE_MARGIN * max(1.0, float(np.linalg.norm(apex)) + float(np.abs(corners[others] - apex).max()))
        if beyond > margin:
            return rows[rows == p]
    return rows


def _meets_portal(
    virtual: CameraView,
    width: int,
    height: int,
    origin: np.ndarray,
    corners: np.ndarray,
    target: np.ndarray,
    exit_row: int,
    rect: np.ndarray,
    log2: int,
) -> bool:
    """Whether a second leg from ``exit_row``'s quad, a primary ray of ``virtual`` in ``rect``'s tiles, may meet a
    linked portal quad (``exit_row``'s own is skipped: the leg leaves it) in front of the exit plane."""
    others = np.flatnonzero((target >= 0) & (np.arange(len(target)) != exit_row))
    if not others.size:
        return False
    apex = virtual.position - origin
    lo, hi = corners[others].min(axis=1), corners[others].max(axis=1)
    seen = boxes_seen(view_planes(virtual, width / height), apex, lo, hi)
    others, lo, hi = others[seen], lo[seen], hi[seen]
    if not others.size:
        return False
    front = _in_front(corners[others], corners[exit_row], apex)
    lo, hi = lo[front], hi[front]
    if not len(lo):
        return False
    ranges, _ = leaf_tiles(virtual, width, height, origin, lo, hi, log2)
    x0, y0, x1, y1 = rect
    hit = (np.minimum(ranges[:, 2], x1) >= np.maximum(ranges[:, 0], x0)) & (
        np.minimum(ranges[:, 3], y1) >= np.maximum(ranges[:, 1], y0)
    )
    return bool(hit.any())
