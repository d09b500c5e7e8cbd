"""glTF scenes: node extras become aberrations and portals, hierarchies compose, meshes, cameras, errors, a render."""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from aberrant.cli import main
from aberrant.importers.gltf import GltfError, load_gltf
from aberrant.levels import open_level
from components import Aberration, Camera, Light, Mesh, Portal, Transform
from engine.maths import quat_to_matrix, trs_matrix

#: A unit cube's 8 corners and 12 triangles.
CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)], np.float32)
TRIANGLES = np.array(
    [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
     [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]],
    np.uint16,
)  # fmt: skip
HALF_TURN_Y = [0.0, 1.0, 0.0, 0.0]
QUARTER_Z = [0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)]


def level_nodes() -> list[dict[str, Any]]:
    """A floor, a parent with a rotated, scaled child box, an aberration, two linked portals and a camera."""
    return [
        {"name": "Floor", "mesh": 0, "translation": [0, -1, 0], "scale": [20, 0.2, 20]},
        {"name": "Group", "translation": [1, 0, -6], "rotation": QUARTER_Z, "scale": [2, 2, 2], "children": [2]},
        {"name": "Crate", "mesh": 0, "translation": [1, 0, 0]},
        {"name": "Squash", "mesh": 0, "translation": [0, 0, -4], "scale": [3, 3, 3],
         "extras": {"aberrant": {"aberration": {"deformation": [0.0, 0.0, 2.0], "priority": 1}}}},
        {"name": "PortalA", "translation": [-3, 0, -5], "extras": {"aberrant": {"portal": {"target": "PortalB"}}}},
        {"name": "PortalB", "translation": [3, 0, -5], "rotation": HALF_TURN_Y,
         "extras": {"aberrant": {"portal": {"target": "PortalA"}}}},
        {"name": "Eye", "camera": 0, "translation": [0, 0.5, 4]},
    ]  # fmt: skip


def write_gltf(folder: Path, nodes: list[dict[str, Any]], *, glb: bool = False, bin_name: str = "level.bin") -> Path:
    """A glTF (JSON + .bin) or GLB holding one cube mesh with a red material and ``nodes``."""
    positions = CORNERS.tobytes()
    indices = TRIANGLES.tobytes()
    blob = positions + indices
    buffer: dict[str, Any] = {"byteLength": len(blob)}
    if not glb:
        buffer["uri"] = bin_name
        (folder / bin_name).write_bytes(blob)
    doc = {
        "asset": {"version": "2.0", "generator": "test"},
        "scene": 0,
        "scenes": [{"nodes": [i for i, n in enumerate(nodes) if n.get("name") != "Crate"]}],
        "nodes": nodes,
        "meshes": [{"name": "Cube", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.1, 1.0]}, "doubleSided": True}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": math.radians(50), "znear": 0.1}}],
        "buffers": [buffer],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(positions)},
            {"buffer": 0, "byteOffset": len(positions), "byteLength": len(indices)},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(CORNERS), "type": "VEC3",
             "min": [-0.5] * 3, "max": [0.5] * 3},
            {"bufferView": 1, "componentType": 5123, "count": TRIANGLES.size, "type": "SCALAR"},
        ],
    }  # fmt: skip
    if not glb:
        path = folder / "level.gltf"
        path.write_text(json.dumps(doc))
        return path
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = blob + b"\0" * (-len(blob) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(body), 0x004E4942) + body
    path = folder / "level.glb"
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks)
    return path


@pytest.mark.parametrize("glb", [False, True], ids=["gltf", "glb"])
def test_nodes_become_entities_with_world_transforms_and_components(tmp_path, glb, monkeypatch):
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path / "cache"))
    nodes = level_nodes()
    nodes[0]["children"] = []
    with open_level(write_gltf(tmp_path, nodes, glb=glb)) as level:
        scene = level.scene
        names = sorted(scene.name_of(e) for e, _ in scene.query(Transform))
        assert names == ["Crate", "Eye", "Floor", "PortalA", "PortalB", "Squash"]
        meshes = {scene.name_of(e): m for e, m in scene.query(Mesh)}
        assert sorted(meshes) == ["Crate", "Floor"]  # the aberration's stand-in cube is not rendered
        assert meshes["Crate"].color == pytest.approx((0.8, 0.1, 0.1)) and not meshes["Crate"].cull_backfaces
        assert scene.asset(meshes["Crate"].asset).triangle_count == 12
        crate = scene.get(scene.entity("Crate"), Transform)
        parent = trs_matrix([1, 0, -6], QUARTER_Z, [2, 2, 2])
        world = parent @ trs_matrix([1, 0, 0], [0, 0, 0, 1], [1, 1, 1])
        assert np.allclose(crate.position, world[:3, 3]) and np.allclose(crate.position, [1, 2, -6])
        assert np.allclose(quat_to_matrix(crate.rotation), quat_to_matrix(QUARTER_Z))
        assert np.allclose(crate.scale, [2, 2, 2])
        squash = scene.get(scene.entity("Squash"), Aberration)
        assert squash.deformation == (0.0, 0.0, 2.0) and squash.priority == 1
        assert scene.get(scene.entity("Squash"), Transform).scale == (3.0, 3.0, 3.0)
        assert scene.get(scene.entity("PortalA"), Portal).target == "PortalB"
        assert scene.get(scene.entity("PortalB"), Portal).target == "PortalA"
        assert scene.name_of(scene.camera_entity) == "Eye"
        assert scene.get(scene.camera_entity, Camera).fov_deg == pytest.approx(50.0)
        assert np.allclose(scene.get(scene.camera_entity, Transform).position, [0, 0.5, 4])


