"""Mesh files read through trimesh: OBJ (with its ``.mtl`` material), glTF, PLY, STL, OFF.

A file's bytes are parsed once (:class:`engine.assets.AssetLibrary` caches by path and content); any
parser failure, encoding oddity or unusable material becomes one line naming the file.
"""

from __future__ import annotations

import codecs
import contextlib
import io
import logging
import os
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from engine.atomic_files import read_regular
from engine.errors import shorten
from engine.mesh_asset import AssetError, MeshAsset, make_asset
from engine.textures import TextureImage, texture_image, warn_unreadable

if TYPE_CHECKING:
    import trimesh


MESH_SUFFIXES = (".obj", ".glb", ".gltf", ".ply", ".stl", ".off")


def load_mesh_file(path: Path, data: bytes) -> MeshAsset:
    """The asset in a mesh file's bytes (``path`` names it and resolves what it refers to)."""
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
