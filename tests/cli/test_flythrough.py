"""Flythroughs: GIF, PNG folder and MP4 outputs, progress, atomic writes, paths from demos, the CLI."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

import aberrant.sinks as sinks
from aberrant.cli import main
from aberrant.flythrough import default_path, path_for, plan_frames, render_flythrough
from aberrant.levels import open_level
from aberrant.sinks import mp4_unavailable
from backends.base import create_backend
from components import Transform
from demos import build_demo
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


def test_a_level_may_define_its_camera_path(tmp_path):
    level_file = tmp_path / "level.py"
    level_file.write_text(
        "from demos import build_demo\n"
        "from systems.camera_path import CameraPath, Keyframe\n"
        "def build():\n    return build_demo('starter')\n"
        "def camera_path():\n"
        "    keys = [Keyframe(0, (0, 1, 5), look_at=(0, 1, 0)), Keyframe(2, (0, 1, 3), look_at=(0, 1, 0))]\n"
        "    return CameraPath(keys)\n"
    )
    with open_level(str(level_file)) as level:
        assert path_for(level).duration == 2.0
    with open_level("starter") as level:  # no camera_path(): a walk from the scene's camera
        default = path_for(level)
        np.testing.assert_allclose(default.positions[0], level.scene.get(level.scene.camera_entity, Transform).position)


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


def test_frame_count_comes_from_the_paths_duration_at_30_fps():
    path = CameraPath([Keyframe(0.0, (0, 1, 5), look_at=(0, 1, 0)), Keyframe(12.4, (0, 1, 3), look_at=(0, 1, 0))])
    assert plan_frames(path) == (372, 30.0)
    assert plan_frames(path, fps=10) == (124, 10)  # the fps changes how often the path is sampled
    assert plan_frames(path, duration=2.0) == (60, 30.0)  # the whole path, in two seconds
    assert plan_frames(path, duration=2.0, fps=5) == (10, 5)
    assert plan_frames(path, frames=32) == (32, 2.5)  # --frames wins; real-time playback
    assert plan_frames(path, frames=32, fps=8) == (32, 8)
    for bad in ({"fps": 0}, {"duration": -1.0}, {"duration": float("nan")}, {"frames": 0}):
        with pytest.raises(AberrantError):
            plan_frames(path, **bad)


def test_cli_samples_the_path_at_fps_for_its_duration(backend, tmp_path, capsys):
    out = tmp_path / "clip.gif"
    argv = ["render", "starter", "--path", "--duration", "0.5", "--fps", "8", "--size", "16x12"]
    code = main([*argv, "--backend", "reference", "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "path: 4.0 s, 4 frames at 8 fps" in captured.out  # the starter's default walk lasts 4 s
    with Image.open(out) as gif:
        assert gif.n_frames == 4
        assert abs(gif.info["duration"] - 125) <= 10  # 1/8 s (GIF keeps centiseconds)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--frames", "3"], "add --path"),
        (["--duration", "3"], "add --path"),
        (["--path", "--duration", "0"], "positive number of seconds"),
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


def _long_walk(scene) -> CameraPath:
    """A walk of 40 m: the floating origin (16 m cells) moves twice on the way."""
    pose = scene.get(scene.camera_entity, Transform)
    end = tuple(np.array(pose.position) + np.array([3.0, 0.0, 40.0]))
    return CameraPath([Keyframe(0.0, pose.position, pose.rotation), Keyframe(2.0, end, pose.rotation)])


@pytest.mark.parametrize("name", ["reference", "glsl", "opencl"])
def test_frames_from_recorded_poses_in_any_order_match_the_tick_loop(backend_factory, name):
    """What a distributed run relies on: a frame from its recorded pose has the pixels of the walk's own tick."""
    from aberrant.flythrough import PoseRenderer, simulate_path
    from systems.app import App

    backend = backend_factory(name)
    scene = build_demo("starter")
    try:
        path = _long_walk(scene)
        ticked, origins, positions = [], [], []
        path.place_camera(scene)
        with App(scene, backend, size=SIZE, aovs=("color",)) as app:
            for index in range(6):
                if index == 1:
                    app.input_source = path.inputs(scene)
                ticked.append(app.tick(path.duration / 5 if index else 0.0).color[..., :3].copy())
                positions.append(np.array(scene.get(scene.camera_entity, Transform).position))
                origins.append(app.packed.origin.copy())
        # The origin moves on the way, and not always to the cell a fresh upload would pick (hysteresis).
        assert len({tuple(o) for o in origins}) >= 2
        assert any(not np.array_equal(o, np.round(p / 16.0) * 16.0) for o, p in zip(origins, positions, strict=True))
        poses = simulate_path(scene, path, 6)
        with PoseRenderer(scene, backend, poses, SIZE) as renderer:
            for index in (3, 5, 0, 4, 1, 2, 2):
                assert np.array_equal(renderer.render(index), ticked[index]), index
                assert np.array_equal(renderer.app.packed.origin, origins[index]), index
    finally:
        scene.close()
