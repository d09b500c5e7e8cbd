"""Aberrations in the fast backends against the float64 reference (docs/semantics.md).

The shared core (backends/shared/*.h) ports the reference's rules one by
one; here GLSL and OpenCL (float32, and OpenCL float64) render scenes with
metric, radial and additive boxes (rotated, overlapping, the camera inside
one, all three exit rules) and must agree with the reference: instance
mismatch <= 0.2 %, no NaN. Two closed forms hold in every backend: a box with
D = 0 changes nothing (bit-identical AOVs but the event count), and a camera
looking down the axis of a D_z = 2 metric box sees the wall behind it at
perceived depth (box length)/3 + (the rest).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from scenes import EVERY, F32_DEPTH_MEDIAN_MAX, F64_DEPTH_P99_MAX, MISMATCH_MAX
from scenes import SPACE_PARITY as FAST
from test_parity import FAR, assert_clean, compare, render, translated

from backends.base import AOVS, Frame
from backends.reference.backend import ReferenceBackend
from engine.scene import Scene
from engine.settings import Settings

#: The frame size of every case.
SIZE = (112, 84)


# --- scenes ----------------------------------------------------------------------------------------


def room(name: str, camera=(0.3, 1.7, 6.5), look_at=(0.0, 1.0, -2.0), fov_deg: float = 68.0, **settings) -> Scene:
    """A walled room with a checkered floor, crates, a ball, a pillar and a pyramid: structure everywhere."""
    scene = Scene(name, settings=Settings(**settings))
    scene.add_mesh("floor", "plane", scale=(30.0, 1.0, 30.0), checker=0.04)
    scene.add_mesh(
        "back", "box", position=(0.0, 3.0, -8.5), scale=(30.0, 8.0, 1.0), color=(0.7, 0.75, 0.9), checker=0.1
    )
    scene.add_mesh("left", "box", position=(-7.5, 3.0, 0.0), scale=(1.0, 8.0, 30.0), color=(0.9, 0.6, 0.5), checker=0.1)
    scene.add_mesh("right", "box", position=(7.5, 3.0, 0.0), scale=(1.0, 8.0, 30.0), color=(0.5, 0.9, 0.6), checker=0.1)
    scene.add_mesh("crate", "box", position=(-2.0, 0.5, -2.0), euler_deg=(0.0, 25.0, 0.0), color=(0.9, 0.7, 0.3))
    scene.add_mesh("crate2", "box", position=(2.6, 0.4, -4.0), euler_deg=(10.0, -35.0, 5.0), scale=0.8, checker=0.2)
    scene.add_mesh("ball", "sphere", position=(1.2, 0.8, -0.8), scale=1.2, color=(0.3, 0.5, 0.95))
    scene.add_mesh("pillar", "cylinder", position=(-0.6, 1.5, -5.0), scale=(0.7, 3.0, 0.7), color=(0.8, 0.3, 0.6))
    scene.add_mesh("pyramid", "pyramid", position=(3.8, 0.6, -1.0), scale=1.2, color=(0.4, 0.9, 0.9))
    scene.set_camera(camera, look_at=look_at, fov_deg=fov_deg)
    return scene


def metric_rotated_overlapping() -> Scene:
    """Rotated metric boxes compressing and stretching, two of them overlapping (priority decides)."""
    scene = room("metric-rotated")
    scene.add_aberration(
        "squeeze", (1.0, 0.0, 0.6), position=(-1.2, 1.2, -1.5), euler_deg=(15.0, 35.0, 5.0), scale=(4.0, 2.5, 3.0)
    )
    scene.add_aberration(
        "stretch", (-0.4, 0.7, -0.5), position=(1.2, 1.0, -2.5), euler_deg=(0.0, -20.0, 10.0), scale=3.0, priority=1
    )
    scene.add_aberration("tall", (0.0, 2.0, 0.0), position=(0.5, 0.6, 2.5), scale=(6.0, 1.2, 1.0))
    return scene


def camera_in_metric() -> Scene:
    """The camera inside a rotated metric box (its rays start bent), a second box ahead."""
    scene = room("camera-in-metric")
    scene.add_aberration(
        "around", (0.8, -0.3, 1.5), position=(0.0, 1.5, 5.5), euler_deg=(5.0, 20.0, -10.0), scale=(5.0, 3.0, 4.0)
    )
    scene.add_aberration("ahead", (0.0, 0.0, -0.6), position=(0.0, 1.0, -1.0), scale=(3.0, 2.0, 2.0))
    return scene


def bending_exits(mode: str) -> Callable[[], Scene]:
    """Three boxes of ``mode`` side by side, one per exit rule (restore, repeat, invert), one rotated."""

    def build() -> Scene:
        scene = room(f"{mode}-exits")
        d = (0.5, 0.35, -0.3) if mode == "radial" else (0.25, 0.15, -0.2)
        scene.add_aberration("restore", d, mode=mode, exit="restore", position=(-3.0, 1.2, 1.0), scale=(2.2, 2.2, 2))
        scene.add_aberration(
            "repeat", d, mode=mode, exit="repeat", position=(0.0, 1.2, 1.0), euler_deg=(0.0, 30.0, 0.0), scale=2.2
        )
        scene.add_aberration("invert", d, mode=mode, exit="invert", position=(3.0, 1.2, 1.0), scale=(2.2, 2.2, 2))
        return scene

    return build


def camera_in_bending() -> Scene:
    """The camera inside a radial box (pre-deformed rays), an additive box of higher priority overlapping it."""
    scene = room("camera-in-bending")
    scene.add_aberration("around", (0.3, -0.25, 0.2), mode="radial", position=(0.3, 1.5, 5.0), scale=(6.0, 4.0, 5.0))
    scene.add_aberration(
        "over", (-0.15, 0.1, 0.0), mode="additive", exit="repeat", position=(1.5, 1.5, 2.8), scale=(3.0, 3.0, 2.0),
        priority=2,
    )  # fmt: skip
    scene.add_aberration("far", (0.0, 0.0, 1.0), position=(-1.5, 1.0, -3.0), euler_deg=(0.0, 40.0, 0.0), scale=2.5)
    return scene


def mixed_overlap() -> Scene:
    """Metric, radial and additive boxes nested and overlapping at several priorities."""
    scene = room("mixed-overlap")
    scene.add_aberration("outer", (0.5, 0.5, 0.5), position=(0.0, 1.2, -1.0), scale=(7.0, 3.0, 5.0))
    scene.add_aberration(
        "radial", (0.4, -0.3, 0.3), mode="radial", exit="invert", position=(-1.5, 1.2, -0.5), scale=(3.0, 2.0, 3.0),
        priority=1,
    )  # fmt: skip
    scene.add_aberration(
        "additive", (0.0, 0.2, 0.1), mode="additive", position=(1.5, 1.0, -1.5), euler_deg=(0.0, 0.0, 25.0),
        scale=(3.0, 2.5, 3.0), priority=1,
    )  # fmt: skip
    scene.add_aberration("inner", (-0.5, 0.0, 2.0), position=(0.0, 1.0, -1.0), scale=(1.5, 1.5, 1.5), priority=3)
    return scene


@dataclass(frozen=True)
class Case:
    build: Callable[[], Scene]
    #: Modes the scene uses (its variant compiles only these).
    modes: frozenset[str]


CASES: dict[str, Case] = {
    "metric-rotated": Case(metric_rotated_overlapping, frozenset({"metric"})),
    "camera-in-metric": Case(camera_in_metric, frozenset({"metric"})),
    "radial-exits": Case(bending_exits("radial"), frozenset({"radial"})),
    "additive-exits": Case(bending_exits("additive"), frozenset({"additive"})),
    "camera-in-bending": Case(camera_in_bending, frozenset({"metric", "radial", "additive"})),
    "mixed-overlap": Case(mixed_overlap, frozenset({"metric", "radial", "additive"})),
}


def extreme(name: str, deformation, mode: str = "metric") -> Callable[[], Scene]:
    """One rotated box of ``mode`` with an extreme ``deformation`` in front of the camera."""

    def build() -> Scene:
        scene = room(name)
        scene.add_aberration(
            "box", deformation, mode=mode, position=(0.2, 1.2, 0.5), euler_deg=(10.0, 20.0, 30.0), scale=(3, 2, 2.5)
        )
        return scene

    return build


def camera_on_a_face() -> Scene:
    """The camera exactly on a box's +z face: each ray's box is decided just along it."""
    scene = room("camera-on-face", camera=(0.3, 1.7, 3.0), look_at=(0.0, 1.0, -2.0))
    scene.add_aberration("box", (0.5, 0.3, 1.0), position=(0.3, 1.7, 1.0), scale=(3.0, 2.0, 4.0))
    return scene


def grazing_and_touching() -> Scene:
    """A box face at the camera's height (rays graze it) and a radial box touching it along a face."""
    scene = room("grazing", camera=(0.0, 1.0, 6.0), look_at=(0.0, 1.0, -2.0))
    scene.add_aberration("above", (0.5, 0.3, 1.0), position=(0.0, 2.0, 0.0), scale=(4.0, 2.0, 6.0))
    scene.add_aberration("beside", (0.3, 0.3, -0.5), mode="radial", position=(4.0, 2.0, 0.0), scale=(4.0, 2.0, 6.0))
    return scene


