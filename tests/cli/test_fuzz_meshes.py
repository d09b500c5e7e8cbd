"""Fuzzing mesh files (OBJ, PLY, STL, OFF, GLB) and TelloEngine mesh resources with hypothesis.

A mesh file either loads as a usable :class:`MeshAsset` (finite float32
vertices of shape (N, 3), int32 faces (M, 3) indexing them, M >= 1) or raises
:class:`AssetError` naming the file; never another exception, never a hang,
and nothing on stderr (trimesh logs tracebacks for some malformed files).
Through a scene file the failure is a SceneFileError naming the entity, the
field ``mesh.asset`` and the asset. Deterministic runs: ``derandomize=True``,
no example database.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import warnings
from collections.abc import Iterator
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aberrant.cli import main
from aberrant.importers.tello import read_mesh_resource
from engine.assets import AssetLibrary
from engine.errors import AberrantError
from engine.mesh_asset import AssetError, MeshAsset, make_asset
from engine.scene_file import SceneFileError, load_scene

ROOT = Path(__file__).resolve().parents[2]
TELLO = Path(__file__).resolve().parents[2] / "tests" / "data" / "tello"
HANG_SECONDS = 30


def fuzz_settings(examples: int) -> settings:
    """Deterministic and database-free: CI runs the same examples every time and writes nothing."""
    return settings(
        max_examples=examples,
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )


class Hang(BaseException):
    """A load ran past :data:`HANG_SECONDS` (a BaseException: trimesh's ``except Exception`` cannot hide it)."""


@contextlib.contextmanager
def hang_guard(seconds: int = HANG_SECONDS) -> Iterator[None]:
    """Fail instead of hanging forever (POSIX; a generous guard, not a speed assertion)."""
    if not hasattr(signal, "SIGALRM"):
        yield
        return

    def on_alarm(signum: int, frame: object) -> None:
        raise Hang(f"still running after {seconds} s")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@contextlib.contextmanager
def silent() -> Iterator[io.StringIO]:
    """Capture stderr and Python warnings (pytest would intercept warnings before they reach stderr)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield err
    for w in caught:
        err.write(f"{w.filename}:{w.lineno}: {w.category.__name__}: {w.message}\n")


def assert_usable(asset: MeshAsset) -> None:
    v, f = asset.vertices, asset.faces
    assert v.dtype == np.float32 and v.ndim == 2 and v.shape[1] == 3
    assert np.all(np.isfinite(v))
    assert f.dtype == np.int32 and f.ndim == 2 and f.shape[1] == 3 and len(f) >= 1
    assert f.min() >= 0 and f.max() < len(v)
    if asset.uvs is not None:
        assert asset.uvs.shape == (len(v), 2) and np.all(np.isfinite(asset.uvs))


def load_or_error(path: Path) -> MeshAsset | AssetError:
    """Load with a fresh library; the only acceptable failure is an AssetError naming the file; stderr stays empty."""
    with hang_guard(), silent() as err:
        try:
            result: MeshAsset | AssetError = AssetLibrary().load(path)
        except AssetError as e:
            result = e
    assert err.getvalue() == "", err.getvalue()
    if isinstance(result, AssetError):
        assert str(path) in str(result), str(result)
        assert "\n" not in str(result)
    else:
        assert_usable(result)
    return result


# --- seed files -------------------------------------------------------------------------------


@cache
def seeds() -> dict[str, tuple[str, bytes]]:
    """A valid small mesh in every format and encoding: ``label -> (suffix, bytes)``."""
    import trimesh

    box = trimesh.creation.box()

    def data(value: str | bytes) -> bytes:
        return value.encode() if isinstance(value, str) else value

    return {
        "obj": (".obj", data(box.export(file_type="obj"))),
        "obj_uv": (".obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n"),
        "ply": (".ply", data(box.export(file_type="ply"))),
        "ply_ascii": (".ply", data(box.export(file_type="ply", encoding="ascii"))),
        "stl": (".stl", data(box.export(file_type="stl"))),
        "stl_ascii": (".stl", data(box.export(file_type="stl_ascii"))),
        "off": (".off", data(box.export(file_type="off"))),
        "glb": (".glb", data(box.export(file_type="glb"))),
    }


TOKENS = [b"nan", b"inf", b"-inf", b"1e39", b"-1e400", b"99999999999", b"-7", b"0", b"4294967297", b" ", b"\n", b"/"]


@st.composite
def mutated_meshes(draw: st.DrawFn) -> tuple[str, bytes]:
    """A seed file truncated, spliced with garbage, given hostile number tokens, emptied, or replaced by noise."""
    suffix, data = seeds()[draw(st.sampled_from(sorted(seeds())))]
    op = draw(st.sampled_from(["truncate", "splice", "tokens", "flip", "garbage", "empty"]))
    if op == "truncate":
        return suffix, data[: draw(st.integers(0, len(data)))]
    if op == "garbage":
        return suffix, draw(st.binary(max_size=300))
    if op == "empty":
        return suffix, draw(st.sampled_from([b"", b" ", b"\n\n\n"]))
    for _ in range(draw(st.integers(1, 6))):
        at = draw(st.integers(0, len(data)))
        if op == "splice":
            data = data[:at] + draw(st.binary(max_size=6)) + data[at + draw(st.integers(0, 6)) :]
        elif op == "tokens":
            data = data[:at] + draw(st.sampled_from(TOKENS)) + data[at + draw(st.integers(0, 4)) :]
        elif data:
            at = min(at, len(data) - 1)
            data = data[:at] + bytes([data[at] ^ (1 << draw(st.integers(0, 7)))]) + data[at + 1 :]
    return suffix, data


@fuzz_settings(500)
@given(mutated_meshes())
def test_mutated_mesh_files_load_or_raise_asset_error(case: tuple[str, bytes]) -> None:
    suffix, data = case
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"mesh{suffix}"
        path.write_bytes(data)
        load_or_error(path)


@fuzz_settings(60)
@given(mutated_meshes())
def test_a_scene_naming_a_broken_mesh_fails_naming_entity_field_and_asset(case: tuple[str, bytes]) -> None:
    suffix, data = case
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / f"mesh{suffix}").write_bytes(data)
        doc = {
            "format": "aberrant-scene",
            "version": 1,
            "assets": {"broken": {"path": f"mesh{suffix}"}},
            "entities": [{"name": "thing", "mesh": {"asset": "broken"}}],
        }
        scene_path = folder / "scene.json"
        scene_path.write_text(json.dumps(doc))
        with hang_guard(), silent() as err:
            try:
                load_scene(scene_path).close()
            except SceneFileError as e:
                message = str(e)
                assert message.startswith(str(scene_path))
                for words in ("entity 'thing'", "field 'mesh.asset'", "asset 'broken'", f"mesh{suffix}"):
                    assert words in message, message
        assert err.getvalue() == ""


# --- hand-written hostile files ---------------------------------------------------------------------

TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
PLY_HEAD = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
PLY_FACE = "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
STL_FACET = "facet normal 0 0 1\nouter loop\nvertex {} 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n"

#: name -> (file name, contents, words the AssetError must hold; None: it must load).
HOSTILE: dict[str, tuple[str, bytes | str, tuple[str, ...] | None]] = {
    "obj empty": ("m.obj", "", ("empty",)),
    "obj whitespace": ("m.obj", " \n\t\n", ("empty",)),
    "obj no faces": ("m.obj", TRI, ("no triangles",)),
    "obj only lines": ("m.obj", TRI + "l 1 2\n", ("no triangles",)),
    "obj NaN vertex": ("m.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ("NaN",)),
    "obj inf vertex": ("m.obj", "v inf 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ("NaN or infinity",)),
    "obj beyond float32": ("m.obj", "v 1e39 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ("float32",)),
    "obj face out of range": ("m.obj", TRI + "f 1 2 9\n", ("m.obj",)),
    "obj negative index out of range": ("m.obj", TRI + "f 1 2 -9\n", ("m.obj",)),
    "obj huge index": ("m.obj", TRI + "f 1 2 4294967298\n", ("m.obj",)),
    "obj enormous index": ("m.obj", TRI + "f 1 2 99999999999999999999999\n", ("m.obj",)),
    "obj two-component vertices": ("m.obj", "v 0 0\nv 1 0\nv 0 1\nf 1 2 3\n", ("m.obj",)),
    "obj one-component vertex line": ("m.obj", TRI + "v 0.5\nf 1 2 3\n", ("vertices must be (N, 3)",)),
    "obj missing material": ("m.obj", "mtllib missing.mtl\nusemtl x\n" + TRI + "f 1 2 3\n", None),
    "obj material outside its folder": ("m.obj", "mtllib ../../../../etc/passwd\n" + TRI + "f 1 2 3\n", None),
    "obj quad": ("m.obj", TRI + "v 1 1 0\nf 1 2 4 3\n", None),
    "obj bad uv index": ("m.obj", TRI + "vt 0 0\nf 1/1 2/2 3/9\n", None),
    "ply no faces": ("m.ply", PLY_HEAD + "end_header\n0 0 0\n1 0 0\n0 1 0\n", ("no triangles",)),
    "ply header only": ("m.ply", "ply\nformat ascii 1.0\nend_header\n", ("no triangles",)),
    "ply magic only": ("m.ply", "ply\n", ("cannot parse",)),
    "ply NaN vertex": ("m.ply", PLY_HEAD + PLY_FACE + "nan 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", ("NaN",)),
    "ply face out of range": ("m.ply", PLY_HEAD + PLY_FACE + "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", ("out of range",)),
    "ply huge index": ("m.ply", PLY_HEAD + PLY_FACE + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2147483647\n", ("out of range",)),
    "ply four billion vertices": (
        "m.ply",
        "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
        ("m.ply",),
    ),
    "off no faces": ("m.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", ("no triangles",)),
    "off header only": ("m.off", "OFF\n", ("cannot parse",)),
    "off face out of range": ("m.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n", ("m.off",)),
    "off huge index": ("m.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 99999999999\n", ("m.off",)),
    "off NaN vertex": ("m.off", "OFF\n3 1 0\nnan 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", ("NaN",)),
    "off enormous count": ("m.off", "OFF\n99999999999 1 0\n0 0 0\n", ("m.off",)),
    "stl no facets": ("m.stl", "solid x\nendsolid x\n", ("no triangles",)),
    "stl NaN vertex": ("m.stl", "solid x\n" + STL_FACET.format("nan") + "endsolid x\n", ("NaN",)),
    "stl bad normal (trimesh logs a traceback)": (
        "m.stl",
        "solid x\n" + STL_FACET.format("0").replace("normal 0 0 1", "normal 0 0 zz") + "endsolid x\n",
        None,
    ),
    "stl binary claiming 1e9 facets": ("m.stl", b"\0" * 80 + struct.pack("<I", 10**9), ("m.stl",)),
    "stl binary zero facets": ("m.stl", b"\0" * 80 + struct.pack("<I", 0), ("no triangles",)),
    "glb garbage": ("m.glb", b"glTF\x02\0\0\0\xff\xff\xff\x7f" + b"\0" * 20, ("cannot parse",)),
    "glb empty": ("m.glb", b"", ("empty",)),
    "gltf without meshes": ("m.gltf", '{"asset": {"version": "2.0"}}', ("no triangles",)),
    "gltf buffer outside its folder": (
        "m.gltf",
        '{"asset": {"version": "2.0"}, "buffers": [{"uri": "/etc/passwd", "byteLength": 10}]}',
        ("cannot parse",),
    ),
    "gltf missing buffer": (
        "m.gltf",
        '{"asset":{"version":"2.0"},"buffers":[{"uri":"missing.bin","byteLength":36}],'
        '"bufferViews":[{"buffer":0,"byteLength":36}],'
        '"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3"}],'
        '"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],"nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}]}',
        ("cannot parse",),
    ),
    "no extension": ("mesh", TRI + "f 1 2 3\n", ("unsupported mesh format",)),
    "unsupported extension": ("m.fbx", TRI + "f 1 2 3\n", ("unsupported mesh format",)),
    "upper-case extension": ("m.OBJ", TRI + "f 1 2 3\n", None),
}


def _glb_variants() -> dict[str, tuple[str, bytes | str, tuple[str, ...] | None]]:
    """A one-triangle GLB, and the same with a NaN vertex and an index past the vertices (binary edits)."""
    import trimesh

    good = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    glb = trimesh.Trimesh(good, [[0, 1, 2]], process=False).export(file_type="glb")
    nan = good.copy()
    nan[0, 0] = np.nan
    indices = np.array([0, 1, 2], np.uint32).tobytes()
    assert glb.count(good.tobytes()) == 1 and glb.count(indices) == 1
    return {
        "glb one triangle": ("m.glb", glb, None),
        "glb NaN vertex": ("m.glb", glb.replace(good.tobytes(), nan.tobytes()), ("NaN",)),
        "glb index past the vertices": (
            "m.glb",
            glb.replace(indices, np.array([0, 1, 70000], np.uint32).tobytes()),
            ("out of range",),
        ),
    }


@pytest.mark.parametrize("name", [*HOSTILE, "glb one triangle", "glb NaN vertex", "glb index past the vertices"])
def test_hostile_mesh_files(tmp_path, name):
    file_name, contents, words = {**HOSTILE, **_glb_variants()}[name]
    path = tmp_path / file_name
    path.write_bytes(contents.encode() if isinstance(contents, str) else contents)
    result = load_or_error(path)
    if words is None:
        assert isinstance(result, MeshAsset), f"{name}: {result}"
    else:
        assert isinstance(result, AssetError), f"{name} loaded"
        for word in words:
            assert word in str(result), str(result)


def test_missing_directory_and_special_paths(tmp_path):
    for path, words in [
        (tmp_path / "missing.obj", "not found"),
        (tmp_path, "not a file"),
        (Path("/dev/null"), "not a file"),
        (tmp_path / "x\0.obj", "not a usable file path"),
    ]:
        with pytest.raises(AssetError, match=words):
            AssetLibrary().load(path)


# --- regressions: crashes this fuzzing found ------------------------------------------------------


def test_obj_with_a_one_component_vertex_line_is_an_asset_error(tmp_path):
    """trimesh returned (N, 1) vertices; make_asset's reshape raised a bare ValueError."""
    path = tmp_path / "broken.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv -0.5\n0 0.5 0.5\nf 1 2 3\n")
    with pytest.raises(AssetError, match=r"broken\.obj: vertices must be \(N, 3\)"):
        AssetLibrary().load(path)


