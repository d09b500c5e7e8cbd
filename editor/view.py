"""The editor's own viewpoint: a fly camera that is not part of the scene.

Looking around the level while editing must not edit it (nor make it
"unsaved"), so the viewport has its own camera; "Camera to view" in the Add
menu copies it into the scene's camera, and the view starts where the
scene's camera is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from components import Transform
from engine.camera_view import CameraView
from engine.maths import quat_from_matrix, quat_to_matrix

#: Near and far planes of the preview rasteriser (the tracer has none).
NEAR = 0.05
FAR = 2000.0


def rotation_from_angles(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """``Ry(yaw) Rx(pitch)``: columns are right, up, back (the camera looks along -back)."""
    y, p = math.radians(yaw_deg), math.radians(pitch_deg)
    ry = np.array([[math.cos(y), 0.0, math.sin(y)], [0.0, 1.0, 0.0], [-math.sin(y), 0.0, math.cos(y)]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(p), -math.sin(p)], [0.0, math.sin(p), math.cos(p)]])
    return ry @ rx


def perspective(fov_deg: float, aspect: float, near: float = NEAR, far: float = FAR) -> np.ndarray:
    """The OpenGL projection matching the tracer's pinhole (vertical field of view, aspect W/H)."""
    f = 1.0 / math.tan(math.radians(fov_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f / aspect
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def view_matrix(view: CameraView) -> np.ndarray:
    """World to camera space for a tracer camera (the inverse of its rigid pose)."""
    m = np.eye(4)
    m[:3, :3] = view.rotation.T
    m[:3, 3] = -(view.rotation.T @ view.position)
    return m


def column_major(m: np.ndarray) -> list[float]:
    """16 floats, column by column, as OpenGL and ImGuizmo take them."""
    return [float(v) for v in np.asarray(m, dtype=np.float64).T.reshape(16)]


@dataclass
class EditorView:
    """Position, yaw and pitch (degrees), vertical field of view, fly speed."""

    position: np.ndarray
    yaw: float = 0.0
    pitch: float = 0.0
    fov_deg: float = 60.0
    speed: float = 4.0

    @classmethod
    def from_transform(cls, transform: Transform, fov_deg: float = 60.0) -> EditorView:
        """The view of a camera pose (roll, which the fly camera has none of, is dropped)."""
        back = quat_to_matrix(transform.rotation)[:, 2]
        yaw = math.degrees(math.atan2(back[0], back[2]))
        pitch = math.degrees(math.asin(max(-1.0, min(1.0, -back[1]))))
        return cls(np.array(transform.position, dtype=np.float64), yaw, pitch, fov_deg)

    @property
    def rotation(self) -> np.ndarray:
        return rotation_from_angles(self.yaw, self.pitch)

    def camera(self) -> CameraView:
        """The tracer's camera for this view."""
        return CameraView(self.position.copy(), self.rotation, self.fov_deg)

    def transform(self) -> Transform:
        """This view as a camera Transform ("Camera to view")."""
        q = quat_from_matrix(self.rotation)
        return Transform(tuple(float(c) for c in self.position), tuple(float(c) for c in q))

    def look(self, dx_deg: float, dy_deg: float) -> None:
        """Turn right by ``dx_deg`` and up by ``dy_deg`` (pitch kept off the poles)."""
        self.yaw = (self.yaw - dx_deg) % 360.0
        self.pitch = max(-89.0, min(89.0, self.pitch + dy_deg))

    def fly(self, move: Sequence[float], dt: float, boost: bool = False) -> None:
        """Move along the view's own axes (``move`` = right, up, back), ``speed`` units a second."""
        v = np.asarray(move, dtype=np.float64)
        if not np.any(v):
            return
        v = v / np.linalg.norm(v)
        self.position = self.position + self.rotation @ v * self.speed * dt * (3.0 if boost else 1.0)

    def pan(self, dx: float, dy: float) -> None:
        """Slide sideways and up by world units."""
        r = self.rotation
        self.position = self.position + r[:, 0] * dx + r[:, 1] * dy

    def focus(self, point: Sequence[float], distance: float) -> None:
        """Step back along the current direction until ``point`` is ``distance`` ahead."""
        self.position = np.asarray(point, dtype=np.float64) + self.rotation[:, 2] * max(distance, 0.5)

    def ray(self, x: float, y: float, width: float, height: float) -> tuple[np.ndarray, np.ndarray]:
        """World origin and unit direction through pixel position ``(x, y)`` (0, 0 = top left)."""
        aspect = width / max(height, 1e-9)
        t = math.tan(math.radians(self.fov_deg) / 2.0)
        local = np.array([(2.0 * x / width - 1.0) * aspect * t, (1.0 - 2.0 * y / height) * t, -1.0])
        d = self.rotation @ local
        return self.position.copy(), d / np.linalg.norm(d)

    def pose_key(self) -> tuple[float, ...]:
        """What a re-render depends on, for "has the view changed?"."""
        return (*(float(c) for c in self.position), self.yaw, self.pitch, self.fov_deg)
