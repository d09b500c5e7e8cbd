"""The view tiles (engine/view_tiles.py): every portal a primary ray's first leg passes through, and every
instance whose bounds it enters, is in the list of that ray's tile, no nearer than the distance stored beside
it, for random scenes and cameras (in front of many portals or instances, near and inside their leaves or
bounds, boxes across the camera plane, any subpixel point)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scenes import crowded, many_instances

from backends.reference.directions import affine_points, linear_vectors
from engine.box_clearance import instance_bounds
from engine.camera_view import CameraView, boxes_seen, seen_leaves, view_planes, view_reaches
from engine.maths import quat_to_matrix
from engine.packing import ScenePacker
from engine.portal_legs import quad_corners
from engine.tlas_wide import TlasLanes
from engine.view_tiles import leaf_tiles, quad_tiles, tile_grid, view_tiles


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return quat_to_matrix(tuple(q / np.linalg.norm(q)))


def first_leg_hits(
    view: CameraView, width: int, height: int, origin: np.ndarray, portals: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every (pixel, portal row) whose primary ray passes through the linked quad at t > 0, and its t: the
    reference's portal test, each quad against every ray."""
    o = view.position - origin
    r = view.primary_directions(width, height).reshape(-1, 3)
    pixels, rows, ts = [], [], []
    with np.errstate(all="ignore"):
        for row, portal in enumerate(portals):
            if portal["meta"][0] < 0:
                continue
            m = portal["world_to_local"].astype(np.float64).reshape(3, 4)
            a, v = affine_points(m, np.broadcast_to(o, r.shape)), linear_vectors(m, r)
            t = -a[:, 2] / np.where(v[:, 2] != 0.0, v[:, 2], np.nan)
            x, y = a[:, 0] + t * v[:, 0], a[:, 1] + t * v[:, 1]
            hit = np.flatnonzero((t > 0.0) & (np.abs(x) <= 1.0) & (np.abs(y) <= 1.0))
            pixels.append(hit)
            rows.append(np.full(len(hit), row))
            ts.append(t[hit])
    return np.stack([np.concatenate(pixels), np.concatenate(rows)]), np.concatenate(ts)


def tree_leaves(nodes: np.ndarray, root: int) -> np.ndarray:
    """Every leaf of the tree from ``root``."""
    stack, leaves = [root], []
    while stack:
        node = stack.pop()
        if nodes["count"][node] > 0:
            leaves.append(node)
        else:
            stack += [int(nodes["first"][node]), int(nodes["first"][node]) + 1]
    return np.array(leaves, np.int64)


def check_tiles(view: CameraView, width: int, height: int, origin: np.ndarray, packed) -> int:
    """Asserts that every first-leg hit of the frame is in its tile's list; returns how many hits there were."""
    nodes, root = packed.tables["space_nodes"], int(packed.tables["settings"]["space_roots"][0][0])
    portals = packed.tables["portals"][: packed.counts["portals"]]
    table = view_tiles(view, width, height, origin, portals=(nodes, root))
    entry = table["entry"]
    (pixels, rows), t = first_leg_hits(view, width, height, origin, portals)
    tiles_x, _ = tile_grid(width, height)
    j, i = pixels // width, pixels % width
    tile = (j >> 3) * tiles_x + (i >> 3)
    for p, row, tile_k, t_k in zip(pixels, rows, tile, t, strict=True):
        first, count = entry[tile_k, 0], entry[tile_k, 1]
        listed = entry[first : first + count]
        where = np.flatnonzero(listed[:, 0] == row)
        assert where.size == 1, f"pixel {p}: portal {row} missing from tile {tile_k}"
        near = listed[where[0], 1:2].view(np.float32)[0]
        assert near <= t_k, f"pixel {p}: portal {row} at t {t_k} listed at {near}"
        assert np.all(np.diff(listed[:, 1].view(np.float32)) >= 0.0)  # nearest first
    return len(t)


