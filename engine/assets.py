"""Mesh assets: triangle meshes from files (through trimesh) or built-in primitives.

An asset is object-space geometry shared by every entity that uses it. Files
are read once: the library caches by resolved path and file content hash, so
two entities naming one file share one asset, and an edited file is re-read.
"""

from __future__ import annotations

import codecs
import contextlib
import hashlib
import io
import logging
import math
import os
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from engine.atomic_files import read_regular
from engine.errors import AberrantError, shorten
from engine.textures import TextureImage, TextureLibrary, texture_image, warn_unreadable

if TYPE_CHECKING:
    import trimesh

MESH_SUFFIXES = (".obj", ".glb", ".gltf", ".ply", ".stl", ".off")
PRIMITIVES = ("box", "plane", "quad", "sphere", "pyramid", "cylinder")


class AssetError(AberrantError, ValueError):
    """A mesh asset cannot be loaded or is unusable."""


@dataclass(frozen=True, eq=False)
class MeshAsset:
    """Object-space triangles: float32 vertices (N, 3), int32 faces (M, 3), optional float32 UVs (N, 2).

    ``normals`` are the file's unit vertex normals (N, 3), if it has them; ``image`` and ``base_color`` its
    material's colour texture and colour (OBJ ``.mtl`` ``map_Kd``/``Kd``, glTF ``baseColor``), which a
    mesh's own colour multiplies.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray | None
    source: str
    content_hash: str = field(default="")
    normals: np.ndarray | None = None
    image: TextureImage | None = None
    base_color: tuple[float, float, float] = (1.0, 1.0, 1.0)

    @property
    def triangle_count(self) -> int:
        return int(self.faces.shape[0])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.vertices.min(axis=0), self.vertices.max(axis=0)


def make_asset(
    vertices: np.ndarray,
    faces: np.ndarray,
    uvs: np.ndarray | None,
    source: str,
    *,
    normals: np.ndarray | None = None,
    image: TextureImage | None = None,
    base_color: tuple[float, float, float] = (1.0, 1.0, 1.0),
) -> MeshAsset:
    """Validate and freeze geometry; the content hash identifies it everywhere (BVH cache, packing).

    Whatever a file parser hands over (odd shapes, float or huge indices,
    values beyond float32) becomes an :class:`AssetError` naming ``source``,
    never a numpy exception or a silently wrapped index.
    """
    try:
        raw_v = np.asarray(vertices)
        raw_f = np.asarray(faces)
    except (TypeError, ValueError) as e:  # ragged nested lists
        raise AssetError(f"{source}: vertices or faces are not arrays ({e})") from None
    if raw_v.ndim != 2 or raw_v.shape[1] != 3 or not np.issubdtype(raw_v.dtype, np.number):
        raise AssetError(f"{source}: vertices must be (N, 3) numbers, got shape {raw_v.shape} of {raw_v.dtype}")
    if raw_f.ndim != 2 or raw_f.shape[1] != 3 or raw_f.shape[0] == 0:
        raise AssetError(f"{source}: holds no triangles (faces of shape {raw_f.shape}); export it as a triangle mesh")
    if not (np.issubdtype(raw_f.dtype, np.integer) or np.issubdtype(raw_f.dtype, np.floating)):
        raise AssetError(f"{source}: face indices must be integers, got {raw_f.dtype}")
    with np.errstate(over="ignore", invalid="ignore"):  # overflow to inf is reported just below
        v = np.ascontiguousarray(raw_v, dtype=np.float32)
    if not np.all(np.isfinite(v)):
        raise AssetError(f"{source}: vertex coordinates contain NaN or infinity (or exceed the float32 range)")
    if np.issubdtype(raw_f.dtype, np.floating) and not (
        np.all(np.isfinite(raw_f)) and np.array_equal(raw_f, np.round(raw_f))
    ):
        raise AssetError(f"{source}: face indices must be whole numbers")
    low, high = raw_f.min(), raw_f.max()
    if low < 0 or high >= len(v):  # checked before the int32 cast, which would wrap a huge index into range
        raise AssetError(f"{source}: face indices out of range [0, {len(v)}) (found {int(low)}..{int(high)})")
    f = np.ascontiguousarray(raw_f, dtype=np.int32)
    uv = None
    if uvs is not None:
        try:
            with np.errstate(over="ignore", invalid="ignore"):
                uv = np.ascontiguousarray(uvs, dtype=np.float32).reshape(-1, 2)
        except (TypeError, ValueError):
            uv = None
        if uv is not None and (len(uv) != len(v) or not np.all(np.isfinite(uv))):
            uv = None  # unusable UVs: fall back to triplanar texturing rather than failing the load
    n = None
    if normals is not None:
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            n = np.asarray(normals, dtype=np.float64).reshape(-1, 3) if np.size(normals) == v.size else None
            if n is not None:
                n = (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(np.float32)
        if n is not None and not np.all(np.isfinite(n)):
            n = None  # unusable normals: computed from the faces instead
    h = hashlib.sha256()
    arrays = tuple(a for a in (v, f, uv, n) if a is not None)
    for a in arrays:
        h.update(a.tobytes())
        a.setflags(write=False)
    if image is not None:
        h.update(image.content_hash.encode())
    h.update(repr(tuple(base_color)).encode())
    r, g, b = (float(c) for c in base_color)
    return MeshAsset(v, f, uv, source, h.hexdigest(), n, image, (r, g, b))


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
            asset = _load_mesh_file(resolved, data)
            self._by_content[digest] = asset
        self._by_stat[key] = asset
        return asset


def _load_mesh_file(path: Path, data: bytes) -> MeshAsset:
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise AssetError(f"{path}: unsupported mesh format {suffix or '(none)'}; use one of {', '.join(MESH_SUFFIXES)}")
    if not data.strip():
        raise AssetError(f"{path}: the file is empty")
    if suffix in TEXT_SUFFIXES:
        try:
            data = as_utf8(data)
        except UnicodeError as e:
            raise AssetError(f"{path}: cannot decode the text ({e})") from None

    import trimesh

    try:
        with _quiet_trimesh():
            loaded = trimesh.load(
                io.BytesIO(data), file_type=suffix.lstrip("."), force="mesh", process=False, resolver=_resolver(path)
            )
    except Exception as e:  # trimesh raises many types on malformed files
        raise AssetError(f"{path}: cannot parse mesh ({type(e).__name__}: {e})") from None
    faces = getattr(loaded, "faces", None)
    vertices = getattr(loaded, "vertices", None)
    if faces is None or vertices is None or len(faces) == 0:
        raise AssetError(f"{path}: holds no triangles")
    uv = getattr(getattr(loaded, "visual", None), "uv", None)
    image, base_color = _material(loaded, path)
    if suffix == ".obj" and not any(line.startswith(b"mtllib") for line in data.splitlines()):
        image, base_color = None, (1.0, 1.0, 1.0)  # trimesh's stand-in material (a grey 2x2 image) for UVs alone
    if image is None and suffix == ".obj":
        _warn_missing_map_kd(path, data)
    return make_asset(
        np.asarray(vertices), np.asarray(faces), None if uv is None else np.asarray(uv), str(path),
        normals=_file_normals(path, data, np.asarray(vertices)), image=image, base_color=base_color,
    )  # fmt: skip


def _material(loaded: object, path: Path) -> tuple[TextureImage | None, tuple[float, float, float]]:
    """The colour texture and colour of a loaded mesh's material (SimpleMaterial from ``.mtl``, PBR from glTF)."""
    material = getattr(getattr(loaded, "visual", None), "material", None)
    if material is None:
        return None, (1.0, 1.0, 1.0)
    picture = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
    factor = getattr(material, "baseColorFactor", None)
    if factor is None:
        factor = getattr(material, "diffuse", None)
    color = (1.0, 1.0, 1.0)
    if factor is not None:
        f = np.asarray(factor, dtype=np.float64).reshape(-1)
        if f.size >= 3 and np.all(np.isfinite(f[:3])):
            scale = 255.0 if np.issubdtype(np.asarray(factor).dtype, np.integer) else 1.0  # trimesh's uint8 Kd
            r, g, b = (float(c) for c in np.clip(f[:3] / scale, 0.0, 1.0))
            color = (r, g, b)
    image = None
    if picture is not None:
        try:
            image = texture_image(np.asarray(picture.convert("RGBA")), f"{shorten(path)} (material)")
        except Exception:  # an image trimesh handed over that Pillow cannot convert: the base colour alone
            image = None
    return image, color


