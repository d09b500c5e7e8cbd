"""Flythroughs stopped by signals, killed outright, or racing each other into one folder.

SIGINT, SIGTERM and SIGHUP end a running ``aberrant render --path`` with its
temporaries removed and the status a shell expects (128 + the signal); SIGKILL
leaves its temporary, named ``.NAME.PID-RANDOM.tmp[.ext]``, and the next run into
the same place removes it. Concurrent runs into one output each finish, and the
output is one whole run's frames, never a mix or a missing folder.
"""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import aberrant.sinks as sinks
from aberrant.sinks import Sink, mp4_unavailable

ROOT = Path(__file__).resolve().parents[2]
LONG = ["--frames", "2000", "--size", "32x24", "--backend", "reference"]

pytestmark = pytest.mark.skipif(os.name != "posix", reason="POSIX signals")


def start(out: Path, *argv: str) -> subprocess.Popen[str]:
    env = {k: v for k, v in os.environ.items() if k != "ABERRANT_BACKEND"}
    return subprocess.Popen(
        [sys.executable, "-m", "aberrant.cli", "render", "starter", "--path", *argv, "--out", str(out)],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def temporaries(folder: Path) -> list[Path]:
    return [p for p in folder.iterdir() if ".tmp" in p.name]


def wait_until_writing(child: subprocess.Popen[str], folder: Path, kind: str) -> None:
    """Until the child's temporary exists (a GIF keeps its frames in memory: a few frames in, then)."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        assert child.poll() is None, child.communicate()
        if kind == "gif":
            time.sleep(3.0)
            return
        if temporaries(folder):
            time.sleep(0.5)  # some frames written
            return
        time.sleep(0.05)
    pytest.fail("the flythrough never started writing")


OUTPUTS = {"gif": "walk.gif", "png": "frames", "mp4": "walk.mp4"}
CASES = [
    ("SIGINT", "mp4"), ("SIGTERM", "png"), ("SIGTERM", "mp4"), ("SIGTERM", "gif"), ("SIGHUP", "png"), ("SIGHUP", "mp4"),
]  # fmt: skip


@pytest.mark.parametrize(("name", "kind"), CASES, ids=[f"{n}-{k}" for n, k in CASES])
def test_a_signal_stops_a_flythrough_and_removes_its_temporaries(tmp_path, name, kind):
    if kind == "mp4" and mp4_unavailable() is not None:
        pytest.skip(f"cannot write .mp4 here: {mp4_unavailable()}")
    folder = tmp_path / "out"
    folder.mkdir()
    child = start(folder / OUTPUTS[kind], *LONG)
    wait_until_writing(child, folder, kind)
    signum = getattr(signal, name)
    child.send_signal(signum)
    _, stderr = child.communicate(timeout=120)
    assert child.returncode == 128 + signum, stderr
    said = [line for line in stderr.splitlines() if line.startswith("aberrant:")]
    assert said == (["aberrant: interrupted"] if name == "SIGINT" else [f"aberrant: terminated ({name})"]), stderr
    assert list(folder.iterdir()) == []


@pytest.mark.parametrize("kind", ["png", "mp4"])
def test_what_a_sigkill_leaves_the_next_run_removes(tmp_path, kind):
    if kind == "mp4" and mp4_unavailable() is not None:
        pytest.skip(f"cannot write .mp4 here: {mp4_unavailable()}")
    folder = tmp_path / "out"
    folder.mkdir()
    out = folder / OUTPUTS[kind]
    child = start(out, *LONG)
    wait_until_writing(child, folder, kind)
    child.kill()
    child.communicate(timeout=60)
    [left] = temporaries(folder)
    assert left.name.startswith(f".{out.name}.{child.pid}-")
    again = start(out, "--frames", "2", "--size", "16x12", "--backend", "reference")
    _, stderr = again.communicate(timeout=300)
    assert again.returncode == 0, stderr
    assert [p.name for p in folder.iterdir()] == [out.name]


@pytest.mark.parametrize("kind", ["png", "gif"])
def test_concurrent_flythroughs_into_one_output_all_finish_whole(tmp_path, kind):
    out = tmp_path / OUTPUTS[kind]
    runs = [start(out, "--frames", "3", "--size", "16x12", "--backend", "reference") for _ in range(12)]
    results = [run.communicate(timeout=600) for run in runs]
    assert [run.returncode for run in runs] == [0] * len(runs), [err for _, err in results if err]
    assert [p.name for p in tmp_path.iterdir()] == [out.name]
    if kind == "png":
        assert sorted(p.name for p in out.iterdir()) == [f"frame_{i:04d}.png" for i in range(3)]


def test_a_folder_swapped_in_by_another_run_meanwhile_is_moved_aside_too(tmp_path, monkeypatch):
    """The race itself, made certain: between moving the old folder aside and renaming ours into place,
    another run puts its folder there; ours is still put in place whole."""
    out = tmp_path / "frames"
    out.mkdir()
    (out / "frame_0000.png").write_bytes(b"old")
    sink = Sink(out, "png", 10.0)
    sink.tmp.joinpath("frame_0000.png").write_bytes(b"mine")
    real_rename = os.rename
    raced: list[bool] = []

    def rename(src: str | os.PathLike[str], dst: str | os.PathLike[str]) -> None:
        if Path(src) == sink.tmp and not raced:
            raced.append(True)
            out.mkdir()
            (out / "frame_0000.png").write_bytes(b"theirs")
            raise OSError(errno.ENOTEMPTY, os.strerror(errno.ENOTEMPTY), str(src), None, str(dst))
        real_rename(src, dst)

    monkeypatch.setattr(sinks.os, "rename", rename)
    sink.commit()
    monkeypatch.undo()
    assert raced and (out / "frame_0000.png").read_bytes() == b"mine"
    assert [p.name for p in tmp_path.iterdir()] == ["frames"]
