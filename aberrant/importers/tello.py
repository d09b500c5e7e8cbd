"""Import the thesis engine's (TelloEngine's) scene files into our scene format.

Format (``docs/tello-format.md``; samples in ``tests/data/tello/``): JSON followed by one NUL byte; a flat,
depth-first list of game objects whose transforms are local to their parent;
mesh resources are binary files named by uid. What this importer maps, and why:

* **Conventions.** TelloEngine is OpenGL/glm like us: right-handed, +Y up,
  quaternions stored ``[x, y, z, w]`` (our order too). Evidence in the data:
  floors lie at y = 0 and ceilings at y = 10 (+Y up), walls are the unit box
  rotated -90° about X so its local +Z height becomes world +Y, and every
  stored normal equals the right-handed cross product of its triangle's edges
  (counter-clockwise front faces). So no axis or handedness conversion.
* **Hierarchy** is composed parent · child (``M = T R S`` matrices) and baked
  into flat world transforms; a non-uniform parent scale under a rotated
  child (shear) cannot be a T·R·S and is approximated, with a warning.
* **Meshes** are converted to OBJ files (geometry exactly as stored, pivot
  included) written beside the output scene, and rendered one-sided
  (``cull_backfaces``), as the thesis's tracer did. Colour: ``ColR/G/B``
  clamped to [0, 1]; the thesis mixed in a 40 % checker texture, which we
  approximate with our checker (``checker`` cells per UV unit, 0 for none).
* **Aberrations** use the unit box [-½,½]² × [0, 1] (pivot on its bottom face,
  in local z); ours is the centred cube, so the centre moves by
  ``R (s ⊙ (0, 0, ½))``. Deformation along world axes, ``radial`` with the
  ``restore`` exit rule (docs/semantics.md, rules 7-8).
* **Portals** are the quad [-1, 1]² in local XY facing +Z, exactly ours: no
  conversion; ``connectedGO`` becomes the target's (de-duplicated) name.
* **Camera** component: the camera's world pose (scale dropped). Without one, a
  camera inside the scene's bounds looking at their centre. A **PointLight**
  (no fields) becomes a white shadowing point light at its object's world
  position, as bright at half the scene's extent as the default sun;
  ProceduralMesh is skipped with a warning that lists the objects.
"""

from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aberrant.importers.tello_format import (
    ABERRATION,
    CAMERA,
    COMPONENT_NAMES,
    MATERIAL,
    MESH,
    POINT_LIGHT,
    PORTAL,
    PROCEDURAL_MESH,
    TRANSFORM,
    TelloError,
    TelloMesh,
    mesh_to_obj,
    read_mesh_resource,
    read_tello_document,
)
from components import MAX_LIGHTS, Aberration, Light, Mesh, Portal, Transform, ValidationError
from components.validation import real, vector
from engine.errors import AberrantError
from engine.maths import look_at_quat, quat_from_matrix, quat_multiply, quat_normalize, quat_to_matrix, trs_matrix
from engine.scene import Scene
from engine.scene_file import save_scene

#: The thesis's box pivot: the centre of [-½,½]² × [0, 1] in its local space.
BOX_CENTRE = np.array([0.0, 0.0, 0.5])
#: Default checker cells per UV unit (the thesis textured every box face with one checker image).
DEFAULT_CHECKER = 0.125
#: A PointLight is as bright as the default sun at this fraction of the scene's extent (inverse square).
POINT_LIGHT_REACH = 0.5


@dataclass
class ImportResult:
    """The imported scene, the files written and what was left out."""

    scene: Scene
    mesh_files: list[Path] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    camera: str = "default"  # where the camera came from: "default" or the game object's label