def test_light_extras_become_lights_shining_along_the_nodes_minus_z(tmp_path, monkeypatch):
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path / "cache"))
    down = [-math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)]  # -90 degrees about X: -Z onto -Y
    nodes = [
        *level_nodes(),
        {"name": "Sun", "rotation": down, "extras": {"aberrant": {"light": {"kind": "sun", "intensity": 0.8}}}},
        {"name": "Lamp", "translation": [0, 3, 0],
         "extras": {"aberrant": {"light": {"kind": "point", "intensity": 9, "shadows": False, "range": 12}}}},
    ]  # fmt: skip
    with open_level(write_gltf(tmp_path, nodes)) as level:
        scene = level.scene
        assert scene.get(scene.entity("Sun"), Light) == Light("sun", intensity=0.8)
        forward = quat_to_matrix(scene.get(scene.entity("Sun"), Transform).rotation) @ [0, 0, -1]
        assert np.allclose(forward, [0, -1, 0])
        assert scene.get(scene.entity("Lamp"), Light) == Light("point", intensity=9.0, shadows=False, range=12.0)
        assert scene.get(scene.entity("Lamp"), Transform).position == (0.0, 3.0, 0.0)


def test_render_a_glb_directly_with_the_reference_backend(tmp_path, capsys, monkeypatch):
    from conftest import require_backend

    require_backend("reference")
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path / "cache"))
    path = write_gltf(tmp_path, level_nodes(), glb=True)
    code = main(["render", str(path), "--backend", "reference", "--size", "48x32",
                 "--out", str(tmp_path / "r.png"), "--aovs", str(tmp_path / "r.npz")])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    aovs = np.load(tmp_path / "r.npz")
    assert len(np.unique(aovs["instance"][aovs["instance"] >= 0])) >= 2


def _broken(nodes: list[dict[str, Any]], index: int, **changes: Any) -> list[dict[str, Any]]:
    nodes[index] = {**nodes[index], **changes}
    return nodes


@pytest.mark.parametrize(
    ("change", "needles"),
    [
        (lambda n: _broken(n, 4, extras={"aberrant": {"portal": {"target": "Nowhere"}}}),
         ["node 'PortalA'", "extras.aberrant.portal.target", "Nowhere"]),
        (lambda n: _broken(n, 3, extras={"aberrant": {"aberration": {"mode": "wobbly"}}}),
         ["node 'Squash'", "extras.aberrant.aberration.mode"]),
        (lambda n: _broken(n, 3, extras={"aberrant": {"aberration": {"speed": 2}}}),
         ["node 'Squash'", "extras.aberrant.aberration.speed", "unknown key"]),
        (lambda n: _broken(n, 3, extras={"aberrant": {"teleporter": {}}}),
         ["node 'Squash'", "extras.aberrant.teleporter"]),
        (lambda n: _broken(n, 3, extras={"aberrant": "portal"}), ["node 'Squash'", "extras.aberrant"]),
        (lambda n: _broken(n, 3, extras={"aberrant": {"light": {"kind": "spot"}}}),
         ["node 'Squash'", "extras.aberrant.light.kind", "'sun', 'point'"]),
        (lambda n: _broken(n, 3, extras={"aberrant": {"light": {}, "portal": {}}}),
         ["node 'Squash'", "one component", "light, portal"]),
    ],
)  # fmt: skip
def test_bad_extras_name_the_file_node_and_field(tmp_path, change, needles, monkeypatch):
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path / "cache"))
    with pytest.raises(GltfError) as info:
        load_gltf(write_gltf(tmp_path, change(level_nodes())))
    message = str(info.value)
    assert "level.gltf" in message and "\n" not in message
    for needle in needles:
        assert needle in message


def test_cli_a_missing_buffer_is_one_line_and_exit_2(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path / "cache"))
    path = write_gltf(tmp_path, level_nodes())
    (tmp_path / "level.bin").unlink()
    code = main(["render", str(path), "--backend", "reference", "--size", "8x8", "--out", str(tmp_path / "r.png")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "level.gltf" in err and "missing buffer 'level.bin'" in err and "Floor" in err
    assert not (tmp_path / "r.png").exists()
