"""Scene files, the writing half: a scene as canonical JSON (docs/design.md section 8).

Canonical means fixed key order, every field spelt out, floats by ``repr`` so
they round-trip exactly, rotations as quaternions unless they were given as
``euler_deg`` angles (then as those angles): saving a loaded file
gives the same bytes, and diffs of saved levels show only what changed.
:mod:`engine.scene_file` reads these documents and saves them atomically.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

from components import Aberration, Camera, Light, Mesh, Portal, Transform
from engine.errors import SceneError
from engine.keyframes import Keyframe
from engine.maths import quat_from_euler_deg, quat_to_euler_deg
from engine.scene import Scene
from engine.scene_world import AssetSpec

FORMAT = "aberrant-scene"
VERSION = 1


def _floats(values: tuple[float, ...]) -> list[float]:
    return [float(v) for v in values]


def _rotation(scene: Scene, entity: int, transform: Transform) -> dict[str, list[float]]:
    """``{"euler_deg": ...}`` when the rotation was given as angles (the same angles while it is unchanged,
    else the angles of the new rotation to a billionth of a degree), otherwise ``{"rotation": quaternion}``."""
    angles = scene.euler_deg.get(entity)
    if angles is None:
        return {"rotation": _floats(transform.rotation)}
    if tuple(float(c) for c in quat_from_euler_deg(angles)) != tuple(transform.rotation):
        x, y, z = (round(float(a), 9) + 0.0 for a in quat_to_euler_deg(transform.rotation))  # + 0.0: no -0.0
        angles = (x, y, z)
    return {"euler_deg": _floats(angles)}


def _asset_path(scene: Scene, spec: AssetSpec, target_dir: Path) -> str:
    """Where the asset is, as the saved file should say: relative when inside its folder, else absolute."""
    return _file_path(scene.asset_path(spec), target_dir)


def _file_path(path: Path, target_dir: Path) -> str:
    """A file the scene names, as the saved file should say: relative when inside its folder, else absolute."""
    location = Path(os.path.abspath(path))
    try:
        return location.relative_to(target_dir).as_posix()
    except ValueError:
        return str(location)


def scene_document(scene: Scene, target_dir: Path | None = None) -> dict[str, Any]:
    """The JSON document of a scene (asset paths relative to ``target_dir`` where they can be)."""
    target_dir = Path(os.path.abspath(target_dir if target_dir is not None else Path.cwd()))
    s = scene.settings
    doc: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "name": scene.name,
        "settings": {
            "background": _floats(s.background),
            "light_dir": _floats(s.light_dir),
            "max_events": s.max_events,
            "event_limit_color": _floats(s.event_limit_color),
            "ambient": float(s.ambient),
        },
    }
    camera_entity = scene.camera_entity
    if camera_entity is not None:
        transform = scene.get(camera_entity, Transform)
        camera = scene.get(camera_entity, Camera)
        doc["camera"] = {
            "name": scene.name_of(camera_entity),
            "position": _floats(transform.position),
            **_rotation(scene, camera_entity, transform),
            "fov_deg": float(camera.fov_deg),
            "speed": float(camera.speed),
        }
    assets: dict[str, Any] = {}
    for name in sorted(scene.assets):
        spec = scene.assets[name]
        assets[name] = (
            {"primitive": spec.primitive}
            if spec.primitive is not None
            else {"path": _asset_path(scene, spec, target_dir)}
        )
    doc["assets"] = assets
    entities = []
    for entity in scene.entities():
        if entity == camera_entity:
            continue
        name = scene.name_of(entity)
        if scene.has(entity, Camera):
            raise SceneError(
                "only the active camera can be saved; this entity also has a Camera", entity=name, field="camera"
            )
        transform = scene.try_get(entity, Transform) or Transform()
        item: dict[str, Any] = {
            "name": name,
            "transform": {
                "position": _floats(transform.position),
                **_rotation(scene, entity, transform),
                "scale": _floats(transform.scale),
            },
        }
        mesh = scene.try_get(entity, Mesh)
        if mesh is not None:
            item["mesh"] = {
                "asset": mesh.asset,
                "color": _floats(mesh.color),
                "checker": float(mesh.checker),
                "cull_backfaces": mesh.cull_backfaces,
            }
            if mesh.texture:
                item["mesh"]["texture"] = _file_path(scene.texture_path(mesh.texture), target_dir)
            if mesh.smooth:
                item["mesh"]["smooth"] = True
                item["mesh"]["crease_deg"] = float(mesh.crease_deg)
        aberration = scene.try_get(entity, Aberration)
        if aberration is not None:
            item["aberration"] = {
                "deformation": _floats(aberration.deformation),
                "mode": aberration.mode,
                "exit": aberration.exit,
                "priority": aberration.priority,
                "debug_draw": aberration.debug_draw,
                "color": _floats(aberration.color),
            }
        portal = scene.try_get(entity, Portal)
        if portal is not None:
            item["portal"] = {"target": portal.target, "color": _floats(portal.color), "debug_draw": portal.debug_draw}
        light = scene.try_get(entity, Light)
        if light is not None:
            item["light"] = {
                "kind": light.kind,
                "color": _floats(light.color),
                "intensity": float(light.intensity),
                "shadows": light.shadows,
                "range": None if light.range is None else float(light.range),
            }
        entities.append(item)
    doc["entities"] = entities
    if scene.camera_path:
        doc["camera_path"] = [keyframe_document(key) for key in scene.camera_path]
    return doc


def keyframe_document(key: Keyframe) -> dict[str, Any]:
    """One keyframe as the file holds it: its rotation in the form it was given (a quaternion or a point)."""
    out: dict[str, Any] = {"time": float(key.time), "position": _floats(tuple(key.position))}
    if key.look_at is not None:
        out["look_at"] = _floats(tuple(key.look_at))
    else:
        assert key.rotation is not None  # a checked keyframe has exactly one of the two
        out["rotation"] = _floats(tuple(key.rotation))
    return out


def _scalar(value: object) -> str:
    if isinstance(value, float):
        if not math.isfinite(value):  # components never hold these; refuse rather than write invalid JSON
            raise ValueError(f"cannot save the non-finite number {value!r}")
        return repr(value)
    return json.dumps(value, ensure_ascii=False)


def dumps(value: object, indent: int = 0) -> str:
    """Canonical JSON: objects one key a line (2-space indent), arrays of scalars on one line."""
    pad = "  " * (indent + 1)
    if isinstance(value, dict):
        if not value:
            return "{}"
        items = [f"{pad}{json.dumps(str(k), ensure_ascii=False)}: {dumps(v, indent + 1)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + "\n" + "  " * indent + "}"
    if isinstance(value, list | tuple):
        if not value:
            return "[]"
        if all(not isinstance(v, dict | list | tuple) for v in value):
            return "[" + ", ".join(_scalar(v) for v in value) + "]"
        return "[\n" + ",\n".join(pad + dumps(v, indent + 1) for v in value) + "\n" + "  " * indent + "]"
    return _scalar(value)


def scene_to_json(scene: Scene, target_dir: Path | None = None) -> str:
    """The exact text :func:`engine.scene_file.save_scene` writes."""
    return dumps(scene_document(scene, target_dir)) + "\n"
