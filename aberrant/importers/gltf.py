"""Open glTF 2.0 scenes (``.gltf`` / ``.glb``, e.g. exported from Blender) as aberrant scenes.

The file's JSON (and a GLB's binary chunk) is read here, not through trimesh,
because trimesh drops node ``extras``, which is where Blender's exporter puts
an object's custom properties. What maps to what:

* **Nodes** of the default scene, depth first; a node's world TRS (parents
  composed, quaternions ``(x, y, z, w)`` as ours) is its entity's transform.
  glTF is right-handed, +Y up, cameras looking down -Z: our conventions, so no
  conversion.
* **Components** are node extras ``{"aberrant": {"aberration": {...}}}``,
  ``{"aberrant": {"portal": {"target": "<node name>"}}}`` or ``{"aberrant": {"light": {"kind": "sun"}}}``
  (a sun shines along the node's -Z, as glTF's own lights): the same keys and
  values as a scene file's entity components, validated by the scene-file
  reader. A node carrying one is that box, quad or light; its mesh (the stand-in the
  designer saw in Blender) is not rendered.
* **Root nodes** given as translation, rotation and scale keep those values
  exactly (a written scene comes back bit for bit); others are decomposed.
* **Meshes**: each triangle primitive becomes a mesh entity (``<node>`` or
  ``<node>.<i>`` when a mesh has several), its triangles written as an OBJ in
  a folder named by the file's content, with its ``TEXCOORD_0`` (V flipped
  back from glTF's top-left origin); colour from the material's
  ``baseColorFactor``, its ``baseColorTexture`` image written beside the OBJ
  as the mesh's texture, smooth shading where the primitive has normals,
  one-sided unless the material is ``doubleSided``, the checker cell size from
  the material extra ``{"aberrant": {"checker": c}}`` (and ``"smooth"``,
  ``"crease_deg"`` there, as a mesh's fields).
* **Camera**: the first node with a camera, its ``yfov`` the vertical field of
  view (to a billionth of a degree), its walking speed the node extra
  ``{"aberrant": {"camera": {"speed": s}}}``.
* **Scene extras** ``{"aberrant": {"settings": {...}, "camera_path": [...]}}``:
  the scene file's sections of the same names.

:mod:`aberrant.exporters.gltf` writes exactly this, so scenes round-trip.

Every problem is one :class:`GltfError` naming the file, the node and the field.
"""

from __future__ import annotations

import base64
import hashlib
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from aberrant.importers.gltf_format import GltfError, GltfFile
from aberrant.importers.tello_format import TelloMesh, mesh_to_obj
from engine.atomic_files import write_atomically
from engine.bvh_cache import default_cache_dir
from engine.errors import shorten
from engine.maths import quat_from_matrix, trs_matrix
from engine.scene import Scene
from engine.scene_file import SceneFileError, scene_from_document

GLTF_SUFFIXES = (".gltf", ".glb")
#: The keys allowed in a node's ``extras.aberrant`` block (``camera`` on a camera node only).
COMPONENT_KEYS = ("aberration", "portal", "light", "camera")
#: The keys allowed in the scene's ``extras.aberrant`` block: scene-file sections.
SCENE_KEYS = ("settings", "camera_path")
_TRIANGLES = 4


def unique_name(name: str, used: set[str]) -> str:
    """``name``, or ``name.1``, ``name.2``... when taken; the result is added to ``used``."""
    candidate, n = name, 0
    while candidate in used:
        n += 1
        candidate = f"{name}.{n}"
    used.add(candidate)
    return candidate


def _local_matrix(gltf: GltfFile, node: dict[str, Any], name: str) -> np.ndarray:
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


