"""Camera paths as code: keyframes, smooth interpolation, and input that drives the real systems.

Interpolation is C1 in *time*, so a flythrough has no velocity jumps at keyframes:

* positions: a cubic Hermite spline whose tangents are those of Catmull–Rom
  with the keyframe times as knots (the derivative of the parabola through
  each keyframe and its neighbours; the chord slope at the ends), so two
  keyframes give a straight line at constant speed;
* orientations: the cumulative quaternion Hermite curve of Kim, Kim & Shin
  (1995) with angular velocities chosen the same way, so two keyframes give
  exactly a slerp and every sample is a unit quaternion.

A path does not place the camera frame by frame: :meth:`CameraPath.inputs`
returns an :class:`engine.input.InputSource` that turns each tick's step
along the path into what a player would do: yaw/pitch look deltas and a move
in the camera's own frame. The camera movement system then walks it through
the aberrations (which scale the step) and the portal system teleports it, and
after a teleport the path carries on *relative to the camera*: a path is a
sequence of local moves, exactly like a recorded walk. In plain space the
camera follows the path to its end. The movement system normalises the move
direction, so each tick's input carries the speed override
``InputState.speed = (path step) / dt``; the Camera component is never edited.

The system's camera has no roll and keeps pitch within ±89°, so the path is
followed by the yaw/pitch part of its orientations (roll is dropped).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from components import Transform
from engine.errors import AberrantError
from engine.input import NO_INPUT, InputState
from engine.keyframes import CameraPathError, Keyframe, checked_keyframes
from engine.maths import quat_conjugate, quat_from_axis_angle, quat_multiply, quat_to_matrix
from engine.scene import Scene
from systems.camera_movement import PITCH_LIMIT_DEG

Vec3 = tuple[float, float, float]

__all__ = ["CameraPath", "CameraPathError", "Keyframe", "PathInput", "yaw_pitch", "yaw_pitch_quat"]


def quat_exp(rotvec: np.ndarray) -> np.ndarray:
    """The unit quaternion of a rotation vector (axis × angle in radians)."""
    angle = float(np.linalg.norm(rotvec))
    if angle < 1e-12:
        return quat_normalize_safe(np.array([0.5 * rotvec[0], 0.5 * rotvec[1], 0.5 * rotvec[2], 1.0]))
    return quat_from_axis_angle(rotvec / angle, angle)


def quat_log(q: np.ndarray) -> np.ndarray:
    """The rotation vector (angle ≤ π) of a unit quaternion."""
    q = q if q[3] >= 0.0 else -q
    s = float(np.linalg.norm(q[:3]))
    if s < 1e-12:
        return 2.0 * q[:3]
    return q[:3] / s * (2.0 * math.atan2(s, q[3]))


def quat_normalize_safe(q: np.ndarray) -> np.ndarray:
    return q / float(np.linalg.norm(q))


def yaw_pitch(q: np.ndarray) -> tuple[float, float]:
    """Yaw (about world +Y, 0 = looking along -Z) and pitch of a rotation, in degrees; pitch within ±89°."""
    m = quat_to_matrix(q)
    forward, up = -m[:, 2], m[:, 1]
    pitch = math.degrees(math.asin(min(max(float(forward[1]), -1.0), 1.0)))
    heading = forward if math.hypot(forward[0], forward[2]) > 1e-6 else -math.copysign(1.0, forward[1]) * up
    yaw = math.degrees(math.atan2(-heading[0], -heading[2]))
    return yaw, min(max(pitch, -PITCH_LIMIT_DEG), PITCH_LIMIT_DEG)


def yaw_pitch_quat(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """The unrolled camera rotation ``Ry(yaw) · Rx(pitch)`` (what mouse look produces)."""
    qy = quat_from_axis_angle((0.0, 1.0, 0.0), math.radians(yaw_deg))
    return quat_multiply(qy, quat_from_axis_angle((1.0, 0.0, 0.0), math.radians(pitch_deg)))


def _tangents(times: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """Per-keyframe derivatives: time-weighted means of the neighbouring segment rates (chord at the ends).

    This is the slope at ``t_i`` of the parabola through keyframes i-1, i, i+1
    (Catmull–Rom with the keyframe times as knots).
    """
    out = np.empty((len(times), rates.shape[1]))
    out[0], out[-1] = rates[0], rates[-1]
    h = np.diff(times)
    for i in range(1, len(times) - 1):
        out[i] = (rates[i - 1] * h[i] + rates[i] * h[i - 1]) / (h[i - 1] + h[i])
    return out


class CameraPath:
    """A smooth, C1 camera path through keyframes (at least two, times strictly increasing)."""

    def __init__(self, keyframes: Sequence[Keyframe]) -> None:
        keyframes = list(keyframes)
        self.times, self.positions, self.quats = checked_keyframes(keyframes)
        self.keyframes = keyframes
        h = np.diff(self.times)
        self.velocities = _tangents(self.times, np.diff(self.positions, axis=0) / h[:, None])
        turns = np.array([quat_log(quat_multiply(quat_conjugate(a), b)) for a, b in itertools.pairwise(self.quats)])
        self.angular = _tangents(self.times, turns / h[:, None])

    @property
    def start(self) -> float:
        return float(self.times[0])

    @property
    def end(self) -> float:
        return float(self.times[-1])

    @property
    def duration(self) -> float:
        return self.end - self.start

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Position and unit quaternion at time ``t`` (clamped to the path's span)."""
        t = min(max(float(t), self.start), self.end)
        i = min(int(np.searchsorted(self.times, t, side="right")) - 1, len(self.times) - 2)
        h = float(self.times[i + 1] - self.times[i])
        u = (t - float(self.times[i])) / h
        if u <= 0.0:
            return self.positions[i].copy(), self.quats[i].copy()
        if u >= 1.0:
            return self.positions[i + 1].copy(), self.quats[i + 1].copy()
        u2, u3 = u * u, u * u * u
        p0, p1 = self.positions[i], self.positions[i + 1]
        m0, m1 = self.velocities[i] * h, self.velocities[i + 1] * h
        position = (2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * m0 + (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * m1
        # Cumulative Bézier form of the Hermite segment (Kim, Kim & Shin): q0 · Π exp(ω_j β̃_j(u)).
        q0, q3 = self.quats[i], self.quats[i + 1]
        a, c = self.angular[i] * h / 3.0, self.angular[i + 1] * h / 3.0
        q1 = quat_multiply(q0, quat_exp(a))
        q2 = quat_multiply(q3, quat_exp(-c))
        b = quat_log(quat_multiply(quat_conjugate(q1), q2))
        betas = (1.0 - (1.0 - u) ** 3, 3 * u2 - 2 * u3, u3)
        q = q0
        for omega, beta in zip((a, b, c), betas, strict=True):
            q = quat_multiply(q, quat_exp(omega * beta))
        q = quat_normalize_safe(q)
        return position, (q if float(np.dot(q, q0)) >= 0.0 else -q)

    def control_pose(self, t: float) -> tuple[np.ndarray, float, float]:
        """Position, yaw and pitch at ``t``: the pose the movement system can reproduce."""
        position, q = self.sample(t)
        yaw, pitch = yaw_pitch(q)
        return position, yaw, pitch

    def place_camera(self, scene: Scene) -> None:
        """Put the scene's camera at the path's start (yaw/pitch part of its rotation)."""
        if scene.camera_entity is None:
            raise AberrantError("the scene has no camera to fly")
        position, yaw, pitch = self.control_pose(self.start)
        old = scene.get(scene.camera_entity, Transform)
        rotation = tuple(float(c) for c in yaw_pitch_quat(yaw, pitch))
        scene.set(scene.camera_entity, Transform(tuple(float(c) for c in position), rotation, old.scale))

    def inputs(self, scene: Scene, *, rate: float = 1.0) -> PathInput:
        """An input source that walks this path through the real systems (``rate``: path seconds per second)."""
        return PathInput(self, scene, rate=rate)


class PathInput:
    """Replays a :class:`CameraPath` as per-tick local moves and look deltas (see the module docstring)."""

    def __init__(self, path: CameraPath, scene: Scene, *, rate: float = 1.0) -> None:
        if not (math.isfinite(rate) and rate > 0.0):
            raise AberrantError(f"path playback rate must be a positive number, got {rate}")
        if scene.camera_entity is None:
            raise AberrantError("the scene has no camera to fly")
        self.path = path
        self.scene = scene
        self.rate = rate
        self.time = path.start

    @property
    def done(self) -> bool:
        return self.time >= self.path.end

    def poll(self, dt: float) -> InputState:
        if self.done or not dt > 0.0:
            return NO_INPUT
        t0 = self.time
        t1 = min(t0 + dt * self.rate, self.path.end)
        if self.path.end - t1 <= 1e-9 * max(1.0, self.path.duration):
            t1 = self.path.end
        self.time = t1
        p0, yaw0, pitch0 = self.path.control_pose(t0)
        p1, yaw1, pitch1 = self.path.control_pose(t1)
        d_yaw = (yaw1 - yaw0 + 180.0) % 360.0 - 180.0
        # The system turns first, then moves along the turned camera's axes: express the step in that frame.
        move = quat_to_matrix(yaw_pitch_quat(yaw1, pitch1)).T @ (p1 - p0)
        step = float(np.linalg.norm(move))
        move = move / step if step > 1e-12 else np.zeros(3)
        x, y, z = (float(c) for c in move)
        return InputState((x, y, z), (d_yaw, pitch1 - pitch0), speed=step / dt)
