"""Regressions: the crashes the fuzzing of scene files and TelloEngine scene files found
(``test_fuzz_scene_files.py``), each an uncaught exception before its fix, pinned as plain tests: a
:class:`SceneFileError` or one ``aberrant: error:`` line naming the file and field, or a clean load.
"""

from __future__ import annotations

import json
from typing import Any

import pytest
from test_fuzz_scene_files import TELLO, doc_with, expect_error, run_cli, tello_required

from engine.scene import Scene
from engine.scene_file import SceneFileError, load_scene, save_scene


def test_integer_literal_over_4300_digits_is_malformed_json(tmp_path):
    """json raised a bare ValueError (int_max_str_digits) from load_scene."""
    path = tmp_path / "huge.json"
    path.write_text('{"format": "aberrant-scene", "version": 1, "settings": {"max_events": ' + "9" * 5000 + "}}")
    expect_error(path, "malformed JSON", "too long")


def test_integer_too_large_for_a_float_names_the_field(tmp_path):
    """float(10**400) raised OverflowError inside components.validation.real."""
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc_with(camera={"position": [10**400, 0, 0]})))
    expect_error(path, "camera.position[0]", "must be finite")


def test_priority_beyond_int32_is_rejected_at_load(tmp_path):
    """A priority of 2**40 loaded, then packing it as int32 raised OverflowError at render time."""
    path = tmp_path / "scene.json"
    entity = {"name": "box", "aberration": {"deformation": [0.5, 0, 0], "priority": 2**40}}
    path.write_text(json.dumps(doc_with(entities=[entity])))
    expect_error(path, "entity 'box'", "aberration.priority")


def test_look_at_whose_direction_overflows_names_the_field(tmp_path):
    """look_at_quat raised ValueError (zero-length vector) when eye - target overflowed."""
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc_with(camera={"position": [-1e308, 0, 0], "look_at": [1e308, 0, 0]})))
    expect_error(path, "camera.look_at")


def test_lone_surrogate_is_rejected_at_load_naming_the_field(tmp_path):
    """ "\\udc80" loaded, then save_scene raised UnicodeEncodeError: a file that could never be saved again."""
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc_with(entities=[{"name": "ok"}, {"name": "bad\udc80"}])))
    expect_error(path, "entities[1].name", "surrogate")


def test_valid_surrogate_pairs_still_load_and_round_trip(tmp_path):
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc_with(name="emoji \U0001f600", entities=[{"name": "\U0001f600"}])))
    scene = load_scene(path)
    try:
        save_scene(scene, tmp_path / "again.json")
    finally:
        scene.close()
    assert "\U0001f600" in (tmp_path / "again.json").read_text(encoding="utf-8")


def test_saving_a_name_that_is_not_unicode_is_a_scene_file_error(tmp_path):
    """A scene built in code with a lone surrogate in a name: SceneFileError, not UnicodeEncodeError."""
    scene = Scene("bad")
    try:
        scene.add_mesh("x\ud800", "box")
        with pytest.raises(SceneFileError, match="not valid Unicode"):
            save_scene(scene, tmp_path / "scene.json")
    finally:
        scene.close()
    assert list(tmp_path.iterdir()) == []


def test_nul_byte_in_an_asset_path_is_an_error_naming_the_asset(tmp_path):
    """Path.resolve raised ValueError (embedded null byte) from AssetLibrary.load."""
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc_with(assets={"a": {"path": "a\u0000.obj"}})))
    expect_error(path, "asset 'a'", "assets.a", "not a usable file path")


def test_extreme_values_render_without_numpy_warnings_on_stderr(tmp_path):
    """Valid but extreme values (a 1e300 checker, 1e30 positions) printed numpy RuntimeWarnings from the CLI."""
    entities = [
        {
            "name": "far",
            "transform": {"position": [1e30, 0, 0], "scale": 1e30},
            "mesh": {"asset": "box", "checker": 1e300},
        },
        {"name": "floor", "mesh": {"asset": "plane"}},
    ]
    path = tmp_path / "scene.json"
    path.write_text(
        json.dumps(
            doc_with(camera={"position": [0, 1, 3]}, settings={"light_dir": [1e200, 1e200, 0]}, entities=entities)
        )
    )
    png = tmp_path / "out.png"
    code, _, stderr = run_cli(["render", str(path), "--backend", "reference", "--size", "8x6", "--out", str(png)])
    assert (code, stderr) == (0, "")
    assert png.is_file()


def tello_doc(*objects: dict[str, Any]) -> bytes:
    return json.dumps({"scene_name": "T", "game_objects": list(objects)}).encode() + b"\0"


def tello_object(uuid: int, *components: dict[str, Any], parent: int = 0) -> dict[str, Any]:
    return {"uuid": uuid, "parent": parent, "name": f"o{uuid}", "components": list(components)}


def tello_transform(
    position: list[float] | None = None, rotation: list[float] | None = None, scale: list[float] | None = None
) -> dict[str, Any]:
    return {
        "type": 0,
        "position": position or [0, 0, 0],
        "rotation": rotation or [0, 0, 0, 1],
        "scale": scale or [1, 1, 1],
    }


ABERRATION = {"type": 6, "deformationX": 1.0, "deformationY": 0.0, "deformationZ": 0.0}


def tello_pair(first: dict[str, Any], second: dict[str, Any], *, child: bool) -> bytes:
    """Two objects, the second an aberration (a child of the first when ``child``)."""
    return tello_doc(tello_object(1, first, *([] if child else [ABERRATION])),
                     tello_object(2, second, ABERRATION, parent=1 if child else 0))  # fmt: skip


TELLO_REGRESSIONS: list[tuple[str, bytes, tuple[str, ...]]] = [
    # quat_normalize overflowed to a zero quaternion: Transform raised ValidationError
    ("quaternion overflow", tello_doc(tello_object(1, tello_transform(rotation=[1e308, 1e308, 0, 0]), ABERRATION)),
     ("game object 1", "rotation", "cannot be normalised")),
    # parent scale x child position overflowed to inf: quat_to_matrix raised ValueError, or NaN reached the camera
    ("world transform overflow",
     tello_pair(tello_transform(scale=[1e300] * 3), tello_transform(position=[1e300, 0, 0]), child=True),
     ("game object 2", "overflows or collapses")),
    # a world scale that underflows to zero: Transform raised ValidationError
    ("world scale underflow",
     tello_pair(tello_transform(scale=[1e-7] * 3), tello_transform(scale=[1e-7] * 3), child=True),
     ("game object 2", "overflows or collapses")),
    # bounds of far-apart objects overflowed: numpy warnings on stderr, then a NaN camera position
    ("default camera overflow",
     tello_pair(tello_transform(position=[0, 0, -1.7e308], scale=[1e30, 1, 1]),
                tello_transform(position=[0, 0, 1.7e308], scale=[1e30, 1, 1]), child=False),
     ("default camera",)),
    # json raised a bare ValueError / RecursionError
    ("huge integer", b'{"game_objects": [{"uuid": ' + b"1" * 5000 + b"}]}\0", ("too long",)),
    ("deep nesting", b'{"game_objects": ' + b"[" * 200_000 + b"]" * 200_000 + b"}\0", ("nested too deeply",)),
]  # fmt: skip


@pytest.mark.parametrize(
    ("data", "words"), [(d, w) for _, d, w in TELLO_REGRESSIONS], ids=[n for n, _, _ in TELLO_REGRESSIONS]
)
def test_tello_import_regressions_fail_with_one_line(tmp_path, data, words):
    tello_required()
    source = tmp_path / "Scene"
    source.write_bytes(data)
    out = tmp_path / "scene.json"
    code, _, stderr = run_cli(["import-tello", str(source), "--mesh-dir", str(TELLO / "Mesh"), "--out", str(out)])
    assert code == 2, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("aberrant: error: "), stderr
    for word in words:
        assert word in lines[0], lines[0]
    assert not out.exists()
