"""The camera row's box (engine.camera_view.camera_box; docs/semantics.md section 14).

The kernels skip the per-ray look-up of the camera's box when the host proved every primary ray gets the
same one. Here: the host gives the right box (the last row containing the camera: priorities decide
overlaps), falls back to per-ray look-ups where rays may disagree (the camera on or near a face, an edge, a
corner, touching boxes), and the scenes of the parity tests take the path this file says they take.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest
from scenes import render_scene
from test_hard_aberrations import ON_A_BOX, aimed_boxes
from test_parity_aberrations import (
    camera_in_bending,
    camera_in_metric,
    camera_on_a_face,
    grazing_and_touching,
    mixed_overlap,
    room,
)

from backends.base import AOVS
from engine.camera_view import CAMERA_BOX_PER_RAY, camera_box, pack_camera, scene_camera
from engine.packed import PackedScene, TableUpdate
from engine.packing import ScenePacker
from engine.records import Precision
from engine.scene import Scene

FAST = [
    pytest.param("glsl", "f32", id="glsl-f32"),
    pytest.param("glsl", "f64", id="glsl-f64"),
    pytest.param("opencl", "f32", id="opencl-f32"),
    pytest.param("opencl", "f64", id="opencl-f64"),
]


def packed_box(scene: Scene, precision: Precision = "f32") -> tuple[int, np.ndarray]:
    """The camera box the packed scene gives, and the packed rows in use."""
    packer = ScenePacker(precision)
    try:
        packer.sync(scene)
        packed = packer.packed
        rows = packed.tables["aberrations"][: packed.counts.get("aberrations", 0)]
        view = scene_camera(scene)
        return camera_box(view.position - packed.origin, rows), rows
    finally:
        scene.close()


@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_no_boxes_means_no_box(precision):
    box, rows = packed_box(room("plain"), precision)
    assert len(rows) == 0 and box == -1


def test_without_the_table_every_ray_looks_its_box_up():
    assert camera_box(np.zeros(3), None) == CAMERA_BOX_PER_RAY
    row = pack_camera(scene_camera(camera_in_metric()), np.zeros(3), "f32", 8, 6)
    assert row["size"][0, 2] == CAMERA_BOX_PER_RAY


@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_inside_a_box(precision):
    box, rows = packed_box(camera_in_metric(), precision)
    assert box >= 0 and rows["meta"][box, 0] == 0  # the metric box around the camera


@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_overlapping_boxes_go_to_the_last_row(precision):
    """The camera in the radial box and the higher-priority additive one: the additive (last) row wins."""
    scene = camera_in_bending()
    scene.set_camera((1.5, 1.5, 2.8), look_at=(0.0, 1.0, -2.0))
    box, rows = packed_box(scene, precision)
    assert box == len(rows) - 1 or rows["meta"][box, 2] == rows["meta"][:, 2].max()
    assert rows["meta"][box, 0] == 2  # additive
    box, rows = packed_box(camera_in_bending(), precision)  # only in the radial box
    assert rows["meta"][box, 0] == 1


@pytest.mark.parametrize("precision", ["f32", "f64"])
@pytest.mark.parametrize(
    "builder",
    [camera_on_a_face, *[(lambda camera=camera: aimed_boxes(camera=camera)) for _, camera, _ in ON_A_BOX.values()]],
    ids=["camera-on-face", *ON_A_BOX],
)
def test_on_a_face_edge_or_corner_each_ray_looks(precision, builder):
    box, _ = packed_box(builder(), precision)
    assert box == CAMERA_BOX_PER_RAY


@pytest.mark.parametrize("offset", [1e-7, 1e-5, -1e-5, 1e-4])
def test_near_a_face_each_ray_looks(offset):
    """Within the margin of a face, inside or outside: per ray (the nudge could cross the face)."""
    scene = camera_on_a_face()
    scene.set_camera((0.3, 1.7, 3.0 + offset), look_at=(0.0, 1.0, -2.0))
    box, _ = packed_box(scene)
    assert box == CAMERA_BOX_PER_RAY


@pytest.mark.parametrize(("z", "inside"), [(2.9, True), (3.1, False)])
def test_clear_of_the_faces_one_box(z, inside):
    scene = camera_on_a_face()
    scene.set_camera((0.3, 1.7, z), look_at=(0.0, 1.0, -2.0))
    box, _ = packed_box(scene)
    assert box == (0 if inside else -1)


def test_the_parity_scenes_take_both_paths():
    """The parity tests cover the host's box (outside, inside, overlapping) and the per-ray look-up."""
    assert packed_box(mixed_overlap())[0] == -1
    assert packed_box(camera_in_metric())[0] >= 0
    assert packed_box(camera_in_bending())[0] >= 0
    assert packed_box(camera_on_a_face())[0] == CAMERA_BOX_PER_RAY
    assert packed_box(grazing_and_touching())[0] in (-1, CAMERA_BOX_PER_RAY)


@pytest.mark.parametrize("builder", [camera_in_metric, camera_in_bending, mixed_overlap], ids=lambda b: b.__name__)
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_the_hosts_box_renders_as_the_per_ray_look_up(monkeypatch, backend_factory, backend_name, precision, builder):
    """Bit-identical AOVs with the camera row's box and with every ray looking its box up."""
    backend = backend_factory(backend_name, precision)
    upload = backend.upload

    def upload_without_boxes(packed: PackedScene, updates: Sequence[TableUpdate]) -> int:
        written = upload(packed, updates)
        backend._boxes = None  # pack_camera then writes CAMERA_BOX_PER_RAY
        return written

    frames = []
    for per_ray in (False, True):
        if per_ray:
            monkeypatch.setattr(backend, "upload", upload_without_boxes)
        frames.append(render_scene(backend, builder, (64, 48)))
    for name in AOVS:
        assert np.array_equal(frames[0].aov(name), frames[1].aov(name)), name
