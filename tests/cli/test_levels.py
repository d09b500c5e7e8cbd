"""Levels from anywhere: demo discovery, level modules (``level.py[:func]``), scene files with camera paths."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from aberrant.bench.scenes import resolve_scenes
from aberrant.cli import main
from aberrant.flythrough import path_for
from aberrant.levels import LevelError, open_level
from demos import demo_names, discover
from engine.scene_file import SceneFileError, load_scene, save_scene

GALLERY = [
    "starter", "aberration_room", "aberration_tunnels", "geometry_room", "house", "endless_corridor",
    "bigger_inside", "nested_aberrations", "portal_in_aberration",
]  # fmt: skip

LEVEL = '''
"""A test level: a floor, a box and a path."""
from engine.scene import Scene
from systems.route import Stop, route


def build() -> Scene:
    scene = Scene("tiny")
    scene.add_mesh("floor", "plane", scale=(10.0, 1.0, 10.0))
    scene.add_mesh("box", "box", position=(0.0, 0.5, -2.0))
    scene.set_camera((0.0, 1.6, 4.0), look_at=(0.0, 0.5, -2.0))
    return scene


def other() -> Scene:
    scene = build()
    scene.name = "other"
    return scene


def camera_path():
    scene = build()
    try:
        return route(scene, [Stop((0.0, 1.6, 4.0), (0.0, 0.5, -2.0)), Stop((0.0, 1.6, 1.0), (0.0, 0.5, -2.0))])
    finally:
        scene.close()


def broken() -> Scene:
    raise ValueError("the architect forgot the walls")


def not_a_scene():
    return 42
'''

PATH_FILE = {
    "format": "aberrant-scene",
    "version": 1,
    "camera": {"position": [0, 1.6, 5]},
    "entities": [{"name": "floor", "mesh": {"asset": "plane"}, "transform": {"scale": 10}}],
    "camera_path": [
        {"time": 0, "position": [0, 1.6, 5], "look_at": [0, 1, 0]},
        {"time": 3, "position": [0, 1.6, 1], "rotation": [0, 0, 0, 1]},
    ],
}


@pytest.fixture
def level_file(tmp_path: Path) -> Path:
    path = tmp_path / "my_level.py"
    path.write_text(LEVEL)
    return path


def write_json(path: Path, doc: object) -> Path:
    import json

    path.write_text(json.dumps(doc))
    return path


# --- demo discovery -------------------------------------------------------------------------------------------


def test_demos_are_discovered_in_gallery_order():
    assert demo_names()[: len(GALLERY)] == GALLERY


def test_discovery_orders_by_ORDER_then_name_and_skips_non_levels(tmp_path):
    def module(name: str, body: str) -> None:
        (tmp_path / f"{name}.py").write_text(textwrap.dedent(body))

    module("zebra", "ORDER = 1\ndef build(): pass\n")
    module("alpha", "ORDER = 0\ndef build(): pass\n")
    module("hotel", "def build(): pass\n")  # a new demo, no ORDER: after the ordered ones, alphabetically
    module("bakery", "def build(): pass\n")
    module("kit", "def build(): pass\n")
    module("_private", "def build(): pass\n")
    module("helpers", "def make(): pass\n")  # no build(): not a level
    module("typo", "def build(:\n")  # listed, so building it reports the syntax error
    assert discover(tmp_path) == ["alpha", "zebra", "bakery", "hotel", "typo"]


# --- level modules ----------------------------------------------------------------------------------------------


def test_a_level_module_builds_with_its_camera_path(level_file):
    with open_level(str(level_file)) as level:
        assert level.scene.name == "tiny" and level.kind == "code"
        path = level.camera_path()
        assert path is not None and path.duration > 1.0
    with open_level(f"{level_file}:other") as level:
        assert level.scene.name == "other"


@pytest.mark.parametrize(
    ("suffix", "message"),
    [
        (":nothing", "my_level.py: no function 'nothing' (functions: broken, build, camera_path, not_a_scene, other)"),
        (":broken", "my_level.py:broken() raised ValueError: the architect forgot the walls (line"),
        (":not_a_scene", "my_level.py:not_a_scene() returned int, not a Scene"),
    ],
)
def test_level_module_mistakes_name_file_and_function(level_file, suffix, message):
    with pytest.raises(LevelError) as e:
        open_level(f"{level_file}{suffix}")
    assert message in str(e.value)


def test_a_missing_or_unparsable_level_file_is_named(tmp_path):
    with pytest.raises(LevelError, match=r"nope\.py: level file not found"):
        open_level(str(tmp_path / "nope.py"))
    bad = tmp_path / "bad.py"
    bad.write_text("def build(:\n    pass\n")
    with pytest.raises(LevelError, match=r"bad\.py: line 1: syntax error"):
        open_level(str(bad))
    raising = tmp_path / "raising.py"
    raising.write_text("x = 1\nimport no_such_module_here\n")
    with pytest.raises(LevelError, match=r"raising\.py: importing it raised ModuleNotFoundError: .* \(line 2\)"):
        open_level(str(raising))


def test_cli_level_errors_are_one_line_exit_2(level_file, tmp_path, capsys):
    code = main(["render", f"{level_file}:broken", "--backend", "reference", "--out", str(tmp_path / "f.png")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "my_level.py:broken() raised ValueError" in err
    assert not (tmp_path / "f.png").exists()
    assert main(["render", "no_such_thing", "--out", str(tmp_path / "f.png")]) == 2
    assert "neither a scene file (.json), a level module (.py) nor a demo" in capsys.readouterr().err


def test_cli_renders_a_level_module_and_its_flythrough(level_file, tmp_path, capsys):
    out = tmp_path / "frame.png"
    assert main(["render", str(level_file), "--backend", "reference", "--size", "32x24", "--out", str(out)]) == 0
    assert out.is_file()
    gif = tmp_path / "walk.gif"
    argv = ["render", f"{level_file}:build", "--path", "--frames", "2", "--size", "16x12", "--backend", "reference"]
    assert main([*argv, "--out", str(gif)]) == 0, capsys.readouterr().err
    assert gif.is_file()


# --- scene files with camera paths ----------------------------------------------------------------------------


def test_a_scene_files_camera_path_is_read_written_and_used(tmp_path):
    path = write_json(tmp_path / "walk.json", PATH_FILE)
    with open_level(str(path)) as level:
        assert len(level.scene.camera_path) == 2
        assert path_for(level).duration == 3.0  # the file's path, not the default walk
        save_scene(level.scene, tmp_path / "again.json")
    again = load_scene(tmp_path / "again.json")
    try:
        assert again.camera_path == level.scene.camera_path
        assert again.camera_path[0].look_at == (0.0, 1.0, 0.0)  # kept in the form it was given
    finally:
        again.close()


@pytest.mark.parametrize(
    ("keys", "field", "message"),
    [
        ([{"time": 0, "position": [0, 0, 0], "look_at": [0, 0, -1]}], "camera_path", "at least 2 keyframes"),
        (
            [{"time": 0, "position": [0, 0, 0], "look_at": [0, 0, -1]}, {"time": 1, "position": [0, 0, 1]}],
            "camera_path[1].rotation",
            "exactly one of rotation or look_at",
        ),
        (
            [
                {"time": 1, "position": [0, 0, 0], "look_at": [0, 0, -1]},
                {"time": 0.5, "position": [0, 0, 1], "look_at": [0, 0, -1]},
            ],
            "camera_path[1].time",
            "increase strictly",
        ),
        ([{"time": 0, "position": [0, 0], "look_at": [0, 0, -1]}] * 2, "camera_path[0].position", "3 finite numbers"),
        ([{"time": 0, "speed": 2}], "camera_path[0].speed", "unknown key"),
    ],
)  # fmt: skip
def test_bad_camera_path_keyframes_name_the_field(tmp_path, keys, field, message):
    path = write_json(tmp_path / "bad.json", {**PATH_FILE, "camera_path": keys})
    with pytest.raises(SceneFileError) as e:
        load_scene(path)
    assert f"field {field!r}" in str(e.value) and message in str(e.value)


def test_bench_takes_scene_files_and_level_modules(level_file, tmp_path):
    scene_file = write_json(tmp_path / "walk.json", PATH_FILE)
    specs = resolve_scenes(["ten-boxes", str(scene_file), f"{level_file}:other"])
    assert [s.name for s in specs] == ["ten-boxes", str(scene_file), f"{level_file}:other"]
    scene = specs[2].build(tmp_path)
    try:
        assert scene.name == "other"
    finally:
        scene.close()
    with pytest.raises(LevelError, match="broken"):
        resolve_scenes([f"{level_file}:broken"])
