"""glTF export: every demo written as GLB and read back is the same scene and the same frame; bad outputs and
hostile extras are one line and exit 2."""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import aberrant
from aberrant.cli import main
from aberrant.exporters.gltf import export_gltf, gltf_document
from aberrant.importers.gltf import load_gltf
from backends.reference.backend import ReferenceBackend
from components import Aberration, Camera, Mesh, Portal, Transform
from demos import build_demo, demo_names
from engine.keyframes import Keyframe
from engine.scene import Scene
from systems.app import render_once

SIZE = (48, 36)
#: The AOVs compared bit for bit; ``instance`` holds entity ids, compared by the entities' names.
PLAIN_AOVS = ("color", "depth", "perceived", "events")


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def reference():
    with ReferenceBackend() as backend:
        yield backend


def assert_same_scene(original: Scene, loaded: Scene) -> None:
    """Same names, settings, camera path and components (mesh assets compared by their triangles)."""
    assert original.settings == loaded.settings
    assert original.camera_path == loaded.camera_path
    names = {original.name_of(e) for e in original.entities()}
    assert names == {loaded.name_of(e) for e in loaded.entities()}
    assert original.name_of(original.camera_entity) == loaded.name_of(loaded.camera_entity)
    for name in names:
        a, b = original.entity(name), loaded.entity(name)
        for kind in (Aberration, Portal, Camera):
            assert original.try_get(a, kind) == loaded.try_get(b, kind), (name, kind)
        ta, tb = original.get(a, Transform), loaded.get(b, Transform)
        for field in ("position", "rotation", "scale"):
            if a == original.camera_entity and field == "scale":
                continue  # a glTF camera node has no scale
            np.testing.assert_allclose(getattr(ta, field), getattr(tb, field), rtol=0, atol=1e-6)
        ma, mb = original.try_get(a, Mesh), loaded.try_get(b, Mesh)
        assert (ma is None) == (mb is None), name
        if ma is not None and mb is not None:
            assert (ma.color, ma.checker, ma.cull_backfaces) == (mb.color, mb.checker, mb.cull_backfaces), name
            assert (ma.smooth, ma.crease_deg) == (mb.smooth, mb.crease_deg), name
            ia, ib = original.texture(ma), loaded.texture(mb)
            assert (ia is None) == (ib is None), name
            if ia is not None and ib is not None:
                np.testing.assert_array_equal(ia.pixels, ib.pixels)
            ga, gb = original.asset(ma.asset), loaded.asset(mb.asset)
            np.testing.assert_array_equal(ga.vertices, gb.vertices)
            np.testing.assert_array_equal(ga.faces, gb.faces)
            assert (ga.uvs is None) == (gb.uvs is None), name
            if ga.uvs is not None:
                np.testing.assert_allclose(ga.uvs, gb.uvs, rtol=0, atol=1e-6)


def assert_same_frame(original: Scene, loaded: Scene, backend) -> None:
    a, b = render_once(original, backend, SIZE), render_once(loaded, backend, SIZE)
    for aov in PLAIN_AOVS:
        np.testing.assert_array_equal(a.aov(aov), b.aov(aov), err_msg=aov)
    ids = {e: loaded.entity(original.name_of(e)) for e in original.entities()}
    mapped = np.vectorize(lambda e: ids.get(int(e), -1))(a.aov("instance")) if a.aov("instance").size else []
    np.testing.assert_array_equal(mapped, b.aov("instance"))


@pytest.mark.parametrize("demo", demo_names())
def test_every_demo_comes_back_from_glb_as_the_same_scene_and_frame(demo, tmp_path, reference):
    original = build_demo(demo)
    try:
        export_gltf(original, tmp_path / f"{demo}.glb")
        loaded = load_gltf(tmp_path / f"{demo}.glb")
        try:
            assert_same_scene(original, loaded)
            assert_same_frame(original, loaded, reference)
        finally:
            loaded.close()
    finally:
        original.close()


def test_settings_camera_path_checker_and_uvs_round_trip_through_gltf_text(tmp_path, reference):
    scene = aberrant.Scene("odd", settings=aberrant.Settings(background=(0.1, 0.2, 0.3), max_events=5, ambient=0.2))
    scene.add_mesh("ball", "sphere", position=(0, 1, -4), checker=0.125, cull_backfaces=True, color=(0.3, 0.6, 0.9))
    scene.add_mesh("floor", "plane", scale=(10, 1, 10), checker=1.0)
    scene.add_aberration("squeeze", (0.5, 0, -0.25), position=(0, 1, -4), scale=(2, 2, 2), priority=2)
    scene.add_portal_pair("a", "b", a=dict(position=(-3, 1, -2)), b=dict(position=(3, 1, -2), euler_deg=(0, 180, 0)))
    scene.set_camera((0, 1.6, 3), look_at=(0, 1, -4), fov_deg=47.5, speed=2.5)
    scene.camera_path = (Keyframe(0.0, (0.0, 1.6, 3.0), look_at=(0.0, 1.0, -4.0)),
                         Keyframe(2.0, (0.0, 1.6, 1.0), rotation=(0.0, 0.0, 0.0, 1.0)))  # fmt: skip
    try:
        export_gltf(scene, tmp_path / "odd.gltf")
        doc = json.loads((tmp_path / "odd.gltf").read_text())
        assert doc["buffers"][0]["uri"].startswith("data:")  # one self-contained file
        loaded = load_gltf(tmp_path / "odd.gltf")
        try:
            assert_same_scene(scene, loaded)
            assert_same_frame(scene, loaded, reference)
        finally:
            loaded.close()
    finally:
        scene.close()


def test_the_document_instances_each_asset_once_and_marks_boxes_and_quads():
    scene = build_demo("aberration_room")
    try:
        doc, blob = gltf_document(scene)
    finally:
        scene.close()
    positions = [m["primitives"][0]["attributes"]["POSITION"] for m in doc["meshes"]]
    by_asset: dict[str, set[int]] = {}
    for mesh, accessor in zip(doc["meshes"], positions, strict=True):
        by_asset.setdefault(mesh["name"], set()).add(accessor)
    assert all(len(accessors) == 1 for accessors in by_asset.values())  # shared vertex data per asset
    assert len(set(positions)) == len(by_asset)
    boxes = [n for n in doc["nodes"] if "aberration" in n.get("extras", {}).get("aberrant", {})]
    assert boxes and all(doc["meshes"][n["mesh"]]["name"] == "aberration_box" for n in boxes)
    cameras = [n for n in doc["nodes"] if "camera" in n]
    assert len(cameras) == 1 and "speed" in cameras[0]["extras"]["aberrant"]["camera"]
    names = [n["name"] for n in doc["nodes"]]
    assert len(set(names)) == len(names)
    assert len(blob) == doc["buffers"][0]["byteLength"] and len(blob) % 4 == 0


def test_cli_export_writes_a_glb_that_renders(tmp_path, capsys):
    out = tmp_path / "corridor.glb"
    assert main(["export", "endless_corridor", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out and out.read_bytes()[:4] == b"glTF"
    png = tmp_path / "corridor.png"
    assert main(["render", str(out), "--backend", "reference", "--size", "32x24", "--out", str(png)]) == 0
    assert png.is_file()


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda d: d / "missing" / "x.glb", "does not exist"),
        (lambda d: d / "x.obj", ".glb or .gltf"),
        (lambda d: (d / "folder.glb").mkdir() or d / "folder.glb", "a directory"),
        (lambda d: os.mkfifo(d / "pipe.glb") or d / "pipe.glb", "a FIFO"),
    ],
    ids=["no-folder", "suffix", "directory", "fifo"],
)
def test_cli_export_refuses_bad_outputs_in_one_line(tmp_path, capsys, make, needle):
    out = make(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["export", "starter", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err and out.name in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing partial left


def test_an_entity_that_is_two_nodes_is_refused(tmp_path, capsys):
    scene = aberrant.Scene("both")
    scene.create_entity("odd", Transform(), Mesh("box"), Aberration())
    try:
        with pytest.raises(aberrant.AberrantError, match=r"both.glb.*'odd'.*not several"):
            export_gltf(scene, tmp_path / "both.glb")
    finally:
        scene.close()
    assert not (tmp_path / "both.glb").exists()


def _tamper(path: Path, change) -> None:
    """Edit the JSON chunk of a GLB in place (the binary chunk kept)."""
    data = path.read_bytes()
    (length,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20 : 20 + length])
    change(doc)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    rest = data[20 + length :]
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text + rest
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)


