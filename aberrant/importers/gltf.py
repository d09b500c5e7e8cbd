"""Open glTF 2.0 scenes (``.gltf`` / ``.glb``, e.g. exported from Blender) as aberrant scenes.

The file's JSON (and a GLB's binary chunk) is read here, not through trimesh,
because trimesh drops node ``extras``, which is where Blender's exporter puts
an object's custom properties. What maps to what:

* **Nodes** of the default scene, depth first; a node's world TRS (parents
  composed, quaternions ``(x, y, z, w)`` as ours) is its entity's transform.
  glTF is right-handed, +Y up, cameras looking down -Z: our conventions, so no
  conversion.
* **Components** are node extras ``{"aberrant": {"aberration": {...}}}`` or
  ``{"aberrant": {"portal": {"target": "<node name>"}}}``: the same keys and
  values as a scene file's entity components, validated by the scene-file
  reader. A node carrying one is that box or quad; its mesh (the stand-in the
  designer saw in Blender) is not rendered.
* **Meshes**: each triangle primitive becomes a mesh entity (``<node>`` or
  ``<node>.<i>`` when a mesh has several), its triangles written as an OBJ in
  a folder named by the file's content; colour from the material's
  ``baseColorFactor``, its ``baseColorTexture`` image written beside the OBJ
  as the mesh's texture (UVs from ``TEXCOORD_0``), smooth shading where the
  primitive has normals, one-sided unless the material is ``doubleSided``.
* **Camera**: the first node with a camera, its ``yfov`` the vertical field of view.

Every problem is one :class:`GltfError` naming the file, the node and the field.
"""

from __future__ import annotations

import base64
import hashlib
import json
import math
import os
import struct
from pathlib import Path
from typing import Any

import numpy as np

from aberrant.importers.tello_format import TelloMesh, mesh_to_obj
from engine.atomic_files import write_atomically
from engine.bvh_cache import default_cache_dir
from engine.errors import AberrantError, shorten
from engine.maths import quat_from_matrix, trs_matrix
from engine.scene import Scene
from engine.scene_file import SceneFileError, scene_from_document

GLTF_SUFFIXES = (".gltf", ".glb")
#: The keys allowed in a node's ``extras.aberrant`` block.
COMPONENT_KEYS = ("aberration", "portal")
_COMPONENT_TYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
_TRIANGLES = 4


class GltfError(AberrantError, ValueError):
    """A glTF file cannot be opened; the one-line message names the file, the node and the field."""


