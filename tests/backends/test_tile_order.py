"""A frame with portals on OpenCL traces the view tiles whose camera rays meet no portal with its Euclidean
variant, in packets, and the others with its own (TILE_ORDER, backends/opencl/tile_order.py): its frames are
those of one launch over the image to the bit, in every AOV, from cameras among many doors and instances
turned at random, at image sizes that are no multiple of a tile; frames with shadows, boxes or double
precision keep one launch."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import many_instances
from test_packets import on_and_off
from test_parity import render
from test_space_trees import same_frames

from backends.opencl.tile_order import TILE_PIXELS, items_per_tile, tile_order
from backends.shared import INSTANCE_TILE_MIN_BESIDE
from engine.scene import Scene

ONE_LAUNCH = {"TILE_ORDER": 0}
SIZES = ((72, 54), (61, 37), (5, 3))


def doors(seed: int) -> Scene:
    """A floor, enough instances for the tiles' lists beside the portal tree, and twelve doors on a row, each
    opening onto a place across the scene, some turned, some scaled."""
    scene = many_instances(seed, INSTANCE_TILE_MIN_BESIDE + 16)
    for k in range(12):
        scene.add_portal_pair(
            f"a{k}", f"b{k}",
            a=dict(position=(1.6 * k - 9.0, 1.5, 3.0), scale=(0.6, 1.0, 1.0)),
            b=dict(position=(7.0 - 1.3 * k, 1.2, -6.0), euler_deg=(0.0, 30.0 * k, 0.0), scale=(0.6, 1.0, 1.0)),
        )  # fmt: skip
    scene.set_camera((0.0, 1.8, 12.0), look_at=(0.0, 1.2, 0.0), fov_deg=70.0)
    return scene


def both_ways(backend, scene: Scene, size: tuple[int, int]):
    """The frame by tiles and in one launch, and the tile launches' rows of the first (None: one launch)."""
    split, whole, launches, whole_launches = on_and_off(backend, scene, size, ONE_LAUNCH, lambda b: b.last_frame_tiles)
    assert whole_launches is None
    return split, whole, launches


@pytest.mark.parametrize("size", SIZES)
def test_tiles_without_doors_give_the_one_launchs_frames(backend_factory, size):
    backend = backend_factory("opencl", "f32")
    rng = np.random.default_rng(3)
    scene = doors(4)
    cameras = [((0.0, 1.8, 12.0), (0.0, 1.2, 0.0)), ((-9.0, 1.5, 6.0), (-9.0, 1.5, 2.0))]
    cameras += [((-12.0, 1.6, 3.4), (10.0, 1.4, 2.9)), ((-11.0, 1.5, 3.05), (10.0, 1.5, 3.0))]  # along the doors
    lo, hi = np.array([-10.0, 0.5, 4.0]), np.array([10.0, 4.0, 14.0])
    cameras += [(tuple(rng.uniform(lo, hi)), (float(rng.uniform(-8.0, 8.0)), 1.5, 3.0)) for _ in range(3)]
    try:
        used, through = [], 0
        for position, look_at in cameras:
            scene.set_camera(position, look_at=look_at, fov_deg=float(rng.uniform(50.0, 100.0)))
            split, whole, launches = both_ways(backend, scene, size)
            same_frames(split, whole)
            used.append(launches is not None)
            through += int((whole.events > 0).sum())
        assert through > 0  # some rays went through the doors
        assert sum(used) >= 3 if size[0] >= 8 else True
    finally:
        scene.close()


def test_the_launches_split_the_tiles(backend_factory):
    backend = backend_factory("opencl", "f32")
    scene = doors(5)
    try:
        render(backend, scene, (72, 54))
        launches = backend.last_frame_tiles
        assert launches is not None and backend.last_frame_packets
        free, rest = launches
        assert free > 0 and rest > 0
        assert free + rest >= 9 * 7  # every tile once, each part padded to whole work-groups
    finally:
        scene.close()


@pytest.mark.parametrize("change", ["f64", "shadows", "box", "no doors in view"])
def test_frames_that_cannot_split_keep_one_launch(backend_factory, change):
    backend = backend_factory("opencl", "f64" if change == "f64" else "f32")
    scene = doors(6)
    if change == "shadows":
        scene.add_light("sun", look_at=(0.3, -1.0, -0.2), shadows=True)
    if change == "box":
        scene.add_aberration("lens", (0.2, 0.0, 0.0), position=(0.0, 1.0, 8.0), scale=(1.0, 1.0, 1.0))
    if change == "no doors in view":
        scene.set_camera((0.0, 1.8, 12.0), look_at=(0.0, 1.2, 30.0))
    try:
        render(backend, scene, (32, 24))
        assert backend.last_frame_tiles is None
    finally:
        scene.close()


def test_the_order_pads_each_part_to_whole_groups():
    order, launches = tile_order([(np.array([3, 5, 9]), True), (np.array([0, 1, 2, 4, 6]), False)], 256)
    packets, rays = launches
    assert (packets.items, rays.items) == (items_per_tile(True), TILE_PIXELS) == (8, 64)
    assert (packets.group, rays.group) == (32, 4)
    assert (packets.offset, packets.rows, rays.offset, rays.rows) == (0, 32, 32, 8)
    assert list(order[:3]) == [3, 5, 9] and (order[3:32] == -1).all()
    assert list(order[32:37]) == [0, 1, 2, 4, 6] and (order[37:] == -1).all()
    assert rays.global_offset == (0, 32) and rays.local_size == (64, 4)
    order, launches = tile_order([(np.array([7]), False)], None)
    assert list(order) == [7] and launches[0].local_size is None and launches[0].rows == 1