#: Hard inputs: defined output, no NaN, every backend agreeing with the reference.
HARD: dict[str, Callable[[], Scene]] = {
    "D=-0.99": extreme("D=-0.99", (-0.99, -0.99, -0.99)),
    "D=100": extreme("D=100", (100.0, 100.0, 100.0)),
    "radial-mirror": extreme("radial-mirror", (3.0, -4.0, 5.0), "radial"),
    "additive-mirror": extreme("additive-mirror", (0.5, -3.0, 4.0), "additive"),
    "camera-on-a-face": camera_on_a_face,
    "grazing-and-touching": grazing_and_touching,
}


@pytest.fixture(scope="module")
def reference_frames():
    """``frame(name)``: the reference's frame of a case, rendered once per module."""
    backend = ReferenceBackend()
    cache: dict[str, Frame] = {}

    def frame(name: str) -> Frame:
        if name not in cache:
            scene = CASES[name].build() if name in CASES else HARD[name]()
            try:
                cache[name] = render(backend, scene, SIZE)
            finally:
                scene.close()
        return cache[name]

    yield frame
    backend.release()


# --- parity ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_parity_with_the_reference(backend_factory, reference_frames, backend_name, precision, case):
    backend = backend_factory(backend_name, precision)
    ref = reference_frames(case)
    scene = CASES[case].build()
    try:
        fast = render(backend, scene, SIZE)
        assert backend._features.aberration_modes == CASES[case].modes
    finally:
        scene.close()
    assert_clean(fast)
    assert_clean(ref)
    assert (ref.instance >= 0).mean() > 0.8 and (ref.events > 0).mean() > 0.3, "the case should bend most rays"
    result = compare(fast, ref)
    assert result.mismatch <= MISMATCH_MAX, result
    if precision == "f64":
        assert result.depth_p99 <= F64_DEPTH_P99_MAX, result
    else:
        assert result.depth_median <= F32_DEPTH_MEDIAN_MAX, result
    # Bent rays: perceived depth agrees as well as depth does.
    same = (fast.instance == ref.instance) & (ref.instance >= 0)
    rel = np.abs(fast.perceived[same].astype(np.float64) - ref.perceived[same]) / ref.perceived[same]
    assert np.median(rel) <= (1e-12 if precision == "f64" else F32_DEPTH_MEDIAN_MAX), np.median(rel)


