"""Clearances that let the kernels skip work (engine/box_clearance.py; docs/semantics.md section 14).

The host proves a mesh search empty (a segment inside a box clear of every instance, the first leg ending
nearer than the camera's clearance) and a box look-up decided by the crossed face (a box farther than the
nudge from every other box). Here: the bounds are lower bounds and vanish where they must (overlapping
boxes, an instance moved into a box, incrementally), and the frames are bit-identical with the shortcuts
on and off (SKIP_CLEAR_SEARCH, FACE_NEXT_BOX, OWN_BOX_FACES, LEFT_BOX_GAP, the box code a frame compiles out:
FACE_NEXT_ONLY, CAMERA_BOX_ENTRY, and the loops' compiled-in counts PORTAL_COUNT, BOX_COUNT) in every fast
backend, f32 and f64.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scenes import render_scene
from test_parity import render
from test_parity_aberrations import camera_in_metric, grazing_and_touching, mixed_overlap
from test_parity_portals import portal_in_aberrations

from aberrant.bench.scenes import ten_boxes, ten_boxes_aberration, ten_boxes_portals
from aberrant.bench.space import space_scene
from backends.base import AOVS, Frame
from backends.shared import UploadedScene
from components import Transform
from engine.box_clearance import camera_clearance, instance_bounds
from engine.camera_view import pack_camera, scene_camera
from engine.clearances import box_clearances
from engine.packing import ScenePacker
from engine.scene import Scene

FAST = [
    pytest.param("glsl", "f32", id="glsl-f32"),
    pytest.param("glsl", "f64", id="glsl-f64"),
    pytest.param("opencl", "f32", id="opencl-f32"),
    pytest.param("opencl", "f64", id="opencl-f64"),
]
OFF = {
    "SKIP_CLEAR_SEARCH": 0, "CAMERA_CLEAR_SEARCH": 0, "FACE_NEXT_BOX": 0, "OWN_BOX_FACES": 0, "LEFT_BOX_GAP": 0,
    "FACE_NEXT_ONLY": 0, "CAMERA_BOX_ENTRY": 1, "PORTAL_COUNT": -1, "BOX_COUNT": -1, "LEFT_PORTAL_GAP": 0,
}  # fmt: skip


Vec3 = tuple[float, float, float]


def unit_box(centre: Vec3, size: Vec3, angle_deg: float = 0.0) -> np.ndarray:
    """world_to_local rows (1, 3, 4) of a box turned about y."""
    a = np.radians(angle_deg)
    rot = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    linear = rot @ np.diag(size)
    inverse = np.linalg.inv(linear)
    return np.concatenate([inverse, (-inverse @ np.asarray(centre))[:, None]], axis=1)[None]


def test_instance_clearance_is_a_lower_bound_and_vanishes_on_contact():
    box = unit_box((0.0, 0.0, 0.0), (2.0, 2.0, 2.0))  # [-1, 1]^3
    lo = np.array([[1.5, -0.5, -0.5], [-0.5, -3.0, -0.5]])
    hi = np.array([[2.5, 0.5, 0.5], [0.5, -1.25, 0.5]])
    clear, _ = box_clearances(box, lo, hi)
    assert 0.24 < clear[0] <= 0.25  # the nearer instance, less the slack
    clear, _ = box_clearances(box, np.array([[0.9, 0.0, 0.0]]), np.array([[2.0, 0.1, 0.1]]))
    assert clear[0] == 0.0
    clear, _ = box_clearances(box, np.zeros((0, 3)), np.zeros((0, 3)))
    assert clear[0] > 1e20


def test_turned_box_clearance_stays_below_the_distance():
    """A box turned 45 degrees: its corner reaches sqrt(2) along x; an instance at x = 1.6 is 0.19 away."""
    box = unit_box((0.0, 0.0, 0.0), (2.0, 2.0, 2.0), 45.0)
    clear, _ = box_clearances(box, np.array([[1.6, -0.1, -0.1]]), np.array([[2.0, 0.1, 0.1]]))
    assert 0.0 < clear[0] <= 1.6 - np.sqrt(2.0)


def test_box_gaps_vanish_for_overlapping_and_touching_boxes():
    boxes = np.concatenate(
        [unit_box((0, 0, 0), (2, 2, 2)), unit_box((2.0, 0, 0), (2, 2, 2)), unit_box((0, 0, 5.0), (2, 2, 2))]
    )
    _, gaps = box_clearances(boxes, np.zeros((0, 3)), np.zeros((0, 3)))
    assert gaps[0] == 0.0 and gaps[1] == 0.0  # touching: the face is shared
    assert 2.9 < gaps[2] <= 3.0
    boxes[1] = unit_box((1.5, 0.2, 0), (2, 2, 2), 30.0)[0]
    _, gaps = box_clearances(boxes, np.zeros((0, 3)), np.zeros((0, 3)))
    assert gaps[0] == 0.0 and gaps[1] == 0.0


def test_camera_clearance():
    lo, hi = np.array([[1.0, -1.0, -1.0]]), np.array([[2.0, 1.0, 1.0]])
    assert 0.99 < camera_clearance(np.zeros(3), (lo, hi)) <= 1.0
    assert camera_clearance(np.array([1.5, 0.0, 0.0]), (lo, hi)) == 0.0
    assert camera_clearance(np.zeros(3), None) == 0.0


def packer_of(scene: Scene, precision: str = "f32") -> ScenePacker:
    packer = ScenePacker(precision)
    packer.sync(scene)
    return packer


def test_the_bench_box_is_clear_and_alone(tmp_path: Path):
    """The view-filling box gets both shortcuts; boxes that overlap get neither gap."""
    rotation = packer_of(ten_boxes_aberration(tmp_path)).packed.tables["aberrations"]["rotation"]
    assert rotation[0, 0, 3] > 1e-3 and rotation[0, 1, 3] > 1e20
    packed = packer_of(mixed_overlap()).packed
    gaps = packed.tables["aberrations"]["rotation"][: packed.counts["aberrations"], 1, 3]
    assert np.count_nonzero(gaps == 0.0) >= 2


def test_an_instance_moved_into_a_box_clears_its_clearance_and_is_rendered(tmp_path: Path, backend_factory):
    """Moving a mesh into the bench box updates the box row incrementally, and every fast backend draws it."""
    scene = ten_boxes_aberration(tmp_path)
    packer = packer_of(scene)
    assert packer.packed.tables["aberrations"]["rotation"][0, 0, 3] > 0.0
    box = scene.entity("box4")
    old = scene.get(box, Transform)
    scene.set(box, Transform((0.0, 2.2, 2.5), old.rotation, old.scale))  # inside the lens, in view
    updates = packer.sync(scene)
    assert any(u.table == "aberrations" for u in updates)
    assert packer.packed.tables["aberrations"]["rotation"][0, 0, 3] == 0.0
    fresh = packer_of(scene).packed.tables["aberrations"]
    assert np.array_equal(fresh["rotation"], packer.packed.tables["aberrations"]["rotation"])
    for name, precision in (("glsl", "f32"), ("opencl", "f32"), ("opencl", "f64")):
        backend = backend_factory(name, precision)
        frame = render(backend, scene, (48, 48))
        assert np.any(frame.instance == box), name
    scene.close()


def boxes_in_a_row() -> Scene:
    """Six metric boxes one behind another, a little apart, seen at an angle: rays leave one box and enter the
    next a gap later (the box tree, its walk after each exit started past the gap)."""
    scene = Scene("boxes-in-a-row")
    scene.add_mesh("floor", "plane", scale=(20.0, 1.0, 20.0), checker=0.5)
    scene.add_mesh("crate", "box", position=(0.3, 0.5, -9.0), scale=0.8)
    for k in range(6):
        scene.add_aberration(
            f"lens{k}",
            (0.2 * (k % 3) - 0.2, 0.15, -0.1),
            position=(0.1 * k, 1.2, -1.0 - 1.1 * k),
            scale=(3.0, 1.6, 1.0),
        )
    scene.set_camera((1.5, 1.6, 3.0), look_at=(0.0, 1.0, -8.0), fov_deg=60.0)
    return scene


def scenes(folder: Path) -> dict[str, object]:
    return {
        "boxes-in-a-row": boxes_in_a_row,
        "bench-aberration": lambda: ten_boxes_aberration(folder),
        "bench-portals": lambda: ten_boxes_portals(folder),
        "mixed-overlap": mixed_overlap,
        "grazing-and-touching": grazing_and_touching,
        "portal-in-aberrations": portal_in_aberrations,
        "boxes-in-view": lambda: space_scene("boxes", "in", 64),  # the box tree, every box alone
    }


@pytest.mark.parametrize("case", ["bench-aberration", "bench-portals", "mixed-overlap", "grazing-and-touching",
                                  "portal-in-aberrations", "boxes-in-view", "boxes-in-a-row"])  # fmt: skip
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_shortcuts_are_bit_identical(tmp_path, backend_factory, backend_name, precision, case):
    backend = backend_factory(backend_name, precision)
    frames: list[Frame] = []
    try:
        for defines in ({}, OFF):
            backend.extra_defines = dict(defines)
            frames.append(render_scene(backend, scenes(tmp_path)[case], (64, 48)))
    finally:
        backend.extra_defines = {}
    for name in AOVS:
        assert np.array_equal(frames[0].aov(name), frames[1].aov(name), equal_nan=True), name


def frame_space_defines(scene: Scene, position: Vec3 | None = None) -> dict[str, int]:
    """The box code a GLSL frame of ``scene`` compiles out, seen from its camera or from ``position``."""
    packer = packer_of(scene)
    packed = packer.packed
    uploaded = UploadedScene()
    uploaded._forget_upload()
    uploaded._note_upload(packed, set(packed.tables), set(packed.tables))
    view = scene_camera(scene)
    if position is not None:
        view = replace(view, position=np.asarray(position, dtype=np.float64))
    row = pack_camera(view, uploaded._origin, "f32", 64, 48, uploaded._boxes, uploaded._bounds, uploaded._box_tree)
    return uploaded._frame_space_defines(packed.features, row, "f32")


def test_a_frame_compiles_out_the_box_code_it_provably_never_runs(tmp_path: Path):
    """The bench camera starts in no box and its box is alone: both compile out. Overlapping boxes keep the
    look-up after a face, a camera in a box its entry; a gap proves the look-up dead only for a near camera."""
    assert frame_space_defines(ten_boxes_aberration(tmp_path)) == {"CAMERA_BOX_ENTRY": 0, "FACE_NEXT_ONLY": 1}
    assert frame_space_defines(mixed_overlap())["FACE_NEXT_ONLY"] == 0
    assert frame_space_defines(camera_in_metric())["CAMERA_BOX_ENTRY"] == 1
    scene = ten_boxes(tmp_path)
    scene.add_aberration("left", (0.3, 0.0, 0.0), position=(-2.0, 1.0, 0.0), scale=(1.0, 1.0, 1.0))
    scene.add_aberration("right", (0.3, 0.0, 0.0), position=(2.0, 1.0, 0.0), scale=(1.0, 1.0, 1.0))
    assert frame_space_defines(scene)["FACE_NEXT_ONLY"] == 1
    assert frame_space_defines(scene, (0.0, 2.0, 1e5))["FACE_NEXT_ONLY"] == 0
    assert frame_space_defines(ten_boxes_portals(tmp_path)) == {}


def test_the_bench_camera_is_clear(tmp_path: Path):
    """The bench scenes' first legs end before the floor: the camera's clearance is about its height."""
    scene = ten_boxes_portals(tmp_path)
    packer = packer_of(scene)
    view = scene_camera(scene)
    clear = camera_clearance(view.position - packer.packed.origin, instance_bounds(packer.packed))
    assert 2.4 < clear <= 2.5
    scene.close()
