"""Flythroughs: GIF, PNG folder and MP4 outputs, progress, atomic writes, paths from demos, the CLI."""

from __future__ import annotations

import io
import sys
import types

import numpy as np
import pytest
from PIL import Image

import aberrant.sinks as sinks
from aberrant.cli import main
from aberrant.flythrough import default_path, path_for, render_flythrough
from aberrant.sinks import mp4_unavailable
from backends.base import create_backend
from components import Transform
from demos import DEMOS, build_demo
from engine.errors import AberrantError
from systems.camera_path import CameraPath, Keyframe

SIZE = (48, 36)


@pytest.fixture(scope="module")
def backend():
    from conftest import require_backend

    require_backend("reference")
    b = create_backend("reference")
    yield b
    b.release()


def fly(backend, out, frames=6, size=SIZE, **kwargs):
    scene = build_demo("starter")
    try:
        return render_flythrough(scene, backend, default_path(scene), frames, size, out, progress=False, **kwargs)
    finally:
        scene.close()


def test_gif_has_one_frame_per_tick_and_loops(backend, tmp_path):
    out = tmp_path / "clip.gif"
    assert fly(backend, out) == 6
    with Image.open(out) as gif:
        assert gif.n_frames == 6
        assert gif.size == SIZE
        assert gif.info.get("loop") == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.gif"]  # no temporary left


def test_png_folder_has_numbered_frames(backend, tmp_path):
    out = tmp_path / "frames"
    fly(backend, out)
    names = sorted(p.name for p in out.iterdir())
    assert names == [f"frame_{i:04d}.png" for i in range(6)]
    with Image.open(out / "frame_0000.png") as first, Image.open(out / "frame_0005.png") as last:
        assert first.size == SIZE
        assert not np.array_equal(np.asarray(first), np.asarray(last))  # the camera moved
    fly(backend, out, frames=3)  # an earlier run's frames are replaced, not mixed
    assert sorted(p.name for p in out.iterdir()) == [f"frame_{i:04d}.png" for i in range(3)]


def test_mp4_is_h264_yuv420p_with_even_sides(backend, tmp_path):
    reason = mp4_unavailable()
    if reason is not None:
        pytest.skip(f"cannot write .mp4 here: {reason}")
    import imageio_ffmpeg

    out = tmp_path / "clip.mp4"
    fly(backend, out, size=(49, 37))
    reader = imageio_ffmpeg.read_frames(str(out))
    meta = reader.__next__()
    assert meta["codec"] == "h264"
    assert meta["pix_fmt"].startswith("yuv420p")
    assert meta["size"] == (50, 38)
    assert sum(1 for _ in reader) == 6


def test_the_first_frame_is_the_path_start_and_the_camera_ends_at_its_end(backend, tmp_path):
    scene = build_demo("starter")
    positions = []
    try:
        path = default_path(scene)
        start = np.array(scene.get(scene.camera_entity, Transform).position)
        render_flythrough(
            scene, backend, path, 5, SIZE, tmp_path / "f.gif", progress=False,
            on_frame=lambda i, app: positions.append(app.scene.get(app.scene.camera_entity, Transform).position),
        )  # fmt: skip
        np.testing.assert_allclose(positions[0], start, atol=1e-12)
        np.testing.assert_allclose(positions[-1], path.positions[-1], atol=1e-9)
    finally:
        scene.close()


@pytest.mark.parametrize("name", ["clip.gif", "frames", "clip.mp4"])
def test_an_interrupted_flythrough_leaves_nothing(backend, tmp_path, monkeypatch, name):
    if name.endswith(".mp4") and mp4_unavailable() is not None:
        pytest.skip(f"cannot write .mp4 here: {mp4_unavailable()}")
    real_add = sinks.Sink.add

    def add(self, rgb):
        if self.count == 3:
            raise KeyboardInterrupt
        real_add(self, rgb)

    monkeypatch.setattr(sinks.Sink, "add", add)
    with pytest.raises(KeyboardInterrupt):
        fly(backend, tmp_path / name)
    assert list(tmp_path.iterdir()) == []


def test_an_interrupted_run_keeps_the_old_output(backend, tmp_path, monkeypatch):
    out = tmp_path / "clip.gif"
    out.write_bytes(b"old")
    monkeypatch.setattr(sinks.Sink, "commit", lambda self: (_ for _ in ()).throw(RuntimeError("disk full")))
    with pytest.raises(RuntimeError):
        fly(backend, out)
    assert out.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["clip.gif"]


def test_progress_shows_frames_fps_and_time_left(backend, tmp_path):
    stream = io.StringIO()
    scene = build_demo("starter")
    try:
        render_flythrough(scene, backend, default_path(scene), 3, SIZE, tmp_path / "a.gif", progress=stream)
    finally:
        scene.close()
    text = stream.getvalue()  # not a terminal: whole lines, the last at completion
    assert text.endswith("\n")
    assert "3/3 frames" in text and "frames/s" in text and "ETA" in text


def test_bad_outputs_fail_before_rendering(backend, tmp_path):
    with pytest.raises(AberrantError, match=r"\.mp4, \.gif or a folder"):
        fly(backend, tmp_path / "clip.png")
    with pytest.raises(AberrantError, match="does not exist"):
        fly(backend, tmp_path / "missing" / "clip.gif")
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "notes.txt").write_text("mine")
    with pytest.raises(AberrantError, match="holds other files"):
        fly(backend, tmp_path / "busy")
    with pytest.raises(AberrantError, match="at least 1"):
        fly(backend, tmp_path / "a.gif", frames=0)


def test_a_demo_may_define_its_camera_path(monkeypatch):
    module = types.ModuleType("fake_demo_with_path")
    module.build = lambda: build_demo("starter")
    module.camera_path = lambda: CameraPath(
        [Keyframe(0, (0, 1, 5), look_at=(0, 1, 0)), Keyframe(2, (0, 1, 3), look_at=(0, 1, 0))]
    )
    monkeypatch.setitem(sys.modules, "fake_demo_with_path", module)
    monkeypatch.setitem(DEMOS, "fake", "fake_demo_with_path")
    scene = build_demo("starter")
    try:
        assert path_for("fake", scene).duration == 2.0
        default = path_for("starter", scene)  # no camera_path(): a walk from the scene's camera
        np.testing.assert_allclose(default.positions[0], scene.get(scene.camera_entity, Transform).position)
    finally:
        scene.close()


# --- the command line ------------------------------------------------------------------------


def test_cli_renders_a_flythrough(backend, tmp_path, capsys):
    out = tmp_path / "clip.gif"
    code = main(["render", "starter", "--path", "--frames", "3", "--size", "32x24", "--backend", "reference",
                 "--out", str(out)])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "3/3 frames" in captured.err
    assert f"wrote {out}" in captured.out
    with Image.open(out) as gif:
        assert gif.n_frames == 3


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--frames", "3"], "add --path"),
        (["--path", "--frames", "0"], "at least 1"),
        (["--path", "--aovs", "x.npz"], "cannot be combined"),
        (["--path", "--out", "clip.png"], ".gif or a folder"),
    ],
)
def test_cli_flythrough_errors_are_one_line(backend, tmp_path, capsys, monkeypatch, extra, message):
    monkeypatch.chdir(tmp_path)
    code = main(["render", "starter", "--size", "32x24", "--backend", "reference", *extra])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []
