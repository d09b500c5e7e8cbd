"""Angles given as angles are saved as angles: ``euler_deg`` in a scene file (or the builder) survives a save."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from components import Transform
from engine.maths import quat_from_axis_angle, quat_to_euler_deg
from engine.scene import Scene
from engine.scene_file import load_scene, save_scene, scene_to_json

AUTHORED = {
    "format": "aberrant-scene",
    "version": 1,
    "name": "angles",
    "camera": {"position": [0, 1.6, 5], "euler_deg": [-10, 15, 0]},
    "entities": [
        {"name": "crate", "transform": {"position": [2, 0.5, -3], "euler_deg": [0, 30, 0]}, "mesh": {"asset": "box"}},
        {"name": "door", "transform": {"euler_deg": [0, -90, 0]}, "portal": {}},
        {"name": "ball", "transform": {"rotation": [0, 0, 0, 1]}, "mesh": {"asset": "sphere"}},
    ],
}


def doc_of(text: str) -> dict:
    return json.loads(text)


def transforms(doc: dict) -> dict[str, dict]:
    return {e["name"]: e["transform"] for e in doc["entities"]}


def test_euler_deg_is_saved_as_the_same_angles_and_round_trips(tmp_path: Path):
    source = tmp_path / "authored.json"
    source.write_text(json.dumps(AUTHORED))
    scene = load_scene(source)
    first = tmp_path / "first.json"
    save_scene(scene, first)
    saved = doc_of(first.read_text())
    assert transforms(saved)["crate"]["euler_deg"] == [0.0, 30.0, 0.0] and "rotation" not in transforms(saved)["crate"]
    assert transforms(saved)["door"]["euler_deg"] == [0.0, -90.0, 0.0]
    assert transforms(saved)["ball"]["rotation"] == [0.0, 0.0, 0.0, 1.0]  # a quaternion stays a quaternion
    assert saved["camera"]["euler_deg"] == [-10.0, 15.0, 0.0] and "rotation" not in saved["camera"]
    again = load_scene(first)
    try:
        for name in ("crate", "door", "ball", "camera"):
            assert again.get(again.entity(name), Transform) == scene.get(scene.entity(name), Transform)
        second = tmp_path / "second.json"
        save_scene(again, second)
        assert second.read_bytes() == first.read_bytes()
    finally:
        again.close()
        scene.close()


def test_an_edited_rotation_is_saved_as_its_new_angles(tmp_path: Path):
    source = tmp_path / "authored.json"
    source.write_text(json.dumps(AUTHORED))
    scene = load_scene(source)
    try:
        crate = scene.entity("crate")
        turned = tuple(float(c) for c in quat_from_axis_angle((0.0, 1.0, 0.0), np.radians(45.0)))
        scene.set(crate, replace(scene.get(crate, Transform), rotation=turned))
        angles = transforms(doc_of(scene_to_json(scene)))["crate"]["euler_deg"]
        np.testing.assert_allclose(angles, [0.0, 45.0, 0.0], atol=1e-9)
        np.testing.assert_allclose(angles, quat_to_euler_deg(turned), atol=1e-9)
    finally:
        scene.close()


def test_builder_angles_are_saved_as_angles():
    scene = Scene("built")
    try:
        scene.add_mesh("crate", "box", euler_deg=(0, 30, 0))
        scene.add_mesh("ball", "sphere")
        scene.set_camera((0, 1.6, 5), euler_deg=(-5, 0, 0))
        doc = doc_of(scene_to_json(scene))
        assert transforms(doc)["crate"]["euler_deg"] == [0.0, 30.0, 0.0]
        assert "rotation" in transforms(doc)["ball"]
        assert doc["camera"]["euler_deg"] == [-5.0, 0.0, 0.0]
        scene.set_camera((0, 1.6, 5), look_at=(0, 0, 0))  # re-aimed by a point: no angles to keep
        assert "rotation" in doc_of(scene_to_json(scene))["camera"]
    finally:
        scene.close()
