"""Small mutable records the systems of one tick share with each other and with the app.

They are handed to the processors' ``__init__`` (dependencies are explicit),
so the app, the editor and tests read them without reaching into esper.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from backends.base import Frame
from engine.packed import TableUpdate


@dataclass
class MotionRecord:
    """The camera's path this tick: movement writes it, portal teleport tests and extends it.

    ``path`` is the polyline the camera walked (start, one point per
    aberration-face sub-step, end), in world space; empty when the camera did
    not move. ``crossings`` lists ``(portal, target)`` entity pairs the camera
    was teleported through this tick, in order.
    """

    path: list[np.ndarray] = field(default_factory=list)
    crossings: list[tuple[int, int]] = field(default_factory=list)
    tick: int = 0

    def begin_tick(self) -> None:
        """Forget the previous tick (a camera that does not move leaves an empty path)."""
        self.path = []
        self.crossings = []
        self.tick += 1

    @property
    def moved(self) -> bool:
        return len(self.path) >= 2


@dataclass
class UploadStats:
    """What the GPU upload system sent this tick (and in total), for tests and the editor's overlay."""

    bytes: int = 0
    updates: list[TableUpdate] = field(default_factory=list)
    total_bytes: int = 0
    uploads: int = 0


@dataclass
class FrameSlot:
    """Where the render system leaves the latest frame."""

    frame: Frame | None = None
    frames: int = 0
