"""Textures and vertex normals on the host: loading, materials from files, the atlas, its budget, packing."""

from __future__ import annotations

import base64
import json
import logging
import struct

import numpy as np
import pytest
from PIL import Image

from aberrant.importers.gltf import load_gltf
from components import Mesh
from engine.assets import AssetLibrary
from engine.normals import corner_normals
from engine.packing import ScenePacker
from engine.scene import Scene
from engine.scene_file import load_scene, save_scene
from engine.textures import TextureBudgetError

QUAD_OBJ = """mtllib {mtl}
v -1 -1 0
v 1 -1 0
v 1 1 0
v -1 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
usemtl paint
f 1/1 2/2 3/3
f 1/1 3/3 4/4
"""


def png(path, size=(4, 4), color=(200, 100, 50)) -> str:
    Image.fromarray(np.full((*size, 3), color, np.uint8)).save(path)
    return str(path)


def quad_scene(texture: str = "") -> Scene:
    scene = Scene()
    scene.add_mesh("quad", "quad", texture=texture, color=(0.5, 0.5, 0.5))
    scene.set_camera((0.0, 0.0, 3.0), look_at=(0.0, 0.0, 0.0))
    return scene


def test_a_plain_scene_compiles_textures_and_smooth_normals_out():
    scene = quad_scene()
    packer = ScenePacker()
    packer.sync(scene)
    packed = packer.packed
    assert not packed.features.textures and not packed.features.smooth
    assert packed.features.defines()["HAS_TEXTURES"] == 0 and packed.features.defines()["HAS_SMOOTH"] == 0
    assert packed.counts["texels"] == 0 and packed.counts["triangle_normals"] == 0


def test_a_texture_is_packed_once_and_a_colour_edit_uploads_no_texels(tmp_path):
    path = png(tmp_path / "t.png")
    scene = quad_scene(path)
    scene.add_mesh("other", "box", texture=path, smooth=True)
    packer = ScenePacker()
    packer.sync(scene)
    assert packer.packed.features.textures and packer.packed.features.smooth
    assert packer.packed.counts["texels"] == 16  # one 4x4 image, though two meshes use it
    assert packer.packed.counts["triangle_normals"] == 12
    texture = packer.packed.tables["materials"]["texture"]
    assert list(texture[0, :3]) == list(texture[1, :3]) == [0, 4, 4]
    scene.set(scene.entity("quad"), Mesh("quad", color=(1.0, 0.0, 0.0), texture=path))
    updates = {u.table for u in packer.sync(scene)}
    assert "texels" not in updates and "materials" in updates
    scene.set(scene.entity("quad"), Mesh("quad", texture=png(tmp_path / "u.png", (2, 3))))
    assert "texels" in {u.table for u in packer.sync(scene)}
    assert packer.packed.counts["texels"] == 16 + 6


def test_a_missing_texture_warns_once_and_draws_the_base_colour(tmp_path, caplog):
    from backends.reference.backend import ReferenceBackend
    from backends.upload import SceneUploader
    from engine.camera_view import scene_camera

    frames = []
    for texture in ("", str(tmp_path / "gone.png")):
        scene = quad_scene(texture)
        backend = ReferenceBackend()
        with caplog.at_level(logging.WARNING):
            SceneUploader(backend).sync(scene)
            SceneUploader(backend).sync(scene)
        frames.append(backend.render(scene_camera(scene), 16, 16, ("color",)).color)
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "gone.png" in lines[0] and "base colour" in lines[0]
    assert np.array_equal(frames[0], frames[1])


def test_past_the_budget_is_an_error_naming_the_texture(tmp_path):
    scene = quad_scene(png(tmp_path / "big.png", (64, 64)))
    with pytest.raises(TextureBudgetError, match=r"quad\.mesh\.texture: texture .*big\.png \(64x64\).*0\.01 MiB"):
        ScenePacker(texture_budget_mib=0.01).sync(scene)
    ScenePacker(texture_budget_mib=0.0625).sync(scene)  # exactly 64 * 64 * 16 bytes fits


