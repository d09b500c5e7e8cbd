"""Recording the camera while playing: the recorded path, replayed by the real systems, walks the same walk
(through portals and aberrations), and saving it writes a scene file whose camera_path is that path."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from components import Transform
from demos import build_demo
from engine.input import InputState, ScriptedInput
from engine.scene_file import SceneFileError, load_scene, save_scene
from engine.scene_writer import scene_document
from systems.app import App
from systems.camera_path import CameraPath
from systems.camera_recording import INTERVAL, CameraRecorder, save_recording, scene_file_document

DT = 1 / 30


def record(demo: str, states: list[InputState]):
    """Play ``states`` in ``demo`` recording the camera; the keyframes, the start and the end pose."""
    scene = build_demo(demo)
    try:
        start = scene.get(scene.camera_entity, Transform)
        recorder = CameraRecorder(scene)
        with App(scene, input_source=ScriptedInput(states)) as app:
            recorder.start()
            for _ in states:
                app.tick(DT)
                recorder.update(DT)
        return recorder.stop(), start, scene.get(scene.camera_entity, Transform)
    finally:
        scene.close()


def replay(demo: str, keys, start: Transform) -> Transform:
    scene = build_demo(demo)
    try:
        scene.set(scene.camera_entity, start)
        path = CameraPath(keys)
        with App(scene, input_source=path.inputs(scene)) as app:
            app.run(round(path.duration / DT) + 2, DT)
        return scene.get(scene.camera_entity, Transform)
    finally:
        scene.close()


def test_a_recorded_walk_through_portals_replays_to_the_same_pose():
    states = [InputState(move=(0.0, 0.0, -1.0)) for _ in range(240)]  # 8 s straight down the corridor
    keys, start, end = record("endless_corridor", states)
    world = np.linalg.norm(np.subtract(end.position, start.position))
    walked = sum(np.linalg.norm(np.subtract(b.position, a.position)) for a, b in itertools.pairwise(keys))
    assert walked > world + 6.0  # it went through the corridor's portals: the world pose jumped back
    replayed = replay("endless_corridor", keys, start)
    np.testing.assert_allclose(replayed.position, end.position, atol=1e-6)
    np.testing.assert_allclose(replayed.rotation, end.rotation, atol=1e-6)


def test_a_recorded_flight_through_aberrations_replays_to_the_same_pose():
    states = [InputState(move=(0.2, 0.0, -1.0), look=(0.8, 0.1)) for _ in range(120)]
    states += [InputState(move=(0.0, 0.0, -1.0), look=(-0.5, 0.0)) for _ in range(120)]
    keys, start, end = record("aberration_room", states)
    replayed = replay("aberration_room", keys, start)
    # Within the spline's rounding of the steps that cross box faces (4 mm after 8 s here).
    np.testing.assert_allclose(replayed.position, end.position, atol=0.02)
    np.testing.assert_allclose(replayed.rotation, end.rotation, atol=1e-6)


def test_keyframes_come_every_interval_and_at_the_stop():
    keys, _, _ = record("starter", [InputState(move=(0.0, 0.0, -1.0))] * 20)  # 2/3 s
    times = [k.time for k in keys]
    gaps = np.diff(times[:-1])  # a keyframe at the first tick at or past each interval, then one at the stop
    assert times[0] == 0.0 and times[-1] == pytest.approx(20 * DT) and len(times) == 4
    assert np.all(gaps >= INTERVAL - 1e-9) and np.all(gaps < INTERVAL + DT)


def test_a_recording_of_no_time_has_no_keyframes():
    scene = build_demo("starter")
    try:
        recorder = CameraRecorder(scene)
        recorder.start()
        recorder.update(0.0)
        assert recorder.stop() == () and not recorder.recording
    finally:
        scene.close()


def test_save_writes_a_scene_file_holding_the_path(tmp_path):
    keys, _, _ = record("starter", [InputState(move=(0.0, 0.0, -1.0))] * 20)
    scene = build_demo("starter")
    out = tmp_path / "walk.json"
    try:
        save_recording(keys, out, scene_document(scene, tmp_path))
    finally:
        scene.close()
    loaded = load_scene(out)
    try:
        assert [k.time for k in loaded.camera_path] == [k.time for k in keys]
        np.testing.assert_array_equal([k.position for k in loaded.camera_path], [k.position for k in keys])
    finally:
        loaded.close()


def test_save_into_a_scene_file_keeps_what_it_holds_and_replaces_its_path(tmp_path):
    scene = build_demo("endless_corridor")
    path = tmp_path / "level.json"
    try:
        save_scene(scene, path)
    finally:
        scene.close()
    before = json.loads(path.read_text())
    keys, _, _ = record("endless_corridor", [InputState(move=(0.0, 0.0, -1.0))] * 10)
    save_recording(keys, path, scene_file_document(path))
    after = json.loads(path.read_text())
    assert {k: v for k, v in after.items() if k != "camera_path"} == before
    assert len(after["camera_path"]) == len(keys)


def test_a_bad_target_is_one_error_naming_it_and_writes_nothing(tmp_path):
    keys, _, _ = record("starter", [InputState(move=(0.0, 0.0, -1.0))] * 10)
    (tmp_path / "taken.json").mkdir()
    with pytest.raises(SceneFileError, match=r"taken.json: cannot save the recording"):
        save_recording(keys, tmp_path / "taken.json", {"format": "aberrant-scene", "version": 1})
    with pytest.raises(SceneFileError, match=r"x.json: field .camera_path.: cannot save the recording"):
        save_recording(keys[:1], tmp_path / "x.json", {"format": "aberrant-scene", "version": 1})
    assert [p.name for p in tmp_path.iterdir()] == ["taken.json"]


def test_the_record_key_starts_then_stops_and_saves_into_the_scene_file(tmp_path):
    from systems.camera_recording import RecordingSession

    path = tmp_path / "level.json"
    scene = build_demo("starter")
    try:
        save_scene(scene, path)
        session = RecordingSession(scene, path)
        assert "recording" in session.toggle() and session.recording
        with App(scene, input_source=ScriptedInput([InputState(move=(0.0, 0.0, -1.0))] * 30)) as app:
            for _ in range(30):
                app.tick(DT)
                session.update(DT)
        assert session.status().startswith("recording")
        message = session.toggle()
    finally:
        scene.close()
    assert not session.recording and "saved a camera path of 5 keyframes, 1.0 s" in message, message
    loaded = load_scene(path)
    try:
        assert len(loaded.camera_path) == 5 and loaded.camera_path[-1].time == pytest.approx(1.0)
    finally:
        loaded.close()


def test_without_a_file_the_record_key_says_how_and_records_nothing():
    from systems.camera_recording import RecordingSession

    scene = build_demo("starter")
    try:
        session = RecordingSession(scene, None)
        assert "--record" in session.toggle() and not session.recording
    finally:
        scene.close()
