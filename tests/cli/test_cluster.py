"""Flythroughs on a Dask cluster: the same bytes as one process, resumable, and robust to a dying worker."""

from __future__ import annotations

import io
import os
import signal
import sys
from pathlib import Path

import pytest

pytest.importorskip("distributed")

import aberrant.cluster as cluster
from aberrant.cli import main
from aberrant.cluster import render_distributed
from aberrant.flythrough import default_path, render_flythrough
from demos import build_demo
from engine.errors import AberrantError, BackendUnavailable

SIZE = (48, 36)


@pytest.fixture
def local_cluster():
    """``start(n, **kwargs)``: a LocalCluster of n worker processes on loopback, closed when the test ends."""
    started = []

    def start(n: int = 2, **kwargs):
        made = cluster.local_cluster(n, **kwargs)
        started.append(made)
        return made

    try:
        yield start
    finally:
        for made in started:
            made.close()


def single_process(backend, out: Path, frames: int, size=SIZE, spp: int = 1) -> None:
    scene = build_demo("starter")
    try:
        render_flythrough(scene, backend, default_path(scene), frames, size, out, progress=False, spp=spp)
    finally:
        scene.close()


def distributed(out: Path, frames: int, size=SIZE, **kwargs) -> str:
    scene = build_demo("starter")
    try:
        return render_distributed(scene, default_path(scene), frames, size, out, progress=False, **kwargs)
    finally:
        scene.close()


def files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.mark.parametrize("name", ["reference", "glsl", "opencl"])
def test_the_clip_and_every_frame_match_the_single_process_run(backend_factory, local_cluster, tmp_path, name):
    backend = backend_factory(name)
    alone, spread = tmp_path / "alone", tmp_path / "spread"
    alone.mkdir()
    spread.mkdir()
    single_process(backend, alone / "clip.gif", 5)
    single_process(backend, alone / "frames", 5)
    address = local_cluster(2).scheduler_address
    assert distributed(spread / "clip.gif", 5, backend=name, scheduler=address) == name
    distributed(spread / "frames", 5, backend=name, scheduler=address)
    assert sorted(p.name for p in spread.iterdir()) == ["clip.gif", "frames"]  # the work folders are gone
    assert (spread / "clip.gif").read_bytes() == (alone / "clip.gif").read_bytes()
    assert files(spread / "frames") == files(alone / "frames")


def test_frames_of_several_samples_a_pixel_match_the_single_process_run(backend_factory, local_cluster, tmp_path):
    backend = backend_factory("opencl")
    alone, spread, plain = tmp_path / "alone", tmp_path / "spread", tmp_path / "plain"
    single_process(backend, alone, 3, spp=4)
    single_process(backend, plain, 3)
    distributed(spread, 3, backend="opencl", workers=1, spp=4)
    assert files(spread) == files(alone)
    assert files(spread) != files(plain)  # the samples reached the workers


def test_a_restarted_run_renders_only_the_missing_frames(backend_factory, local_cluster, tmp_path, monkeypatch):
    address = local_cluster(1).scheduler_address
    out = tmp_path / "clip.gif"

    def stop(*args):
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(cluster, "_write_clip", stop)
        with pytest.raises(KeyboardInterrupt):
            distributed(out, 6, backend="reference", scheduler=address)
    (work,) = tmp_path.iterdir()
    assert work.name.startswith(".clip.gif.frames-")
    kept = sorted(work.iterdir())
    assert len(kept) == 6
    for lost in kept[::2]:
        lost.unlink()
    inodes = {p.name: p.stat().st_ino for p in kept[1::2]}
    before_clip = {}
    real_write_clip = cluster._write_clip

    def write_clip(out, kind, fps, folder, job):
        before_clip.update({p.name: p.stat().st_ino for p in folder.iterdir()})
        real_write_clip(out, kind, fps, folder, job)

    monkeypatch.setattr(cluster, "_write_clip", write_clip)
    stream = io.StringIO()
    scene = build_demo("starter")
    try:
        render_distributed(
            scene, default_path(scene), 6, SIZE, out, backend="reference", scheduler=address, progress=stream
        )
    finally:
        scene.close()
    assert "6/6 frames" in stream.getvalue()
    assert [p.name for p in tmp_path.iterdir()] == ["clip.gif"]
    single_process(backend_factory("reference"), tmp_path / "alone.gif", 6)
    assert out.read_bytes() == (tmp_path / "alone.gif").read_bytes()
    # The kept frames were read back, not rendered again (a rendered frame is a new file).
    assert len(before_clip) == 6
    assert all(before_clip[name] == inode for name, inode in inodes.items())