class _Gltf:
    """One parsed glTF document with its buffers; reads accessors and names where a problem is."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.file = shorten(path)
        try:
            self.data = path.read_bytes()
        except OSError as e:
            raise GltfError(f"{self.file}: cannot read the file ({e.strerror or e})") from None
        self.bin: bytes | None = None
        self.doc = self.parse()
        self.buffers: dict[int, bytes] = {}

    def fail(self, message: str, *, node: str | None = None, field: str | None = None) -> GltfError:
        parts = [self.file] + ([f"node {node!r}"] if node is not None else [])
        parts += [f"field {field!r}"] if field is not None else []
        return GltfError(": ".join([*parts, message]))

    def parse(self) -> dict[str, Any]:
        text = self.data
        if self.data[:4] == b"glTF":
            text = self.glb_chunks()
        try:
            doc = json.loads(text.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            raise self.fail(f"not glTF JSON ({e})") from None
        if not isinstance(doc, dict) or not str(doc.get("asset", {}).get("version", "")).startswith("2"):
            raise self.fail("not a glTF 2.0 document", field="asset.version")
        return doc

    def glb_chunks(self) -> bytes:
        """The JSON chunk of a GLB; its BIN chunk is kept as buffer 0."""
        data = self.data
        if len(data) < 20:
            raise self.fail("truncated GLB header")
        _, version, length = struct.unpack_from("<4sII", data, 0)
        if version != 2:
            raise self.fail(f"GLB version {version} is not supported (only 2)")
        offset, json_chunk = 12, None
        while offset + 8 <= min(length, len(data)):
            size, kind = struct.unpack_from("<II", data, offset)
            chunk = data[offset + 8 : offset + 8 + size]
            if len(chunk) != size:
                raise self.fail("truncated GLB chunk")
            if kind == 0x4E4F534A and json_chunk is None:
                json_chunk = chunk
            elif kind == 0x004E4942 and self.bin is None:
                self.bin = chunk
            offset += 8 + size
        if json_chunk is None:
            raise self.fail("GLB without a JSON chunk")
        return json_chunk

    def items(self, key: str) -> list[Any]:
        value = self.doc.get(key, [])
        if not isinstance(value, list):
            raise self.fail("expected an array", field=key)
        return value

    def item(self, key: str, index: object, *, node: str | None, field: str) -> dict[str, Any]:
        items = self.items(key)
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(items):
            raise self.fail(f"no {key} entry {index!r} (the file has {len(items)})", node=node, field=field)
        value = items[index]
        if not isinstance(value, dict):
            raise self.fail("expected an object", field=f"{key}[{index}]")
        return value

    def buffer(self, index: int, node: str | None, field: str) -> bytes:
        if index in self.buffers:
            return self.buffers[index]
        spec = self.item("buffers", index, node=node, field=field)
        uri = spec.get("uri")
        where = f"buffers[{index}].uri"
        if uri is None:
            if self.bin is None:
                raise self.fail("the buffer has no uri and the file no GLB binary chunk", node=node, field=where)
            data = self.bin
        elif not isinstance(uri, str):
            raise self.fail("expected a string", node=node, field=where)
        elif uri.startswith("data:"):
            try:
                data = base64.b64decode(uri.partition(",")[2], validate=True)
            except ValueError as e:
                raise self.fail(f"bad base64 data URI ({e})", node=node, field=where) from None
        else:
            target = self.path.parent / uri
            try:
                data = target.read_bytes()
            except OSError as e:
                raise self.fail(f"missing buffer {uri!r} ({e.strerror or e})", node=node, field=where) from None
        if len(data) < int(spec.get("byteLength", 0)):
            raise self.fail(f"holds {len(data)} bytes, byteLength says {spec['byteLength']}", node=node, field=where)
        self.buffers[index] = data
        return data

    def accessor(self, index: object, node: str, field: str) -> np.ndarray:
        """An accessor's elements as an ``(count, width)`` array."""
        acc = self.item("accessors", index, node=node, field=field)
        where = f"accessors[{index}]"
        if "sparse" in acc:
            raise self.fail("sparse accessors are not supported", node=node, field=f"{where}.sparse")
        dtype = _COMPONENT_TYPES.get(acc.get("componentType"))  # type: ignore[arg-type]
        width = _WIDTHS.get(acc.get("type"))  # type: ignore[arg-type]
        count = acc.get("count")
        if dtype is None or width is None or not isinstance(count, int) or count < 0:
            raise self.fail("unsupported componentType, type or count", node=node, field=where)
        view = self.item("bufferViews", acc.get("bufferView"), node=node, field=f"{where}.bufferView")
        data = self.buffer(view.get("buffer"), node, f"{where}.bufferView")  # type: ignore[arg-type]
        item = np.dtype(dtype).itemsize * width
        stride = int(view.get("byteStride", item))
        start = int(view.get("byteOffset", 0)) + int(acc.get("byteOffset", 0))
        end = start + (stride * (count - 1) + item if count else 0)
        if end > int(view.get("byteOffset", 0)) + int(view.get("byteLength", 0)) or end > len(data):
            raise self.fail("reads past the end of its buffer view", node=node, field=where)
        raw = np.frombuffer(data, dtype=np.uint8, count=end - start, offset=start) if count else np.zeros(0, np.uint8)
        rows = [raw[i * stride : i * stride + item] for i in range(count)] if stride != item else [raw]
        return np.concatenate(rows).view(dtype).reshape(count, width) if count else np.zeros((0, width), dtype)


