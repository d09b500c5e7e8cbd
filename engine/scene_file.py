"""Scene files: JSON in, JSON out (docs/design.md section 8).

Loading parses with ``json`` only (never executes code), builds the scene
through the component dataclasses so every value is validated in one place,
and turns each failure into a one-line :class:`SceneFileError` that names the
file, the entity and the field. Mesh files are read at load time, so a
missing or empty mesh fails here rather than in the middle of a render.

Saving writes canonical JSON (:mod:`engine.scene_writer`: fixed key order,
every field spelt out, floats by ``repr`` so they round-trip exactly,
rotations as quaternions unless given as ``euler_deg``) through :mod:`engine.atomic_files`: a temporary
file beside the target, fsynced and renamed over it, so a crash leaves either
the old file or the new one, never half of one.

Format, version 1::

    {
      "format": "aberrant-scene", "version": 1, "name": "...",
      "settings": {"background", "light_dir", "max_events", "event_limit_color", "ambient"},
      "camera": {"name", "position", "rotation" | "look_at" | "euler_deg", "fov_deg", "speed"},
      "assets": {NAME: {"path": "relative/to/scene.obj"} | {"primitive": "box"}},
      "entities": [{"name", "transform": {"position", "rotation" | "euler_deg", "scale"},
                    "mesh": {...}, "aberration": {...}, "portal": {...}, "light": {...}}],
      "camera_path": [{"time", "position", "rotation" | "look_at"}, ...]   (optional: the level's flythrough)
    }
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path

from engine.atomic_files import read_regular, write_atomically
from engine.errors import SceneError, SceneFileError, shorten
from engine.scene import Scene
from engine.scene_reader import object_pairs, scene_from_document
from engine.scene_writer import FORMAT, VERSION, dumps, scene_document, scene_to_json

__all__ = [
    "FORMAT",
    "VERSION",
    "SceneFileError",
    "dumps",
    "load_scene",
    "save_scene",
    "scene_document",
    "scene_from_document",
    "scene_to_json",
]


def load_scene(path: str | os.PathLike[str]) -> Scene:
    """Read a scene file.

    Raises :class:`engine.scene_file.SceneFileError` naming file, entity and field on any problem.
    """
    file = shorten(path)
    try:
        text = read_regular(path).decode("utf-8")
    except FileNotFoundError:
        raise SceneFileError(file, "scene file not found") from None
    except IsADirectoryError:
        raise SceneFileError(file, "is a directory, not a scene file") from None
    except UnicodeDecodeError as e:
        raise SceneFileError(file, f"not UTF-8 text (byte {e.start}): not a scene file") from None
    except OSError as e:  # unreadable, or a FIFO or device (refused rather than read forever)
        raise SceneFileError(file, f"cannot read scene file ({e.strerror or e})") from None
    return scene_from_text(text, file, Path(os.path.abspath(path)).parent)


def scene_from_text(text: str, file: str, base_dir: Path) -> Scene:
    """A scene from the text of a scene file; errors name ``file``, relative asset paths start at ``base_dir``."""
    try:
        doc = json.loads(text, object_pairs_hook=object_pairs)
    except json.JSONDecodeError as e:
        raise SceneFileError(file, f"line {e.lineno}, column {e.colno}: malformed JSON: {e.msg}") from None
    except RecursionError:
        raise SceneFileError(file, "malformed JSON: nested too deeply") from None
    except ValueError:  # an integer literal of more than 4300 digits (sys.int_max_str_digits)
        raise SceneFileError(file, "malformed JSON: an integer literal is too long (over 4300 digits)") from None
    where = _unencodable_string(doc)
    if where is not None:  # "\ud800" is valid JSON but no Unicode text: it could never be saved again
        raise SceneFileError(file, "a string holds a lone UTF-16 surrogate (\\ud800-\\udfff escape)", field=where)
    return scene_from_document(doc, file, base_dir)


def _unencodable_string(doc: object) -> str | None:
    """The path of the first key or string value that is not valid Unicode (a lone surrogate), or ``None``.

    Iterative, so a deeply nested document cannot exhaust the stack here.
    """
    stack: list[tuple[str, object]] = [("", doc)]
    while stack:
        where, value = stack.pop()
        if isinstance(value, str):
            try:
                value.encode("utf-8")
            except UnicodeEncodeError:
                return where or "(document)"
        elif isinstance(value, dict):
            for key, item in value.items():
                child = f"{where}.{key}" if where else str(key)
                try:
                    key.encode("utf-8")
                except UnicodeEncodeError:
                    return child
                stack.append((child, item))
        elif isinstance(value, list):
            stack.extend((f"{where}[{i}]", item) for i, item in enumerate(value))
    return None


def save_scene(scene: Scene, path: str | os.PathLike[str], *, with_files: Mapping[Path, bytes] | None = None) -> None:
    """Write ``scene`` to ``path`` atomically.

    Raises :class:`engine.scene_file.SceneFileError` (the old file intact) on failure.

    ``with_files`` (an importer's meshes) are written in the same atomic write:
    all of them and the scene, or, when one cannot be written, none of them.
    """
    file = str(path)
    target_dir = Path(os.path.abspath(path)).parent
    try:
        text = scene_to_json(scene, target_dir)
    except SceneError as e:
        raise SceneFileError(file, f"cannot save: {e.detail}", entity=e.entity, field=e.field) from None
    except ValueError as e:  # a value JSON cannot hold (set by code; a loaded file never has one)
        raise SceneFileError(file, f"cannot save: {e}") from None
    try:
        data = text.encode("utf-8")
    except UnicodeEncodeError as e:
        raise SceneFileError(file, f"cannot save: a name holds text that is not valid Unicode ({e.reason})") from None
    try:
        write_atomically({**(with_files or {}), path: data})
    except OSError as e:
        if not target_dir.is_dir():
            raise SceneFileError(file, f"cannot save: the folder {str(target_dir)!r} does not exist") from e
        raise SceneFileError(shorten(e.filename or file), f"cannot save ({e.strerror or e})") from e