def _node(doc: dict[str, Any], name: str) -> dict[str, Any]:
    return next(n for n in doc["nodes"] if n["name"] == name)


def _material_of(doc: dict[str, Any], name: str) -> dict[str, Any]:
    return doc["materials"][doc["meshes"][_node(doc, name)["mesh"]]["primitives"][0]["material"]]


@pytest.mark.parametrize(
    ("change", "needles"),
    [
        (lambda d: _material_of(d, "floor")["extras"]["aberrant"].update(checker="fine"),
         ["node 'floor'", "extras.aberrant.checker", "expected a cell size"]),
        (lambda d: _material_of(d, "floor")["extras"]["aberrant"].update(checker=-1),
         ["node 'floor'", "materials[", "extras.aberrant.checker"]),
        (lambda d: _node(d, "camera")["extras"]["aberrant"]["camera"].update(speed=-3),
         ["node 'camera'", "extras.aberrant.camera.speed"]),
        (lambda d: _node(d, "camera")["extras"]["aberrant"]["camera"].update(zoom=2),
         ["node 'camera'", "extras.aberrant.camera", "only 'speed'"]),
        (lambda d: _node(d, "floor").setdefault("extras", {}).update(aberrant={"camera": {"speed": 1}}),
         ["node 'floor'", "extras.aberrant.camera", "only a camera node"]),
        (lambda d: d["scenes"][0]["extras"]["aberrant"]["settings"].update(max_events="many"),
         ["scenes[0].extras.aberrant.settings.max_events"]),
        (lambda d: d["scenes"][0]["extras"]["aberrant"].update(lights=[]),
         ["scenes[0].extras.aberrant.lights", "unknown key"]),
        (lambda d: d["scenes"][0]["extras"]["aberrant"].update(camera_path=[{"time": 0, "position": [0, 0, 0]}]),
         ["scenes[0].extras.aberrant.camera_path"]),
    ],
    ids=["checker-type", "checker-negative", "camera-speed", "camera-key", "camera-on-mesh", "settings", "scene-key",
         "camera-path"],
)  # fmt: skip
def test_hostile_extras_are_one_line_naming_file_node_and_field(tmp_path, capsys, change, needles):
    path = tmp_path / "level.glb"
    assert main(["export", "starter", str(path)]) == 0
    capsys.readouterr()
    _tamper(path, change)
    assert main(["render", str(path), "--backend", "reference", "--size", "8x6", "--out", str(tmp_path / "f.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "level.glb" in err, err
    for needle in needles:
        assert needle in err, err
    assert not (tmp_path / "f.png").exists()


EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "blender"


def test_the_blender_example_is_what_its_script_makes_and_renders_through_its_portal(tmp_path, reference):
    import subprocess
    import sys

    made = tmp_path / "two_rooms.glb"
    env = {**os.environ, "PYTHONPATH": str(EXAMPLE.parents[1])}
    subprocess.run([sys.executable, str(EXAMPLE / "make_two_rooms.py"), str(made)], check=True, env=env, timeout=120)
    assert made.read_bytes() == (EXAMPLE / "two_rooms.glb").read_bytes()  # the checked-in file is reproducible
    scene = load_gltf(EXAMPLE / "two_rooms.glb")
    try:
        assert len(scene.query(Portal)) == 2 and len(scene.query(Aberration)) == 1
        frame = render_once(scene, reference, (64, 48))
    finally:
        scene.close()
    events = frame.aov("events")
    assert (events > 0).any() and (events == 0).mean() > 0.5  # the doorway shows the other room, the rest is room A