def test_an_obj_materials_map_kd_and_kd_reach_the_asset(tmp_path):
    png(tmp_path / "paint.png", (2, 2), (10, 20, 30))
    (tmp_path / "q.mtl").write_text("newmtl paint\nKd 1.0 0.5 0.25\nmap_Kd paint.png\n")
    (tmp_path / "q.obj").write_text(QUAD_OBJ.format(mtl="q.mtl"))
    asset = AssetLibrary().load(tmp_path / "q.obj")
    assert asset.image is not None and asset.image.pixels.shape == (2, 2, 4)
    assert tuple(asset.image.pixels[0, 0]) == (10, 20, 30, 255)
    assert asset.base_color == pytest.approx((1.0, 0.5, 0.25), abs=1 / 255)
    scene = Scene()
    scene.add_asset("q", path=tmp_path / "q.obj")
    scene.add_mesh("q", "q", color=(0.5, 0.5, 0.5))
    scene.set_camera((0.0, 0.0, 3.0))
    packer = ScenePacker()
    packer.sync(scene)
    material = packer.packed.tables["materials"][0]
    assert material["color"][:3] == pytest.approx((0.5, 0.25, 0.125), abs=1e-2)
    assert list(material["texture"][1:3]) == [2, 2]


def test_a_gltf_base_color_texture_and_uvs_become_the_meshs_texture(tmp_path, monkeypatch):
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path / "cache"))
    png(tmp_path / "skin.png", (2, 2), (0, 128, 255))
    positions = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    uvs = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)  # glTF: v runs down the image
    normals = np.tile(np.array([0, 0, 1], np.float32), (4, 1))
    indices = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    blob = positions.tobytes() + uvs.tobytes() + normals.tobytes() + indices.tobytes()
    views = [(0, 48), (48, 32), (80, 48), (128, 12)]
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "Sign", "mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1, "NORMAL": 2}, "indices": 3,
                                    "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 1, 1, 1], "baseColorTexture": {"index": 0}}}],
        "textures": [{"source": 0}], "images": [{"uri": "skin.png"}],
        "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                     + base64.b64encode(blob).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": o, "byteLength": n} for o, n in views],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"},
        ],
    }  # fmt: skip
    (tmp_path / "sign.gltf").write_text(json.dumps(doc))
    scene = load_gltf(tmp_path / "sign.gltf")
    ((_, mesh),) = scene.query(Mesh)
    assert mesh.texture == "image0.png" and mesh.smooth and mesh.color == pytest.approx((0.5, 1.0, 1.0))
    asset = scene.asset(mesh.asset)
    assert asset.uvs is not None and asset.uvs[2].tolist() == [1.0, 1.0]  # flipped to OBJ's v-up
    image = scene.texture(mesh)
    assert image is not None and tuple(image.pixels[0, 0]) == (0, 128, 255, 255)
    assert struct  # the GLB helpers of test_gltf cover the binary chunk


def test_the_scene_file_reads_and_writes_texture_and_smooth(tmp_path):
    png(tmp_path / "wood.png")
    mesh = {"asset": "box", "texture": "wood.png", "smooth": True, "crease_deg": 45.0}
    doc = {"format": "aberrant-scene", "version": 1, "camera": {"position": [0, 0, 3]}}
    doc["entities"] = [{"name": "crate", "mesh": mesh}]
    (tmp_path / "level.json").write_text(json.dumps(doc))
    scene = load_scene(tmp_path / "level.json")
    mesh = scene.get(scene.entity("crate"), Mesh)
    assert (mesh.texture, mesh.smooth, mesh.crease_deg) == ("wood.png", True, 45.0)
    assert scene.texture(mesh) is not None
    save_scene(scene, tmp_path / "again.json")
    saved = json.loads((tmp_path / "again.json").read_text())
    block = next(e for e in saved["entities"] if e["name"] == "crate")["mesh"]
    assert (block["texture"], block["smooth"], block["crease_deg"]) == ("wood.png", True, 45.0)