def _warn_missing_map_kd(path: Path, data: bytes) -> None:
    """One warning line when an OBJ's material names a ``map_Kd`` image that trimesh could not read."""
    for line in data.decode("utf-8", "replace").splitlines():
        if not line.startswith("mtllib "):
            continue
        try:
            mtl = _resolver(path).get(line.split(None, 1)[1].strip()).decode("utf-8", "replace")
        except Exception:  # no material file: nothing was promised
            continue
        for entry in mtl.splitlines():
            if entry.strip().startswith("map_Kd "):
                image = entry.split()[-1]
                warn_unreadable(f"{shorten(path.parent / image)}", f"named by {path.name}'s material, cannot be read")
                return


def _file_normals(path: Path, data: bytes, vertices: np.ndarray) -> np.ndarray | None:
    """An OBJ's ``vn`` or a PLY's ``nx ny nz`` per loaded vertex, read again: trimesh drops them from the
    cache of a mesh it does not process."""
    import trimesh

    suffix = path.suffix.lower()
    try:
        with _quiet_trimesh():
            if suffix == ".obj" and b"\nvn " in data:
                parts = list(
                    trimesh.exchange.obj.load_obj(io.BytesIO(data), resolver=_resolver(path))
                    .get("geometry", {})
                    .values()
                )
            elif suffix == ".ply" and b"property float nx" in data[:4096]:
                parts = [trimesh.exchange.ply.load_ply(io.BytesIO(data))]
            else:
                return None
    except Exception:  # the mesh loaded; only its normals are unusable
        return None
    if len(parts) != 1 or parts[0].get("vertex_normals") is None:
        return None
    normals = np.asarray(parts[0]["vertex_normals"])
    same = np.shape(parts[0]["vertices"]) == vertices.shape and np.allclose(parts[0]["vertices"], vertices)
    return normals if same and normals.shape == vertices.shape else None


