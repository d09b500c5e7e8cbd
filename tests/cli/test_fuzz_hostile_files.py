"""Hostile inputs the validator used to accept: FIFOs and loops where files should be, foreign
encodings, values whose products overflow, absurd rates, deep nesting, unencodable names.

Each was a hang or a traceback (exit 1) before; each is now one of: it works (a
FIFO named as a material is skipped like a missing one, a Latin-1 OBJ loads) or
one line on stderr naming file, entity and field, exit 2, nothing written.
Hangs fail the test after ``HANG_SECONDS`` instead of blocking the run.
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np
import pytest
from test_fuzz_meshes import hang_guard, load_or_error
from test_fuzz_scene_files import doc_with, run_cli

from editor.play import PlaySession
from engine import bvh_cache
from engine.assets import AssetLibrary
from engine.mesh_asset import AssetError, MeshAsset
from engine.mesh_files import as_utf8
from engine.scene import Scene
from engine.scene_file import SceneFileError, load_scene

pytestmark = pytest.mark.skipif(os.name != "posix", reason="FIFOs and symlinks are POSIX")

TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
CLI = ["--backend", "reference", "--size", "8x6"]


def one_error_line(code: int, stderr: str, *words: str) -> str:
    assert code == 2, (code, stderr)
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("aberrant: error: "), stderr
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]


# --- FIFOs where files should be ----------------------------------------------------------------------


@pytest.mark.parametrize("names", ["mtllib", "map_Kd"])
def test_an_obj_whose_material_file_is_a_fifo_loads_without_it(tmp_path, names):
    os.mkfifo(tmp_path / "fifo")  # nothing ever writes to it: reading it would block forever
    if names == "mtllib":
        (tmp_path / "m.obj").write_text(f"mtllib fifo\n{TRIANGLE}usemtl x\nf 1/1 2/2 3/3\n")
    else:
        (tmp_path / "t.mtl").write_text("newmtl x\nKd 1 0 0\nmap_Kd fifo\n")
        (tmp_path / "m.obj").write_text(f"mtllib t.mtl\n{TRIANGLE}usemtl x\nf 1/1 2/2 3/3\n")
    asset = load_or_error(tmp_path / "m.obj")
    assert isinstance(asset, MeshAsset) and asset.triangle_count == 1


def test_a_scene_and_a_mesh_that_are_fifos_are_refused_at_once(tmp_path):
    os.mkfifo(tmp_path / "scene.json")
    with hang_guard(), pytest.raises(SceneFileError, match="a FIFO"):
        load_scene(tmp_path / "scene.json")
    os.mkfifo(tmp_path / "mesh.obj")
    with hang_guard(), pytest.raises(AssetError, match="not a file"):
        AssetLibrary().load(tmp_path / "mesh.obj")
    code, _, stderr = run_cli(["render", str(tmp_path / "scene.json"), *CLI, "--out", str(tmp_path / "o.png")])
    one_error_line(code, stderr, "scene.json", "FIFO")


def test_a_bvh_cache_file_that_is_a_fifo_is_a_cache_miss(tmp_path):
    bvh_cache.clear_memory_cache()
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    faces = np.array([[0, 1, 2], [1, 3, 2]], np.int32)
    built = bvh_cache.cached_bvh(vertices, faces, cache_dir=tmp_path)
    [cached] = (tmp_path / "bvh").glob("*.npz")
    cached.unlink()
    os.mkfifo(cached)
    bvh_cache.clear_memory_cache()
    with hang_guard():
        again = bvh_cache.cached_bvh(vertices, faces, cache_dir=tmp_path)
    assert again.nodes.tobytes() == built.nodes.tobytes()
    assert cached.is_file()  # rewritten whole in place of the FIFO
    bvh_cache.clear_memory_cache()


def test_a_mesh_path_that_is_a_symlink_loop_names_the_entity_and_field(tmp_path):
    (tmp_path / "a.obj").symlink_to("b.obj")
    (tmp_path / "b.obj").symlink_to("a.obj")
    path = tmp_path / "scene.json"
    path.write_text(
        json.dumps(doc_with(assets={"m": {"path": "a.obj"}}, entities=[{"name": "e", "mesh": {"asset": "m"}}]))
    )
    code, _, stderr = run_cli(["render", str(path), *CLI, "--out", str(tmp_path / "o.png")])
    one_error_line(code, stderr, "entity 'e'", "mesh.asset", "symlink loop")


# --- encodings -----------------------------------------------------------------------------------------

OBJ = "# caf\u00e9\nmtllib m.mtl\n" + TRIANGLE + "usemtl cr\u00e8me\nf 1/1 2/2 3/3\n"
ENCODINGS = {
    "latin-1": OBJ.encode("latin-1"),
    "utf-16 with a byte-order mark": OBJ.encode("utf-16"),
    "utf-16-le without one": OBJ.encode("utf-16-le"),
    "utf-16-be without one": OBJ.encode("utf-16-be"),
    "utf-32": OBJ.encode("utf-32"),
    "utf-8 with a byte-order mark before the first vertex": ("v 5 0 0\n" + OBJ).encode("utf-8-sig"),
}


@pytest.mark.parametrize("encoding", list(ENCODINGS))
def test_obj_files_in_other_encodings_load_as_in_utf8(tmp_path, encoding):
    (tmp_path / "m.mtl").write_bytes("newmtl cr\u00e8me\nKd 1 0 0\n".encode("latin-1"))
    (tmp_path / "utf8.obj").write_text(OBJ if "mark" not in encoding or "utf-8" not in encoding else "v 5 0 0\n" + OBJ)
    (tmp_path / "other.obj").write_bytes(ENCODINGS[encoding])
    expected = load_or_error(tmp_path / "utf8.obj")
    asset = load_or_error(tmp_path / "other.obj")
    assert isinstance(asset, MeshAsset), asset
    assert isinstance(expected, MeshAsset)
    np.testing.assert_array_equal(asset.vertices, expected.vertices)
    np.testing.assert_array_equal(asset.faces, expected.faces)


def test_as_utf8_leaves_utf8_alone_and_never_fails_on_single_byte_text():
    assert as_utf8(b"v 0 0 0\n") == b"v 0 0 0\n"
    assert as_utf8("\u00e9".encode()) == "\u00e9".encode()
    assert as_utf8(bytes(range(1, 256))).decode("utf-8") == bytes(range(1, 256)).decode("latin-1")


# --- values whose products overflow ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("entity", "words"),
    [
        ({"name": "box", "transform": {"scale": [1e50, 1, 1]}, "aberration": {"deformation": [1, 0, 0]}}, "scale[0]"),
        ({"name": "big", "transform": {"scale": 1e308}, "mesh": {"asset": "plane"}}, "scale[0]"),
        ({"name": "big", "transform": {"scale": [1, -1e37, 1]}, "mesh": {"asset": "box"}}, "scale[1]"),
    ],
)
def test_scales_beyond_the_float32_range_are_refused_naming_the_field(tmp_path, entity, words):
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc_with(camera={"position": [0, 1, 5]}, entities=[entity])))
    for backend in ("reference", "glsl", "opencl"):  # the fast backends raised LinAlgError at packing before
        argv = ["render", str(path), "--backend", backend, "--size", "8x6", "--out", str(tmp_path / "o.png")]
        code, _, stderr = run_cli(argv)
        one_error_line(code, stderr, f"entity {entity['name']!r}", words, "1e+36")
    assert not (tmp_path / "o.png").exists()


def test_a_mesh_whose_scale_times_its_vertices_overflows_is_refused(tmp_path):
    (tmp_path / "far.obj").write_text("v 0 0 0\nv 1e10 0 0\nv 0 1 0\nf 1 2 3\n")
    path = tmp_path / "scene.json"
    entity = {"name": "far", "transform": {"scale": 1e27}, "mesh": {"asset": "m"}}
    path.write_text(json.dumps(doc_with(assets={"m": {"path": "far.obj"}}, entities=[entity])))
    with pytest.raises(SceneFileError, match=r"entity 'far'.*transform\.scale.*world-space size"):
        load_scene(path).close()


def test_a_camera_speed_beyond_the_limit_is_refused_and_a_fast_one_flies(tmp_path):
    path = tmp_path / "scene.json"
    out = tmp_path / "walk.gif"
    path.write_text(json.dumps(doc_with(camera={"position": [0, 1, 5], "speed": 1e308})))
    code, _, stderr = run_cli(["render", str(path), "--path", "--frames", "2", *CLI, "--out", str(out)])
    one_error_line(code, stderr, "camera.speed", "1e+36")
    path.write_text(json.dumps(doc_with(camera={"position": [0, 1, 5], "speed": 1e30})))
    code, _, stderr = run_cli(["render", str(path), "--path", "--frames", "2", *CLI, "--out", str(out)])
    assert code == 0 and out.is_file(), stderr


@pytest.mark.parametrize("fps", ["0.001", "1e9", "nan", "-1"])
def test_flythrough_rates_outside_the_range_are_one_line(tmp_path, fps):
    out = tmp_path / "x.gif"
    code, _, stderr = run_cli(["render", "starter", "--path", "--frames", "2", "--fps", fps, *CLI, "--out", str(out)])
    one_error_line(code, stderr, "--fps must lie in [0.01, 1000]")
    assert list(tmp_path.iterdir()) == []


def test_bench_from_deeply_nested_results_is_one_line(tmp_path):
    path = tmp_path / "results.json"
    depth = sys.getrecursionlimit() * 4
    path.write_text("[" * depth + "]" * depth)
    code, _, stderr = run_cli(["bench", "--from-results", str(path), "--out", str(tmp_path / "report")])
    one_error_line(code, stderr, "nested too deeply")


def test_play_mode_with_a_name_that_is_not_unicode_names_the_scene_and_field():
    scene = Scene("mine")
    scene.add_mesh("\ud800", "box")
    scene.set_camera((0.0, 0.0, 5.0))
    try:
        with pytest.raises(SceneFileError) as failure:
            PlaySession(scene, None)
    finally:
        scene.close()
    message = str(failure.value)
    assert message.startswith("scene 'mine': field 'entities[0].name'") and "play" not in message.split(":")[0]
    assert "aberrant-play" not in message
