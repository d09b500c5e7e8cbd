"""Camera paths: exact keyframes, C1 interpolation, unit quaternions, validation, and walks through the real systems."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from components import Camera, Transform
from engine.maths import quat_from_axis_angle, quat_to_matrix
from engine.scene import Scene
from systems.app import App
from systems.camera_path import CameraPath, CameraPathError, Keyframe, yaw_pitch, yaw_pitch_quat

DT = 1.0 / 30.0


def wiggly_path() -> CameraPath:
    """Uneven key spacing, mixed rotation forms, a turn of more than 90 degrees."""
    return CameraPath(
        [
            Keyframe(0.0, (0.0, 1.0, 0.0), look_at=(0.0, 1.0, -5.0)),
            Keyframe(1.5, (1.0, 1.2, -2.0), look_at=(0.0, 1.0, -6.0)),
            Keyframe(2.0, (2.0, 1.0, -3.0), rotation=tuple(quat_from_axis_angle((0, 1, 0), math.radians(-45)))),
            Keyframe(4.0, (0.0, 2.0, -6.0), look_at=(5.0, 0.0, -8.0)),
            Keyframe(4.3, (0.5, 2.0, -6.5), rotation=(0.0, 0.0, 0.0, -1.0)),
        ]
    )


def same_rotation(a: np.ndarray, b: np.ndarray, tol: float = 1e-12) -> bool:
    return abs(abs(float(np.dot(a, b))) - 1.0) < tol


def test_passes_through_every_keyframe_exactly():
    path = wiggly_path()
    for i, t in enumerate(path.times):
        position, q = path.sample(float(t))
        np.testing.assert_array_equal(position, path.positions[i])
        assert same_rotation(q, path.quats[i])


def test_position_and_orientation_are_c1_at_keyframes():
    path = wiggly_path()
    eps = 1e-6
    for t in path.times[1:-1]:
        before = (path.sample(t)[0] - path.sample(t - eps)[0]) / eps
        after = (path.sample(t + eps)[0] - path.sample(t)[0]) / eps
        np.testing.assert_allclose(before, after, atol=1e-4)
        q_before = (path.sample(t)[1] - path.sample(t - eps)[1]) / eps
        q_after = (path.sample(t + eps)[1] - path.sample(t)[1]) / eps
        np.testing.assert_allclose(q_before, q_after, atol=1e-4)


def test_two_keyframes_are_a_straight_line_and_a_slerp():
    q1 = quat_from_axis_angle((0, 1, 0), 1.2)
    path = CameraPath([Keyframe(0.0, (0, 0, 0), rotation=(0, 0, 0, 1)), Keyframe(2.0, (4, 2, 0), rotation=q1)])
    position, q = path.sample(0.5)
    np.testing.assert_allclose(position, (1.0, 0.5, 0.0), atol=1e-12)
    assert same_rotation(q, quat_from_axis_angle((0, 1, 0), 0.3), 1e-12)


@settings(max_examples=200, deadline=None)
@given(st.floats(-1.0, 5.0, allow_nan=False))
def test_samples_are_unit_quaternions_and_clamped(t):
    path = wiggly_path()
    position, q = path.sample(t)
    assert abs(float(np.linalg.norm(q)) - 1.0) < 1e-12
    assert np.all(np.isfinite(position))


@pytest.mark.parametrize(
    ("keys", "message"),
    [
        ([Keyframe(0, (0, 0, 0), rotation=(0, 0, 0, 1))], "at least 2 keyframes"),
        (
            [Keyframe(0, (0, 0, 0), rotation=(0, 0, 0, 1)), Keyframe(0, (1, 0, 0), rotation=(0, 0, 0, 1))],
            "keyframe 1, field 'time'",
        ),
        (
            [Keyframe(0, (0, 0, 0), rotation=(0, 0, 0, 1)), Keyframe(float("nan"), (1, 0, 0), rotation=(0, 0, 0, 1))],
            "keyframe 1, field 'time'",
        ),
        (
            [Keyframe(0, (0, 0), rotation=(0, 0, 0, 1)), Keyframe(1, (1, 0, 0), look_at=(0, 0, 0))],
            "keyframe 0, field 'position'",
        ),
        ([Keyframe(0, (0, 0, 0)), Keyframe(1, (1, 0, 0), look_at=(0, 0, 0))], "keyframe 0, field 'rotation'"),
        (
            [
                Keyframe(0, (0, 0, 0), rotation=(0, 0, 0, 1), look_at=(1, 0, 0)),
                Keyframe(1, (1, 0, 0), look_at=(0, 0, 0)),
            ],
            "keyframe 0, field 'rotation': give exactly one",
        ),
        ([Keyframe(0, (0, 0, 0), rotation=(0, 0, 0, 2)), Keyframe(1, (1, 0, 0), look_at=(0, 0, 0))], "unit length"),
        (
            [Keyframe(0, (0, 0, 0), look_at=(1, 0, 0)), Keyframe(1, (1, 0, 0), look_at=(1, 0, 0))],
            "keyframe 1, field 'look_at'",
        ),
    ],
)
def test_validation_names_the_keyframe_and_field(keys, message):
    with pytest.raises(CameraPathError, match=message.replace("(", r"\(")):
        CameraPath(keys)


# --- driving the real systems -------------------------------------------------------


def flat_scene() -> Scene:
    scene = Scene("walk")
    scene.add_mesh("floor", "plane", scale=50.0)
    scene.set_camera((9.0, 9.0, 9.0), look_at=(0.0, 0.0, 0.0), speed=1.7)
    return scene


def walk(scene: Scene, path: CameraPath, ticks: int) -> Transform:
    path.place_camera(scene)
    dt = path.duration / ticks
    with App(scene, None, input_source=path.inputs(scene)) as app:
        app.run(ticks + 2, dt)  # extra ticks: the path is over, the camera stays
    assert scene.camera_entity is not None
    return scene.get(scene.camera_entity, Transform)


def test_walk_in_euclidean_space_ends_at_the_final_keyframe():
    path = wiggly_path()
    scene = flat_scene()
    try:
        end = walk(scene, path, 90)
        np.testing.assert_allclose(end.position, path.positions[-1], atol=1e-9)
        yaw, pitch = yaw_pitch(path.quats[-1])
        assert same_rotation(np.array(end.rotation), yaw_pitch_quat(yaw, pitch), 1e-9)
        assert scene.get(scene.camera_entity, Camera).speed == 1.7  # the path's speed override is undone
    finally:
        scene.close()


def test_walk_follows_the_path_at_every_tick():
    path = wiggly_path()
    scene = flat_scene()
    seen = []
    try:
        path.place_camera(scene)
        ticks = 40
        with App(scene, None, input_source=path.inputs(scene)) as app:
            for k in range(1, ticks + 1):
                app.tick(path.duration / ticks)
                seen.append((k, scene.get(scene.camera_entity, Transform).position))
        for k, position in seen:
            np.testing.assert_allclose(position, path.sample(path.duration * k / ticks)[0], atol=1e-9)
    finally:
        scene.close()


def test_an_aberration_scales_the_walk():
    """A metric box with D_x = 1 around the whole walk: the camera covers twice the path's x distance."""
    path = CameraPath(
        [Keyframe(0.0, (0.0, 1.0, 0.0), rotation=(0, 0, 0, 1)), Keyframe(2.0, (3.0, 1.0, 0.0), rotation=(0, 0, 0, 1))]
    )
    scene = flat_scene()
    try:
        scene.add_aberration("fast", (1.0, 0.0, 0.0), position=(0.0, 1.0, 0.0), scale=40.0)
        end = walk(scene, path, 20)
        np.testing.assert_allclose(end.position, (6.0, 1.0, 0.0), atol=1e-9)
    finally:
        scene.close()


def test_after_a_portal_the_path_continues_relative_to_the_camera():
    """Walk 4 units along -Z through a portal at z = -2 whose target is turned 90° about Y, 100 units away."""
    path = CameraPath(
        [Keyframe(0.0, (0.0, 0.0, 0.0), rotation=(0, 0, 0, 1)), Keyframe(2.0, (0.0, 0.0, -4.0), rotation=(0, 0, 0, 1))]
    )
    scene = flat_scene()
    try:
        scene.add_portal_pair(
            "a", "b", a={"position": (0.0, 0.0, -2.0)}, b={"position": (100.0, 0.0, 0.0), "euler_deg": (0, 90, 0)}
        )
        end = walk(scene, path, 20)
        np.testing.assert_allclose(end.position, (98.0, 0.0, 0.0), atol=1e-9)
        forward = -quat_to_matrix(end.rotation)[:, 2]
        np.testing.assert_allclose(forward, (-1.0, 0.0, 0.0), atol=1e-9)
    finally:
        scene.close()