@pytest.mark.parametrize("seed", range(6))
def test_every_first_leg_portal_is_in_its_tiles_list(seed: int) -> None:
    rng = np.random.default_rng(seed)
    scene = crowded("portals", 60, seed=seed)
    packer = ScenePacker("f32")
    packer.sync(scene)
    packed = packer.packed
    origin = np.asarray(packed.origin, dtype=np.float64)
    nodes, root = packed.tables["space_nodes"], int(packed.tables["settings"]["space_roots"][0][0])
    leaves = np.flatnonzero(nodes["count"][: len(nodes)] == 1)
    leaves = leaves[leaves < 2 * packed.counts["portals"]]
    hits = 0
    for k in range(8):
        width, height = (int(rng.integers(17, 90)), int(rng.integers(17, 90)))
        if k % 2:  # inside or beside a leaf: it straddles the camera plane or fills the view
            leaf = int(rng.choice(leaves))
            lo, hi = nodes["bounds_min"][leaf].astype(np.float64), nodes["bounds_max"][leaf].astype(np.float64)
            position = origin + lo + rng.uniform(-0.2, 1.2, 3) * (hi - lo)
        else:
            position = np.array([rng.uniform(-5.0, 5.0), rng.uniform(0.2, 3.5), rng.uniform(-2.0, 8.0)])
        rotation = random_rotation(rng)
        if k % 4 == 0:  # looking into the crowd from the camera of the scene
            forward = np.array([0.0, 1.0, -3.0]) - position
            forward /= np.linalg.norm(forward)
            right = np.cross(forward, [0.0, 1.0, 0.0])
            right /= np.linalg.norm(right)
            rotation = np.stack([right, np.cross(right, forward), -forward], axis=1)
        view = CameraView(position, rotation, float(rng.uniform(20.0, 120.0)), tuple(rng.uniform(0.0, 1.0, 2)))
        hits += check_tiles(view, width, height, origin, packed)
        leaves_seen = seen_leaves(view, width / height, origin, nodes, root)
        assert bool(leaves_seen.size) == view_reaches(view, width / height, origin, nodes, root)
        # The walk (which skips every other level) finds exactly the tree's leaves whose boxes are seen.
        every = tree_leaves(nodes, root)
        lo, hi = nodes["bounds_min"][every].astype(np.float64), nodes["bounds_max"][every].astype(np.float64)
        flat = every[boxes_seen(view_planes(view, width / height), view.position - origin, lo, hi)]
        assert np.array_equal(np.sort(leaves_seen), np.sort(flat))
    assert hits > 0


def test_a_leaf_across_the_camera_plane_covers_every_tile() -> None:
    scene = crowded("portals", 20, seed=3)
    packer = ScenePacker("f32")
    packer.sync(scene)
    packed = packer.packed
    origin = np.asarray(packed.origin, dtype=np.float64)
    nodes, root = packed.tables["space_nodes"], int(packed.tables["settings"]["space_roots"][0][0])
    leaf = int(np.flatnonzero(nodes["count"] == 1)[0])
    lo, hi = nodes["bounds_min"][leaf].astype(np.float64), nodes["bounds_max"][leaf].astype(np.float64)
    view = CameraView(origin + 0.5 * (lo + hi), np.eye(3), 60.0)
    table = view_tiles(view, 40, 30, origin, portals=(nodes, root))
    tiles = math.prod(tile_grid(40, 30))
    entry = table["entry"]
    for k in range(tiles):
        first, count = entry[k, 0], entry[k, 1]
        assert int(nodes["first"][leaf]) in entry[first : first + count, 0]


