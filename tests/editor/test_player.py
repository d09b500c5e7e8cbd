"""``aberrant play``: one-line errors without a display, and the player in a real window (Xvfb) walking a demo."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("imgui_bundle", reason="the editor extra is not installed: pip install 'aberrant[editor]'")

from test_editor_window import display  # noqa: F401  (the Xvfb fixture)

from aberrant.cli import main

ROOT = Path(__file__).resolve().parents[2]

#: Runs in the subprocess: play a demo for some frames with W held, then Tab to fly, and report.
SCRIPT = r"""
import json
from imgui_bundle import imgui
from aberrant.levels import open_level
from components import Transform
from editor.player import PlayerWindow
level = open_level("starter")
level.scene.set_camera((2.3, 2.2, 3.0), look_at=(0.0, 1.15, -1.6))  # over the floor (the demo's camera is not)
window = PlayerWindow(level.scene, size=(320, 240), backend="reference")
camera = level.scene.camera_entity
start = list(level.scene.get(camera, Transform).position)
window.run(frames=20)
settled = list(level.scene.get(camera, Transform).position)
imgui.get_io().add_key_event(imgui.Key.w, True)
drawn = window.run(frames=10)
imgui.get_io().add_key_event(imgui.Key.w, False)
walked = list(level.scene.get(camera, Transform).position)
imgui.get_io().add_key_event(imgui.Key.tab, True)
window.frame()
imgui.get_io().add_key_event(imgui.Key.tab, False)
window.frame()
report = dict(start=start, settled=settled, walked=walked, drawn=drawn, traced=window.host.frames,
              flying=window.flying, on_ground=window.walker.on_ground, errors=window.errors)
window.close()
print("REPORT " + json.dumps(report))
"""


def test_no_display_is_a_one_line_error(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["play", "starter"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "player needs a display" in err and "xvfb-run aberrant play" in err


def test_a_bad_level_or_size_fails_before_a_window(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("DISPLAY", ":424242")  # never contacted
    assert main(["play", "starter", "--size", "0x3"]) == 2
    assert "--size" in capsys.readouterr().err
    assert main(["play", str(tmp_path / "missing.json")]) == 2
    assert "missing.json" in capsys.readouterr().err


def test_the_player_walks_a_demo_in_a_window(display):  # noqa: F811
    report = run_script(SCRIPT, display)
    assert report["errors"] == [] and report["drawn"] == 10 and report["traced"] >= 30
    assert report["on_ground"] and report["settled"][1] < report["start"][1] + 1e-9  # gravity put it on the floor
    assert report["walked"][2] < report["settled"][2] - 0.05  # W walked forward (-z)
    assert report["flying"]  # Tab switched to fly


def test_the_readme_lists_the_player_keys():
    from editor.keys import PLAYER

    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for binding in PLAYER.values():
        assert f"`{binding.label}` {binding.does}" in readme


#: Runs in the subprocess: play a scene file, save a change, break it, fix it; report what the window played.
RELOAD_SCRIPT = r"""
import json, os, sys
from pathlib import Path
from aberrant.levels import open_level
from components import Transform
from editor.player import PlayerWindow
from editor.reload import LevelWatcher
from engine.scene import Scene
from engine.scene_file import save_scene

path = Path(sys.argv[1])
def save(x, text=None):
    old = path.stat() if path.exists() else None
    if text is None:
        scene = Scene("reload")
        scene.add_mesh("floor", "plane", scale=(20.0, 1.0, 20.0))
        scene.add_mesh("box", "box", position=(x, 0.5, 0.0))
        scene.set_camera((0.0, 1.7, 5.0), look_at=(0.0, 1.0, 0.0))
        save_scene(scene, path)
        scene.close()
    else:
        path.write_text(text)
    if old is not None:
        os.utime(path, ns=(old.st_atime_ns, old.st_mtime_ns + 10**9))
def box():
    return window.scene.get(window.scene.entity("box"), Transform).position[0]
