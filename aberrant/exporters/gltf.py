"""Write a scene as glTF 2.0 (``.glb``, or ``.gltf`` with its buffer embedded): what Blender opens and edits.

The file holds what :mod:`aberrant.importers.gltf` reads back into the same
scene, so a level can go to Blender and come back:

* **Meshes**: each mesh asset's triangles (positions, indices, UVs as
  ``TEXCOORD_0`` with glTF's top-left origin) are written once; a glTF mesh per
  (asset, material) pair shares them, and each mesh entity is a root node with
  its world TRS instancing one. Materials carry ``baseColorFactor`` (the
  colour), ``baseColorTexture`` (the image the mesh samples, as a PNG),
  ``doubleSided`` (not ``cull_backfaces``) and the checker cell size and smooth
  shading as the material extra ``{"aberrant": {"checker": c, "smooth": true,
  "crease_deg": a}}``.
* **Aberrations and portals** are nodes whose extras hold the component,
  ``{"aberrant": {"aberration": {...}}}`` / ``{"aberrant": {"portal": {"target":
  "<node name>", ...}}}``, with the scene-file keys. So that Blender shows the
  box or quad where it is, such a node also instances a stand-in mesh (the unit
  cube [-1/2, 1/2]^3, the quad [-1, 1]^2 facing +Z) in a translucent material
  of the component's colour; the component extra is what marks the node, and
  the importer never turns its mesh into a mesh entity.
* **Lights** are empty nodes with the extra ``{"aberrant": {"light": {...}}}``
  (a sun shines along the node's -Z).
* **The camera** is a node with a perspective camera (``yfov`` from
  ``fov_deg``); its walking speed is the extra ``{"aberrant": {"camera":
  {"speed": s}}}``.
* **The scene's** extras ``{"aberrant": {"settings": {...}, "camera_path":
  [...]}}`` keep the settings and flythrough.

Node names are the entities' names (unique; an empty one becomes ``entity<i>``).
"""

from __future__ import annotations

import base64
import io
import json
import math
import os
import struct
from pathlib import Path
from typing import Any

import numpy as np
import PIL.Image

from aberrant.importers.gltf import unique_name
from components import Aberration, Camera, Light, Mesh, Portal, Transform
from engine.atomic_files import write_atomically
from engine.errors import AberrantError, SceneError, shorten
from engine.mesh_asset import MeshAsset
from engine.scene import Scene
from engine.scene_writer import scene_document
from engine.textures import TextureImage

#: The suffixes :func:`export_gltf` writes.
EXPORT_SUFFIXES = (".glb", ".gltf")
#: Opacity of the stand-in meshes of aberrations and portals (translucent in Blender's material preview).
STAND_IN_ALPHA = 0.25
#: The camera's near plane as glTF requires one (our tracer has none).
ZNEAR = 0.01
_FLOAT, _UINT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_QUAD = MeshAsset(
    np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32),
    np.array([[0, 1, 2], [0, 2, 3]], np.int32),
    None,
    "portal quad",
)


class GltfExportError(AberrantError, ValueError):
    """A scene cannot be written as glTF; the one-line message names the file and what is wrong."""