def _local_matrix(gltf: _Gltf, node: dict[str, Any], name: str) -> np.ndarray:
    try:
        if "matrix" in node:
            m = np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T  # column-major in the file
        else:
            t = np.asarray(node.get("translation", (0, 0, 0)), dtype=np.float64).reshape(3)
            r = np.asarray(node.get("rotation", (0, 0, 0, 1)), dtype=np.float64).reshape(4)
            s = np.asarray(node.get("scale", (1, 1, 1)), dtype=np.float64).reshape(3)
            m = trs_matrix(t, r / np.linalg.norm(r), s)
    except (TypeError, ValueError) as e:
        raise gltf.fail(f"not a transform ({e})", node=name, field="matrix/translation/rotation/scale") from None
    if not np.all(np.isfinite(m)):
        raise gltf.fail("the transform holds NaN or infinity", node=name, field="matrix/translation/rotation/scale")
    return m


def _decompose(m: np.ndarray) -> dict[str, list[float]]:
    """``T R S`` of a world matrix (the nearest rotation when parents' non-uniform scales shear it)."""
    linear = m[:3, :3]
    scale = np.linalg.norm(linear, axis=0)
    if np.linalg.det(linear) < 0.0:
        scale[0] = -scale[0]
    u, _, vt = np.linalg.svd(linear / np.where(scale == 0.0, 1.0, scale))
    rotation = quat_from_matrix(u @ vt)
    return {
        "position": [float(c) for c in m[:3, 3]],
        "rotation": [float(c) for c in rotation],
        "scale": [float(c) for c in scale],
    }


