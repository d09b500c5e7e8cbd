"""scripts/bench_gpu.sh: it parses, lints, refuses a machine that is not an NVIDIA one with one clear line, and
(with the NVIDIA checks stubbed, on this machine's backends) runs the bench into OUT/<size>/."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import require_backend

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "bench_gpu.sh"


def _bash(script: str, env: dict[str, str] | None = None, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, **(env or {})})  # fmt: skip


def test_the_script_parses_and_passes_shellcheck():
    assert subprocess.run(["bash", "-n", str(SCRIPT)], capture_output=True).returncode == 0
    if shutil.which("shellcheck") is None:
        pytest.skip("shellcheck is not installed")
    result = subprocess.run(["shellcheck", str(SCRIPT)], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout


def test_usage_and_a_machine_without_nvidia_smi_fail_clearly(tmp_path):
    usage = _bash(f"'{SCRIPT}' bogus")
    assert usage.returncode == 2 and "usage: scripts/bench_gpu.sh prepare | run [OUT]" in usage.stderr
    if shutil.which("nvidia-smi"):
        pytest.skip("this machine has nvidia-smi")
    result = _bash(f"'{SCRIPT}' run '{tmp_path / 'out'}'")
    assert result.returncode == 2
    errors = [line for line in result.stdout.splitlines() if "error" in line]
    assert errors == ["bench_gpu: error: no nvidia-smi: this is not an NVIDIA machine (or its driver is not mounted)"]
    assert "no nvidia-smi" in (tmp_path / "out" / "bench_gpu.log").read_text()


def test_missing_python_modules_name_what_to_bring(tmp_path):
    (tmp_path / "python").write_text('#!/bin/sh\nexec python3 -S "$@"\n')  # a Python with no site packages
    (tmp_path / "python").chmod(0o755)
    (tmp_path / "wheels").mkdir()  # nothing staged
    env = {"PYTHON": str(tmp_path / "python"), "WHEEL_DIR": str(tmp_path / "wheels")}
    result = _bash(f"source '{SCRIPT}' && setup_python", env=env)
    assert result.returncode == 2
    assert "missing Python modules (esper trimesh" in result.stderr and "bench_gpu.sh prepare" in result.stderr


def test_backends_off_the_nvidia_driver_are_refused():
    require_backend("glsl")
    result = _bash(f"source '{SCRIPT}' && PYTHON='{sys.executable}' NO_OPENCL=1 check_backends")
    if result.returncode == 0:
        pytest.skip(f"GLSL renders on NVIDIA here: {result.stderr.strip()}")
    assert "bench_gpu: error: GLSL does not render on the NVIDIA driver (runs on 'llvmpipe" in result.stderr


@pytest.mark.slow
def test_a_tiny_run_writes_a_report_per_size(tmp_path):
    require_backend("glsl")
    out = tmp_path / "gpu"
    stubs = "setup_loaders() { :; }; check_backends() { echo glsl; }"
    env = {"PYTHON": sys.executable, "SIZES": "32x24 24x16", "SCENES_1080": "ten-boxes space-portals-in-4",
           "REPEAT": "1", "BUDGET_S": "300"}  # fmt: skip
    result = _bash(f"source '{SCRIPT}' && {stubs} && run '{out}'", env=env, timeout=300)
    assert result.returncode == 0, result.stdout[-2000:]
    for size in ("32x24", "24x16"):
        results = json.loads((out / size / "results.json").read_text())
        assert results["config"]["size"] == [int(v) for v in size.split("x")]
        assert results["config"]["time_limit_s"] > 0 and results["config"]["jobs"] >= 1
        assert {r["status"] for r in results["rows"]} == {"ok"}
        assert (out / size / "report.md").is_file() and (out / size / "space_count.png").is_file()
    assert (json.loads((out / "24x16" / "results.json").read_text())["overhead"]) == []  # measured once, first
    assert "bench at 24x16" in (out / "bench_gpu.log").read_text()
