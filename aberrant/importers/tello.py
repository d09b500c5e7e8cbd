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
    MATERIAL,
    MESH,
    POINT_LIGHT,
    PORTAL,
    PROCEDURAL_MESH,
    TelloError,
    TelloMesh,
    mesh_to_obj,
    read_mesh_resource,
    read_tello_document,
)
from aberrant.importers.tello_hierarchy import GameObject, TelloHierarchy
from components import MAX_LIGHTS, Aberration, Light, Mesh, Portal, Transform
from engine.errors import AberrantError
from engine.maths import look_at_quat
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


class _Importer(TelloHierarchy):
    """Builds a Scene from one parsed document; every error names file, object and field."""

    def __init__(self, file: str, mesh_dir: Path, out: Path, checker: float) -> None:
        super().__init__(file)
        self.mesh_dir = mesh_dir
        self.out = out
        self.checker = checker
        self.names: dict[int, str] = {}
        self.meshes: dict[int, TelloMesh] = {}
        self.camera_source = "default (none in the file), looking at the centre of the scene"

    # --- names -----------------------------------------------------------------------

    def assign_names(self, objects: list[GameObject], reserved: set[str]) -> None:
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

    def mesh(self, obj: GameObject, comp: tuple[int, dict[str, Any]]) -> int:
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

    def add_object(self, scene: Scene, obj: GameObject, mesh_dir_out: Path, files: list[tuple[int, Path]]) -> None:
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

    def add_point_lights(self, scene: Scene, lights: list[GameObject]) -> None:
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

    def pose_transform(self, obj: GameObject, offset: np.ndarray | None = None) -> Transform:
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

    def portal(self, obj: GameObject, comp: tuple[int, dict[str, Any]]) -> Portal:
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

    def add_camera(self, scene: Scene, camera_obj: GameObject | None) -> None:
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
