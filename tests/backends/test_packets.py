"""Camera rays eight at a time on OpenCL (PACKET_PRIMARY, backends/opencl/packet.cl): a float Euclidean frame
without shadows traces each 4x2 block of pixels in one work-item, and its frames are those of one ray a
work-item to the bit, in every AOV: images whose size is no multiple of the block, a scene of one instance (no
tiles' lists) and of many (the lists), cameras inside instances' bounds and turned at random, back faces culled,
sample offsets; the frames that do not qualify (double precision, shadows, portals, boxes) keep one ray a
work-item."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scenes import many_instances
from test_parity import render
from test_space_trees import same_frames

from backends.opencl.packets import packet_frame
from engine.camera_view import scene_camera
from engine.scene import Scene

SIZES = ((61, 37), (4, 2), (5, 3), (72, 54))
SCALAR = {"PACKET_PRIMARY": 0}


def one_mesh() -> Scene:
    """One instance (its search culls it by its bounds, no tiles): a turned sphere filling most of the view."""
    scene = Scene("one-sphere")
    scene.add_mesh("ball", "sphere", euler_deg=(60.0, 10.0, 0.0), scale=(3.0, 2.2, 2.6), checker=0.2)
    scene.set_camera((0.0, 0.3, 2.6), look_at=(0.0, 0.0, 0.0), fov_deg=60.0)
    return scene


def culled_crowd() -> Scene:
    """Many instances (the tiles' lists), half of them culling back faces, a camera inside some of their bounds."""
    scene = many_instances(7, 60)
    for k in range(0, 60, 2):
        scene.add_mesh(f"c{k}", "box", position=(0.3 * k - 9.0, 1.0, 0.5 * (k % 7)), scale=1.3, cull_backfaces=True)
    scene.set_camera((0.2, 1.1, 0.4), look_at=(3.0, 0.8, -4.0), fov_deg=95.0)
    return scene


def on_and_off(backend, scene: Scene, size: tuple[int, int], off: dict[str, int], used=lambda b: b.last_frame_packets):
    """The scene's frame as the backend chooses and with the ``off`` extra defines, and what ``used`` reads of the
    backend after each."""
    backend.extra_defines = {}
    chosen = render(backend, scene, size)
    chosen_used = used(backend)
    backend.extra_defines = dict(off)
    other = render(backend, scene, size)
    other_used = used(backend)
    backend.extra_defines = {}
    return chosen, other, chosen_used, other_used


def packets_and_rays(backend, scene: Scene, size: tuple[int, int]):
    """The scene's frame in packets and with one ray a work-item, and whether the first used packets."""
    packed, single, used, single_used = on_and_off(backend, scene, size, SCALAR)
    assert not single_used
    return packed, single, used


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("build", [one_mesh, culled_crowd])
def test_packets_give_the_single_rays_frames(backend_factory, build, size):
    backend = backend_factory("opencl", "f32")
    scene = build()
    try:
        packed, single, used = packets_and_rays(backend, scene, size)
        assert used
        same_frames(packed, single)
        assert (packed.instance >= 0).any()
    finally:
        backend.extra_defines = {}
        scene.close()


def test_packets_from_random_cameras_and_sample_offsets(backend_factory):
    backend = backend_factory("opencl", "f32")
    rng = np.random.default_rng(11)
    scene = culled_crowd()
    lo, hi = np.array([-10.0, 0.2, -10.0]), np.array([10.0, 5.0, 10.0])
    try:
        for _ in range(5):
            scene.set_camera(tuple(rng.uniform(lo, hi)), look_at=tuple(rng.uniform(lo, hi)), fov_deg=80.0)
            packed, single, used = packets_and_rays(backend, scene, (45, 29))
            assert used
            same_frames(packed, single)
        camera = scene_camera(scene)
        for subpixel in ((0.1, 0.9), (0.73, 0.27)):
            shifted = replace(camera, subpixel=subpixel)
            backend.extra_defines = {}
            a = backend.render(shifted, 45, 29)
            backend.extra_defines = dict(SCALAR)
            b = backend.render(shifted, 45, 29)
            same_frames(a, b)
    finally:
        backend.extra_defines = {}
        scene.close()


@pytest.mark.parametrize("change", ["f64", "shadows", "portal", "box"])
def test_frames_that_do_not_qualify_keep_one_ray_a_work_item(backend_factory, change):
    backend = backend_factory("opencl", "f64" if change == "f64" else "f32")
    scene = one_mesh()
    if change == "shadows":
        scene.add_light("sun", look_at=(0.3, -1.0, -0.2), shadows=True)
    if change == "portal":
        scene.add_portal_pair("pa", "pb", a=dict(position=(0.0, 0.0, 1.0)), b=dict(position=(30.0, 0.0, 0.0)))
    if change == "box":
        scene.add_aberration("lens", (0.2, 0.0, 0.0), position=(0.0, 0.0, 0.5), scale=(1.0, 1.0, 1.0))
    try:
        render(backend, scene, (16, 12))
        assert not backend.last_frame_packets
    finally:
        scene.close()


def test_the_rule_names_every_condition():
    qualifying = {
        "REAL_IS_DOUBLE": 0, "BVH_WIDTH": 8, "INSTANCE_TILES_ONLY": 1, "INSTANCE_TILES": 1, "VIEW_TILE_LOG2": 3,
        "HAS_PORTALS": 0, "HAS_ABERRATIONS": 0, "HAS_SHADOWS": 0, "EDGE_FALLBACK_FP64": 0, "USE_TLAS": 1,
    }  # fmt: skip
    assert packet_frame(qualifying)
    assert not packet_frame(qualifying, wanted=0)
    one = {**qualifying, "INSTANCE_TILES_ONLY": 0, "INSTANCE_TILES": 0, "USE_TLAS": 0}
    assert packet_frame(one)
    for key, value in [
        ("REAL_IS_DOUBLE", 1), ("BVH_WIDTH", 4), ("HAS_PORTALS", 1), ("HAS_ABERRATIONS", 1), ("HAS_SHADOWS", 1),
        ("EDGE_FALLBACK_FP64", 1), ("BRUTE_FORCE", 1), ("VIEW_TILE_LOG2", 1),
    ]:  # fmt: skip
        assert not packet_frame({**qualifying, key: value}), key
    assert not packet_frame({**one, "USE_TLAS": 1})