class KillOnFirstFrame(io.StringIO):
    """A progress stream that, when the first frame is reported, kills a worker that is rendering one."""

    def __init__(self, address: str) -> None:
        super().__init__()
        from distributed import Client

        self.client = Client(address, set_as_default=False)
        self.pids = self.client.run(os.getpid)
        self.killed: list[str] = []

    def write(self, text: str) -> int:
        if not self.killed and "frames" in text:
            busy = [worker for worker, keys in self.client.processing().items() if keys]
            assert busy, "no worker was rendering when the first frame came in"
            os.kill(self.pids[busy[0]], signal.SIGKILL)
            self.killed.append(busy[0])
        return super().write(text)


def test_a_worker_killed_mid_frame_loses_and_duplicates_nothing(backend_factory, local_cluster, tmp_path):
    address = local_cluster(2).scheduler_address
    out = tmp_path / "frames"
    stream = KillOnFirstFrame(address)
    try:
        scene = build_demo("starter")
        try:
            render_distributed(
                scene, default_path(scene), 10, (64, 48), out, backend="reference", scheduler=address, progress=stream
            )
        finally:
            scene.close()
    finally:
        stream.client.close()
    assert stream.killed
    single_process(backend_factory("reference"), tmp_path / "alone", 10, size=(64, 48))
    assert files(out) == files(tmp_path / "alone")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["alone", "frames"]


def test_a_worker_whose_backend_cannot_start_fails_in_one_line_leaving_nothing(local_cluster, tmp_path):
    address = local_cluster(1, env={"LIBGL_DRIVERS_PATH": "/nonexistent"}).scheduler_address
    with pytest.raises(BackendUnavailable, match=r"^worker tcp://127\.0\.0\.1:\d+: glsl backend cannot run here"):
        distributed(tmp_path / "clip.gif", 3, backend="glsl", scheduler=address)
    assert list(tmp_path.iterdir()) == []


def test_cli_workers_renders_and_a_bad_backend_is_one_line(tmp_path, capsys):
    out = tmp_path / "clip.gif"
    common = ["render", "starter", "--path", "--frames", "3", "--size", "32x24", "--workers", "1"]
    assert main([*common, "--backend", "reference", "--out", str(out)]) == 0
    assert "3 frames of 32x24 with the reference backend" in capsys.readouterr().out
    assert main([*common, "--backend", "nosuch", "--out", str(tmp_path / "other.gif")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("aberrant: error: worker tcp://127.0.0.1:"), err
    assert "nosuch" in err[0]
    assert [p.name for p in tmp_path.iterdir()] == ["clip.gif"]


def test_an_unreachable_scheduler_is_one_line_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 0.5)
    argv = ["render", "starter", "--path", "--frames", "2", "--size", "16x12", "--out", str(tmp_path / "c.gif")]
    assert main([*argv, "--scheduler", "tcp://127.0.0.1:1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [err[0]] and err[0].startswith("aberrant: error: --scheduler tcp://127.0.0.1:1: cannot reach")
    assert list(tmp_path.iterdir()) == []


def test_without_dask_workers_say_how_to_install_it(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    argv = ["render", "starter", "--path", "--frames", "2", "--size", "16x12", "--out", str(tmp_path / "c.gif")]
    assert main([*argv, "--workers", "2"]) == 2
    expected = "aberrant: error: --workers needs the cluster extra: pip install -e '.[cluster]'\n"
    assert capsys.readouterr().err == expected
    with pytest.raises(AberrantError, match="cluster extra"):
        distributed(tmp_path / "c.gif", 2, workers=1)
    assert list(tmp_path.iterdir()) == []


def test_workers_and_scheduler_need_a_path_and_each_other_not(tmp_path, capsys):
    assert main(["render", "starter", "--workers", "2", "--out", str(tmp_path / "a.png")]) == 2
    assert "add --path" in capsys.readouterr().err
    argv = ["render", "starter", "--path", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"]
    assert main([*argv, "--out", str(tmp_path / "a.gif")]) == 2
    assert "not both" in capsys.readouterr().err
    assert main(["render", "starter", "--path", "--workers", "0", "--out", str(tmp_path / "a.gif")]) == 2
    assert "at least 1" in capsys.readouterr().err
