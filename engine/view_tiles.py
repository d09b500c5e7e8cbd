"""Per-frame view tiles: for each screen tile, the portal rows and the instance rows the first leg of its
primary rays may meet, so the kernels loop over short lists there instead of walking the portals' tree and
the instances' one.

A primary ray meets a portal only inside that row's leaf of the space tree (grown by the kernels' SPACE_PAD),
so a tile's list holds every leaf whose box any ray of the tile can enter: the leaves the camera's
pyramid sees (:func:`engine.camera_view.seen_leaves`), each projected through its box's 8 corners to a pixel
range (the image of a box in front of the camera lies in the hull of its corners' images) and padded by pixels
for the rays' rounding; a leaf with a corner at or near the camera plane covers every tile. The kernels test
the same rows with the same test, and a tie goes to the lower row whatever the order, so the frame is the
tree's one. The table (:data:`engine.layout.VIEW_TILE`) is CSR: a header row per tile, then the rows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from engine import layout
from engine.camera_view import CameraView, seen_instances, seen_leaves
from engine.tlas import SPACE_SLACK
from engine.tlas_wide import TlasLanes

#: log2 of a tile's side in pixels: 8 x 8, the GLSL backend's work-group, whose 4 x 2 lane blocks each lie in
#: one tile (llvmpipe runs a block's 8 lanes as one vector: one list for them all).
TILE_LOG2 = 3
#: The kernels' widest per-ray growth of a leaf (SPACE_PAD in core.h, float32's), times max(1, |camera|).
KERNEL_PAD = 1e-5
#: Pixels added on each side of a leaf's projected range: the rays' subpixel point lies in [0, 1) of their
#: pixel, and float32 directions stray by far less than a pixel.
PIXEL_PAD = 1.0
#: Relative margin of a projected range, on top of the pixels (rounding of the projection near the edges).
RANGE_MARGIN = 1e-3
#: A leaf's distance from the camera, as the kernels' loops stop at it, is shrunk by this relative margin: far
#: above float32's rounding of a hit's t.
NEAR_MARGIN = 1e-3
#: A corner nearer the camera plane than this (times max(1, its distance)) makes its leaf cover every tile.
NEAR_PLANE = 1e-3
#: (8, 3): which axes of a box's 8 corners take its hi bound (1) over its lo one (0).
CORNER_PICK = np.array([[(k >> a) & 1 for a in range(3)] for k in range(8)], np.float64)


@dataclass(frozen=True)
class PortalLegs:
    """What the portal legs' lists of a frame say: per slot (a portal its first legs can cross, with a
    virtual camera) the portal row, its tile rect ``(x0, y0, x1, y1)``, and per tile of the rect (row-major)
    the instance rows, their bounds and counts (:func:`engine.view_tiles.tile_rows`' form); and whether
    every second leg has its list and meets no portal (no third leg: the tree is not needed)."""

    rows: np.ndarray
    rects: np.ndarray
    lists: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
    complete: bool


def tile_grid(width: int, height: int, log2: int = TILE_LOG2) -> tuple[int, int]:
    """Tiles across and down an image."""
    side = 1 << log2
    return -(-width // side), -(-height // side)


def leaf_tiles(
    view: CameraView, width: int, height: int, origin: np.ndarray, lo: np.ndarray, hi: np.ndarray, log2: int
) -> tuple[np.ndarray, np.ndarray]:
    """The tile ranges ``(x0, y0, x1, y1)`` (inclusive; x1 < x0 for none) of leaves lo/hi (n, 3,
    camera-relative): every tile one of whose primary rays can enter the leaf grown by the kernels' pad; and
    each leaf's distance from the camera, shrunk by :data:`NEAR_MARGIN` (no ray meets the leaf nearer)."""
    # Leaves along the last axis ((3, n), corners (8, n)): each reduction over an axis or the corners is then
    # one elementwise operation across rows, not a short row per leaf (half the time at 1,024 leaves).
    apex = np.asarray(view.position, dtype=np.float64) - origin
    grow = 2.0 * KERNEL_PAD * max(1.0, float(np.linalg.norm(apex)))
    lo = (lo - apex - grow).T
    hi = (hi - apex + grow).T
    grow_rel = 2.0 * KERNEL_PAD * np.maximum(np.abs(lo), np.abs(hi))
    lo, hi = lo - grow_rel, hi + grow_rel
    gap = np.maximum(np.maximum(lo, -hi), 0.0)
    distance = np.sqrt(gap[0] ** 2 + gap[1] ** 2 + gap[2] ** 2) * (1.0 - NEAR_MARGIN)
    # The 8 corners' right, up and back components: the lo corner's plus the extents picked per corner, one
    # small product per component.
    rotation = view.rotation
    base, extent = rotation.T @ lo, hi - lo
    right = base[0] + CORNER_PICK @ (extent * rotation[:, 0:1])
    up = base[1] + CORNER_PICK @ (extent * rotation[:, 1:2])
    depth = -(base[2] + CORNER_PICK @ (extent * rotation[:, 2:3]))
    reach = np.maximum(np.abs(lo), np.abs(hi))
    size = np.sqrt(reach[0] ** 2 + reach[1] ** 2 + reach[2] ** 2)  # at least each corner's distance
    near = depth.min(axis=0) <= NEAR_PLANE * np.maximum(1.0, size)
    inverse = 1.0 / np.where(depth > 0.0, depth, 1.0)
    t = math.tan(math.radians(view.fov_deg) / 2.0)
    aspect = width / height
    # Continuous pixel coordinates i + s, j + s of each corner's image (primary_ray's mapping inverted): the
    # extremes of right / depth and up / depth, scaled once per leaf.
    x, y = right * inverse, up * inverse
    scale_u, scale_v = width / (2.0 * aspect * t), height / (2.0 * t)
    u0, u1 = x.min(axis=0) * scale_u + width / 2.0, x.max(axis=0) * scale_u + width / 2.0
    v0, v1 = height / 2.0 - y.max(axis=0) * scale_v, height / 2.0 - y.min(axis=0) * scale_v
    pad_u = PIXEL_PAD + RANGE_MARGIN * (np.maximum(-u0, u1) + width)
    pad_v = PIXEL_PAD + RANGE_MARGIN * (np.maximum(-v0, v1) + height)
    tiles_x, tiles_y = tile_grid(width, height, log2)
    limit = float(1 << 30)
    i0 = np.clip(np.floor(u0 - pad_u), -1, limit)
    i1 = np.clip(np.floor(u1 + pad_u), -1, limit)
    j0 = np.clip(np.floor(v0 - pad_v), -1, limit)
    j1 = np.clip(np.floor(v1 + pad_v), -1, limit)
    out = np.empty((lo.shape[1], 4), np.int64)
    out[:, 0] = np.clip(i0, 0, width - 1).astype(np.int64) >> log2
    out[:, 1] = np.clip(j0, 0, height - 1).astype(np.int64) >> log2
    out[:, 2] = np.clip(i1, 0, width - 1).astype(np.int64) >> log2
    out[:, 3] = np.clip(j1, 0, height - 1).astype(np.int64) >> log2
    off = (i1 < 0) | (j1 < 0) | (i0 > width - 1) | (j0 > height - 1)
    out[off] = (0, 0, -1, -1)
    out[near] = (0, 0, tiles_x - 1, tiles_y - 1)
    return out, distance


def quad_tiles(
    view: CameraView, width: int, height: int, origin: np.ndarray, corners: np.ndarray, log2: int = TILE_LOG2
) -> np.ndarray:
    """Per tile (row-major), whether one of its primary rays can pass through one of the quads ``corners`` (n, 4,
    3, in order around each quad, camera-relative): each quad's tiles by :func:`leaf_tiles` of its box, less
    those its padded image's edges separate from the tile (a door seen at a slant covers far fewer tiles than
    its box's rect). The image of a quad wholly in front of the camera is the convex hull of its corners'
    images; a quad near the camera plane keeps its rect (every tile)."""
    tiles_x, tiles_y = tile_grid(width, height, log2)
    rects, _ = leaf_tiles(view, width, height, origin, corners.min(axis=1), corners.max(axis=1), log2)
    apex = np.asarray(view.position, dtype=np.float64) - origin
    relative = corners - apex
    local = relative @ view.rotation  # right, up, back
    depth = -local[..., 2]
    reach = np.sqrt(np.einsum("nkc,nkc->nk", relative, relative).max(axis=1))
    near = depth.min(axis=1) <= NEAR_PLANE * np.maximum(1.0, reach)
    t = math.tan(math.radians(view.fov_deg) / 2.0)
    scale_u, scale_v = width / (2.0 * (width / height) * t), height / (2.0 * t)
    safe = np.where(depth > 0.0, depth, 1.0)
    x, y = local[..., 0] / safe, local[..., 1] / safe
    image = np.stack([x * scale_u + width / 2.0, height / 2.0 - y * scale_v], axis=2)  # (n, 4, 2)
    # The pad: leaf_tiles' pixels and margin, and how far the rays' and the quads' rounding (the kernels' pad, the
    # space trees' slack) can move a point of the quad's image, from its nearest corner.
    grow = 2.0 * KERNEL_PAD * max(1.0, math.sqrt(float(apex @ apex))) + SPACE_SLACK * (
        1.0 + np.abs(corners).max(axis=(1, 2))
    )
    slope = 1.0 + np.maximum(np.abs(x), np.abs(y)).max(axis=1)
    pad = PIXEL_PAD + RANGE_MARGIN * (np.abs(image).max(axis=(1, 2)) + width + height)
    pad = pad + 4.0 * grow * max(scale_u, scale_v) * slope / np.where(near, 1.0, depth.min(axis=1))
    # Each edge's outward normal (none for an edge through the centre: a quad seen edge-on keeps its rect).
    edge = np.roll(image, -1, axis=1) - image
    normal = np.stack([edge[..., 1], -edge[..., 0]], axis=2)
    side = np.einsum("nkc,nkc->nk", normal, image.mean(axis=1, keepdims=True) - image)
    normal = np.where((side < 0.0)[..., None], normal, np.where((side > 0.0)[..., None], -normal, 0.0))
    normal[near] = 0.0
    # Every (quad, tile) pair of the rects; a tile is cut off where, for some edge, its nearest corner lies
    # beyond the padded edge.
    w = np.maximum(rects[:, 2] - rects[:, 0] + 1, 0)
    h = np.maximum(rects[:, 3] - rects[:, 1] + 1, 0)
    area = w * h
    quad = np.repeat(np.arange(len(rects)), area)
    down, across = np.divmod(np.arange(len(quad)) - np.repeat(np.cumsum(area) - area, area), np.repeat(w, area))
    tx, ty = rects[quad, 0] + across, rects[quad, 1] + down
    side_px = float(1 << log2)
    # Per edge the bound n . p <= n . q + pad |n| of the padded image; a tile's nearest corner beyond it is cut.
    bound = np.einsum("nkc,nkc->nk", normal, image) + pad[:, None] * np.hypot(normal[..., 0], normal[..., 1])
    n = normal[quad]  # (pairs, 4, 2)
    nearest_x = (tx[:, None] + (n[..., 0] <= 0.0)) * side_px
    nearest_y = (ty[:, None] + (n[..., 1] <= 0.0)) * side_px
    cut = (n[..., 0] * nearest_x + n[..., 1] * nearest_y > bound[quad]).any(axis=1)
    covered = np.zeros(tiles_x * tiles_y, bool)
    covered[(ty * tiles_x + tx)[~cut]] = True
    return covered


def tile_rows(
    ranges: np.ndarray, rows: np.ndarray, distance: np.ndarray, tiles_x: int, tiles: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each tile's rows among those of ``ranges``: the rows and their distances sorted by tile, then nearest
    first, and the count per tile."""
    near_first = np.lexsort((rows, distance))
    ranges, rows, distance = ranges[near_first], rows[near_first], distance[near_first]
    w = np.maximum(ranges[:, 2] - ranges[:, 0] + 1, 0)
    h = np.maximum(ranges[:, 3] - ranges[:, 1] + 1, 0)
    area = w * h
    # Each (leaf, tile) entry: its leaf, its place in the leaf's rect (row-major) and so its tile, with one
    # division for both coordinates and each leaf's values repeated rather than gathered per entry.
    leaf = np.repeat(np.arange(len(rows)), area)
    local = np.arange(len(leaf)) - np.repeat(np.cumsum(area) - area, area)
    down, across = np.divmod(local, np.repeat(w, area))
    tile = np.repeat(ranges[:, 1] * tiles_x + ranges[:, 0], area) + down * tiles_x + across
    # The leaves' order, nearest first, within each tile: a stable sort, a radix sort on 16-bit keys.
    order = np.argsort(tile.astype(np.uint16) if tiles <= 1 << 16 else tile, kind="stable")
    leaf = leaf[order]
    return rows[leaf], distance[leaf], np.bincount(tile, minlength=tiles)


def cut_long(
    part: tuple[np.ndarray, np.ndarray, np.ndarray], instance_max: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A section's rows, bounds and counts without the tiles listing more than ``instance_max``: those tiles'
    rays walk the tree (count -1), as a long list slabs more boxes than its walk."""
    rows, near, counts = part
    long = counts > instance_max
    if not long.any():
        return part
    keep = ~np.repeat(long, np.maximum(counts, 0))
    return rows[keep], near[keep], np.where(long, -1, counts)


def _section(
    view: CameraView,
    width: int,
    height: int,
    origin: np.ndarray,
    rows: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    log2: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One section of the table: the rows whose boxes lo/hi (float64, camera-relative) a tile's rays may enter,
    per tile nearest first, with their distances, and the count per tile."""
    tiles_x, tiles_y = tile_grid(width, height, log2)
    ranges, distance = leaf_tiles(view, width, height, origin, lo, hi, log2)
    return tile_rows(ranges, rows, distance, tiles_x, tiles_x * tiles_y)


def view_tiles(
    view: CameraView,
    width: int,
    height: int,
    origin: np.ndarray,
    portals: tuple[np.ndarray, int] | None = None,
    instances: tuple[TlasLanes, np.ndarray, np.ndarray] | None = None,
    log2: int = TILE_LOG2,
    instance_max: int = 1 << 30,
    legs: tuple[PortalLegs, int] | None = None,
    portal_leaves: np.ndarray | None = None,
) -> np.ndarray:
    """The frame's :data:`engine.layout.VIEW_TILE` table: for each tile the portal rows (``portals``: the
    ``space_nodes`` table and the portals' root) and the instance rows (``instances``: the ``tlas_nodes``
    table's lanes and the instances' exact bounds, camera-relative) its primary rays' first legs may meet; a section
    not asked for is empty. A tile with more than ``instance_max`` instances lists none, its count -1. ``legs``: the
    portal legs' lists (:mod:`engine.portal_legs`) and the number of portal rows, for their slot map;
    ``portal_leaves`` the portal tree's leaves the camera sees where the caller has them
    (:func:`engine.camera_view.seen_leaves`)."""
    tiles_x, tiles_y = tile_grid(width, height, log2)
    tiles = tiles_x * tiles_y
    aspect = width / height
    empty = (np.zeros(0, np.int64), np.zeros(0), np.zeros(tiles, np.int64))
    portal_part = instance_part = empty
    if portals is not None:
        nodes, root = portals
        leaves = seen_leaves(view, aspect, origin, nodes, root) if portal_leaves is None else portal_leaves
        lo, hi = nodes["bounds_min"][leaves].astype(np.float64), nodes["bounds_max"][leaves].astype(np.float64)
        portal_part = _section(view, width, height, origin, nodes["first"][leaves].astype(np.int64), lo, hi, log2)
    if instances is not None:
        tlas, lo, hi = instances
        rows = seen_instances(view, aspect, origin, tlas)
        instance_part = cut_long(_section(view, width, height, origin, rows, lo[rows], hi[rows], log2), instance_max)
    # Each part: where its headers lie, the column of theirs it fills, its rows.
    parts = [(slice(0, tiles), 0, portal_part), (slice(0, tiles), 2, instance_part)]
    slot_rows = 0
    if legs is not None:  # after the tiles' headers the slot map (a row per portal), then the slots' headers
        slot_rows = legs[1] + sum(len(counts) for _, _, counts in legs[0].lists)
        base = tiles + legs[1]
        for part in legs[0].lists:
            parts.append((slice(base, base + len(part[2])), 0, part))
            base += len(part[2])
    table = np.zeros(tiles + slot_rows + sum(len(part[0]) for *_, part in parts), layout.VIEW_TILE_DTYPE)
    entry = table["entry"]
    if legs is not None:
        entry[tiles : tiles + legs[1]] = (-1, 0, 0, 0)
        for row, (x0, y0, x1, y1), (heads, _, _) in zip(legs[0].rows, legs[0].rects, parts[2:], strict=True):
            entry[tiles + row] = (heads.start, x0 | (x1 << 16), y0 | (y1 << 16), 0)
    start = tiles + slot_rows
    for heads, column, (rows, near, counts) in parts:
        listed = np.maximum(counts, 0)
        entry[heads, column] = start + np.cumsum(listed) - listed
        entry[heads, column + 1] = counts
        entry[start : start + len(rows), 0] = rows
        entry[start : start + len(rows), 1] = near.astype(np.float32).view(np.int32)
        start += len(rows)
    return table