ODD_STL = "solid x\n" + STL_FACET.format("0").replace("normal 0 0 1", "normal 0 0 zz") + "endsolid x\n"


def test_a_loadable_stl_that_makes_trimesh_log_a_traceback_logs_nothing(tmp_path, caplog):
    """trimesh logged 'failed to extract face_normals' with a traceback (through logging's last-resort
    handler, i.e. on stderr, in a process that configured no logging: the CLI)."""
    path = tmp_path / "odd.stl"
    path.write_text(ODD_STL)
    caplog.set_level(logging.DEBUG)
    asset = load_or_error(path)
    assert isinstance(asset, MeshAsset) and asset.triangle_count == 1
    assert [r.getMessage() for r in caplog.records if r.name.startswith("trimesh")] == []


def test_the_cli_shows_no_trimesh_traceback(tmp_path):
    """In a fresh process, where logging has no handler and its last resort prints to stderr."""
    (tmp_path / "odd.stl").write_text(ODD_STL)
    scene = tmp_path / "scene.json"
    doc = {
        "format": "aberrant-scene",
        "version": 1,
        "camera": {"position": [0.3, 0.3, 2]},
        "assets": {"odd": {"path": "odd.stl"}},
        "entities": [{"name": "odd", "mesh": {"asset": "odd"}}],
    }
    scene.write_text(json.dumps(doc))
    argv = ["render", str(scene), "--backend", "reference", "--size", "8x6", "--out", str(tmp_path / "o.png")]
    result = subprocess.run(
        [sys.executable, "-m", "aberrant.cli", *argv], capture_output=True, text=True, timeout=120, cwd=ROOT
    )
    assert (result.returncode, result.stderr) == (0, "")


