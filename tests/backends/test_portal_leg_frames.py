"""The leg after a camera ray's first portal takes its instances from the portal legs' lists (PORTAL_LEGS,
engine/portal_legs.py) where they prove every mesh search a first or second leg with its list: the tree's walk
and the later legs' portal search compiled out, the frames are the tree's to the bit. On the bench scene from
cameras about its own and on a portal pair seen at a slant; where a second leg may meet another portal, or with
shadows, they are not used."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_instance_tiles import frame_tiles
from test_parity import render
from test_space_trees import SIZE, same_frames

from aberrant.bench.scenes import ten_boxes, ten_boxes_portals
from engine.camera_view import scene_camera

OFF = {"PORTAL_LEGS": 0}
VARIANTS: tuple[dict[str, int], ...] = ({}, OFF, {"PORTAL_LEGS_FREE": 0}, {"INSTANCE_TILES_ONLY": 0})


def legs_used(backend, scene) -> bool:
    tiles = frame_tiles(backend, scene, {})
    return tiles is not None and tiles.portal_legs and tiles.portal_legs_free and tiles.instances_only


def frames_agree(backend, scene) -> None:
    frames = []
    for defines in VARIANTS:
        backend.extra_defines = dict(defines)
        frames.append(render(backend, scene, SIZE))
    backend.extra_defines = {}
    for other in frames[1:]:
        same_frames(frames[0], other)


def test_the_bench_doors_legs_give_the_trees_frames(backend_factory, tmp_path: Path):
    backend = backend_factory("glsl", "f32")
    rng = np.random.default_rng(11)
    scene = ten_boxes_portals(tmp_path)
    base = scene_camera(scene)
    forward = -base.rotation[:, 2]
    try:
        used = []
        for k in range(4):
            position = base.position + (rng.uniform([-0.4, -0.3, 0.0], [0.4, 0.3, 1.5]) if k else 0.0)
            scene.set_camera(tuple(position), look_at=tuple(position + forward), fov_deg=base.fov_deg)
            frames_agree(backend, scene)
            used.append(legs_used(backend, scene))
        assert used[0] and sum(used) >= 2  # the others see past the door: not used, the same frames
        scene.add_light("sun", look_at=(0.3, -1.0, -0.2), shadows=True)
        frames_agree(backend, scene)
        assert not legs_used(backend, scene)
    finally:
        backend.extra_defines = {}
        scene.close()


@pytest.mark.parametrize("back", [False, True])
def test_a_slanted_pair_gives_the_trees_frames(backend_factory, tmp_path: Path, back: bool):
    """A small pair at an angle among the boxes; ``back``: a second pair beyond the exit, which a second leg may
    meet (the lists are then not used)."""
    backend = backend_factory("glsl", "f32")
    scene = ten_boxes(tmp_path)
    scene.add_portal_pair(
        "sa", "sb", a=dict(position=(-2.0, 1.5, 1.0), euler_deg=(0.0, 20.0, 0.0), scale=(1.0, 1.0, 1.0)),
        b=dict(position=(3.0, 1.0, -2.0), euler_deg=(0.0, -30.0, 0.0), scale=(1.0, 1.0, 1.0)),
    )  # fmt: skip
    if back:
        scene.add_portal_pair("ta", "tb", a=dict(position=(0.0, 1.5, -12.0), scale=(8.0, 6.0, 1.0)),
                              b=dict(position=(0.0, 1.5, 30.0), scale=(8.0, 6.0, 1.0)))  # fmt: skip
    try:
        frames_agree(backend, scene)
        assert legs_used(backend, scene) != back
    finally:
        backend.extra_defines = {}
        scene.close()
