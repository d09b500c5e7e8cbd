"""TelloEngine's file formats, decoded (``docs/tello-format.md``).

A scene file is JSON followed by one NUL byte; mesh resources are binary files
named by uid: four uint32 counts, then vertices, normals, UVs (float32) and
indices (uint32). Decoding is kept apart from :mod:`aberrant.importers.tello`, which maps
the decoded objects onto our components, so each can be fuzzed on its own.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from engine.errors import AberrantError
from engine.scene_file import SceneFileError

TRANSFORM, MESH, MATERIAL, CAMERA, POINT_LIGHT, PROCEDURAL_MESH, ABERRATION, PORTAL = range(8)
COMPONENT_NAMES = ("Transform", "Mesh", "Material", "Camera", "PointLight", "ProceduralMesh", "Aberration", "Portal")
MESH_HEADER = struct.Struct("<4I")


class TelloError(SceneFileError):
    """A TelloEngine file cannot be imported; names the file, the game object (uuid, name) and the field."""


@dataclass
class TelloMesh:
    """A decoded mesh: positions, faces, optional UVs and vertex normals, written out as an OBJ."""

    vertices: np.ndarray  # (N, 3) float32
    faces: np.ndarray  # (M, 3) int64
    uvs: np.ndarray | None  # (N, 2) float32
    normals: np.ndarray | None = None  # (N, 3) vertex normals for smooth shading (glTF's NORMAL; Tello's are not kept)


def read_mesh_resource(path: Path) -> TelloMesh:
    """Decode ``Mesh/<uid>``: four uint32 counts, then vertices, normals, UVs (float32), indices (uint32)."""
    data = path.read_bytes()
    if len(data) < MESH_HEADER.size:
        raise AberrantError(f"{path}: {len(data)} bytes is too short for a mesh resource header (16 bytes)")
    n_vertex, n_normal, n_uv, n_index = MESH_HEADER.unpack_from(data)
    expected = MESH_HEADER.size + 4 * (n_vertex + n_normal + n_uv + n_index)
    if len(data) != expected:
        raise AberrantError(f"{path}: header promises {expected} bytes, the file has {len(data)}: not a mesh resource")
    if n_vertex % 3 or n_index % 3 or n_vertex == 0 or n_index == 0:
        raise AberrantError(f"{path}: {n_vertex} vertex floats and {n_index} indices do not make triangles")
    offset = MESH_HEADER.size
    vertices = np.frombuffer(data, "<f4", n_vertex, offset).reshape(-1, 3)
    offset += 4 * (n_vertex + n_normal)
    uvs = np.frombuffer(data, "<f4", n_uv, offset).reshape(-1, 2) if n_uv % 2 == 0 else None
    offset += 4 * n_uv
    faces = np.frombuffer(data, "<u4", n_index, offset).astype(np.int64).reshape(-1, 3)
    if faces.max() >= len(vertices):
        raise AberrantError(f"{path}: triangle index {int(faces.max())} is past the {len(vertices)} vertices")
    if not np.all(np.isfinite(vertices)):
        raise AberrantError(f"{path}: vertex coordinates contain NaN or infinity")
    if uvs is not None and len(uvs) != len(vertices):
        uvs = None
    return TelloMesh(vertices, faces, uvs)


def mesh_to_obj(mesh: TelloMesh, comment: str) -> bytes:
    """Wavefront OBJ text of a mesh (floats by ``repr``: float32 values round-trip exactly)."""
    lines = [f"# {comment}"]
    lines += [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in mesh.vertices]
    if mesh.uvs is not None:
        lines += [f"vt {float(u)!r} {float(v)!r}" for u, v in mesh.uvs]
    if mesh.normals is not None:
        lines += [f"vn {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in mesh.normals]
    uv, normal = mesh.uvs is not None, mesh.normals is not None
    suffix = "/{0}/{0}" if uv and normal else "/{0}" if uv else "//{0}" if normal else ""
    corner = "{0}" + suffix
    lines += [" ".join(["f", *(corner.format(int(i) + 1) for i in face)]) for face in mesh.faces]
    return ("\n".join(lines) + "\n").encode("ascii")


def read_tello_document(path: Path) -> dict[str, Any]:
    """Parse a scene file: JSON plus a trailing NUL (tolerated when missing)."""
    file = str(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise TelloError(file, f"cannot read the scene file ({e.strerror or e})") from None
    text = raw[:-1] if raw.endswith(b"\0") else raw
    try:
        doc = json.loads(text.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise TelloError(file, f"not UTF-8 text (byte {e.start}): not a TelloEngine scene file") from None
    except json.JSONDecodeError as e:
        raise TelloError(file, f"line {e.lineno}, column {e.colno}: not JSON: {e.msg}") from None
    except RecursionError:
        raise TelloError(file, "not JSON: nested too deeply") from None
    except ValueError:  # an integer literal of more than 4300 digits (sys.int_max_str_digits)
        raise TelloError(file, "not JSON: an integer literal is too long (over 4300 digits)") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("game_objects"), list):
        raise TelloError(
            file, "expected an object with a 'game_objects' list: not a TelloEngine scene", field="game_objects"
        )
    return doc