def test_make_asset_checks_indices_before_the_int32_cast():
    """An int64 index of 2**32 + 1 used to wrap to 1 in the int32 cast and pass as a valid triangle."""
    vertices = np.eye(3)
    with pytest.raises(AssetError, match="out of range"):
        make_asset(vertices, np.array([[0, 1, 2**32 + 1]], np.int64), None, "wrapped")
    with pytest.raises(AssetError, match="out of range"):
        make_asset(vertices, np.array([[0, 1, -(2**32) + 2]], np.int64), None, "wrapped")


@pytest.mark.parametrize(
    ("vertices", "faces", "words"),
    [
        (np.zeros(8), [[0, 1, 2]], "vertices must be (N, 3)"),
        (np.zeros((3, 2)), [[0, 1, 2]], "vertices must be (N, 3)"),
        (np.array([["a", "b", "c"]] * 3), [[0, 1, 2]], "vertices must be (N, 3)"),
        (np.eye(3), np.array([[0.0, 1.0, np.nan]]), "whole numbers"),
        (np.eye(3), np.array([[0.0, 1.0, 1.5]]), "whole numbers"),
        (np.eye(3), np.array([["0", "1", "2"]]), "integers"),
        (np.eye(3), np.zeros((0, 3), np.int64), "no triangles"),
        (np.eye(3), [[0, 1]], "no triangles"),
        (np.full((3, 3), 1e39), [[0, 1, 2]], "float32"),
    ],
)
def test_make_asset_rejects_what_a_parser_may_hand_over(vertices, faces, words):
    with pytest.raises(AssetError, match=f"^source: .*{__import__('re').escape(words)}"):
        make_asset(np.asarray(vertices), np.asarray(faces), None, "source")