def _root_trs(node: dict[str, Any]) -> dict[str, list[float]]:
    """A root node's own TRS as the transform (its matrix was checked already): no decomposition rounding."""
    rotation = [float(c) for c in node.get("rotation", (0, 0, 0, 1))]
    norm = math.sqrt(sum(c * c for c in rotation))
    if abs(norm - 1.0) > 1e-9:
        rotation = [c / norm for c in rotation]
    return {
        "position": [float(c) for c in node.get("translation", (0, 0, 0))],
        "rotation": rotation,
        "scale": [float(c) for c in node.get("scale", (1, 1, 1))],
    }


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
    def __init__(self, gltf: GltfFile) -> None:
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
        #: Where the scene's settings and camera path came from, for messages.
        self.scene_field = "scenes[0].extras.aberrant"

    def node_names(self) -> None:
        """Unique names: a node's own, else ``node<i>``; duplicates get ``.1``, ``.2``..."""
        used: set[str] = set()
        for index, node in enumerate(self.gltf.items("nodes")):
            given = node.get("name") if isinstance(node, dict) else None
            self.names[index] = unique_name((given.strip() if isinstance(given, str) else "") or f"node{index}", used)

    def roots(self) -> list[int]:
        scenes = self.gltf.items("scenes")
        if not scenes:
            return list(range(len(self.gltf.items("nodes"))))
        scene = self.gltf.item("scenes", self.gltf.doc.get("scene", 0), node=None, field="scene")
        return list(scene.get("nodes", []))

    def scene_extras(self, roots: list[int]) -> None:
        """The default scene's ``extras.aberrant``: settings and a camera path, as in a scene file."""
        scenes = self.gltf.items("scenes")
        if not scenes:
            return
        index = self.gltf.doc.get("scene", 0)
        where = f"scenes[{index}].extras"
        extras = self.gltf.item("scenes", index, node=None, field="scene").get("extras", {})
        if not isinstance(extras, dict):
            raise self.gltf.fail("expected an object", field=where)
        block = extras.get("aberrant", {})
        if not isinstance(block, dict):
            raise self.gltf.fail("expected an object", field=f"{where}.aberrant")
        for key, value in block.items():
            if key not in SCENE_KEYS:
                raise self.gltf.fail(
                    f"unknown key {key!r}; allowed: {', '.join(SCENE_KEYS)}", field=f"{where}.aberrant.{key}"
                )
            self.document[key] = value
        self.scene_field = f"{where}.aberrant"

    def run(self) -> None:
        self.node_names()
        self.scene_extras(self.roots())
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
            exact = not seen and "matrix" not in node
            self.add(index, node, name, _root_trs(node) if exact else _decompose(world))
            stack.extend((child, world, (*seen, index)) for child in reversed(node.get("children", [])))

    def add(self, index: int, node: dict[str, Any], name: str, transform: dict[str, list[float]]) -> None:
        components = self.components(node, name)
        lens = components.pop("camera", None)
        if lens is not None and "camera" not in node:
            raise self.gltf.fail("only a camera node holds camera settings", node=name, field="extras.aberrant.camera")
        if "camera" in node and "camera" not in self.document:
            camera = self.gltf.item("cameras", node["camera"], node=name, field="camera")
            block: dict[str, Any] = {"name": name, "position": transform["position"], "rotation": transform["rotation"]}
            yfov = camera.get("perspective", {}).get("yfov")
            if isinstance(yfov, int | float):
                block["fov_deg"] = round(math.degrees(yfov), 9)
            if lens is not None:
                if not isinstance(lens, dict) or set(lens) - {"speed"}:
                    raise self.gltf.fail(
                        "expected an object holding only 'speed'", node=name, field="extras.aberrant.camera"
                    )
                block.update(lens)
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
            raise self.gltf.fail(
                f"a node carries one component (aberration, portal, light or camera), this one {len(block)}: "
                f"{', '.join(block)}",
                node=name,
                field="extras",
            )
        return dict(block)

    def per_vertex(
        self, primitive: dict[str, Any], key: str, width: int, count: int, name: str, field: str
    ) -> np.ndarray | None:
        """A primitive's optional float attribute ``key`` of ``width`` components, one per vertex."""
        if key not in primitive["attributes"]:
            return None
        where = f"{field}.attributes.{key}"
        values = self.gltf.accessor(primitive["attributes"][key], name, where)
        if values.shape != (count, width) or values.dtype != np.float32:
            raise self.gltf.fail(f"expected float VEC{width} values, one per vertex", node=name, field=where)
        return values

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
        uvs = self.per_vertex(primitive, "TEXCOORD_0", 2, len(vertices), name, field)
        if uvs is not None:
            uvs = uvs.astype(np.float64)
            uvs[:, 1] = 1.0 - uvs[:, 1]  # glTF's UV origin is the image's top left, ours the bottom left
        normals = self.per_vertex(primitive, "NORMAL", 3, len(vertices), name, field)
        asset = f"mesh{mesh_index}.{i}"
        if asset not in self.document["assets"]:
            self.meshes[f"{asset}.obj"] = mesh_to_obj(
                TelloMesh(vertices.astype(np.float32), faces, None if uvs is None else uvs.astype(np.float32), normals),
                f"{self.gltf.file} {field}",
            )
            self.document["assets"][asset] = {"path": f"{asset}.obj"}
        block: dict[str, Any] = {"asset": asset, "cull_backfaces": True}
        if "NORMAL" in primitive["attributes"]:
            block["smooth"] = True  # the file shades smoothly, with its vertex normals
        if "material" in primitive:
            material = self.gltf.item("materials", primitive["material"], node=name, field=f"{field}.material")
            pbr = material.get("pbrMetallicRoughness", {})
            factor = pbr.get("baseColorFactor")
            if isinstance(factor, list) and len(factor) == 4:
                block["color"] = [float(c) for c in factor[:3]]
            block["cull_backfaces"] = not material.get("doubleSided", False)
            extras = material.get("extras", {})
            checker = extras.get("aberrant", {}).get("checker") if isinstance(extras, dict) else None
            if checker is not None:
                if isinstance(checker, int | float) and not isinstance(checker, bool) and checker >= 0:
                    block["checker"] = checker
                else:
                    where = f"materials[{primitive['material']}].extras.aberrant.checker"
                    raise self.gltf.fail(
                        f"expected a cell size >= 0 (0: none), got {checker!r}", node=name, field=where
                    )
            for key in ("smooth", "crease_deg"):
                if isinstance(extras, dict) and key in extras.get("aberrant", {}):
                    block[key] = extras["aberrant"][key]  # validated with the mesh block by the scene-file reader
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
    document, meshes, _ = _imported(path)
    return document, meshes


def _imported(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, bytes], str]:
    importer = _Importer(GltfFile(Path(path)))
    importer.run()
    return importer.document, importer.meshes, importer.scene_field


def load_gltf(path: str | os.PathLike[str], mesh_dir: Path | None = None) -> Scene:
    """Open a glTF file as a scene; its meshes are written as OBJ files into ``mesh_dir``.

    By default ``mesh_dir`` is ``$ABERRANT_CACHE_DIR/gltf/<content hash>``, so opening the same file again
    writes nothing. Raises :class:`GltfError` naming the file, the node and the field.
    """
    path = Path(path)
    document, meshes, scene_field = _imported(path)
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
        top = (field or "").split(".")[0].split("[")[0]
        if top in COMPONENT_KEYS:
            field = f"extras.aberrant.{field}"
        elif top in SCENE_KEYS:
            field = f"{scene_field}.{field}"
        kind = "node" if e.kind == "entity" else e.kind
        raise GltfError(str(SceneFileError(e.file, e.detail, entity=e.entity, field=field, kind=kind))) from None