def test_crease_normals_keep_a_cube_flat_and_round_a_sphere():
    library = AssetLibrary()
    box = library.primitive("box")
    corners = corner_normals(box.vertices, box.faces, 30.0)
    faces = np.cross(*(box.vertices[box.faces[:, k]] - box.vertices[box.faces[:, 0]] for k in (1, 2)))
    faces /= np.linalg.norm(faces, axis=1, keepdims=True)
    assert np.allclose(corners, faces[:, None, :], atol=1e-6)
    sphere = library.primitive("sphere")
    computed = corner_normals(sphere.vertices, sphere.faces, 30.0)  # the file normals left out
    radial = sphere.vertices[sphere.faces] / np.linalg.norm(sphere.vertices[sphere.faces], axis=2, keepdims=True)
    assert np.abs(computed - radial).max() < 0.02
    assert np.allclose(corner_normals(sphere.vertices, sphere.faces, 30.0, sphere.normals), radial, atol=1e-6)


def test_an_obj_material_naming_a_missing_image_warns_and_keeps_kd(tmp_path, caplog):
    (tmp_path / "q.mtl").write_text("newmtl paint\nKd 0.2 0.4 0.6\nmap_Kd lost.png\n")
    (tmp_path / "q.obj").write_text(QUAD_OBJ.format(mtl="q.mtl"))
    with caplog.at_level(logging.WARNING):
        asset = AssetLibrary().load(tmp_path / "q.obj")
    lines = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(lines) == 1 and "lost.png" in lines[0] and "base colour" in lines[0]
    assert asset.image is None and asset.base_color == pytest.approx((0.2, 0.4, 0.6), abs=1 / 255)


def test_ply_uvs_and_file_normals_reach_the_asset(tmp_path):
    header = ["ply", "format ascii 1.0", "element vertex 3"]
    header += [f"property float {c}" for c in ("x", "y", "z", "nx", "ny", "nz", "s", "t")]
    header += ["element face 1", "property list uchar int vertex_indices", "end_header"]
    rows = ["0 0 0 0 0.6 0.8 0 0", "1 0 0 0 0 1 1 0", "0 1 0 0 0 1 0 1", "3 0 1 2"]
    (tmp_path / "tri.ply").write_text("\n".join(header + rows) + "\n")
    asset = AssetLibrary().load(tmp_path / "tri.ply")
    assert asset.uvs is not None and asset.uvs.tolist() == [[0, 0], [1, 0], [0, 1]]
    assert asset.normals is not None and asset.normals[0] == pytest.approx((0.0, 0.6, 0.8))
    # smooth shading uses them as they are, no crease applied
    assert corner_normals(asset.vertices, asset.faces, 30.0, asset.normals)[0, 0] == pytest.approx((0.0, 0.6, 0.8))


def test_a_glb_mesh_assets_pbr_base_colour_and_texture_reach_the_asset(tmp_path):
    import trimesh

    image = Image.fromarray(np.full((2, 2, 3), (10, 200, 30), np.uint8))
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=image, baseColorFactor=[255, 128, 255, 255])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    quad = trimesh.Trimesh(
        np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]),
        visual=trimesh.visual.TextureVisuals(uv=uv, material=material), process=False,
    )  # fmt: skip
    (tmp_path / "q.glb").write_bytes(quad.export(file_type="glb"))
    asset = AssetLibrary().load(tmp_path / "q.glb")
    assert asset.uvs is not None and asset.image is not None
    assert tuple(asset.image.pixels[0, 0]) == (10, 200, 30, 255)
    assert asset.base_color == pytest.approx((1.0, 0.5, 1.0), abs=1 / 255)
