"""Walk mode headless: gravity, walls, steps and walls seen through portals, probed by the reference tracer."""

from __future__ import annotations

import numpy as np
import pytest

from components import Transform
from engine.input import InputState
from engine.scene import Scene
from systems.walking import Body, Walker

DT = 1.0 / 60.0
FORWARD = InputState(move=(0.0, 0.0, -1.0))
STILL = InputState()


def room(*, eye=(0.0, 3.0, 0.0)) -> Scene:
    """A 60 m floor whose top is y = 0 and the camera above it looking down -z."""
    scene = Scene("walk")
    scene.add_mesh("floor", "box", position=(0.0, -0.1, 0.0), scale=(60.0, 0.2, 60.0))
    scene.set_camera(eye, look_at=(eye[0], eye[1], eye[2] - 1.0), speed=3.0)
    return scene


def run(scene: Scene, state: InputState, seconds: float) -> tuple[Walker, np.ndarray]:
    walker = Walker.of(scene, Body())
    for _ in range(round(seconds / DT)):
        walker.step(DT, state)
    eye = np.array(scene.get(scene.camera_entity, Transform).position)
    walker.close()
    return walker, eye


@pytest.fixture
def scenes():
    made: list[Scene] = []
    yield made
    for scene in made:
        scene.close()


def test_gravity_settles_the_eye_at_eye_height(scenes):
    scenes.append(scene := room())
    walker, eye = run(scene, STILL, 2.0)
    assert walker.on_ground and eye[1] == pytest.approx(1.6, abs=1e-6)
    assert eye[0] == pytest.approx(0.0) and eye[2] == pytest.approx(0.0)


def test_a_wall_stops_you(scenes):
    scenes.append(scene := room(eye=(0.0, 1.6, 0.0)))
    scene.add_mesh("wall", "box", position=(0.0, 1.5, -3.0), scale=(10.0, 3.0, 0.2))
    _, eye = run(scene, FORWARD, 3.0)  # 9 m of walking into a wall 2.9 m away
    assert eye[2] == pytest.approx(-2.9 + 0.3, abs=0.02) and eye[1] == pytest.approx(1.6, abs=1e-6)


def test_a_wall_at_an_angle_is_slid_along(scenes):
    scenes.append(scene := room(eye=(0.0, 1.6, 0.0)))
    scene.add_mesh("wall", "box", position=(0.0, 1.5, -2.0), scale=(10.0, 3.0, 0.2))
    _, eye = run(scene, InputState(move=(1.0, 0.0, -1.0)), 1.0)
    assert -1.9 + 0.2 < eye[2] < -1.9 + 0.35 and eye[0] > 1.5  # the radius is kept along the probe, not the normal


def test_a_step_of_0_3_is_climbed_and_a_ramp_too(scenes):
    scenes.append(scene := room(eye=(0.0, 1.6, 0.0)))
    scene.add_mesh("step", "box", position=(0.0, 0.15, -5.0), scale=(4.0, 0.3, 6.0))  # z from -2 to -8
    _, eye = run(scene, FORWARD, 1.5)
    assert eye[2] < -3.0 and eye[1] == pytest.approx(1.9, abs=1e-6)
    scenes.append(ramp := room(eye=(0.0, 1.6, 0.0)))
    ramp.add_mesh("ramp", "box", position=(0.0, 0.0, -6.0), euler_deg=(15.0, 0.0, 0.0), scale=(4.0, 0.2, 8.0))
    _, eye = run(ramp, FORWARD, 3.0)
    top = 0.1 / np.cos(np.radians(15.0)) + (-6.0 - eye[2]) * np.tan(np.radians(15.0))  # the ramp's surface there
    assert eye[2] < -8.0 and eye[1] == pytest.approx(top + 1.6, abs=0.02)  # walked up the slope


def test_a_wall_too_high_to_step_stops_you(scenes):
    scenes.append(scene := room(eye=(0.0, 1.6, 0.0)))
    scene.add_mesh("ledge", "box", position=(0.0, 0.3, -5.0), scale=(4.0, 0.6, 6.0))
    _, eye = run(scene, FORWARD, 1.5)
    assert eye[2] == pytest.approx(-2.0 + 0.3, abs=0.02) and eye[1] == pytest.approx(1.6, abs=1e-6)


def test_a_wall_seen_through_a_portal_stops_you_after_the_teleport(scenes):
    scenes.append(scene := room(eye=(0.0, 1.6, 0.0)))
    door = dict(scale=(1.5, 2.5, 1.0))
    scene.add_portal_pair(
        "a", "b", a=dict(position=(0.0, 1.5, -2.0), **door), b=dict(position=(20.0, 1.5, 0.0), **door)
    )
    scene.add_mesh("wall", "box", position=(20.0, 1.5, -2.0), scale=(10.0, 3.0, 0.2))  # 2 m beyond b, not a
    _, eye = run(scene, FORWARD, 3.0)
    assert eye[0] == pytest.approx(20.0, abs=1e-6) and eye[2] == pytest.approx(-1.9 + 0.3, abs=0.02)
    assert eye[1] == pytest.approx(1.6, abs=1e-6)


def test_a_wall_just_behind_the_far_portal_stops_you_before_it(scenes):
    scenes.append(scene := room(eye=(0.0, 1.6, 0.0)))
    door = dict(scale=(1.5, 2.5, 1.0))
    scene.add_portal_pair(
        "a", "b", a=dict(position=(0.0, 1.5, -2.0), **door), b=dict(position=(20.0, 1.5, 0.0), **door)
    )
    scene.add_mesh("wall", "box", position=(20.0, 1.5, -0.2), scale=(10.0, 3.0, 0.2))  # 0.1 m beyond b
    _, eye = run(scene, FORWARD, 3.0)
    assert eye[0] == pytest.approx(0.0) and eye[2] == pytest.approx(-2.0 - 0.1 + 0.3, abs=0.02)


def test_a_compressed_corridor_is_walked_as_it_looks(scenes):
    """Inside a box that halves z, the wall 4 m (world) ahead is 8 m away as seen, and as walked."""
    scenes.append(scene := room(eye=(0.0, 1.6, 0.0)))
    scene.add_aberration("stretch", (0.0, 0.0, -0.5), position=(0.0, 1.5, -2.0), scale=(6.0, 4.0, 20.0))
    scene.add_mesh("wall", "box", position=(0.0, 1.5, -4.1), scale=(10.0, 3.0, 0.2))
    _, eye = run(scene, FORWARD, 1.0)  # 3 m perceived = 1.5 m world
    assert eye[2] == pytest.approx(-1.5, abs=0.02)
    _, eye = run(scene, FORWARD, 3.0)  # the wall stops you 0.3 m (as seen) short of it: 0.15 m of world
    assert eye[2] == pytest.approx(-4.0 + 0.15, abs=0.02)


def test_ground_below_says_whether_walking_has_a_floor(scenes):
    scenes.append(scene := room())
    walker = Walker.of(scene)
    assert walker.ground_below()
    scene.set_camera((100.0, 3.0, 0.0), look_at=(100.0, 3.0, -1.0))
    assert not walker.ground_below()
    walker.close()