@contextlib.contextmanager
def _quiet_trimesh() -> Iterator[None]:
    """Keep trimesh's log records and numpy warnings off stderr while it parses a file.

    On a malformed file trimesh logs tracebacks (through logging's last-resort
    handler when the application configured none) before raising or giving
    up; the caller reports the outcome as one AssetError instead.
    """
    logger = logging.getLogger("trimesh")
    handler = logging.NullHandler()
    propagate = logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            yield
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate


#: Mesh formats that are text, decoded by :func:`as_utf8` before trimesh parses them (it assumes UTF-8).
TEXT_SUFFIXES = (".obj", ".off", ".mtl")
_BOMS = (
    (codecs.BOM_UTF32_LE, "utf-32"),
    (codecs.BOM_UTF32_BE, "utf-32"),
    (codecs.BOM_UTF8, "utf-8-sig"),
    (codecs.BOM_UTF16_LE, "utf-16"),
    (codecs.BOM_UTF16_BE, "utf-16"),
)


def as_utf8(data: bytes) -> bytes:
    """Text in any encoding a mesh exporter writes, as UTF-8 without a byte-order mark.

    A byte-order mark says the encoding (UTF-8, UTF-16, UTF-32; a UTF-8 mark
    left in place would become part of the first keyword); without one, NUL
    bytes in every other position mean UTF-16, then UTF-8 is tried, then
    Latin-1 (which decodes any bytes: names and comments are all it can touch).
    trimesh would otherwise guess with ``charset_normalizer``, an optional
    dependency, and fail without it.
    """
    for bom, codec in _BOMS:
        if data.startswith(bom):
            return data.decode(codec).encode("utf-8")
    sample = data[:4096]
    if len(sample) >= 4:
        even, odd = sample[0::2].count(0), sample[1::2].count(0)
        if odd > len(sample) // 4 and even == 0:
            return data.decode("utf-16-le").encode("utf-8")
        if even > len(sample) // 4 and odd == 0:
            return data.decode("utf-16-be").encode("utf-8")
    try:
        data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1").encode("utf-8")
    return data


_SAFE_RESOLVER: type | None = None


def _resolver(path: Path) -> trimesh.resolvers.FilePathResolver:
    """trimesh's resolver for files a mesh names (``mtllib``, ``map_Kd``), refusing FIFOs and devices.

    trimesh would ``open()`` and read them: a FIFO blocks forever, a device
    never ends. Materials are read as text in any encoding (:func:`as_utf8`).
    """
    global _SAFE_RESOLVER
    if _SAFE_RESOLVER is None:
        import trimesh

        class SafeResolver(trimesh.resolvers.FilePathResolver):
            def get(self, name: str) -> bytes:
                for candidate in (name.strip(), name.strip().lstrip("/"), os.path.split(name)[-1]):
                    try:
                        file = self.absolute(candidate)
                    except ValueError:  # outside the mesh's folder
                        continue
                    if file.exists():
                        data = read_regular(file)
                        return as_utf8(data) if file.suffix.lower() in TEXT_SUFFIXES else data
                self.absolute(name)  # the actionable error when the name escapes the folder
                raise FileNotFoundError(name)

        _SAFE_RESOLVER = SafeResolver
    return _SAFE_RESOLVER(str(path))
