"""Play mode: run the real systems on a throwaway copy of the edited scene.

Starting play writes the edited scene to JSON (the same text a save writes)
and loads that text as a separate scene with its own esper world; an
:class:`systems.app.App` runs camera movement, portal teleport, upload and
render on the copy with keyboard and mouse input. Stopping discards the
copy. The edited scene is never touched, so a save after Stop is byte for
byte the save before Play.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from backends.base import Backend, Frame
from engine.camera_view import CameraView, scene_camera
from engine.errors import AberrantError, shorten
from engine.input import NO_INPUT, InputState
from engine.scene import Scene
from engine.scene_file import scene_from_text, scene_to_json
from systems.app import App

#: Degrees turned per pixel of mouse movement.
MOUSE_SENSITIVITY = 0.15


class LiveInput:
    """Play mode's input source: the editor stores each frame's keys here, the movement system polls them."""

    def __init__(self) -> None:
        self.state: InputState = NO_INPUT

    def poll(self, dt: float) -> InputState:
        return self.state


@dataclass(frozen=True)
class Keys:
    """Which movement keys are held this frame (WASD, up/down, Shift) and how far the mouse moved (pixels)."""

    forward: bool = False
    back: bool = False
    left: bool = False
    right: bool = False
    up: bool = False
    down: bool = False
    sprint: bool = False
    mouse_dx: float = 0.0
    mouse_dy: float = 0.0


def input_state(keys: Keys, sensitivity: float = MOUSE_SENSITIVITY) -> InputState:
    """The movement system's input for held keys: local -z forward, +x right, +y up; mouse right turns right."""
    move = (
        float(keys.right) - float(keys.left),
        float(keys.up) - float(keys.down),
        float(keys.back) - float(keys.forward),
    )
    dx = keys.mouse_dx if math.isfinite(keys.mouse_dx) else 0.0
    dy = keys.mouse_dy if math.isfinite(keys.mouse_dy) else 0.0
    return InputState(move=move, look=(-dx * sensitivity, -dy * sensitivity), sprint=keys.sprint)


def scene_copy(scene: Scene) -> Scene:
    """A separate scene built from the JSON text of ``scene``; an error names the edited scene.

    Asset paths are written relative to the filesystem root, so they read back
    as the same absolute files without a temporary file to name in messages.
    """
    root = Path(os.path.abspath(os.sep))
    return scene_from_text(scene_to_json(scene, root), f"scene {shorten(scene.name)!r}", root)


class PlaySession:
    """One run of play mode; :meth:`stop` throws the played copy away."""

    def __init__(
        self,
        edited: Scene,
        backend: Backend | None,
        size: Sequence[int] = (640, 480),
        aovs: Sequence[str] = ("color",),
    ) -> None:
        edited.validate()  # no camera, a broken portal link: say so before anything runs
        self.scene = scene_copy(edited)
        self.input = LiveInput()
        self.error: str | None = None
        self.elapsed = 0.0
        try:
            #: The tick loop that plays the copy (movement, teleport, upload, render).
            self.runner = App(self.scene, backend, size=size, aovs=aovs, input_source=self.input)
        except BaseException:
            self.scene.close()
            raise
        edited.activate()

    @property
    def backend(self) -> Backend | None:
        return self.runner.backend

    @property
    def ticks(self) -> int:
        return self.runner.ticks

    def resize(self, size: Sequence[int]) -> None:
        if self.runner.backend is not None and tuple(size) != self.runner.size:
            self.runner.size = size

    def step(self, dt: float, state: InputState = NO_INPUT) -> Frame | None:
        """One tick with this frame's input; a backend that fails leaves movement running without renders."""
        self.input.state = state
        self.elapsed += dt
        try:
            return self.runner.tick(dt)
        except AberrantError as e:
            if self.runner.backend is None:
                raise
            self.error = f"{e} (play continues without the tracer: preview only)"
            self._drop_backend()
            return None

    def _drop_backend(self) -> None:
        """Keep playing with movement and teleport only (the camera pose lives in the scene, so nothing jumps)."""
        ticks = self.runner.ticks
        self.runner.close()
        self.runner = App(self.scene, None, input_source=self.input)
        self.runner.ticks = ticks

    @property
    def camera_view(self) -> CameraView:
        """Where the played camera is now."""
        return scene_camera(self.scene)

    def stop(self) -> None:
        """Discard the played copy (idempotent)."""
        self.runner.close()
        self.scene.close()