@pytest.mark.parametrize("case", list(HARD))
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_hard_cases_agree_with_the_reference(backend_factory, reference_frames, backend_name, precision, case):
    backend = backend_factory(backend_name, precision)
    ref = reference_frames(case)
    scene = HARD[case]()
    try:
        fast = render(backend, scene, SIZE)
    finally:
        scene.close()
    assert_clean(fast)
    assert_clean(ref)
    result = compare(fast, ref)
    assert result.mismatch <= MISMATCH_MAX, result
    assert np.mean(fast.events != ref.events) <= MISMATCH_MAX


@pytest.mark.parametrize("case", ["mixed-overlap", "camera-in-bending"])
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_far_from_the_origin(backend_factory, reference_frames, backend_name, precision, case):
    """Boxes and camera moved by 1e5: camera-relative tables keep the float32 frames as good as at the origin."""
    backend = backend_factory(backend_name, precision)
    scene = translated(CASES[case].build(), FAR)
    try:
        fast = render(backend, scene, SIZE)
    finally:
        scene.close()
    assert_clean(fast)
    result = compare(fast, reference_frames(case))
    assert result.mismatch <= MISMATCH_MAX and result.depth_median <= F32_DEPTH_MEDIAN_MAX, result


# --- closed forms, in every backend ------------------------------------------------------------------

