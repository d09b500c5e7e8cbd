"""Mesh assets: triangle meshes from files (through trimesh) or built-in primitives.

An asset is object-space geometry shared by every entity that uses it. Files
are read once: the library caches by resolved path and file content hash, so
two entities naming one file share one asset, and an edited file is re-read.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

from engine.atomic_files import read_regular
from engine.errors import shorten
from engine.mesh_asset import AssetError, MeshAsset, make_asset
from engine.mesh_files import load_mesh_file
from engine.textures import TextureLibrary

PRIMITIVES = ("box", "plane", "quad", "sphere", "pyramid", "cylinder")


# --- primitives ---------------------------------------------------------------


def _box() -> MeshAsset:
    """The unit cube [-1/2, 1/2]^3 with a UV square per face (24 vertices, outward winding)."""
    verts: list[list[float]] = []
    uvs: list[list[float]] = []
    faces: list[list[int]] = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
            base = len(verts)
            for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0.0, 0.0, 0.0]
                p[axis] = 0.5 * sign
                p[u_axis] = 0.5 * du
                p[v_axis] = 0.5 * dv
                verts.append(p)
                uvs.append([(du + 1) / 2, (dv + 1) / 2])
            quad = [(0, 1, 2), (0, 2, 3)] if sign > 0 else [(0, 2, 1), (0, 3, 2)]
            faces += [[base + a, base + b, base + c] for a, b, c in quad]
    return make_asset(np.array(verts), np.array(faces), np.array(uvs), "primitive:box")


def _plane() -> MeshAsset:
    """The unit square [-1/2, 1/2]^2 in XZ, facing +Y (a floor)."""
    v = np.array([[-0.5, 0, 0.5], [0.5, 0, 0.5], [0.5, 0, -0.5], [-0.5, 0, -0.5]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    return make_asset(v, np.array([[0, 1, 2], [0, 2, 3]]), uv, "primitive:plane")


def _quad() -> MeshAsset:
    """The square [-1, 1]^2 in XY facing +Z: the same shape as a portal."""
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    return make_asset(v, np.array([[0, 1, 2], [0, 2, 3]]), uv, "primitive:quad")


def _sphere(subdivisions: int = 3) -> MeshAsset:
    """An icosphere of radius 1/2 (closed, shared vertices)."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.5)
    return make_asset(m.vertices, m.faces, None, "primitive:sphere", normals=m.vertices)


def _pyramid() -> MeshAsset:
    """Square base [-1/2, 1/2]^2 at y = -1/2, apex at (0, 1/2, 0)."""
    v = np.array([[-0.5, -0.5, -0.5], [0.5, -0.5, -0.5], [0.5, -0.5, 0.5], [-0.5, -0.5, 0.5], [0, 0.5, 0]])
    f = np.array([[0, 1, 2], [0, 2, 3], [3, 2, 4], [2, 1, 4], [1, 0, 4], [0, 3, 4]])
    return make_asset(v, f, None, "primitive:pyramid")


def _cylinder(segments: int = 32) -> MeshAsset:
    """Radius 1/2, height 1 along Y, centred; closed with caps."""
    a = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
    ring = np.column_stack([0.5 * np.cos(a), np.zeros(segments), -0.5 * np.sin(a)])
    bottom, top = ring + np.array([0.0, -0.5, 0.0]), ring + np.array([0.0, 0.5, 0.0])
    v = np.vstack([bottom, top, [[0, -0.5, 0], [0, 0.5, 0]]])
    cb, ct = 2 * segments, 2 * segments + 1
    faces = []
    for i in range(segments):
        j = (i + 1) % segments
        faces += [[i, j, segments + j], [i, segments + j, segments + i]]
        faces += [[cb, j, i], [ct, segments + i, segments + j]]
    return make_asset(v, np.array(faces), None, "primitive:cylinder")


_PRIMITIVE_BUILDERS = {
    "box": _box,
    "plane": _plane,
    "quad": _quad,
    "sphere": _sphere,
    "pyramid": _pyramid,
    "cylinder": _cylinder,
}


class AssetLibrary:
    """Loads each mesh file once and builds each primitive once."""

    def __init__(self) -> None:
        self._primitives: dict[str, MeshAsset] = {}
        self._by_stat: dict[tuple[str, int, int], MeshAsset] = {}
        self._by_content: dict[str, MeshAsset] = {}
        #: The image files meshes name as textures, read once like the meshes.
        self.textures = TextureLibrary()

    def primitive(self, name: str) -> MeshAsset:
        if name not in _PRIMITIVE_BUILDERS:
            raise AssetError(f"unknown primitive {name!r}; primitives are {', '.join(PRIMITIVES)}")
        if name not in self._primitives:
            self._primitives[name] = _PRIMITIVE_BUILDERS[name]()
        return self._primitives[name]

    def load(self, path: str | Path) -> MeshAsset:
        p = Path(path).expanduser()
        name = shorten(p)
        try:
            resolved = p.resolve(strict=True)
            st = resolved.stat()
        except FileNotFoundError:
            raise AssetError(f"{name}: mesh file not found") from None
        except RuntimeError:  # Python 3.11's Path.resolve on a symlink loop (3.13 raises OSError ELOOP)
            raise AssetError(f"{name}: a symlink loop, not a mesh file") from None
        except OSError as e:
            raise AssetError(f"{name}: cannot read mesh file ({e.strerror or e})") from None
        except ValueError as e:  # a NUL byte in the path (a hand-edited or hostile scene file)
            raise AssetError(f"{shorten(p)!r}: not a usable file path ({e})") from None
        if not resolved.is_file():
            raise AssetError(f"{name}: not a file")
        key = (str(resolved), st.st_mtime_ns, st.st_size)
        if key in self._by_stat:
            return self._by_stat[key]
        try:
            data = read_regular(resolved)  # swapped for a FIFO since the stat: refused, not read forever
        except OSError as e:  # unreadable (permissions, I/O error) or removed since the stat
            raise AssetError(f"{name}: cannot read mesh file ({e.strerror or e})") from None
        digest = hashlib.sha256(data).hexdigest()
        asset = self._by_content.get(digest)
        if asset is None:
            asset = load_mesh_file(resolved, data)
            self._by_content[digest] = asset
        self._by_stat[key] = asset
        return asset