def check_instance_tiles(view: CameraView, width: int, height: int, packed) -> int:
    """Asserts that every instance whose exact bounds a primary ray enters (t > 0, the kernels' cull before
    any triangle) is in its tile's list, no nearer than the distance stored beside it; returns how many."""
    origin = np.asarray(packed.origin, dtype=np.float64)
    lo, hi = instance_bounds(packed)
    table = view_tiles(view, width, height, origin, instances=(TlasLanes.of(packed.tables["tlas_nodes"]), lo, hi))
    entry = table["entry"]
    o = view.position - origin
    r = view.primary_directions(width, height).reshape(-1, 3)
    with np.errstate(all="ignore"):
        t0, t1 = (lo[:, None] - o) / r[None], (hi[:, None] - o) / r[None]  # (instances, pixels, 3)
        enter = np.nanmax(np.minimum(t0, t1), axis=2)
        leave = np.nanmin(np.maximum(t0, t1), axis=2)
    rows, pixels = np.nonzero((leave >= np.maximum(enter, 0.0)) & (leave > 0.0))
    tiles_x, _ = tile_grid(width, height)
    tile = (pixels // width >> 3) * tiles_x + (pixels % width >> 3)
    for row, p, tile_k in zip(rows, pixels, tile, strict=True):
        first, count = entry[tile_k, 2], entry[tile_k, 3]
        listed = entry[first : first + count]
        where = np.flatnonzero(listed[:, 0] == row)
        assert where.size == 1, f"pixel {p}: instance {row} missing from tile {tile_k}"
        near = listed[where[0], 1:2].view(np.float32)[0]
        assert near <= max(enter[row, p], 0.0), (
            f"pixel {p}: instance {row} entered at {enter[row, p]}, listed at {near}"
        )
        assert np.all(np.diff(listed[:, 1].view(np.float32)) >= 0.0)  # nearest first
    return len(rows)


@pytest.mark.parametrize(("seed", "width"), [(0, 2), (1, 2), (2, 4), (3, 8), (4, 8)])
def test_every_instance_a_primary_ray_enters_is_in_its_tiles_list(seed: int, width: int) -> None:
    """Random scenes of many instances (binary, 4- and 8-wide trees), cameras among them and inside their
    bounds (boxes across the camera plane), any field of view and subpixel point."""
    rng = np.random.default_rng(100 + seed)
    packer = ScenePacker("f32", tlas_width=width)
    packer.sync(many_instances(seed, 120))
    packed = packer.packed
    lo, hi = instance_bounds(packed)
    origin = np.asarray(packed.origin, dtype=np.float64)
    hits = 0
    for k in range(6):
        size = (int(rng.integers(17, 70)), int(rng.integers(17, 70)))
        if k % 2:  # inside or beside an instance's bounds
            row = int(rng.integers(len(lo)))
            position = origin + lo[row] + rng.uniform(-0.2, 1.2, 3) * (hi[row] - lo[row])
        else:
            position = rng.uniform([-10.0, 0.2, -10.0], [10.0, 5.0, 10.0])
        view = CameraView(position, random_rotation(rng), float(rng.uniform(20.0, 120.0)), tuple(rng.uniform(0, 1, 2)))
        hits += check_instance_tiles(view, *size, packed)
    assert hits > 0


def test_a_tile_with_too_many_instances_lists_none() -> None:
    """Past ``instance_max`` a tile's count is -1 (its rays walk the tree) and its rows are not stored."""
    packer = ScenePacker("f32", tlas_width=8)
    packer.sync(many_instances(7, 200))
    packed = packer.packed
    lo, hi = instance_bounds(packed)
    view = CameraView(np.array([0.0, 2.0, 20.0]), np.eye(3), 60.0)
    lanes = TlasLanes.of(packed.tables["tlas_nodes"])
    full = view_tiles(view, 64, 48, packed.origin, instances=(lanes, lo, hi))["entry"]
    capped = view_tiles(view, 64, 48, packed.origin, instances=(lanes, lo, hi), instance_max=8)["entry"]
    tiles = math.prod(tile_grid(64, 48))
    long = full[:tiles, 3] > 8
    assert long.any() and not long.all()
    assert np.array_equal(capped[:tiles, 3], np.where(long, -1, full[:tiles, 3]))
    assert len(capped) == tiles + int(full[:tiles, 3][~long].sum())
    for k in np.flatnonzero(~long):
        a, b = full[k, 2], capped[k, 2]
        assert np.array_equal(full[a : a + full[k, 3]], capped[b : b + capped[k, 3]])


@pytest.mark.parametrize("seed", range(4))
def test_every_first_leg_portal_hit_lies_in_a_tile_its_quad_covers(seed: int) -> None:
    """quad_tiles, which tells OpenCL's frames which tiles no portal can reach: every pixel whose primary ray
    passes through a quad lies in a tile marked covered, from cameras among the portals, beside and inside
    their boxes and turned at random; and it marks fewer tiles than the quads' box rects do."""
    rng = np.random.default_rng(40 + seed)
    scene = crowded("portals", 60, seed=seed)
    packer = ScenePacker("f32")
    packer.sync(scene)
    packed = packer.packed
    origin = np.asarray(packed.origin, dtype=np.float64)
    portals = packed.tables["portals"][: packed.counts["portals"]]
    corners = quad_corners(portals["world_to_local"].astype(np.float64))
    hits = tighter = 0
    for k in range(10):
        width, height = (int(rng.integers(17, 90)), int(rng.integers(17, 90)))
        if k % 2:  # beside or on a quad
            quad = corners[int(rng.integers(len(corners)))]
            position = origin + quad.mean(axis=0) + rng.normal(scale=0.3, size=3)
        else:
            position = np.array([rng.uniform(-5.0, 5.0), rng.uniform(0.2, 3.5), rng.uniform(-2.0, 8.0)])
        view = CameraView(position, random_rotation(rng), float(rng.uniform(20.0, 120.0)), tuple(rng.uniform(0, 1, 2)))
        (pixels, rows), _ = first_leg_hits(view, width, height, origin, portals)
        tiles_x, _ = tile_grid(width, height)
        tile = (pixels // width >> 3) * tiles_x + (pixels % width >> 3)
        covered = quad_tiles(view, width, height, origin, corners)
        assert covered[tile].all(), f"camera {k}: a portal hit in a tile marked free"
        hits += len(pixels)
        rects, _ = leaf_tiles(view, width, height, origin, corners.min(axis=1), corners.max(axis=1), 3)
        for q, (x0, y0, x1, y1) in enumerate(rects):  # each quad's tiles within its box's rect
            alone = quad_tiles(view, width, height, origin, corners[q : q + 1])
            assert alone[tile[rows == q]].all(), f"camera {k}: a hit of portal {q} in a tile marked free"
            alone = alone.reshape(-1, tiles_x)
            rect = np.zeros_like(alone)
            rect[y0 : y1 + 1, x0 : x1 + 1] = True
            assert not (alone & ~rect).any()
            tighter += int((rect & ~alone).sum())
    assert hits > 0 and tighter > 0