#: The wall's front face lies in the plane z = WALL_Z.
WALL_Z = -5.5


def wall_scene() -> Scene:
    scene = Scene("wall")
    scene.add_mesh("wall", "box", position=(0.0, 0.0, WALL_Z - 0.5), scale=(60.0, 60.0, 1.0), checker=0.5)
    scene.set_camera((0.0, 0.0, 5.0), look_at=(0.0, 0.0, 0.0))
    return scene


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_metric_box_on_axis_closed_form(backend_factory, backend_name, precision):
    """Camera on the axis of a D_z = 2 box of length 4: perceived 3 + 4/3 + 3.5, world 3 + 4 + 3.5."""
    backend = backend_factory(backend_name, precision)
    scene = wall_scene()
    try:
        scene.add_aberration("squeeze", (0.0, 0.0, 2.0), scale=(10.0, 10.0, 4.0))
        frame = render(backend, scene, (33, 25))  # odd size: the centre pixel looks along the axis
    finally:
        scene.close()
    tolerance = 1e-5 if precision == "f32" else 1e-7  # f64 tracers still write float32 AOVs
    assert frame.events[12, 16] == 2
    assert frame.depth[12, 16] == pytest.approx(10.5, rel=tolerance)
    assert frame.perceived[12, 16] == pytest.approx(3.0 + 4.0 / 3.0 + 3.5, rel=tolerance)
    assert_clean(frame)


@pytest.mark.parametrize("mode", ["metric", "radial", "additive"])
@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_zero_deformation_changes_nothing(backend_factory, backend_name, precision, mode):
    """A D = 0 box (rotated, the camera's rays crossing it, a mesh inside it) leaves every AOV but events as it is."""
    backend = backend_factory(backend_name, precision)
    frames = []
    for with_box in (False, True):
        scene = room("zero", camera=(0.7, 1.4, 6.0), look_at=(0.0, 0.8, -2.0))
        try:
            if with_box:
                scene.add_aberration(
                    "zero", (0.0, 0.0, 0.0), mode=mode, position=(0.6, 0.9, -0.5), euler_deg=(15.0, 25.0, 5.0),
                    scale=(3.5, 1.8, 3.0),
                )  # fmt: skip
            frames.append(render(backend, scene, (64, 48)))
        finally:
            scene.close()
    plain, boxed = frames
    for name in AOVS:
        if name != "events":
            assert np.array_equal(plain.aov(name), boxed.aov(name)), name
    assert np.all(plain.events == 0)
    assert (boxed.events == 2).mean() > 0.05 and (boxed.events == 1).mean() > 0.01  # crossed, and ending inside
