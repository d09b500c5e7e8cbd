"""Recording the camera while a level is played, as a camera path that replays the same walk.

A :class:`systems.camera_path.CameraPath` is replayed as local moves at
perceived speed that portals turn (see :mod:`systems.route`), so the world
poses the camera went through are not the path: :class:`CameraRecorder`
turns each tick's world step into the path step that makes it, exactly as
:func:`systems.route.route` turns a leg between stops (:func:`systems.route.walk_leg`),
and a step that jumped through a portal (the camera teleported) is walked
through that portal. A keyframe is kept every :data:`INTERVAL` seconds of play
and at the end, its rotation the camera's turned into the path's frame.

The recorder only reads the scene's camera; the player (``aberrant play``,
:mod:`editor.player`) ticks it and saves what it returns with :func:`save_recording`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from components import Transform
from engine.atomic_files import read_regular, write_atomically
from engine.errors import AberrantError, shorten
from engine.keyframes import Keyframe
from engine.maths import quat_from_matrix, quat_to_matrix
from engine.scene import Scene
from engine.scene_file import SceneFileError, scene_from_document
from engine.scene_writer import dumps, keyframe_document
from systems.camera_movement import speed_boxes
from systems.portal_teleport import portal_links
from systems.route import walk_leg

#: Seconds of play between recorded keyframes.
INTERVAL = 0.25


class CameraRecorder:
    """Keyframes of the scene's camera from :meth:`start` to :meth:`stop`, in the path's own coordinates."""

    def __init__(self, scene: Scene, interval: float = INTERVAL) -> None:
        if scene.camera_entity is None:
            raise AberrantError("the scene has no camera to record")
        self.scene = scene
        self.interval = interval
        self.keyframes: list[Keyframe] = []
        self.recording = False
        self.time = 0.0
        self._boxes = speed_boxes(scene)
        self._links = portal_links(scene)
        self._frame = np.eye(3)
        self._world = np.zeros(3)
        self._path = np.zeros(3)

    def _camera(self) -> Transform:
        assert self.scene.camera_entity is not None
        return self.scene.get(self.scene.camera_entity, Transform)

    def _keep(self) -> None:
        rotation = quat_from_matrix(self._frame @ quat_to_matrix(self._camera().rotation))
        self.keyframes.append(
            Keyframe(self.time, tuple(float(c) for c in self._path), rotation=tuple(float(c) for c in rotation))
        )

    def start(self) -> None:
        """Begin a new recording at the camera's pose now (time 0)."""
        self.keyframes, self.recording, self.time = [], True, 0.0
        self._frame = np.eye(3)
        self._world = np.array(self._camera().position, dtype=np.float64)
        self._path = self._world.copy()
        self._keep()

    def update(self, dt: float) -> None:
        """After a tick of ``dt`` seconds: follow the camera's step, keeping a keyframe every :attr:`interval`."""
        if not self.recording or not dt > 0.0:
            return
        here = np.array(self._camera().position, dtype=np.float64)
        step, self._frame = self._leg(self._world, here)
        self._path = self._path + step
        self._world = here
        self.time += dt
        if self.time - self.keyframes[-1].time >= self.interval - 1e-9:
            self._keep()

    def _leg(self, start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The path step of one tick: through the portal it teleported by, if any (the one whose far side
        brings ``end`` nearer ``start``), else straight."""
        direct = float(np.linalg.norm(end - start))
        for link in self._links:
            inverse = np.linalg.inv(link.transfer)
            virtual = inverse[:3, :3] @ end + inverse[:3, 3]
            if float(np.linalg.norm(virtual - start)) < direct:
                leg = walk_leg(self._boxes, self._frame, start, end, link)
                if leg is not None:
                    return leg
        leg = walk_leg(self._boxes, self._frame, start, end)
        assert leg is not None  # a straight leg always exists
        return leg

    def stop(self) -> tuple[Keyframe, ...]:
        """End the recording: its keyframes (the last at the stop), or none when it lasted no time at all."""
        if self.recording and self.time > self.keyframes[-1].time:
            self._keep()
        self.recording = False
        return tuple(self.keyframes) if len(self.keyframes) >= 2 else ()


def save_recording(keyframes: Sequence[Keyframe], out: str | os.PathLike[str], template: Mapping[str, Any]) -> None:
    """Write the scene document ``template`` with ``keyframes`` as its ``camera_path`` to ``out``, atomically.

    The document is checked as a scene file is before anything is written, so a recording never leaves a
    file that does not open. Raises :class:`engine.scene_file.SceneFileError` naming ``out``.
    """
    file = shorten(out)
    doc = {**template, "camera_path": [keyframe_document(key) for key in keyframes]}
    try:
        scene_from_document(json.loads(json.dumps(doc)), file, Path(os.path.abspath(out)).parent).close()
    except SceneFileError as e:
        raise SceneFileError(file, f"cannot save the recording: {e.detail}", entity=e.entity, field=e.field) from None
    try:
        write_atomically({out: (dumps(doc) + "\n").encode("utf-8")})
    except OSError as e:
        raise SceneFileError(file, f"cannot save the recording ({e.strerror or e})") from None


def scene_file_document(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A scene file's JSON document as written (the template that saves a recording into that file)."""
    try:
        doc = json.loads(read_regular(path).decode("utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise SceneFileError(shorten(path), f"cannot read it to add the recording ({e})") from None
    if not isinstance(doc, dict):
        raise SceneFileError(shorten(path), "not a scene file: cannot add the recording")
    return doc


class RecordingSession:
    """What the player's record key does: start recording, then stop and save, each with a line to show.

    ``out`` is the scene file the path is saved into (``None``: recording is refused, saying how to enable
    it); ``template`` is the document it is saved with, else ``out``'s own document as it is on disk then.
    """

    def __init__(self, scene: Scene, out: Path | None, template: Mapping[str, Any] | None = None) -> None:
        self.recorder = CameraRecorder(scene)
        self.out = out
        self.template = template

    @property
    def recording(self) -> bool:
        return self.recorder.recording

    def status(self) -> str:
        """The overlay's reminder while recording."""
        return f"recording {self.recorder.time:4.1f} s" if self.recording else ""

    def toggle(self) -> str:
        """Start, or stop and save; the message says what happened (an error is a message too, not raised)."""
        if self.out is None:
            return "recording needs a scene file to save into: play a .json level or give --record FILE.json"
        if not self.recording:
            self.recorder.start()
            return f"recording the camera path (into {shorten(self.out)})"
        return self.finish()

    def finish(self) -> str:
        """Stop a recording in progress and save it ("" when none was)."""
        if not self.recording:
            return ""
        keys = self.recorder.stop()
        if not keys or self.out is None:
            return "recording too short: nothing saved"
        try:
            save_recording(keys, self.out, self.template or scene_file_document(self.out))
        except AberrantError as e:
            return f"not saved: {e}"
        return f"saved a camera path of {len(keys)} keyframes, {keys[-1].time:.1f} s, into {shorten(self.out)}"

    def update(self, dt: float) -> None:
        self.recorder.update(dt)

    def rebind(self, scene: Scene) -> str:
        """The level was reloaded as ``scene``: a recording in progress ends (and is saved) here."""
        message = self.finish()
        self.recorder = CameraRecorder(scene)
        return message
