"""Scene documents read into scenes: the parsed JSON of a scene file (or an importer's document) checked
key by key and built through the component dataclasses, so every value is validated in one place and each
failure is one :class:`engine.errors.SceneFileError` naming the file, the entity and the field.

The format is in :mod:`engine.scene_file`, which reads files through this and saves them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from components import Aberration, Camera, Light, Mesh, Portal, Transform, ValidationError
from components.validation import vec3
from engine.assets import PRIMITIVES
from engine.errors import AberrantError, SceneError, SceneFileError
from engine.keyframes import CameraPathError, Keyframe, checked_keyframes
from engine.maths import look_at_quat, quat_from_euler_deg
from engine.scene import Scene
from engine.scene_world import AssetSpec
from engine.scene_writer import FORMAT, VERSION
from engine.settings import Settings

TOP_KEYS = ("format", "version", "name", "settings", "camera", "assets", "entities", "camera_path")
KEYFRAME_KEYS = ("time", "position", "rotation", "look_at")
SETTINGS_KEYS = ("background", "light_dir", "max_events", "event_limit_color", "ambient")
CAMERA_KEYS = ("name", "position", "rotation", "look_at", "euler_deg", "fov_deg", "speed")
ASSET_KEYS = ("path", "primitive")
ENTITY_KEYS = ("name", "transform", "mesh", "aberration", "portal", "light")
TRANSFORM_KEYS = ("position", "rotation", "euler_deg", "scale")
MESH_KEYS = ("asset", "color", "checker", "cull_backfaces", "texture", "smooth", "crease_deg")
ABERRATION_KEYS = ("deformation", "mode", "exit", "priority", "debug_draw", "color")
PORTAL_KEYS = ("target", "color", "debug_draw")
LIGHT_KEYS = ("kind", "color", "intensity", "shadows", "range")

#: The camera entity's name when the file does not give one.
DEFAULT_CAMERA_NAME = "camera"


class _Object(dict):
    """A JSON object that remembers keys it saw twice (json keeps only the last silently)."""

    duplicates: tuple[str, ...] = ()


def object_pairs(pairs: list[tuple[str, Any]]) -> _Object:
    """``json``'s ``object_pairs_hook``: the object, remembering keys given twice."""
    obj = _Object(pairs)
    if len(obj) != len(pairs):
        seen: set[str] = set()
        duplicates = []
        for key, _ in pairs:
            if key in seen:
                duplicates.append(key)
            seen.add(key)
        obj.duplicates = tuple(duplicates)
    return obj


