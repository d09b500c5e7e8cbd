"""Flythroughs: a camera path walked by the real systems, one rendered frame per tick, to a video or PNGs.

The first frame shows the path's start; each later tick advances the path by
``duration / (frames - 1)`` seconds through :class:`systems.camera_path.PathInput`
(so aberrations scale the motion and portals teleport the camera) and renders.
The command line takes 30 frames per second of the clip, and the clip is as
long as the path unless ``--duration`` says otherwise (:func:`plan_frames`).
Outputs (:mod:`aberrant.sinks`): ``.mp4`` (H.264, yuv420p, through imageio-ffmpeg; odd sizes are padded
to even by repeating the last row/column), ``.gif`` (Pillow, looping; identical
consecutive frames are merged by Pillow, their time kept), or a folder of
``frame_0000.png``... Everything is written to a temporary sibling first and
renamed at the end, so an interrupted or failed run leaves no partial output.

Where a path comes from: a level module's (or demo's) optional ``camera_path()``
or a scene file's ``camera_path`` keyframes; otherwise :func:`default_path`,
a slow walk forward from the scene's camera that turns its head a little left
and back. A demo's path, for example::

    def camera_path() -> CameraPath:
        return CameraPath([
            Keyframe(0.0, (0.0, 1.6, 6.0), look_at=(0.0, 1.0, 0.0)),
            Keyframe(4.0, (3.0, 1.6, 2.0), look_at=(0.0, 1.0, 0.0)),
        ])
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

import numpy as np

from aberrant.progress import Progress
from aberrant.sinks import Sink, check_fps, check_gif_memory, check_output
from backends.base import Backend
from backends.samples import check_spp
from components import Camera, Transform
from engine.errors import AberrantError
from engine.input import NoInput
from engine.maths import quat_from_axis_angle, quat_multiply, quat_to_matrix
from engine.scene import Scene
from systems.app import App
from systems.camera_path import CameraPath, Keyframe

if TYPE_CHECKING:
    from aberrant.levels import Level

__all__ = [
    "PoseRenderer",
    "check_output",
    "default_path",
    "path_for",
    "plan_frames",
    "render_flythrough",
    "simulate_path",
]

#: Length of the default path (seconds) and its walking pace (fraction of the camera's speed).
DEFAULT_DURATION = 4.0
DEFAULT_PACE = 0.3
#: How far the default path turns its head (degrees).
DEFAULT_GLANCE_DEG = 15.0
#: Frames per second of a flythrough when neither ``--fps`` nor ``--frames`` is given.
DEFAULT_FPS = 30.0


def plan_frames(
    path: CameraPath, *, fps: float | None = None, frames: int | None = None, duration: float | None = None
) -> tuple[int, float]:
    """``(frames, fps)`` of a flythrough of ``path``: ``fps`` (default 30) samples of each second of the clip.

    The clip lasts ``duration`` seconds (default: the path's own), so the path
    is walked at ``path.duration / duration`` times its speed. ``frames``, when
    given, wins; its fps then defaults to real time (see :func:`render_flythrough`).
    """
    if fps is not None:
        check_fps(fps)
    if duration is not None and not (math.isfinite(duration) and duration > 0.0):
        raise AberrantError(f"--duration must be a positive number of seconds, got {duration}")
    seconds = path.duration if duration is None else duration
    if frames is None:
        fps = DEFAULT_FPS if fps is None else fps
        return max(2, round(seconds * fps)), fps
    if frames < 1:
        raise AberrantError(f"--frames must be at least 1, got {frames}")
    if fps is None:  # the given frames spread over the clip's seconds
        fps = min(max((frames - 1) / seconds, 1.0), 60.0) if frames > 1 else 1.0
    return frames, fps


def render_flythrough(
    scene: Scene,
    backend: Backend,
    path: CameraPath,
    frames: int,
    size: Sequence[int],
    out: str | os.PathLike[str],
    *,
    fps: float | None = None,
    progress: TextIO | bool = True,
    on_frame: Callable[[int, App], None] | None = None,
    spp: int = 1,
) -> int:
    """Walk ``path`` through ``scene`` with the real systems, rendering ``frames`` frames to ``out``.

    ``fps`` (playback) defaults to real time, ``(frames - 1) / path.duration``
    (within [1, 60]); :func:`plan_frames` chooses both from a frame rate.
    ``progress``: True for a bar on stderr, False for none, or a stream.
    ``on_frame(index, app)`` runs after each tick (tests, overlays). The
    scene's camera is moved (it ends where the walk ends). ``spp``: samples a pixel of every frame.
    Returns the frames written.
    """
    frames, fps = plan_frames(path, fps=fps, frames=frames)
    out_path = Path(out)
    kind = check_output(out_path)
    check_fps(fps)
    if kind == "gif":
        check_gif_memory(frames, (int(size[0]), int(size[1])))
    poses = simulate_path(scene, path, frames)
    sink = Sink(out_path, kind, fps)
    bar = progress_bar(progress, frames)
    try:
        with PoseRenderer(scene, backend, poses, size, spp=spp) as renderer:
            for index in range(frames):
                rgb = renderer.render(index)
                if on_frame is not None:
                    on_frame(index, renderer.app)
                sink.add(rgb)
                if bar is not None:
                    bar.step()
        sink.commit()
    except BaseException:
        sink.discard()
        raise
    finally:
        if bar is not None:
            bar.finish()
    return frames


def progress_bar(progress: TextIO | bool, frames: int) -> Progress | None:
    """The flythrough's bar: on stderr for True, none for False, else on the stream given."""
    stream = sys.stderr if progress is True else (progress or None)
    return None if stream is None else Progress(frames, stream, interval_s=2.0, label="flythrough", unit="frames")


def simulate_path(scene: Scene, path: CameraPath, frames: int) -> list[Transform]:
    """The camera's pose at each of ``frames`` frames: ``path`` walked once by the movement and teleport systems.

    Frame 0 is the path's start; each later tick advances the walk by ``duration / (frames - 1)``
    seconds (aberrations scale the steps, portals teleport the camera). Rendering needs nothing
    else from the walk, so the frames can then be rendered in any order, anywhere. The scene's
    camera is left where the walk ends.
    """
    if scene.camera_entity is None:
        raise AberrantError("the scene has no camera to fly")
    dt = path.duration / (frames - 1) if frames > 1 else 0.0
    path.place_camera(scene)
    walker = path.inputs(scene)
    poses: list[Transform] = []
    with App(scene, None, input_source=NoInput()) as app:
        for index in range(frames):
            if index == 1:
                app.input_source = walker
            app.tick(dt if index else 0.0)
            poses.append(scene.get(scene.camera_entity, Transform))
    return poses


class PoseRenderer:
    """Renders frames of a scene from recorded camera poses through the tick loop's upload and render systems.

    The tables a float32 backend traces are relative to a floating origin that follows the camera
    with hysteresis, so they depend on every pose before the frame, not only its own. Frame ``i``
    is therefore rendered after the uploader has followed poses ``0..i`` (without rendering them),
    which makes its pixels those of a run that rendered every frame in order, whatever order the
    frames are asked for in.
    """

    def __init__(
        self, scene: Scene, backend: Backend, poses: Sequence[Transform], size: Sequence[int], *, spp: int = 1
    ) -> None:
        if scene.camera_entity is None:
            raise AberrantError("the scene has no camera to fly")
        self.scene, self.backend, self.poses, self.size = scene, backend, list(poses), size
        self.spp = check_spp(spp)
        self.camera = scene.camera_entity
        self.app = self._new_app()
        self.followed = -1  # the last pose the uploader has followed

    def _new_app(self) -> App:
        return App(self.scene, self.backend, size=self.size, aovs=("color",), input_source=NoInput(), spp=self.spp)

    def render(self, index: int) -> np.ndarray:
        """Frame ``index`` as (H, W, 3) uint8 RGB."""
        if not 0 <= index < len(self.poses):
            raise AberrantError(f"frame {index} is not in this flythrough's {len(self.poses)} frames")
        if index < self.followed:  # an earlier frame: start again from the first pose
            self.app.close()
            self.app = self._new_app()
            self.followed = -1
        upload = self.app.upload
        assert upload is not None
        for earlier in range(self.followed + 1, index):
            upload.uploader.sync(self.scene, np.asarray(self.poses[earlier].position, dtype=np.float64))
        self.scene.set(self.camera, self.poses[index])
        frame = self.app.tick(0.0)
        self.followed = index
        assert frame is not None
        return np.ascontiguousarray(frame.aov("color")[..., :3])

    def close(self) -> None:
        self.app.close()

    def __enter__(self) -> PoseRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def default_path(scene: Scene, duration: float = DEFAULT_DURATION) -> CameraPath:
    """A slow walk forward from the scene's camera (half its speed), glancing left and back."""
    if scene.camera_entity is None:
        raise AberrantError("the scene has no camera to start a flythrough from")
    transform = scene.get(scene.camera_entity, Transform)
    camera = scene.get(scene.camera_entity, Camera)
    m = quat_to_matrix(transform.rotation)
    forward = -m[:, 2]
    flat = np.array([forward[0], 0.0, forward[2]])
    if np.linalg.norm(flat) < 1e-6:  # looking straight up or down: walk towards the top of the picture
        flat = np.array([m[0, 1], 0.0, m[2, 1]]) * (1.0 if forward[1] < 0 else -1.0)
    flat = flat / np.linalg.norm(flat)
    distance = camera.speed * DEFAULT_PACE * duration
    start = np.asarray(transform.position, dtype=np.float64)
    keys = []
    for fraction, glance in ((0.0, 0.0), (0.5, DEFAULT_GLANCE_DEG), (1.0, 0.0)):
        turn = quat_from_axis_angle((0.0, 1.0, 0.0), math.radians(glance))
        rotation = tuple(float(c) for c in quat_multiply(turn, transform.rotation))
        keys.append(Keyframe(fraction * duration, tuple(start + fraction * distance * flat), rotation=rotation))
    return CameraPath(keys)


def path_for(level: Level) -> CameraPath:
    """The level's own camera path (its ``camera_path()`` or its file's keyframes), else :func:`default_path`."""
    path = level.camera_path()
    return path if path is not None else default_path(level.scene)
