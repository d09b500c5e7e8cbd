"""The ``aberrant`` command line: renders, listings, and one-line errors that write nothing."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from aberrant.arguments import parse_size
from aberrant.cli import main
from engine.errors import AberrantError

ROOT = Path(__file__).resolve().parents[2]
KNOT = ROOT / "demos" / "assets" / "knot.obj"
SIZE = ["--size", "64x48"]


@pytest.fixture(autouse=True)
def _reference_backend():
    from conftest import require_backend

    require_backend("reference")


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def scene_doc(**extra: object) -> dict[str, Any]:
    doc: dict[str, Any] = {
        "format": "aberrant-scene",
        "version": 1,
        "camera": {"position": [0, 1, 4], "look_at": [0, 0.5, 0]},
        "entities": [{"name": "floor", "mesh": {"asset": "plane"}, "transform": {"scale": [4, 1, 4]}}],
    }
    doc.update(extra)
    return doc


def write(path: Path, doc: object) -> Path:
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return path


# --- rendering -----------------------------------------------------------------------------


def test_render_starter_writes_a_png_of_the_right_size(tmp_path, capsys):
    out = tmp_path / "frame.png"
    code, stdout, stderr = run(capsys, "render", "starter", "--backend", "reference", *SIZE, "--out", str(out))
    assert code == 0, stderr
    with Image.open(out) as image:
        assert image.size == (64, 48)
        assert image.format == "PNG"
        pixels = np.asarray(image)
    assert len(np.unique(pixels.reshape(-1, pixels.shape[-1]), axis=0)) > 10  # a picture, not a blank
    assert str(out) in stdout
    assert " ms" in stdout and "reference" in stdout
    assert [p.name for p in tmp_path.iterdir()] == ["frame.png"]  # no temporaries left behind


def test_render_with_aovs_writes_the_four_arrays(tmp_path, capsys):
    out, npz = tmp_path / "frame.png", tmp_path / "frame.npz"
    argv = ["render", "starter", "--backend", "reference", "--precision", "f64", *SIZE]
    code, stdout, stderr = run(capsys, *argv, "--out", str(out), "--aovs", str(npz))
    assert code == 0, stderr
    assert str(npz) in stdout
    with np.load(npz) as arrays:
        assert sorted(arrays.files) == ["depth", "events", "instance", "perceived"]
        expected = {"depth": np.float32, "perceived": np.float32, "instance": np.int32, "events": np.uint8}
        for name, dtype in expected.items():
            assert arrays[name].shape == (48, 64), name
            assert arrays[name].dtype == dtype, name
        assert not np.isnan(arrays["depth"]).any()
        assert len(set(np.unique(arrays["instance"])) - {-1}) >= 5


def test_render_a_scene_file(tmp_path, capsys):
    (tmp_path / "meshes").mkdir()
    shutil.copy(KNOT, tmp_path / "meshes" / "knot.obj")
    doc = scene_doc(assets={"knot": {"path": "meshes/knot.obj"}})
    doc["entities"].append({"name": "knot", "mesh": {"asset": "knot"}, "transform": {"position": [0, 0.5, 0]}})
    path = write(tmp_path / "level.json", doc)
    out = tmp_path / "level.png"
    code, _, stderr = run(capsys, "render", str(path), "--backend", "reference", *SIZE, "--out", str(out))
    assert code == 0, stderr
    assert Image.open(out).size == (64, 48)


def test_render_overwrites_an_old_output_on_success(tmp_path, capsys):
    out = tmp_path / "frame.png"
    out.write_bytes(b"old")
    code, _, stderr = run(capsys, "render", "starter", "--backend", "reference", *SIZE, "--out", str(out))
    assert code == 0, stderr
    assert out.read_bytes().startswith(b"\x89PNG")


# --- bad input: one line, exit 2, nothing written ------------------------------------------------


def bad_scene(tmp_path: Path, kind: str) -> tuple[str, list[str]]:
    """A scene argument of the given kind of badness, and words its error must contain."""
    path = tmp_path / "level.json"
    if kind == "malformed":
        write(path, '{"format": "aberrant-scene",\n "version": 1,,}')
        return str(path), ["level.json", "line 2", "column"]
    if kind == "unknown key":
        write(path, scene_doc(entities=[{"name": "crate", "mesh": {"asset": "box", "colour": [1, 0, 0]}}]))
        return str(path), ["level.json", "'crate'", "'mesh.colour'", "allowed keys"]
    if kind == "wrong type":
        write(path, scene_doc(entities=[{"name": "crate", "transform": {"position": "here"}}]))
        return str(path), ["level.json", "'crate'", "'transform.position'"]
    if kind == "missing mesh":
        doc = scene_doc(assets={"statue": {"path": "statue.obj"}})
        doc["entities"] = [{"name": "statue", "mesh": {"asset": "statue"}}]
        write(path, doc)
        return str(path), ["level.json", "'statue'", "'mesh.asset'", "not found"]
    if kind == "no triangles":
        (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\n")
        doc = scene_doc(assets={"flat": {"path": "flat.obj"}})
        doc["entities"] = [{"name": "flat", "mesh": {"asset": "flat"}}]
        write(path, doc)
        return str(path), ["level.json", "'flat'", "'mesh.asset'", "no triangles"]
    if kind == "zero scale":
        write(path, scene_doc(entities=[{"name": "squashed", "transform": {"scale": [1, 0, 1]}}]))
        return str(path), ["level.json", "'squashed'", "'transform.scale[1]'"]
    if kind == "bad portal":
        doc = scene_doc()
        doc["entities"].append({"name": "door", "portal": {"target": "floor"}})
        write(path, doc)
        return str(path), ["level.json", "'door'", "'portal.target'", "not a portal"]
    if kind == "missing file":
        return str(tmp_path / "nowhere.json"), ["nowhere.json", "not found"]
    if kind == "unknown demo":
        return "no_such_demo", ["no_such_demo", "starter"]
    raise AssertionError(kind)


SCENE_CASES = [
    "malformed",
    "unknown key",
    "wrong type",
    "missing mesh",
    "no triangles",
    "zero scale",
    "bad portal",
    "missing file",
    "unknown demo",
]
OPTION_CASES = [
    (["--backend", "nonesuch"], ["nonesuch", "reference"]),
    (["--size", "0x10"], ["--size", "0x10"]),
    (["--size", "abc"], ["--size", "abc"]),
    (["--size", "64x"], ["--size"]),
    (["--size", "99999x10"], ["--size"]),
    (["--precision", "f16"], ["f16"]),
]


def assert_one_line_error(code: int, stderr: str, words: list[str]) -> None:
    assert code == 2
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("aberrant: error: ")
    assert "Traceback" not in stderr
    for word in words:
        assert word in lines[0]


@pytest.mark.parametrize("pre_existing", [False, True], ids=["new", "pre-existing"])
@pytest.mark.parametrize("kind", SCENE_CASES)
def test_bad_scene_is_one_line_and_writes_nothing(tmp_path, capsys, kind, pre_existing):
    scene, words = bad_scene(tmp_path, kind)
    out, npz = tmp_path / "out.png", tmp_path / "out.npz"
    if pre_existing:
        out.write_bytes(b"keep me")
    before = sorted(p.name for p in tmp_path.iterdir())
    code, stdout, stderr = run(
        capsys, "render", scene, "--backend", "reference", *SIZE, "--out", str(out), "--aovs", str(npz)
    )
    assert_one_line_error(code, stderr, words)
    assert stdout == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    if pre_existing:
        assert out.read_bytes() == b"keep me"


@pytest.mark.parametrize(("options", "words"), OPTION_CASES)
def test_bad_option_is_one_line_and_writes_nothing(tmp_path, capsys, options, words):
    out = tmp_path / "out.png"
    code, _, stderr = run(capsys, "render", "starter", "--backend", "reference", *SIZE, *options, "--out", str(out))
    assert_one_line_error(code, stderr, words)
    assert not out.exists()


@pytest.mark.parametrize("option", ["--out", "--aovs"])
def test_missing_output_directory(tmp_path, capsys, option):
    target = str(tmp_path / "missing" / ("x.png" if option == "--out" else "x.npz"))
    outputs = ["--out", target] if option == "--out" else ["--out", str(tmp_path / "ok.png"), "--aovs", target]
    code, _, stderr = run(capsys, "render", "starter", "--backend", "reference", *SIZE, *outputs)
    assert_one_line_error(code, stderr, [option, "does not exist"])
    assert list(tmp_path.iterdir()) == []


def test_failed_render_keeps_the_old_output(tmp_path, capsys, monkeypatch):
    import systems.app

    def broken(*args: object, **kwargs: object) -> None:
        raise AberrantError("the tracer gave up")

    monkeypatch.setattr(systems.app, "render_once", broken)
    out = tmp_path / "out.png"
    out.write_bytes(b"keep me")
    code, _, stderr = run(capsys, "render", "starter", "--backend", "reference", *SIZE, "--out", str(out))
    assert_one_line_error(code, stderr, ["the tracer gave up"])
    assert out.read_bytes() == b"keep me"
    assert [p.name for p in tmp_path.iterdir()] == ["out.png"]


def test_missing_subcommand_is_a_usage_error(capsys):
    code, _, stderr = run(capsys)
    assert code == 2
    assert "Traceback" not in stderr


def test_help_exits_zero(capsys):
    code, stdout, _ = run(capsys, "render", "--help")
    assert code == 0
    assert "--aovs" in stdout and "--size" in stdout


@pytest.mark.parametrize(("text", "size"), [("64x48", (64, 48)), ("800X600", (800, 600)), (" 1x1 ", (1, 1))])
def test_parse_size(text, size):
    assert parse_size(text) == size


# --- listings ----------------------------------------------------------------------------------


def test_backends_lists_reference_as_available(capsys):
    code, stdout, _ = run(capsys, "backends")
    assert code == 0
    lines = stdout.splitlines()
    assert "reference: available" in lines
    for name in ("glsl", "opencl"):
        assert any(line.startswith(f"{name}: ") for line in lines)
    info = lines[lines.index("reference: available") + 1]
    assert info.startswith("  ")


def test_demos_lists_starter_with_its_description(capsys):
    from demos import describe

    code, stdout, _ = run(capsys, "demos")
    assert code == 0
    line = next(line for line in stdout.splitlines() if line.startswith("starter "))
    assert describe("starter") in line


# --- as a real process ----------------------------------------------------------------------------


def command() -> list[str]:
    script = Path(sys.executable).parent / "aberrant"
    return [str(script)] if script.is_file() and os.access(script, os.X_OK) else [sys.executable, "-m", "aberrant.cli"]


def test_subprocess_render_and_error(tmp_path):
    out = tmp_path / "frame.png"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    ok = subprocess.run(
        [*command(), "render", "starter", "--backend", "reference", *SIZE, "--out", str(out)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert ok.returncode == 0, ok.stderr
    assert Image.open(out).size == (64, 48)
    write(tmp_path / "bad.json", '{"format": "aberrant-scene", "version": 1, "entities": [}')
    bad = subprocess.run(
        [*command(), "render", "bad.json", "--out", "bad.png"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert bad.returncode == 2
    assert_one_line_error(bad.returncode, bad.stderr, ["bad.json", "line 1"])
    assert not (tmp_path / "bad.png").exists()


def test_module_entry_point(tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "aberrant.cli", "demos"], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0
    assert "starter" in result.stdout