@dataclass
class _Pose:
    """A world pose ``T(p) R(q) S(s)``, kept as its parts so that plain hierarchies stay exact."""

    p: np.ndarray
    q: np.ndarray
    s: np.ndarray

    @property
    def matrix(self) -> np.ndarray:
        return trs_matrix(self.p, self.q, self.s)

    def transform(self, offset: np.ndarray | None = None) -> Transform:
        """Our Transform of this pose, its origin moved to the local point ``offset``."""
        position = self.p if offset is None else self.p + quat_to_matrix(self.q) @ (self.s * offset)
        q = self.q if self.q[3] >= 0.0 else -self.q

        def clean(values: np.ndarray) -> tuple[float, ...]:
            return tuple(float(c) + 0.0 for c in values)  # + 0.0 turns -0.0 into 0.0

        return Transform(clean(position), clean(q), clean(self.s))


@dataclass
class _Object:
    """One game object as read: its components as ``(index in its list, type, fields)``."""

    uuid: int
    parent: int
    name: str
    components: list[tuple[int, int, dict[str, Any]]]

    @property
    def label(self) -> str:
        return f"game object {self.uuid} {self.name!r}"

    def first(self, kind: int) -> tuple[int, dict[str, Any]] | None:
        for i, t, c in self.components:
            if t == kind:
                return i, c
        return None