save(1.0)
level = open_level(path)
watcher = LevelWatcher(path, lambda: open_level(path).scene, level.scene, period=0.0)
window = PlayerWindow(level.scene, size=(160, 120), backend="reference", fly=True, watcher=watcher)
window.run(frames=2)
camera = Transform(position=(2.0, 3.0, 4.0), rotation=window.scene.get(window.scene.camera_entity, Transform).rotation)
window.scene.set(window.scene.camera_entity, camera)
save(2.0)
window.frame()
kept = window.scene.get(window.scene.camera_entity, Transform) == camera
reloaded = [box(), window.scene is not level.scene]
save(0.0, "{ not json")
window.frame()
broken = [box(), watcher.error]
save(3.0)
window.run(frames=2)
report = dict(kept=kept, reloaded=reloaded, broken=broken, fixed=[box(), watcher.error], errors=window.errors)
window.close()
level.close()
print("REPORT " + json.dumps(report))
"""


def run_script(script: str, screen: str, *args: str) -> dict:
    """Run a player script on the Xvfb display ``screen``; its REPORT line (skips where the window cannot open)."""
    env = {"DISPLAY": screen, **{k: v for k, v in __import__("os").environ.items() if k != "DISPLAY"}}
    result = subprocess.run(
        [sys.executable, "-c", script, *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=240
    )
    if "needs a display" in result.stderr or "GLX" in result.stderr:
        pytest.skip(f"the player window cannot open here: {result.stderr.strip().splitlines()[-1]}")
    lines = [line for line in result.stdout.splitlines() if line.startswith("REPORT ")]
    assert result.returncode == 0 and lines, result.stderr
    return json.loads(lines[-1][len("REPORT ") :])


def test_the_player_reloads_a_saved_level_and_keeps_the_last_good_one(display, tmp_path):  # noqa: F811
    report = run_script(RELOAD_SCRIPT, display, str(tmp_path / "level.json"))
    assert report["errors"] == [] and report["kept"] and report["reloaded"] == [2.0, True]
    assert report["broken"][0] == 2.0 and "level.json" in report["broken"][1] and "JSON" in report["broken"][1]
    assert report["fixed"] == [3.0, None]


#: Runs in the subprocess: play a scene file, press R, fly forward, press R again; report what was saved.
RECORD_SCRIPT = r"""
import json, sys
from pathlib import Path
from imgui_bundle import imgui
from aberrant.levels import open_level
from editor.player import PlayerWindow

path = Path(sys.argv[1])
level = open_level(path)
window = PlayerWindow(level.scene, size=(160, 120), backend="reference", fly=True, record=path)
window.run(frames=2)
def press(key):
    imgui.get_io().add_key_event(key, True)
    window.frame()
    imgui.get_io().add_key_event(key, False)
    window.frame()
press(imgui.Key.r)
started = window.recording.recording
imgui.get_io().add_key_event(imgui.Key.w, True)
window.run(frames=12)
imgui.get_io().add_key_event(imgui.Key.w, False)
press(imgui.Key.r)
report = dict(started=started, stopped=not window.recording.recording, notice=window.notice, errors=window.errors)
window.close()
level.close()
print("REPORT " + json.dumps(report))
"""


def test_the_record_key_saves_the_played_camera_path_into_the_scene_file(display, tmp_path):  # noqa: F811
    from engine.scene_file import load_scene, save_scene

    path = tmp_path / "level.json"
    scene = __import__("demos").build_demo("starter")
    save_scene(scene, path)
    scene.close()
    report = run_script(RECORD_SCRIPT, display, str(path))
    assert report["errors"] == [] and report["started"] and report["stopped"], report
    assert report["notice"].startswith("saved a camera path of"), report
    loaded = load_scene(path)
    try:
        path_keys = loaded.camera_path
        assert len(path_keys) >= 2 and path_keys[-1].position[2] < path_keys[0].position[2]  # W flew forward (-z)
    finally:
        loaded.close()


def test_cli_play_refuses_a_record_file_that_is_no_scene_file(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("DISPLAY", ":424242")  # never contacted
    assert main(["play", "starter", "--record", str(tmp_path / "walk.txt")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--record" in err and ".json" in err
    assert main(["play", "starter", "--record", str(tmp_path / "missing" / "walk.json")]) == 2
    assert "does not exist" in capsys.readouterr().err