def test_make_asset_drops_unusable_uvs_instead_of_failing():
    for uvs in (np.zeros(5), np.zeros((2, 2)), np.full((3, 2), np.nan), np.array([["u", "v"]] * 3)):
        asset = make_asset(np.eye(3), np.array([[0, 1, 2]]), uvs, "uv")
        assert asset.uvs is None
    assert make_asset(np.eye(3), np.array([[0.0, 1.0, 2.0]]), np.zeros((3, 2)), "uv").uvs is not None


# --- TelloEngine mesh resources -----------------------------------------------------------------------


def tello_meshes() -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((TELLO / "Mesh").iterdir())}


@st.composite
def resource_edits(draw: st.DrawFn) -> tuple[str, int, int, int]:
    """(operation, position, value, length) applied to a resource by :func:`edit_resource`."""
    op = draw(st.sampled_from(["truncate", "header", "flip", "splice", "nan"]))
    value = draw(st.sampled_from([0, 1, 2, 3, 5, 2**31, 2**32 - 1])) if op == "header" else draw(st.integers(0, 255))
    return op, draw(st.integers(0, 10**6)), value, draw(st.integers(0, 8))


def edit_resource(data: bytes, edit: tuple[str, int, int, int]) -> bytes:
    op, at, value, length = edit
    at %= len(data) + 1
    if op == "truncate":
        return data[:at]
    if op == "header":
        return data[: 4 * (at % 4)] + struct.pack("<I", value) + data[4 * (at % 4) + 4 :]
    if op == "nan":  # a float past the header becomes NaN (vertex, normal or uv; indices then go huge)
        at = 16 + 4 * ((at - 16) // 4 if at > 16 else 0)
        return data[:at] + struct.pack("<f", float("nan")) + data[at + 4 :]
    if op == "flip" and at < len(data):
        return data[:at] + bytes([data[at] ^ (1 << (value % 8))]) + data[at + 1 :]
    return data[:at] + bytes([value]) * length + data[at + length :]


@fuzz_settings(150)
@given(st.data())
def test_mutated_tello_mesh_resources_decode_or_raise_a_clear_error(data: st.DataObject) -> None:
    meshes = tello_meshes()
    name = data.draw(st.sampled_from(sorted(meshes)))
    mutated = meshes[name]
    for edit in data.draw(st.lists(resource_edits(), min_size=1, max_size=3)):
        mutated = edit_resource(mutated, edit)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / name
        path.write_bytes(mutated)
        with hang_guard(), silent() as err:
            try:
                mesh = read_mesh_resource(path)
            except AberrantError as e:
                assert str(e).startswith(str(path)), str(e)
            else:
                assert np.all(np.isfinite(mesh.vertices)) and mesh.vertices.shape[1] == 3
                assert len(mesh.faces) >= 1 and mesh.faces.min() >= 0 and mesh.faces.max() < len(mesh.vertices)
        assert err.getvalue() == ""


@fuzz_settings(25)
@given(st.data())
def test_tello_import_with_a_mutated_mesh_resource_exits_0_or_2(data: st.DataObject) -> None:
    meshes = tello_meshes()
    scene = TELLO / "Scenes" / "AberrationRoom"
    name = data.draw(st.sampled_from(sorted(meshes)))
    mutated = meshes[name]
    for edit in data.draw(st.lists(resource_edits(), min_size=1, max_size=2)):
        mutated = edit_resource(mutated, edit)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        shutil.copytree(TELLO / "Mesh", folder / "Mesh")
        (folder / "Mesh" / name).write_bytes(mutated)
        out = folder / "out.json"
        argv = ["import-tello", str(scene), "--mesh-dir", str(folder / "Mesh"), "--out", str(out)]
        with hang_guard(), silent() as err, contextlib.redirect_stdout(io.StringIO()):
            code = main(argv)
        stderr = err.getvalue()
        assert "Traceback" not in stderr and "Warning:" not in stderr, stderr
        if code == 0:
            load_scene(out).close()
        else:
            assert code == 2
            lines = stderr.splitlines()
            assert len(lines) == 1 and lines[0].startswith("aberrant: error: ") and "components[" in lines[0], stderr
            assert not out.exists()