class _Importer:
    """Builds a Scene from one parsed document; every error names file, object and field."""

    def __init__(self, file: str, mesh_dir: Path, out: Path, checker: float) -> None:
        self.file = file
        self.mesh_dir = mesh_dir
        self.out = out
        self.checker = checker
        self.objects: dict[int, _Object] = {}
        self.world: dict[int, _Pose] = {}
        self.names: dict[int, str] = {}
        self.warnings: list[str] = []
        self.meshes: dict[int, TelloMesh] = {}
        self.camera_source = "default (none in the file), looking at the centre of the scene"

    def fail(self, message: str, obj: _Object | None = None, field: str | None = None) -> TelloError:
        return TelloError(self.file, message, entity=obj.label if obj else None, field=field, kind=None)

    # --- parsing -------------------------------------------------------------------

    def parse(self, doc: dict[str, Any]) -> list[_Object]:
        order: list[_Object] = []
        for index, item in enumerate(doc["game_objects"]):
            where = f"game_objects[{index}]"
            if not isinstance(item, dict):
                raise self.fail("expected an object", field=where)
            uuid = self.uuid_field(item.get("uuid"), f"{where}.uuid")
            parent = self.uuid_field(item.get("parent", 0), f"{where}.parent")
            name = item.get("name")
            name = name.strip() if isinstance(name, str) and name.strip() else f"object_{uuid}"
            obj = _Object(uuid, parent, name, [])
            if uuid in self.objects:
                raise self.fail(f"uuid {uuid} is used twice (also by {self.objects[uuid].label})", obj, "uuid")
            comps = item.get("components", [])
            if not isinstance(comps, list):
                raise self.fail("expected a list", obj, "components")
            for i, comp in enumerate(comps):
                kind = comp.get("type") if isinstance(comp, dict) else None
                if isinstance(kind, bool) or not isinstance(kind, int) or not 0 <= kind < len(COMPONENT_NAMES):
                    raise self.fail(
                        f"unknown component type {kind!r} (known: 0-7, {', '.join(COMPONENT_NAMES)})",
                        obj,
                        f"components[{i}].type",
                    )
                obj.components.append((i, kind, comp))
            self.objects[uuid] = obj
            order.append(obj)
        return order

    def uuid_field(self, value: object, field: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(f"expected an integer uuid, got {value!r}", field=field)
        return value

    def number(self, obj: _Object, comp: tuple[int, dict[str, Any]], key: str, default: float | None = None) -> float:
        i, fields = comp
        if key not in fields and default is not None:
            return default
        try:
            return real(fields.get(key), key)
        except ValidationError as e:
            raise self.fail(e.message, obj, f"components[{i}].{key}") from None

    def local_pose(self, obj: _Object) -> _Pose:
        comp = obj.first(TRANSFORM)
        if comp is None:
            return _Pose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.ones(3))
        i, fields = comp
        try:
            position = vector(fields.get("position", [0, 0, 0]), 3, "position")
            rotation = vector(fields.get("rotation", [0, 0, 0, 1]), 4, "rotation")
            scale = vector(fields.get("scale", [1, 1, 1]), 3, "scale")
            with np.errstate(all="ignore"):  # a length that overflows is reported below
                q = quat_normalize(rotation)
        except ValidationError as e:
            raise self.fail(e.message, obj, f"components[{i}].{e.field}") from None
        except ValueError:
            raise self.fail("the rotation quaternion is zero", obj, f"components[{i}].rotation") from None
        if not np.all(np.isfinite(q)) or abs(float(np.linalg.norm(q)) - 1.0) > 1e-6:  # its length overflowed
            raise self.fail("the rotation quaternion cannot be normalised", obj, f"components[{i}].rotation")
        if min(abs(c) for c in scale) < 1e-12:
            raise self.fail("a scale component is zero (the object collapses)", obj, f"components[{i}].scale")
        return _Pose(np.array(position), q, np.array(scale))

    def world_pose(self, obj: _Object, seen: tuple[int, ...] = ()) -> _Pose:
        """The object's world pose, ``M_parent_world · M_local``, memoised."""
        if obj.uuid in self.world:
            return self.world[obj.uuid]
        if obj.uuid in seen:
            raise self.fail("the parent chain loops back to this object", obj, "parent")
        pose = self.local_pose(obj)
        if obj.parent != 0:
            parent = self.objects.get(obj.parent)
            if parent is None:
                raise self.fail(f"no game object has uuid {obj.parent}", obj, "parent")
            pose = self.compose(obj, self.world_pose(parent, (*seen, obj.uuid)), pose)
            if not all(np.all(np.isfinite(a)) for a in (pose.p, pose.q, pose.s)) or np.min(np.abs(pose.s)) < 1e-12:
                raise self.fail(
                    "its world transform overflows or collapses (the hierarchy's positions or scales are too large "
                    "or too small)",
                    obj,
                    "parent",
                )
        self.world[obj.uuid] = pose
        return pose

    def compose(self, obj: _Object, parent: _Pose, child: _Pose) -> _Pose:
        """``parent · child``: exact on (p, q, s) under a uniform parent scale, else via the matrix."""
        with np.errstate(all="ignore"):  # huge or tiny values: the caller rejects a non-finite result
            return self._compose(obj, parent, child)

    def _compose(self, obj: _Object, parent: _Pose, child: _Pose) -> _Pose:
        """:meth:`compose` without the errstate; a NaN pose when the product overflows (SVD would not converge)."""
        nan = _Pose(np.full(3, np.nan), np.full(4, np.nan), np.full(3, np.nan))
        if not np.all(np.isfinite(parent.s * child.s)) or not np.all(np.isfinite(parent.s * child.p)):
            return nan
        if np.ptp(parent.s) <= 1e-12 * float(np.max(np.abs(parent.s))):
            position = parent.p + quat_to_matrix(parent.q) @ (parent.s * child.p)
            return _Pose(position, quat_normalize(quat_multiply(parent.q, child.q)), parent.s * child.s)
        m = parent.matrix @ child.matrix
        if not np.all(np.isfinite(m)):
            return nan
        linear = m[:3, :3]
        scale = np.linalg.norm(linear, axis=0)
        if not np.all(np.isfinite(scale)) or np.min(scale) < 1e-300:
            return nan
        if np.linalg.det(linear) < 0.0:
            scale[0] = -scale[0]
        rotation = linear / scale
        if np.max(np.abs(rotation.T @ rotation - np.eye(3))) > 1e-6:
            self.warnings.append(f"{obj.label}: its parents' non-uniform scale shears it; kept the nearest rotation")
            u, _, vt = np.linalg.svd(rotation)
            rotation = u @ vt
        return _Pose(m[:3, 3].copy(), quat_from_matrix(rotation), scale)

    # --- names -----------------------------------------------------------------------

    def assign_names(self, objects: list[_Object], reserved: set[str]) -> None:
        """Unique names in file order: the first keeps its name, later ones get ``_2``, ``_3``..."""
        originals = {o.name for o in objects}
        taken = set(reserved)
        for obj in objects:
            name, n = obj.name, 1
            while name in taken or (n > 1 and name in originals):
                n += 1
                name = f"{obj.name}_{n}"
            taken.add(name)
            self.names[obj.uuid] = name

    # --- building ---------------------------------------------------------------------

    def mesh(self, obj: _Object, comp: tuple[int, dict[str, Any]]) -> int:
        i, fields = comp
        uid = fields.get("mesh")
        if isinstance(uid, bool) or not isinstance(uid, int):
            raise self.fail(f"expected a mesh resource uid (integer), got {uid!r}", obj, f"components[{i}].mesh")
        if uid not in self.meshes:
            path = self.mesh_dir / str(uid)
            if not path.is_file():
                raise self.fail(f"mesh resource {uid} not found in {self.mesh_dir}", obj, f"components[{i}].mesh")
            try:
                self.meshes[uid] = read_mesh_resource(path)
            except (AberrantError, OSError) as e:
                raise self.fail(str(e), obj, f"components[{i}].mesh") from None
        return uid

    def build(self, doc: dict[str, Any]) -> tuple[Scene, list[tuple[int, Path]]]:
        objects = self.parse(doc)
        for obj in objects:
            self.world_pose(obj)
        kept = [o for o in objects if any(t in (MESH, ABERRATION, PORTAL, CAMERA) for _, t, _ in o.components)]
        camera_obj = next((o for o in objects if o.first(CAMERA) is not None), None)
        self.assign_names(kept, set() if camera_obj else {"camera"})
        scene_name = doc.get("scene_name") if isinstance(doc.get("scene_name"), str) else self.out.stem
        scene = Scene(scene_name or self.out.stem, base_dir=self.out.parent)
        mesh_dir_out = self.out.parent / f"{self.out.stem}_meshes"
        files: list[tuple[int, Path]] = []
        procedural = [o.label for o in objects if o.first(PROCEDURAL_MESH) is not None]
        if procedural:
            self.warnings.append(f"skipped ProceduralMesh components (not supported) on: {', '.join(procedural)}")
        for obj in kept:
            self.add_object(scene, obj, mesh_dir_out, files)
        self.add_point_lights(scene, [o for o in objects if o.first(POINT_LIGHT) is not None])
        self.add_camera(scene, camera_obj)
        return scene, files

    def add_object(self, scene: Scene, obj: _Object, mesh_dir_out: Path, files: list[tuple[int, Path]]) -> None:
        name = self.names[obj.uuid]
        parts: list[object] = []
        mesh_comp = obj.first(MESH)
        if mesh_comp is not None:
            uid = self.mesh(obj, mesh_comp)
            asset = f"tello_mesh_{uid}"
            if asset not in scene.assets:
                path = mesh_dir_out / f"{uid}.obj"
                files.append((uid, path))
                scene.add_asset(asset, path=path)
            color = (0.8, 0.8, 0.8)
            material = obj.first(MATERIAL)
            if material is not None:
                r, g, b = (min(max(self.number(obj, material, k, 1.0), 0.0), 1.0) for k in ("ColR", "ColG", "ColB"))
                color = (r, g, b)
            parts.append(Mesh(asset, color, self.checker, cull_backfaces=True))
        portal_comp = obj.first(PORTAL)
        if portal_comp is not None:
            parts.append(self.portal(obj, portal_comp))
        if parts:
            scene.create_entity(name, self.pose_transform(obj), *parts)
        aberration_comp = obj.first(ABERRATION)
        if aberration_comp is not None:
            fields = aberration_comp[1]
            dx, dy, dz = (self.number(obj, aberration_comp, f"deformation{k}", 0.0) for k in "XYZ")
            deformation = (dx, dy, dz)
            debug = fields.get("debugDraw", True)
            aberration = Aberration(
                deformation, "radial", "restore", debug_draw=debug if isinstance(debug, bool) else True
            )
            label = name if not parts else self.unique(scene, f"{name}_aberration")
            # bottom pivot -> our cube's centre
            scene.create_entity(label, self.pose_transform(obj, BOX_CENTRE), aberration)

    def add_point_lights(self, scene: Scene, lights: list[_Object]) -> None:
        """A PointLight (no fields in the format) becomes a white shadowing point light at the object's world
        position, bright enough to light the scene's extent (POINT_LIGHT_REACH of it at unit strength); past
        MAX_LIGHTS, the rest are dropped with a warning."""
        if len(lights) > MAX_LIGHTS:
            dropped = ", ".join(o.label for o in lights[MAX_LIGHTS:])
            self.warnings.append(f"kept the first {MAX_LIGHTS} PointLights (a scene holds no more), dropped: {dropped}")
        extent = self.extent(scene)
        for obj in lights[:MAX_LIGHTS]:
            pose = self.pose_transform(obj)
            name = self.unique(scene, f"{obj.name}_light")
            light = Light("point", intensity=(POINT_LIGHT_REACH * extent) ** 2, shadows=True)
            scene.create_entity(name, Transform(pose.position), light)

    @staticmethod
    def extent(scene: Scene) -> float:
        """The largest scale of any mesh entity (walls and floors span the room), at least 1."""
        scales = [max(abs(c) for c in t.scale) for _, (t, _) in scene.query(Transform, Mesh)]
        return max([1.0, *scales])

    def pose_transform(self, obj: _Object, offset: np.ndarray | None = None) -> Transform:
        """The object's world pose as our Transform; one that overflows is an error naming the object."""
        try:
            with np.errstate(all="ignore"):
                return self.world[obj.uuid].transform(offset)
        except ValueError as e:  # ValidationError: a non-finite position, a zero scale
            raise self.fail(f"its world transform cannot be represented ({e})", obj, "transform") from None

    def unique(self, scene: Scene, base: str) -> str:
        taken = {scene.name_of(e) for e in scene.entities()} | set(self.names.values())
        name, n = base, 1
        while name in taken:
            n += 1
            name = f"{base}_{n}"
        return name

    def portal(self, obj: _Object, comp: tuple[int, dict[str, Any]]) -> Portal:
        i, fields = comp
        target_uuid = fields.get("connectedGO", 0)
        if isinstance(target_uuid, bool) or not isinstance(target_uuid, int):
            raise self.fail(f"expected a game object uuid, got {target_uuid!r}", obj, f"components[{i}].connectedGO")
        target = None
        if target_uuid != 0:
            other = self.objects.get(target_uuid)
            if other is None:
                raise self.fail(f"no game object has uuid {target_uuid}", obj, f"components[{i}].connectedGO")
            if other.first(PORTAL) is None:
                raise self.fail(
                    f"links to {other.label}, which has no Portal component", obj, f"components[{i}].connectedGO"
                )
            target = self.names[other.uuid]
        r, g, b = (min(max(self.number(obj, comp, f"debugDrawCol{k}", 1.0), 0.0), 1.0) for k in "RGB")
        debug = fields.get("debugDraw", True)
        return Portal(target, (r, g, b), debug if isinstance(debug, bool) else True)

    def add_camera(self, scene: Scene, camera_obj: _Object | None) -> None:
        if camera_obj is not None:
            pose = self.pose_transform(camera_obj)
            name = self.names[camera_obj.uuid]
            if name in {scene.name_of(e) for e in scene.entities()}:  # the camera object also holds a mesh/portal
                name = self.unique(scene, f"{name}_camera")
            scene.set_camera(pose.position, rotation=pose.rotation, name=name)
            self.camera_source = camera_obj.label
            return
        eye, rotation = self.default_camera()
        scene.set_camera(eye, rotation=rotation)

    def default_camera(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Position and rotation of a camera for a scene that has none, looking at the centre of its bounds.

        With meshes (a level is a room to stand in) the camera stands inside the
        bounds, 40 % of their depth towards -Z from the centre, looking along +Z
        (for AberrationRoom: at the room's end, the x-compressed half on the left
        as the thesis describes it). Without meshes it looks at the aberration
        and portal boxes from outside.
        """
        with np.errstate(all="ignore"):  # overflowing bounds are reported below
            low, high, has_meshes = self.bounds()
            centre = np.round(0.5 * (low + high), 6) + 0.0
            if has_meshes:
                eye = centre - np.array([0.0, 0.0, 0.4 * (high[2] - low[2])])
            else:
                eye = centre - np.array([0.0, 0.0, 0.5 * (high[2] - low[2]) + 1.5 * float(np.max(high - low)) + 1.0])
            if np.linalg.norm(eye - centre) < 1e-6:
                eye = centre - np.array([0.0, 0.0, 5.0])
            eye = np.round(eye, 6) + 0.0
            try:
                rotation = look_at_quat(eye, centre)
            except ValueError:  # eye == centre in float: the scene is too far from the origin
                rotation = np.full(4, np.nan)
        if not (np.all(np.isfinite(eye)) and np.all(np.isfinite(rotation))):
            raise self.fail(
                "the scene's bounds are too large (or too far from the origin) to place a default camera; "
                "give one game object a Camera component"
            )
        return tuple(float(c) for c in eye), tuple(float(c) + 0.0 for c in rotation)

    def bounds(self) -> tuple[np.ndarray, np.ndarray, bool]:
        """World bounds of the meshes (else of the aberration and portal shapes, else ±1) and whether meshes."""
        meshes, shapes = [], []
        corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (0.0, 1.0)])
        for obj in self.objects.values():
            m = self.world[obj.uuid].matrix
            comp = obj.first(MESH)
            if comp is not None:
                meshes.append(self.meshes[comp[1]["mesh"]].vertices.astype(np.float64) @ m[:3, :3].T + m[:3, 3])
            if obj.first(ABERRATION) is not None:
                shapes.append(corners @ m[:3, :3].T + m[:3, 3])
            if obj.first(PORTAL) is not None:
                shapes.append(2.0 * corners[::2] * (1, 1, 0) @ m[:3, :3].T + m[:3, 3])
        points = meshes or shapes
        if not points:
            return np.full(3, -1.0), np.full(3, 1.0), False
        stacked = np.vstack(points)
        return stacked.min(axis=0), stacked.max(axis=0), bool(meshes)


def import_tello(
    scene_file: str | os.PathLike[str],
    mesh_dir: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    checker: float = DEFAULT_CHECKER,
) -> ImportResult:
    """Convert ``scene_file`` to ``out`` (our scene format) plus OBJ files in ``<out stem>_meshes/``."""
    scene_path, mesh_path, out_path = Path(scene_file), Path(mesh_dir), Path(out)
    doc = read_tello_document(scene_path)
    if not mesh_path.is_dir():
        raise TelloError(str(scene_path), f"the mesh folder {str(mesh_path)!r} does not exist")
    if not math.isfinite(checker) or checker < 0.0:
        raise AberrantError(f"checker must be a finite number >= 0, got {checker}")
    importer = _Importer(str(scene_path), mesh_path, out_path, checker)
    scene, files = importer.build(doc)
    folder = files[0][1].parent if files else None
    made = folder is not None and not folder.exists()
    try:
        scene.validate()
        if folder is not None:
            folder.mkdir(exist_ok=True)
        meshes = {path: mesh_to_obj(importer.meshes[uid], f"TelloEngine mesh {uid}") for uid, path in files}
        save_scene(scene, out_path, with_files=meshes)  # the meshes and the scene, or (a full disk) none
    except BaseException:
        scene.close()
        if made and folder is not None:
            shutil.rmtree(folder, ignore_errors=True)
        raise
    counts = {
        "meshes": len(scene.query(Mesh)),
        "aberrations": len(scene.query(Aberration)),
        "portals": len(scene.query(Portal)),
    }
    return ImportResult(scene, [path for _, path in files], importer.warnings, counts, importer.camera_source)
