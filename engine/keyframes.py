"""Camera keyframes as data: what a camera path is made of, checked where both scene files and paths need it.

A scene file's ``camera_path`` section and :class:`systems.camera_path.CameraPath`
hold the same keyframes; the engine reads and writes them, the systems
interpolate and replay them. :func:`checked_keyframes` is the one validation
both use, so a bad keyframe fails the same way whether it came from a file or
from code.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from engine.errors import AberrantError
from engine.maths import look_at_quat


class CameraPathError(AberrantError, ValueError):
    """A camera path is invalid; the message names the keyframe index and field."""

    def __init__(self, message: str, *, index: int | None = None, field: str | None = None) -> None:
        where = [] if index is None else [f"keyframe {index}"]
        if field is not None:
            where.append(f"field {field!r}")
        super().__init__(", ".join(where) + f": {message}" if where else message)
        self.index, self.field, self.detail = index, field, message


@dataclass(frozen=True)
class Keyframe:
    """Where the camera is at ``time`` (seconds): a position and a rotation (x, y, z, w) *or* a point to look at."""

    time: float
    position: Sequence[float]
    rotation: Sequence[float] | None = None
    look_at: Sequence[float] | None = None


def _vector(value: Sequence[float], n: int, index: int, field: str) -> np.ndarray:
    try:  # a Keyframe is built by callers: its fields may hold anything
        items = [float(c) for c in value]
    except (TypeError, ValueError):
        raise CameraPathError(f"expected {n} numbers, got {value!r}", index=index, field=field) from None
    if len(items) != n or not all(math.isfinite(c) for c in items):
        raise CameraPathError(f"expected {n} finite numbers, got {value!r}", index=index, field=field)
    return np.array(items)


def checked_keyframes(keyframes: Sequence[object]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times, positions and unit quaternions (each in the hemisphere of the one before) of valid keyframes.

    At least two keyframes, times finite and strictly increasing, exactly one
    of ``rotation`` (unit quaternion) or ``look_at`` (a point other than the
    position); anything else raises :class:`CameraPathError` naming the keyframe and field.
    """
    keyframes = list(keyframes)
    if len(keyframes) < 2:
        raise CameraPathError(f"a camera path needs at least 2 keyframes, got {len(keyframes)}")
    times: list[float] = []
    positions: list[np.ndarray] = []
    quats: list[np.ndarray] = []
    for i, key in enumerate(keyframes):
        if not isinstance(key, Keyframe):
            raise CameraPathError(f"expected a Keyframe, got {type(key).__name__}", index=i)
        try:
            t = float(key.time)
        except (TypeError, ValueError):
            raise CameraPathError(f"expected a number, got {key.time!r}", index=i, field="time") from None
        if not math.isfinite(t):
            raise CameraPathError(f"must be finite, got {t}", index=i, field="time")
        if times and t <= times[-1]:
            raise CameraPathError(f"times must increase strictly, got {t} after {times[-1]}", index=i, field="time")
        position = _vector(key.position, 3, i, "position")
        if (key.rotation is None) == (key.look_at is None):
            raise CameraPathError("give exactly one of rotation or look_at", index=i, field="rotation")
        if key.rotation is not None:
            q = _vector(key.rotation, 4, i, "rotation")
            length = float(np.linalg.norm(q))
            if abs(length - 1.0) > 1e-4:
                raise CameraPathError(
                    f"quaternion (x, y, z, w) must have unit length, got length {length:.6g}", index=i, field="rotation"
                )
            q = q / length
        else:
            assert key.look_at is not None  # exactly one of rotation and look_at, checked above
            target = _vector(key.look_at, 3, i, "look_at")
            if float(np.linalg.norm(target - position)) < 1e-12:
                raise CameraPathError("the point looked at equals the position", index=i, field="look_at")
            q = look_at_quat(position, target)
        if quats and float(np.dot(q, quats[-1])) < 0.0:
            q = -q  # same rotation, nearer hemisphere: interpolate the short way
        times.append(t)
        positions.append(position)
        quats.append(q)
    return np.array(times), np.array(positions), np.array(quats)