class _Importer:
    def __init__(self, gltf: _Gltf) -> None:
        self.gltf = gltf
        self.document: dict[str, Any] = {
            "format": "aberrant-scene",
            "version": 1,
            "name": gltf.path.stem,
            "assets": {},
            "entities": [],
        }
        self.meshes: dict[str, bytes] = {}
        self.names: dict[int, str] = {}

    def node_names(self) -> None:
        """Unique names: a node's own, else ``node<i>``; duplicates get ``.1``, ``.2``..."""
        used: set[str] = set()
        for index, node in enumerate(self.gltf.items("nodes")):
            given = node.get("name") if isinstance(node, dict) else None
            name = (given.strip() if isinstance(given, str) else "") or f"node{index}"
            candidate, n = name, 0
            while candidate in used:
                n += 1
                candidate = f"{name}.{n}"
            used.add(candidate)
            self.names[index] = candidate

    def roots(self) -> list[int]:
        scenes = self.gltf.items("scenes")
        if not scenes:
            return list(range(len(self.gltf.items("nodes"))))
        scene = self.gltf.item("scenes", self.gltf.doc.get("scene", 0), node=None, field="scene")
        return list(scene.get("nodes", []))

    def run(self) -> None:
        self.node_names()
        stack: list[tuple[int, np.ndarray, tuple[int, ...]]] = [
            (index, np.eye(4), ()) for index in reversed(self.roots())
        ]
        while stack:
            index, parent, seen = stack.pop()
            node = self.gltf.item("nodes", index, node=None, field="children")
            name = self.names[index]
            if index in seen:
                raise self.gltf.fail("the node hierarchy has a cycle", node=name, field="children")
            world = parent @ _local_matrix(self.gltf, node, name)
            self.add(index, node, name, world)
            stack.extend((child, world, (*seen, index)) for child in reversed(node.get("children", [])))

    def add(self, index: int, node: dict[str, Any], name: str, world: np.ndarray) -> None:
        transform = _decompose(world)
        components = self.components(node, name)
        if "camera" in node and "camera" not in self.document:
            camera = self.gltf.item("cameras", node["camera"], node=name, field="camera")
            block: dict[str, Any] = {"name": name, "position": transform["position"], "rotation": transform["rotation"]}
            yfov = camera.get("perspective", {}).get("yfov")
            if isinstance(yfov, int | float):
                block["fov_deg"] = math.degrees(yfov)
            self.document["camera"] = block
            return
        if components:
            self.document["entities"].append({"name": name, "transform": transform, **components})
            return
        if "mesh" not in node:
            return
        mesh = self.gltf.item("meshes", node["mesh"], node=name, field="mesh")
        primitives = mesh.get("primitives", [])
        for i, primitive in enumerate(primitives):
            entity = name if len(primitives) == 1 else f"{name}.{i}"
            self.document["entities"].append(
                {"name": entity, "transform": transform, "mesh": self.primitive(node["mesh"], i, primitive, name)}
            )

    def components(self, node: dict[str, Any], name: str) -> dict[str, Any]:
        extras = node.get("extras", {})
        if not isinstance(extras, dict):
            raise self.gltf.fail("expected an object", node=name, field="extras")
        block = extras.get("aberrant")
        if block is None:
            return {}
        if not isinstance(block, dict):
            raise self.gltf.fail("expected an object", node=name, field="extras.aberrant")
        for key in block:
            if key not in COMPONENT_KEYS:
                raise self.gltf.fail(
                    f"unknown component {key!r}; allowed: {', '.join(COMPONENT_KEYS)}",
                    node=name,
                    field=f"extras.aberrant.{key}",
                )
        if len(block) > 1:
            raise self.gltf.fail("a node is either an aberration or a portal, not both", node=name, field="extras")
        return dict(block)

    def primitive(self, mesh_index: int, i: int, primitive: dict[str, Any], name: str) -> dict[str, Any]:
        field = f"meshes[{mesh_index}].primitives[{i}]"
        if primitive.get("mode", _TRIANGLES) != _TRIANGLES:
            raise self.gltf.fail("only triangle primitives (mode 4) are supported", node=name, field=f"{field}.mode")
        if "POSITION" not in primitive.get("attributes", {}):
            raise self.gltf.fail("no POSITION attribute", node=name, field=f"{field}.attributes")
        vertices = self.gltf.accessor(primitive["attributes"]["POSITION"], name, f"{field}.attributes.POSITION")
        if "indices" in primitive:
            indices = self.gltf.accessor(primitive["indices"], name, f"{field}.indices").reshape(-1)
        else:
            indices = np.arange(len(vertices))
        if len(indices) % 3 or len(indices) == 0:
            raise self.gltf.fail(f"{len(indices)} indices are no whole triangles", node=name, field=f"{field}.indices")
        faces = indices.astype(np.int64).reshape(-1, 3)
        if faces.max() >= len(vertices):
            raise self.gltf.fail("an index is past the last vertex", node=name, field=f"{field}.indices")
        uvs = None
        if "TEXCOORD_0" in primitive["attributes"]:
            uv = self.gltf.accessor(primitive["attributes"]["TEXCOORD_0"], name, f"{field}.attributes.TEXCOORD_0")
            if uv.shape == (len(vertices), 2) and np.issubdtype(uv.dtype, np.floating):
                uvs = np.column_stack([uv[:, 0], 1.0 - uv[:, 1]]).astype(np.float32)  # glTF's v runs downwards
        asset = f"mesh{mesh_index}.{i}"
        if asset not in self.document["assets"]:
            self.meshes[f"{asset}.obj"] = mesh_to_obj(
                TelloMesh(vertices.astype(np.float32), faces, uvs), f"{self.gltf.file} {field}"
            )
            self.document["assets"][asset] = {"path": f"{asset}.obj"}
        block: dict[str, Any] = {"asset": asset, "cull_backfaces": True}
        if "NORMAL" in primitive["attributes"]:
            block["smooth"] = True  # the file shades smoothly: normals from the faces, creases kept
        if "material" in primitive:
            material = self.gltf.item("materials", primitive["material"], node=name, field=f"{field}.material")
            pbr = material.get("pbrMetallicRoughness", {})
            factor = pbr.get("baseColorFactor")
            if isinstance(factor, list) and len(factor) == 4:
                block["color"] = [float(c) for c in factor[:3]]
            block["cull_backfaces"] = not material.get("doubleSided", False)
            texture = pbr.get("baseColorTexture")
            if isinstance(texture, dict) and uvs is not None:
                block["texture"] = self.image(texture.get("index"), name, f"materials[{primitive['material']}]")
        return block

    def image(self, texture: object, name: str, field: str) -> str:
        """The file name (beside the meshes) of a texture's image, its bytes taken from a URI or buffer view."""
        where = f"{field}.pbrMetallicRoughness.baseColorTexture"
        source = self.gltf.item("textures", texture, node=name, field=f"{where}.index").get("source")
        spec = self.gltf.item("images", source, node=name, field=f"textures[{texture}].source")
        file = f"image{source}{_IMAGE_SUFFIXES.get(str(spec.get('mimeType')), '.png')}"
        if file in self.meshes:
            return file
        uri = spec.get("uri")
        if isinstance(uri, str) and uri.startswith("data:"):
            try:
                data = base64.b64decode(uri.partition(",")[2], validate=True)
            except ValueError as e:
                raise self.gltf.fail(f"bad base64 data URI ({e})", node=name, field=f"images[{source}].uri") from None
        elif isinstance(uri, str):
            suffix = Path(uri).suffix.lower()
            file = f"image{source}{suffix if suffix in _IMAGE_SUFFIXES.values() else '.png'}"
            try:
                data = (self.gltf.path.parent / uri).read_bytes()
            except OSError:
                data = b""  # a missing image: the texture warns when read and the mesh keeps its colour
        else:
            view = self.gltf.item("bufferViews", spec.get("bufferView"), node=name, field=f"images[{source}]")
            buffer = self.gltf.buffer(view.get("buffer"), name, f"images[{source}].bufferView")  # type: ignore[arg-type]
            start = int(view.get("byteOffset", 0))
            data = buffer[start : start + int(view.get("byteLength", 0))]
        self.meshes[file] = data
        return file


