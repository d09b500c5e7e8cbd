"""The first leg of a camera ray takes its instances from its view tile's list where asked for
(engine/view_tiles.py, INSTANCE_TILES=1): the frames are the instance tree's to the bit, from cameras among
many instances, inside their bounds and turned at random; with portals and boxes in the scene, with shadows
(their rays keep the tree), with tiles too full to list; with a box holding the camera the tiles are not
used, nor with fewer than INSTANCE_TILE_MIN instances."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import many_instances
from test_parity import render
from test_space_trees import SIZE, TREES_AND_LOOPS, same_frames

from backends.shared import INSTANCE_TILE_MIN, INSTANCE_TILE_MIN_BESIDE
from engine.camera_view import pack_camera, scene_camera

#: Frames with the instances' lists, without them, with every tile of over 3 on the tree (where the tree is
#: compiled in), with the tree compiled in where the lists could serve alone, and with the first leg's list
#: searched inside the event loop (beside portals and boxes) rather than before it, and (GLSL) in one dispatch
#: rather than two.
ON = {"INSTANCE_TILES": 1}
VARIANTS: tuple[dict[str, int], ...] = (
    ON,
    {"INSTANCE_TILES": 0},
    {**ON, "INSTANCE_TILE_MAX": 3},
    {**ON, "INSTANCE_TILES_ONLY": 0, "INSTANCE_TILE_MAX": 3},
    {**ON, "FIRST_LEG_APART": 0},
    {**ON, "SPLIT_PASSES": 0},
)


def frame_tiles(backend, scene, defines: dict[str, int]):
    """The view tiles the backend's frame of the scene's camera takes with ``defines`` as its extra ones."""
    backend.extra_defines = dict(defines)
    view = scene_camera(scene)
    row = pack_camera(
        view, backend._origin, backend.precision, *SIZE, backend._boxes, backend._bounds, backend._box_tree
    )
    tiles = backend._frame_view_tiles(view, *SIZE, backend._frame_features(view, *SIZE), row)
    backend.extra_defines = {}
    return tiles


def instance_tiles_used(backend, scene) -> bool:
    """Whether the backend's frame of the scene's camera reads the instances' lists (when asked for)."""
    tiles = frame_tiles(backend, scene, ON)
    return tiles is not None and tiles.instances


def lists_alone(backend, scene) -> bool:
    """Whether the lists serve every mesh search of the frame (a Euclidean one without shadows)."""
    tiles = frame_tiles(backend, scene, ON)
    return tiles is not None and tiles.instances_only


def frames_agree(backend, scene) -> None:
    """The scene's frame under every variant is the first one's."""
    frames = []
    for defines in VARIANTS:
        backend.extra_defines = dict(defines)
        frames.append(render(backend, scene, SIZE))
    backend.extra_defines = {}
    for other in frames[1:]:
        same_frames(frames[0], other)


@pytest.mark.parametrize(("backend_name", "precision"), TREES_AND_LOOPS)
def test_instance_tiles_give_the_trees_frames(backend_factory, backend_name, precision):
    backend = backend_factory(backend_name, precision)
    rng = np.random.default_rng(5)
    scene = many_instances(3, 80)
    scene.add_portal_pair(
        "pa", "pb", a=dict(position=(-3.0, 1.5, 4.0), scale=(1.5, 1.5, 1.0)),
        b=dict(position=(40.0, 1.5, 4.0), euler_deg=(0.0, 90.0, 0.0), scale=(1.5, 1.5, 1.0)),
    )  # fmt: skip
    scene.add_aberration("held", (0.2, 0.0, 0.0), position=(30.0, 1.0, 30.0), scale=(4.0, 4.0, 4.0))
    lo, hi = np.array([-10.0, 0.2, -10.0]), np.array([10.0, 5.0, 10.0])
    cameras = [((0.0, 1.8, 12.0), (0.0, 1.0, 0.0)), ((30.0, 1.0, 30.0), (0.0, 1.0, -3.0))]
    cameras += [(tuple(rng.uniform(lo, hi)), tuple(rng.uniform(lo, hi))) for _ in range(4)]
    try:
        used = []
        for shadows in (False, True):
            if shadows:
                scene.add_light("sun", look_at=(0.3, -1.0, -0.2), shadows=True)
            for position, look_at in cameras:
                scene.set_camera(position, look_at=look_at, fov_deg=float(rng.uniform(40.0, 100.0)))
                frames_agree(backend, scene)
                used.append(instance_tiles_used(backend, scene))
        assert used[0] and not used[1] and sum(used) >= 8
    finally:
        backend.extra_defines = {}
        scene.close()


