"""The project's set-up: Makefile, README, CI entry point, demo assets."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

ROOT = Path(__file__).resolve().parents[2]

needs_make = pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")


def run_make(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run(["make", "--no-print-directory", *args], cwd=cwd, capture_output=True, text=True, timeout=60)


@needs_make
@pytest.mark.parametrize(
    "target",
    ["test", "demo", "bench", "bench-gpu", "bench-pytest", "gallery", "docs", "lint", "clean", "setup", "help"],
)
def test_make_targets_parse(target):
    result = run_make("-n", target)
    assert result.returncode == 0, result.stderr


@needs_make
def test_make_demo_renders_the_tunnels_image_and_flythrough():
    plan = run_make("-n", "demo").stdout
    assert 'render aberration_tunnels --backend auto --size 800x600 --spp 4 --out "out/aberration_tunnels.png"' in plan
    assert '--path --duration 14 --fps 15 --out "out/aberration_tunnels.gif"' in plan


@needs_make
def test_make_bench_writes_the_report():
    plan = run_make("-n", "bench").stdout
    assert 'aberrant" bench --out out/bench' in plan


@needs_make
def test_make_bench_gpu_runs_the_script_into_docs():
    plan = run_make("-n", "bench-gpu").stdout
    assert 'scripts/bench_gpu.sh run "docs/bench/gpu"' in plan


@needs_make
def test_make_test_runs_a_worker_per_core_unless_told_otherwise():
    assert "-m pytest -q -n auto" in run_make("-n", "test").stdout
    assert "-m pytest -q -n 0" in run_make("-n", "test", "TEST_WORKERS=0").stdout


def test_make_bench_pytest_runs_benchmarks_despite_skip_in_addopts():
    plan = run_make("-n", "bench-pytest").stdout
    assert "--benchmark-only" in plan


@needs_make
def test_install_is_stamped_on_pyproject(tmp_path):
    """Up to date: no pip install. pyproject edited: pip install again."""
    shutil.copy(ROOT / "Makefile", tmp_path / "Makefile")
    (tmp_path / "pyproject.toml").write_text("[project]\nname = 'x'\n")
    venv_bin = tmp_path / ".venv" / "bin"
    venv_bin.mkdir(parents=True)
    (venv_bin / "python").symlink_to(shutil.which("python3") or "/usr/bin/python3")
    old = time.time() - 100
    os.utime(tmp_path / "pyproject.toml", (old, old))
    for stamp in (".stamp-venv", ".stamp-installed"):
        (tmp_path / ".venv" / stamp).touch()

    fresh = run_make("-n", "test", cwd=tmp_path)
    assert fresh.returncode == 0, fresh.stderr
    assert "pip install" not in fresh.stdout
    assert "-m pytest -q" in fresh.stdout

    os.utime(tmp_path / "pyproject.toml")  # now newer than the stamp
    stale = run_make("-n", "test", cwd=tmp_path)
    assert stale.returncode == 0, stale.stderr
    assert "pip install -q -e '.[dev,glsl,opencl,editor,bench,cluster]'" in stale.stdout
    assert "-m venv" not in stale.stdout  # the venv itself is kept


def first_code_block(markdown: str) -> str:
    match = re.search(r"^```[^\n]*\n(.*?)^```", markdown, re.MULTILINE | re.DOTALL)
    assert match, "README has no fenced code block"
    return match.group(1)


def test_readme_opens_with_the_two_commands():
    block = first_code_block((ROOT / "README.md").read_text())
    commands = [line.split("#")[0].strip() for line in block.splitlines()]
    assert "make demo" in commands
    assert "make test" in commands


def test_readme_documents_environment_variables():
    text = (ROOT / "README.md").read_text()
    for name in ("ABERRANT_BACKEND", "ABERRANT_REQUIRE_BACKENDS", "ABERRANT_CACHE_DIR"):
        assert name in text


def test_ci_run_is_an_executable_script():
    ci = ROOT / ".ci" / "run"
    assert ci.is_file()
    assert os.access(ci, os.X_OK)
    assert ci.read_text().startswith("#!")


def test_ci_run_runs_make_test_with_required_backends(tmp_path):
    """Run .ci/run with a stand-in `make` that records what it was given."""
    fake_make = tmp_path / "make"
    fake_make.write_text(
        "#!/usr/bin/env bash\n"
        'echo "args=$*"\n'
        'echo "cwd=$PWD"\n'
        'echo "require=${ABERRANT_REQUIRE_BACKENDS-unset}"\n'
        'echo "cache=${ABERRANT_CACHE_DIR-unset}"\n'
    )
    fake_make.chmod(0o755)
    env = {**os.environ, "PATH": f"{tmp_path}{os.pathsep}{os.environ['PATH']}"}
    env.pop("ABERRANT_REQUIRE_BACKENDS", None)
    result = subprocess.run(
        [str(ROOT / ".ci" / "run")], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr
    seen = dict(line.split("=", 1) for line in result.stdout.splitlines() if "=" in line and not line.startswith("==>"))
    assert seen["args"] == "test"
    assert Path(seen["cwd"]) == ROOT
    assert "reference" in seen["require"].split(",")
    assert Path(seen["cache"]).is_relative_to(ROOT)


@pytest.fixture(scope="module")
def knot() -> trimesh.Trimesh:
    return trimesh.load(ROOT / "demos" / "assets" / "knot.obj", force="mesh")


def test_knot_is_a_closed_consistently_wound_mesh(knot):
    assert knot.is_watertight
    assert knot.is_winding_consistent
    assert knot.volume > 0  # outward normals
    assert 500 <= len(knot.faces) <= 5000


def test_knot_is_centred_and_about_unit_size(knot):
    centre = knot.bounds.mean(axis=0)
    assert np.allclose(centre, 0.0, atol=1e-3)
    radius = np.linalg.norm(knot.vertices, axis=1).max()
    assert 0.4 <= radius <= 0.6


def test_knot_file_is_small():
    assert (ROOT / "demos" / "assets" / "knot.obj").stat().st_size < 300_000


def test_knot_generator_reproduces_the_committed_file(tmp_path):
    from demos.assets import make_knot

    out = make_knot.main(tmp_path / "knot.obj")
    regenerated = trimesh.load(out, force="mesh", process=False)
    committed = trimesh.load(ROOT / "demos" / "assets" / "knot.obj", force="mesh", process=False)
    assert np.array_equal(regenerated.faces, committed.faces)
    assert np.allclose(regenerated.vertices, committed.vertices, atol=1e-5)
