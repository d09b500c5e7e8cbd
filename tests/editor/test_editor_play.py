"""Play mode: the real systems run on a copy; Stop leaves the edited scene byte for byte as it was."""

from __future__ import annotations

import numpy as np
import pytest

from backends.base import Backend
from components import Transform
from editor.model import EditorModel
from editor.play import Keys, PlaySession, input_state, scene_copy
from engine.errors import AberrantError
from engine.input import InputState
from engine.scene import Scene
from engine.scene_file import scene_to_json

FORWARD = InputState(move=(0.0, 0.0, -1.0))


def corridor() -> EditorModel:
    """A camera facing a portal whose twin stands 10 units to the right, and an aberration on the way back."""
    model = EditorModel()
    scene = model.scene
    scene.set_camera((0.0, 1.0, 2.0), rotation=(0.0, 0.0, 0.0, 1.0), speed=3.0)
    scene.add_portal_pair("door", "exit", a={"position": (0.0, 1.0, 0.0)}, b={"position": (10.0, 1.0, 0.0)})
    scene.add_aberration("slow", (-0.5, -0.5, -0.5), position=(10.0, 1.0, -3.0), scale=2.0)
    return model


def test_keys_to_input():
    state = input_state(Keys(forward=True, right=True, sprint=True, mouse_dx=10.0, mouse_dy=-4.0), sensitivity=0.1)
    assert state.move == (1.0, 0.0, -1.0) and state.sprint
    assert state.look == pytest.approx((-1.0, 0.4))  # mouse right turns right (negative yaw), mouse up looks up
    assert input_state(Keys()).idle


def test_play_moves_and_teleports_through_the_real_systems_then_stop_restores():
    model = corridor()
    edited = model.scene
    before = scene_to_json(edited)
    session = PlaySession(edited, None)
    try:
        assert session.scene is not edited and session.scene.world != edited.world
        for _ in range(30):  # 1 s at 3 units/s: through the door at z = 0, out of the exit at x = 10
            session.step(1.0 / 30.0, FORWARD)
        position = session.camera_view.position
        assert position[0] == pytest.approx(10.0, abs=1e-6)
        assert position[2] < 0.0
        assert session.runner.teleport is not None and session.ticks == 30
    finally:
        session.stop()
    assert scene_to_json(edited) == before
    assert edited.get(edited.camera_entity, Transform).position == (0.0, 1.0, 2.0)
    assert session.scene.world not in __import__("esper").list_worlds()
    edited.close()


def test_play_with_a_backend_renders_frames(backend_factory):
    backend = backend_factory("reference")
    model = corridor()
    before = scene_to_json(model.scene)
    session = PlaySession(model.scene, backend, size=(24, 16), aovs=("color",))
    try:
        frame = session.step(1.0 / 30.0, FORWARD)
        assert frame is not None and frame.color.shape == (16, 24, 4)
        session.resize((12, 8))
        assert session.step(1.0 / 30.0).color.shape == (8, 12, 4)
    finally:
        session.stop()
    assert scene_to_json(model.scene) == before
    model.scene.close()


class _Failing(Backend):
    """A backend whose render always fails the way an unsupported feature does."""

    name = "failing"

    @classmethod
    def probe(cls):
        return None

    def upload(self, packed, updates):
        return 0

    def render(self, camera, width, height, aovs=()):
        raise AberrantError("the failing backend does not trace this scene")


def test_a_failing_backend_leaves_play_running_without_renders():
    model = corridor()
    session = PlaySession(model.scene, _Failing(), size=(8, 8))
    try:
        assert session.step(0.1, FORWARD) is None
        assert "does not trace" in session.error and session.backend is None
        start = session.camera_view.position.copy()
        session.step(0.1, FORWARD)
        assert not np.allclose(session.camera_view.position, start)
    finally:
        session.stop()
    model.scene.close()


def test_play_refuses_a_scene_without_camera():
    scene = Scene("no camera")
    scene.add_mesh("box", "box")
    with pytest.raises(AberrantError, match="camera"):
        PlaySession(scene, None)
    scene.close()


def test_scene_copy_keeps_imported_meshes(tmp_path):
    from demos import build_demo

    scene = build_demo("starter")  # imports knot.obj by absolute path
    copy = scene_copy(scene)
    try:
        assert scene_to_json(copy, tmp_path) == scene_to_json(scene, tmp_path)
    finally:
        copy.close()
        scene.close()
