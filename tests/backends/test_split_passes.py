"""GLSL on llvmpipe traces a frame with portals or boxes in two dispatches where its camera rays' first legs
take the instances' lists (``SPLIT_PASS`` in options.h): the first finishes the rays their first leg ends and
queues the others, the second goes on with those. The frames are one dispatch's to the bit, every AOV, from
random cameras, with tiles too full to list (their rays go on from the start); a frame that queues most of its
pixels (a door filling the view) makes the next ones take one dispatch until the camera has been away from
that view for ``SINGLE_FRAMES`` frames."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import many_instances
from test_parity import render
from test_space_trees import SIZE, same_frames

from backends.glsl.split import SINGLE_FRAMES, SPLIT_QUEUED_MAX, SplitDispatch
from backends.shared import INSTANCE_TILE_MIN_BESIDE
from engine.scene import Scene

#: One dispatch, two, and two with every tile of over 3 instances left to the tree.
VARIANTS: tuple[dict[str, int], ...] = ({"SPLIT_PASSES": 0}, {}, {"INSTANCE_TILE_MAX": 3})


def doors_among_instances() -> Scene:
    """Enough instances and portals for the instance lists beside the portal tree: small doors in view."""
    scene = many_instances(7, INSTANCE_TILE_MIN_BESIDE + 8)
    for k in range(12):
        scene.add_portal_pair(
            f"a{k}", f"b{k}", a=dict(position=(k - 5.5, 1.5, 2.0), scale=(0.45, 0.6, 1.0)),
            b=dict(position=(k - 5.5, 1.5, -20.0), euler_deg=(0.0, 30.0 * k, 0.0), scale=(0.45, 0.6, 1.0)),
        )  # fmt: skip
    return scene


@pytest.fixture
def queued(monkeypatch) -> list[float]:
    """The share of its pixels each split frame queued for the second dispatch, in order."""
    shares: list[float] = []
    dispatch = SplitDispatch.run

    def counted(self, ctx, programs, camera, size, workgroup):
        count = dispatch(self, ctx, programs, camera, size, workgroup)
        shares.append(count / (size[0] * size[1]))
        return count

    monkeypatch.setattr(SplitDispatch, "run", counted)
    return shares


@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_two_dispatches_give_one_dispatchs_frames(backend_factory, queued, precision):
    backend = backend_factory("glsl", precision)
    if not backend.split_passes:
        pytest.skip(f"the GLSL backend splits frames on llvmpipe (tables in images) only: {backend.info()}")
    rng = np.random.default_rng(11)
    scene = doors_among_instances()
    cameras = [(tuple(rng.uniform([-4.0, 1.0, 6.0], [4.0, 3.0, 12.0])), (0.0, 1.5, 2.0)) for _ in range(4)]
    try:
        for position, look_at in cameras:
            scene.set_camera(position, look_at=look_at, fov_deg=float(rng.uniform(40.0, 90.0)))
            frames = []
            for defines in VARIANTS:
                backend.extra_defines = dict(defines)
                backend._split.single_frames = 0  # whatever the frame before queued
                frames.append(render(backend, scene, SIZE))
            for other in frames[1:]:
                same_frames(frames[0], other)
        backend.extra_defines = {}
        # Each camera's two split variants took two dispatches, each queueing some rays, the lists' not most.
        assert len(queued) == 2 * len(cameras) and min(queued) > 0.0, queued
        assert max(queued[::2]) <= SPLIT_QUEUED_MAX, queued
    finally:
        backend.extra_defines = {}
        scene.close()


def test_a_frame_queueing_most_pixels_leaves_the_next_to_one_dispatch(backend_factory, queued):
    backend = backend_factory("glsl", "f32")
    if not backend.split_passes:
        pytest.skip(f"the GLSL backend splits frames on llvmpipe (tables in images) only: {backend.info()}")
    scene = doors_among_instances()
    scene.add_portal_pair(
        "big", "far", a=dict(position=(0.0, 1.8, 9.0), scale=(8.0, 8.0, 1.0)),
        b=dict(position=(0.0, 1.8, 30.0), scale=(8.0, 8.0, 1.0)),
    )  # fmt: skip
    scene.set_camera((0.0, 1.8, 12.0), look_at=(0.0, 1.8, 0.0), fov_deg=60.0)
    try:
        backend._split.single_frames = 0  # whatever the frame before queued
        render(backend, scene, SIZE)
        assert len(queued) == 1 and queued[0] > SPLIT_QUEUED_MAX  # the door fills the view
        for _ in range(3 * SINGLE_FRAMES):  # the camera still: one dispatch from here on
            render(backend, scene, SIZE)
        assert len(queued) == 1
        for k in range(SINGLE_FRAMES):  # away from that view for SINGLE_FRAMES frames: two tried again
            scene.set_camera((0.0, 1.8, 12.0 - 0.01 * (k + 1)), look_at=(0.0, 1.8, 0.0), fov_deg=60.0)
            render(backend, scene, SIZE)
        assert len(queued) == 2
    finally:
        scene.close()