_IMAGE_SUFFIXES = {"image/png": ".png", "image/jpeg": ".jpg"}


def gltf_document(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, bytes]]:
    """The scene document of a glTF file and its meshes' OBJ files (names relative to the document)."""
    importer = _Importer(_Gltf(Path(path)))
    importer.run()
    return importer.document, importer.meshes


def load_gltf(path: str | os.PathLike[str], mesh_dir: Path | None = None) -> Scene:
    """Open a glTF file as a scene; its meshes are written as OBJ files into ``mesh_dir``.

    By default ``mesh_dir`` is ``$ABERRANT_CACHE_DIR/gltf/<content hash>``, so opening the same file again
    writes nothing. Raises :class:`GltfError` naming the file, the node and the field.
    """
    path = Path(path)
    document, meshes = gltf_document(path)
    if mesh_dir is None:
        digest = hashlib.sha256(path.read_bytes() + json.dumps(document, sort_keys=True).encode()).hexdigest()
        mesh_dir = default_cache_dir() / "gltf" / digest[:32]
    missing = {mesh_dir / name: data for name, data in meshes.items() if not (mesh_dir / name).is_file()}
    if missing:
        mesh_dir.mkdir(parents=True, exist_ok=True)
        write_atomically(missing)
    try:
        return scene_from_document(document, shorten(path), mesh_dir)
    except SceneFileError as e:
        field = e.field
        if field and field.split(".")[0] in COMPONENT_KEYS:
            field = f"extras.aberrant.{field}"
        kind = "node" if e.kind == "entity" else e.kind
        raise GltfError(str(SceneFileError(e.file, e.detail, entity=e.entity, field=field, kind=kind))) from None