def _type_name(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__  # pragma: no cover - json produces nothing else


class _Reader:
    """Turns one parsed document into a Scene, raising errors that say where."""

    def __init__(self, file: str) -> None:
        self.file = file
        #: Labels that are not entity names: ``label -> (kind, name)`` for the message.
        self.labels: dict[str, tuple[str | None, str]] = {}

    def fail(self, message: str, *, entity: str | None = None, field: str | None = None) -> SceneFileError:
        """An error about ``entity`` (an entity name, ``asset 'x'`` or ``entities[i]``)."""
        kind: str | None = "entity"
        if entity is not None and entity in self.labels:
            kind, entity = self.labels[entity]
        return SceneFileError(self.file, message, entity=entity, field=field, kind=kind)

    def obj(
        self, value: object, allowed: tuple[str, ...] | None, field: str, entity: str | None = None
    ) -> dict[str, Any]:
        """``value`` as a JSON object holding only ``allowed`` keys (any keys when ``None``)."""
        if not isinstance(value, dict):
            raise self.fail(f"expected an object, got {_type_name(value)}", entity=entity, field=field or None)
        duplicates = getattr(value, "duplicates", ())
        prefix = f"{field}." if field else ""
        if duplicates:
            raise self.fail(
                f"the key {duplicates[0]!r} appears more than once", entity=entity, field=f"{prefix}{duplicates[0]}"
            )
        unknown = [] if allowed is None else [k for k in value if k not in allowed]
        if unknown:
            raise self.fail(
                f"unknown key {unknown[0]!r}; allowed keys: {', '.join(allowed or ())}",
                entity=entity,
                field=f"{prefix}{unknown[0]}",
            )
        return value

    def component(self, factory: Callable[..., Any], fields: dict[str, Any], field: str, entity: str | None) -> Any:
        """Build a component, reporting its validation error under ``field``."""
        try:
            return factory(**fields)
        except ValidationError as e:
            raise self.fail(e.message, entity=entity, field=f"{field}.{e.field}" if field else e.field) from None

    def rotation(self, block: dict[str, Any], field: str, entity: str | None, position: object) -> object:
        """The quaternion named by ``rotation``, ``euler_deg`` or (cameras) ``look_at``; at most one."""
        given = [k for k in ("rotation", "euler_deg", "look_at") if k in block]
        if len(given) > 1:
            raise self.fail(
                f"give only one of {', '.join(given)} (they all set the rotation)",
                entity=entity,
                field=f"{field}.{given[1]}",
            )
        try:
            if "euler_deg" in block:
                return tuple(float(c) for c in quat_from_euler_deg(vec3(block["euler_deg"], "euler_deg")))
            if "look_at" in block:
                target = vec3(block["look_at"], "look_at")
                eye = vec3(position, "position")
                if max(abs(a - b) for a, b in zip(eye, target, strict=True)) < 1e-12:
                    raise ValidationError("look_at", "the point looked at equals the camera position")
                try:
                    with np.errstate(over="ignore", invalid="ignore"):
                        quat = look_at_quat(eye, target)
                except ValueError:  # the difference overflows (points near ±1e308) or underflows
                    quat = np.full(4, np.nan)
                if not np.all(np.isfinite(quat)):
                    raise ValidationError("look_at", "no direction from the camera position to this point (too far)")
                return tuple(float(c) for c in quat)
        except ValidationError as e:
            raise self.fail(e.message, entity=entity, field=f"{field}.{e.field}") from None
        rotation = block.get("rotation", (0.0, 0.0, 0.0, 1.0))
        return tuple(rotation) if isinstance(rotation, list) else rotation

    def transform(self, value: object, field: str, entity: str) -> Transform:
        block = self.obj(value, TRANSFORM_KEYS, field, entity)
        position = block.get("position", (0.0, 0.0, 0.0))
        rotation = self.rotation(block, field, entity, position)
        scale = block.get("scale", (1.0, 1.0, 1.0))
        if isinstance(scale, int | float) and not isinstance(scale, bool):
            scale = (scale, scale, scale)  # a uniform scale may be written as one number
        return self.component(Transform, {"position": position, "rotation": rotation, "scale": scale}, field, entity)

    def read(self, doc: object, base_dir: Path) -> Scene:
        top = self.obj(doc, TOP_KEYS, "")
        if top.get("format") != FORMAT:
            got = "missing" if "format" not in top else repr(top["format"])
            raise self.fail(f"not an aberrant scene file: expected {FORMAT!r}, got {got}", field="format")
        version = top.get("version")
        if isinstance(version, bool) or not isinstance(version, int):
            raise self.fail(f"expected the integer {VERSION}, got {version!r}", field="version")
        if version != VERSION:
            newer = "newer than" if version > VERSION else "not"
            raise self.fail(
                f"scene file version {version} is {newer} supported (this aberrant reads version {VERSION})",
                field="version",
            )
        name = top.get("name", "untitled")
        if not isinstance(name, str):
            raise self.fail(f"expected a string, got {_type_name(name)}", field="name")
        settings = self.component(
            Settings, self.obj(top.get("settings", {}), SETTINGS_KEYS, "settings"), "settings", None
        )
        scene = Scene(name, settings=settings, base_dir=base_dir)
        try:
            self.fill(scene, top)
        except BaseException:
            scene.close()
            raise
        return scene

    def fill(self, scene: Scene, top: dict[str, Any]) -> None:
        assets = self.obj(top.get("assets", {}), None, "assets")
        for asset_name, spec in assets.items():
            self.asset(scene, asset_name, spec)
        if "camera" in top:
            self.camera(scene, top["camera"])
        entities = top.get("entities", [])
        if not isinstance(entities, list):
            raise self.fail(f"expected an array of entities, got {_type_name(entities)}", field="entities")
        for index, value in enumerate(entities):
            self.entity(scene, index, value)
        if "camera_path" in top:
            scene.camera_path = self.camera_path(top["camera_path"])
        self.check(scene)

    def camera_path(self, value: object) -> tuple[Keyframe, ...]:
        """The keyframes of ``camera_path``, checked as a camera path checks them (errors name the keyframe)."""
        if not isinstance(value, list):
            raise self.fail(f"expected an array of keyframes, got {_type_name(value)}", field="camera_path")
        keys = []
        for index, item in enumerate(value):
            block = self.obj(item, KEYFRAME_KEYS, f"camera_path[{index}]")
            if "time" not in block or "position" not in block:
                missing = "time" if "time" not in block else "position"
                raise self.fail(
                    "every keyframe needs a 'time' and a 'position'", field=f"camera_path[{index}].{missing}"
                )
            if isinstance(block["time"], bool) or not isinstance(block["time"], int | float):
                raise self.fail(
                    f"expected a number, got {_type_name(block['time'])}", field=f"camera_path[{index}].time"
                )
            keys.append(Keyframe(block["time"], block["position"], block.get("rotation"), block.get("look_at")))
        try:
            checked_keyframes(keys)
        except CameraPathError as e:
            field = "camera_path" if e.index is None else f"camera_path[{e.index}].{e.field or 'time'}"
            raise self.fail(e.detail, field=field) from None
        return tuple(_plain_keyframe(key) for key in keys)

    def asset_label(self, name: str) -> str:
        label = f"\0asset:{name}"
        self.labels[label] = ("asset", name)
        return label

    def asset(self, scene: Scene, name: str, value: object) -> None:
        where = self.asset_label(name)
        field = f"assets.{name}"
        if not name:
            raise self.fail("an asset name must not be empty", field="assets")
        block = self.obj(value, ASSET_KEYS, field, where)
        for key in ASSET_KEYS:
            if key in block and (not isinstance(block[key], str) or not block[key]):
                raise self.fail(
                    f"expected a non-empty string, got {block[key]!r}", entity=where, field=f"{field}.{key}"
                )
        try:
            AssetSpec(block.get("primitive"), block.get("path"))
        except ValidationError as e:
            sub = "" if e.field == "asset" else f".{e.field}"
            raise self.fail(e.message, entity=where, field=f"{field}{sub}") from None
        scene.add_asset(name, primitive=block.get("primitive"), path=block.get("path"))

    def camera(self, scene: Scene, value: object) -> None:
        block = self.obj(value, CAMERA_KEYS, "camera", DEFAULT_CAMERA_NAME)
        name = block.get("name", DEFAULT_CAMERA_NAME)
        if not isinstance(name, str) or not name.strip():
            raise self.fail(
                f"expected a non-empty string, got {name!r}", entity=DEFAULT_CAMERA_NAME, field="camera.name"
            )
        position = block.get("position", (0.0, 0.0, 0.0))
        rotation = self.rotation(block, "camera", name, position)
        transform = self.component(Transform, {"position": position, "rotation": rotation}, "camera", name)
        lens = {k: block[k] for k in ("fov_deg", "speed") if k in block}
        camera = self.component(Camera, lens, "camera", name)
        scene.camera_entity = self.create(scene, name, "camera.name", transform, camera)
        self.remember_angles(scene, scene.camera_entity, block)

    def entity(self, scene: Scene, index: int, value: object) -> None:
        label = f"\0entities[{index}]"
        self.labels[label] = (None, label[1:])
        if isinstance(value, dict) and isinstance(value.get("name"), str) and value["name"].strip():
            label = value["name"]
        block = self.obj(value, ENTITY_KEYS, "", label)
        if "name" not in block:
            raise self.fail("every entity needs a unique 'name'", entity=label, field="name")
        if not isinstance(block["name"], str) or not block["name"].strip():
            raise self.fail(f"expected a non-empty string, got {block['name']!r}", entity=label, field="name")
        parts: list[object] = [self.transform(block.get("transform", {}), "transform", label)]
        if "mesh" in block:
            fields = self.obj(block["mesh"], MESH_KEYS, "mesh", label)
            if "asset" not in fields:
                raise self.fail(
                    "a mesh needs an 'asset' (a declared asset or a primitive)", entity=label, field="mesh.asset"
                )
            mesh = self.component(Mesh, dict(fields), "mesh", label)
            if mesh.asset not in scene.assets and mesh.asset not in PRIMITIVES:
                known = ", ".join(sorted(scene.assets)) or "none declared"
                raise self.fail(
                    f"unknown asset {mesh.asset!r} (assets: {known}; primitives: {', '.join(PRIMITIVES)})",
                    entity=label,
                    field="mesh.asset",
                )
            parts.append(mesh)
        if "aberration" in block:
            parts.append(
                self.component(
                    Aberration,
                    dict(self.obj(block["aberration"], ABERRATION_KEYS, "aberration", label)),
                    "aberration",
                    label,
                )
            )
        if "portal" in block:
            parts.append(
                self.component(Portal, dict(self.obj(block["portal"], PORTAL_KEYS, "portal", label)), "portal", label)
            )
        if "light" in block:
            parts.append(self.light(block["light"], label))
        entity = self.create(scene, label, "name", *parts)
        self.remember_angles(scene, entity, block.get("transform"))

    def light(self, value: object, label: str) -> Light:
        """An entity's ``"light"`` block (also a glTF node's ``aberrant.light`` extras)."""
        return self.component(Light, dict(self.obj(value, LIGHT_KEYS, "light", label)), "light", label)

    @staticmethod
    def remember_angles(scene: Scene, entity: int, block: object) -> None:
        """Note that the file gave this rotation as ``euler_deg`` (already validated), so saving writes angles."""
        if isinstance(block, dict) and "euler_deg" in block:
            x, y, z = (float(a) for a in block["euler_deg"])
            scene.euler_deg[entity] = (x, y, z)

    def create(self, scene: Scene, name: str, field: str, *components: object) -> int:
        try:
            return scene.create_entity(name, *components)
        except SceneError as e:
            raise self.fail(e.detail, entity=name, field=field) from None

    def check(self, scene: Scene) -> None:
        """Cross-entity checks: portal targets, then every mesh file (so a missing one fails now)."""
        for entity, portal in scene.query(Portal):
            if portal.target is None:
                continue
            label = scene.name_of(entity)
            try:
                target = scene.entity(portal.target)
            except SceneError:
                raise self.fail(f"no entity is named {portal.target!r}", entity=label, field="portal.target") from None
            if not scene.has(target, Portal):
                raise self.fail(f"{portal.target!r} is not a portal", entity=label, field="portal.target")
        loaded: set[str] = set()
        for entity, mesh in scene.query(Mesh):
            if mesh.asset not in loaded:
                self.load_asset(scene, mesh.asset, entity=scene.name_of(entity), field="mesh.asset")
                loaded.add(mesh.asset)
        for name in scene.assets:
            if name not in loaded:
                self.load_asset(scene, name, entity=self.asset_label(name), field=f"assets.{name}")
        try:
            scene.check_lights()
            scene.check_mesh_sizes()
        except SceneError as e:
            raise self.fail(e.detail, entity=e.entity, field=e.field) from None

    def load_asset(self, scene: Scene, name: str, *, entity: str, field: str) -> None:
        try:
            scene.asset(name)
        except AberrantError as e:
            raise self.fail(f"asset {name!r}: {e}", entity=entity, field=field) from None


def _plain_keyframe(key: Keyframe) -> Keyframe:
    """A checked keyframe with its vectors as tuples of floats (as read, they are JSON lists)."""

    def floats(value: Iterable[float] | None) -> tuple[float, ...] | None:
        return None if value is None else tuple(float(c) for c in value)

    return Keyframe(float(key.time), floats(key.position) or (), floats(key.rotation), floats(key.look_at))


def scene_from_document(doc: object, file: str, base_dir: Path) -> Scene:
    """A scene from an already parsed scene document (an importer's), validated exactly as a scene file is."""
    return _Reader(file).read(doc, base_dir)
