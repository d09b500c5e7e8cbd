"""The memory budget: a frame or GIF that would not fit is refused up front in one line, not OOM-killed.

The budget (aberrant/memory.py) is ``$ABERRANT_MEMORY_BUDGET`` or 80 % of the
least of available memory, the address-space limit and the cgroup limit. A
child process under ``ulimit -v`` (RLIMIT_AS, set in ``preexec_fn``) shows the
real thing: the frame that cannot fit fails at once with the size it would need
and what to do; one that fits renders under the same limit. The reference
traces in bands of rows, so its memory grows with the image only by the AOVs.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from test_fuzz_scene_files import run_cli

from aberrant.memory import BUDGET_ENV, format_bytes, memory_budget, parse_bytes
from backends.base import backend_class
from engine.errors import AberrantError

ROOT = Path(__file__).resolve().parents[2]
LIMIT = 2 * 2**30


def limited() -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))


def render_limited(size: str, out: Path) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != BUDGET_ENV}
    argv = ["render", "starter", "--backend", "reference", "--size", size, "--out", str(out)]
    return subprocess.run(
        [sys.executable, "-m", "aberrant.cli", *argv],
        cwd=ROOT, env=env, preexec_fn=limited, capture_output=True, text=True, timeout=600,
    )  # fmt: skip


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS and /proc/self/status (Linux)")
def test_under_an_address_space_limit_a_frame_too_big_is_refused_and_one_that_fits_renders(tmp_path):
    out = tmp_path / "frame.png"
    big = render_limited("16384x16384", out)
    assert big.returncode == 2, big.stderr[-2000:]
    [line] = big.stderr.splitlines()
    assert line.startswith("aberrant: error: a 16384x16384 frame with the reference backend needs about ")
    assert "address-space limit" in line and "choose a smaller --size" in line
    assert not out.exists()
    small = render_limited("512x384", out)
    assert small.returncode == 0, small.stderr[-2000:]
    assert out.is_file()


def test_a_gif_that_would_not_fit_is_refused_before_rendering(tmp_path, monkeypatch):
    monkeypatch.setenv(BUDGET_ENV, "1G")
    out = tmp_path / "walk.gif"
    argv = ["render", "starter", "--path", "--frames", "1000000", "--size", "320x240", "--backend", "reference"]
    code, _, stderr = run_cli([*argv, "--out", str(out)])
    assert code == 2
    [line] = stderr.splitlines()
    assert line.startswith("aberrant: error: a 1000000-frame 320x240 GIF needs about 154 GB of memory")
    assert "budget of 1 GB ($ABERRANT_MEMORY_BUDGET)" in line and "write .mp4 or a folder of PNGs" in line
    assert list(tmp_path.iterdir()) == []


def test_a_frame_over_the_budget_names_the_backend_and_the_aovs(tmp_path, monkeypatch):
    monkeypatch.setenv(BUDGET_ENV, "300M")
    out, npz = tmp_path / "f.png", tmp_path / "f.npz"
    code, _, stderr = run_cli(["render", "starter", "--backend", "reference", "--size", "4096x4096",
                               "--out", str(out), "--aovs", str(npz)])  # fmt: skip
    assert code == 2
    [line] = stderr.splitlines()
    assert "4096x4096 frame with the reference backend" in line and "leave out --aovs" in line
    assert list(tmp_path.iterdir()) == []


def test_frame_estimates_grow_with_the_aovs_and_the_backend():
    reference, glsl = backend_class("reference"), backend_class("glsl")
    color = reference.frame_bytes(4096, 4096, ("color",))
    every = reference.frame_bytes(4096, 4096, ("color", "depth", "perceived", "instance", "events"))
    assert every > color > 4096 * 4096 * 4
    assert glsl.frame_bytes(4096, 4096, ("color",)) > color


def test_budget_sizes_parse_and_print(monkeypatch):
    assert parse_bytes("8G") == 8 * 10**9 and parse_bytes("512MiB") == 512 * 2**20 and parse_bytes("1000") == 1000
    assert parse_bytes(" 1.5 gb ") == 1_500_000_000
    for bad in ("", "lots", "-1G", "1 G B"):
        with pytest.raises(AberrantError, match=BUDGET_ENV):
            parse_bytes(bad)
    assert format_bytes(2.42e9) == "2.42 GB" and format_bytes(999) == "999 bytes"
    monkeypatch.setenv(BUDGET_ENV, "2G")
    assert memory_budget() == (2 * 10**9, f"${BUDGET_ENV}")
    monkeypatch.delenv(BUDGET_ENV)
    budget, source = memory_budget()
    assert budget > 0 and "80%" in source