@pytest.mark.parametrize(("backend_name", "precision"), TREES_AND_LOOPS[1:2])
def test_few_instances_keep_the_tree(backend_factory, backend_name, precision):
    backend = backend_factory(backend_name, precision)
    scene = many_instances(4, INSTANCE_TILE_MIN - 2)
    try:
        render(backend, scene, SIZE)
        assert not instance_tiles_used(backend, scene)
        scene.add_mesh("more", "box", position=(0.0, 1.0, 0.0))
        scene.add_mesh("most", "box", position=(1.0, 1.0, 0.0))
        render(backend, scene, SIZE)
        assert instance_tiles_used(backend, scene)
    finally:
        scene.close()


@pytest.mark.parametrize(("backend_name", "precision"), TREES_AND_LOOPS)
def test_the_lists_alone_give_the_trees_frames(backend_factory, backend_name, precision):
    """A Euclidean frame without shadows: every search takes its tile's list, the tree compiled out."""
    backend = backend_factory(backend_name, precision)
    rng = np.random.default_rng(9)
    scene = many_instances(6, 150)
    lo, hi = np.array([-10.0, 0.2, -10.0]), np.array([10.0, 5.0, 10.0])
    try:
        for _ in range(4):
            scene.set_camera(tuple(rng.uniform(lo, hi)), look_at=tuple(rng.uniform(lo, hi)), fov_deg=70.0)
            frames_agree(backend, scene)
            assert lists_alone(backend, scene)
        scene.add_light("sun", look_at=(0.3, -1.0, -0.2), shadows=True)
        frames_agree(backend, scene)
        assert instance_tiles_used(backend, scene) and not lists_alone(backend, scene)
    finally:
        scene.close()


def default_tiles_used(backend, scene, legs: bool = True) -> bool:
    """Whether the backend's frame reads the instances' lists as it chooses, asked nothing (or, ``legs`` False,
    only for the portal legs off)."""
    tiles = frame_tiles(backend, scene, {} if legs else {"PORTAL_LEGS": 0})
    return tiles is not None and tiles.instances


def test_glsl_lists_stay_off_beside_a_box_or_looped_portals(backend_factory):
    """By default GLSL lists instances in Euclidean frames and beside the portal tree over a deep instance tree
    only: beside boxes, a few (looped) portals or a shallow tree the lists' second copy of the instance code
    costs every llvmpipe lane more than it saves (beside a few portals the portal legs' lists may serve alone,
    tests/backends/test_portal_leg_frames.py)."""
    backend = backend_factory("glsl", "f32")
    scene = many_instances(3, INSTANCE_TILE_MIN_BESIDE - 8)
    scene.set_camera((0.0, 1.8, 12.0), look_at=(0.0, 1.0, 0.0))
    try:
        render(backend, scene, SIZE)
        assert default_tiles_used(backend, scene)
        scene.add_portal_pair("pa", "pb", a=dict(position=(-3.0, 1.5, 4.0)), b=dict(position=(40.0, 1.5, 4.0)))
        render(backend, scene, SIZE)
        assert not backend._space["PORTAL_TREE"] and not default_tiles_used(backend, scene, legs=False)
        tiles = frame_tiles(backend, scene, {})  # ... unless the portal legs' lists serve every search alone
        assert tiles is not None and tiles.portal_legs and tiles.instances_only
        for k in range(12):  # enough portals for their tree
            scene.add_portal_pair(f"qa{k}", f"qb{k}", a=dict(position=(k - 6.0, 1.5, 2.0), scale=(0.3, 0.3, 1.0)),
                                  b=dict(position=(k - 6.0, 1.5, 60.0), scale=(0.3, 0.3, 1.0)))  # fmt: skip
        render(backend, scene, SIZE)
        assert backend._space["PORTAL_TREE"] and not default_tiles_used(backend, scene)  # a shallow tree
        for k in range(8):
            scene.add_mesh(f"more{k}", "box", position=(k - 4.0, 0.5, -8.0), scale=(0.4, 0.4, 0.4))
        render(backend, scene, SIZE)
        assert backend._space["PORTAL_TREE"] and default_tiles_used(backend, scene)
        scene.add_aberration("box", (0.2, 0.0, 0.0), position=(30.0, 1.0, 30.0), scale=(4.0, 4.0, 4.0))
        render(backend, scene, SIZE)
        assert not default_tiles_used(backend, scene)
        assert instance_tiles_used(backend, scene)  # asked for, they serve beside the box too
    finally:
        backend.extra_defines = {}
        scene.close()