class _Writer:
    """Collects the JSON document and the binary buffer of one glTF file."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.blob = bytearray()
        self.textures: dict[str, int] = {}
        self.doc: dict[str, Any] = {
            "asset": {"version": "2.0", "generator": "aberrant"},
            "scene": 0,
            "scenes": [{"name": scene.name, "nodes": []}],
            "nodes": [],
        }
        self.geometry: dict[str, dict[str, int]] = {}  # asset name -> the accessors of its primitive
        self.meshes: dict[tuple[str, int], int] = {}  # (asset, material) -> glTF mesh
        self.materials: dict[str, int] = {}  # canonical JSON of a material -> its index

    def add(self, key: str, item: dict[str, Any]) -> int:
        items = self.doc.setdefault(key, [])
        items.append(item)
        return len(items) - 1

    def view(self, data: bytes, target: int | None) -> int:
        self.blob += b"\0" * (-len(self.blob) % 4)
        offset = len(self.blob)
        self.blob += data
        item = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        return self.add("bufferViews", item if target is None else {**item, "target": target})

    def texture(self, image: TextureImage) -> int:
        """A glTF texture of ``image`` (a PNG in the buffer), written once per distinct image."""
        if image.content_hash not in self.textures:
            png = io.BytesIO()
            PIL.Image.fromarray(image.pixels).save(png, format="PNG")
            source = self.add("images", {"bufferView": self.view(png.getvalue(), None), "mimeType": "image/png"})
            self.textures[image.content_hash] = self.add("textures", {"source": source})
        return self.textures[image.content_hash]

    def accessor(self, array: np.ndarray, kind: str, target: int, bounds: bool = False) -> int:
        component = _UINT if array.dtype == np.uint32 else _FLOAT
        item: dict[str, Any] = {
            "bufferView": self.view(array.tobytes(), target),
            "componentType": component,
            "count": int(array.shape[0]),
            "type": kind,
        }
        if bounds:  # POSITION accessors must state them
            item["min"] = [float(c) for c in array.min(axis=0)]
            item["max"] = [float(c) for c in array.max(axis=0)]
        return self.add("accessors", item)

    def primitive_of(self, name: str, asset: MeshAsset) -> dict[str, int]:
        if name not in self.geometry:
            attributes = {"POSITION": self.accessor(asset.vertices.astype("<f4"), "VEC3", _ARRAY_BUFFER, bounds=True)}
            if asset.uvs is not None:
                uvs = asset.uvs.astype(np.float64)
                uvs[:, 1] = 1.0 - uvs[:, 1]  # glTF's UV origin is the image's top left
                attributes["TEXCOORD_0"] = self.accessor(uvs.astype("<f4"), "VEC2", _ARRAY_BUFFER)
            if asset.normals is not None:
                attributes["NORMAL"] = self.accessor(asset.normals.astype("<f4"), "VEC3", _ARRAY_BUFFER)
            indices = self.accessor(asset.faces.reshape(-1).astype("<u4"), "SCALAR", _ELEMENT_ARRAY_BUFFER)
            self.geometry[name] = {"indices": indices, **attributes}
        return self.geometry[name]

    def material(self, item: dict[str, Any]) -> int:
        key = json.dumps(item, sort_keys=True)
        if key not in self.materials:
            self.materials[key] = self.add("materials", item)
        return self.materials[key]

    def mesh(self, name: str, asset: MeshAsset, material: dict[str, Any]) -> int:
        """The glTF mesh showing ``asset`` in ``material`` (made once per pair, sharing the asset's data)."""
        index = self.material(material)
        if (name, index) not in self.meshes:
            accessors = dict(self.primitive_of(name, asset))
            indices = accessors.pop("indices")
            primitive = {"attributes": accessors, "indices": indices, "material": index, "mode": 4}
            self.meshes[name, index] = self.add("meshes", {"name": name, "primitives": [primitive]})
        return self.meshes[name, index]

    def node(self, item: dict[str, Any]) -> None:
        self.doc["scenes"][0]["nodes"].append(self.add("nodes", item))


def _trs(transform: Transform, *, scale: bool = True) -> dict[str, list[float]]:
    out = {"translation": [float(c) for c in transform.position], "rotation": [float(c) for c in transform.rotation]}
    if scale:
        out["scale"] = [float(c) for c in transform.scale]
    return out


def _stand_in(color: tuple[float, float, float]) -> dict[str, Any]:
    """A translucent unlit-looking material for an aberration's box or a portal's quad."""
    return {
        "pbrMetallicRoughness": {"baseColorFactor": [*map(float, color), STAND_IN_ALPHA], "metallicFactor": 0.0},
        "alphaMode": "BLEND",
        "doubleSided": True,
    }


def _node_names(scene: Scene) -> dict[int, str]:
    """Each entity's node name: its own, else ``entity<i>``; unique (``.1``, ``.2``... as the importer does)."""
    names: dict[int, str] = {}
    used: set[str] = set()
    for entity in scene.entities():
        names[entity] = unique_name(scene.name_of(entity).strip() or f"entity{entity}", used)
    return names


def gltf_document(scene: Scene) -> tuple[dict[str, Any], bytes]:
    """The glTF JSON of ``scene`` and its binary buffer (the document's buffer 0, given no ``uri`` yet)."""
    saved = scene_document(scene)  # settings and keyframes in the scene file's canonical form
    writer = _Writer(scene)
    names = _node_names(scene)
    for entity in scene.entities():
        name = names[entity]
        transform = scene.try_get(entity, Transform) or Transform()
        if entity == scene.camera_entity:
            camera = scene.get(entity, Camera)
            lens = {"yfov": math.radians(camera.fov_deg), "znear": ZNEAR}
            index = writer.add("cameras", {"type": "perspective", "perspective": lens})
            lens_extras = {"aberrant": {"camera": {"speed": float(camera.speed)}}}
            writer.node({"name": name, "camera": index, **_trs(transform, scale=False), "extras": lens_extras})
            continue
        mesh = scene.try_get(entity, Mesh)
        aberration = scene.try_get(entity, Aberration)
        portal = scene.try_get(entity, Portal)
        light = scene.try_get(entity, Light)
        if sum(c is not None for c in (mesh, aberration, portal, light)) > 1:
            raise SceneError(
                "a glTF node is a mesh, an aberration, a portal or a light, not several", entity=scene.name_of(entity)
            )
        item: dict[str, Any] = {"name": name, **_trs(transform)}
        if mesh is not None:
            # smooth always written: a NORMAL attribute alone reads back as a smooth mesh
            shading: dict[str, Any] = {"checker": float(mesh.checker), "smooth": bool(mesh.smooth)}
            if mesh.smooth:
                shading["crease_deg"] = float(mesh.crease_deg)
            pbr: dict[str, Any] = {"baseColorFactor": [*map(float, mesh.color), 1.0], "metallicFactor": 0.0}
            image = scene.texture(mesh) if scene.asset(mesh.asset).uvs is not None else None
            if image is not None:
                pbr["baseColorTexture"] = {"index": writer.texture(image)}
            material = {
                "pbrMetallicRoughness": pbr,
                "doubleSided": not mesh.cull_backfaces,
                "extras": {"aberrant": shading},
            }
            item["mesh"] = writer.mesh(mesh.asset, scene.asset(mesh.asset), material)
        elif aberration is not None:
            block = _entity_block(saved, scene.name_of(entity))["aberration"]
            item["mesh"] = writer.mesh("aberration_box", scene.asset("box"), _stand_in(aberration.color))
            item["extras"] = {"aberrant": {"aberration": block}}
        elif portal is not None:
            block = dict(_entity_block(saved, scene.name_of(entity))["portal"])
            if portal.target is not None:
                block["target"] = _node_of(scene, names, portal.target)
            item["mesh"] = writer.mesh("portal_quad", _QUAD, _stand_in(portal.color))
            item["extras"] = {"aberrant": {"portal": block}}
        elif light is not None:
            item["extras"] = {"aberrant": {"light": _entity_block(saved, scene.name_of(entity))["light"]}}
        writer.node(item)
    extras: dict[str, Any] = {"settings": saved["settings"]}
    if "camera_path" in saved:
        extras["camera_path"] = saved["camera_path"]
    writer.doc["scenes"][0]["extras"] = {"aberrant": extras}
    blob = bytes(writer.blob) + b"\0" * (-len(writer.blob) % 4)
    writer.doc["buffers"] = [{"byteLength": len(blob)}]
    return writer.doc, blob


def _node_of(scene: Scene, names: dict[int, str], entity_name: str) -> str:
    """The node name of the entity named ``entity_name`` (the name itself when no entity has it)."""
    try:
        return names[scene.entity(entity_name)]
    except SceneError:
        return entity_name


def _entity_block(saved: dict[str, Any], name: str) -> dict[str, Any]:
    return next(item for item in saved["entities"] if item["name"] == name)


def gltf_bytes(scene: Scene, suffix: str = ".glb") -> bytes:
    """The bytes of ``scene`` as a GLB (``.glb``) or as glTF JSON with the buffer as a data URI (``.gltf``)."""
    doc, blob = gltf_document(scene)
    if suffix == ".gltf":
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode("ascii")
        return (json.dumps(doc, indent=1) + "\n").encode("utf-8")
    text = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(blob), 0x004E4942) + blob
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def export_gltf(scene: Scene, path: str | os.PathLike[str]) -> None:
    """Write ``scene`` to ``path`` (``.glb`` or ``.gltf``) atomically: the old file stays unless the new one is whole.

    Raises :class:`engine.errors.AberrantError` (a ``GltfExportError``) naming the file (a wrong suffix, an
    entity glTF cannot hold) and ``OSError`` naming it when it cannot be written (a folder, a FIFO, a read-only
    file or a missing folder).
    """
    target = Path(path)
    file = shorten(target)
    suffix = target.suffix.lower()
    if suffix not in EXPORT_SUFFIXES:
        raise GltfExportError(f"{file}: a glTF export is a .glb or .gltf file, not {suffix or 'a name without one'}")
    try:
        data = gltf_bytes(scene, suffix)
    except SceneError as e:
        raise GltfExportError(f"{file}: cannot export: {e}") from None
    write_atomically({target: data})
