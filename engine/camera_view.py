"""The camera a frame is rendered from: float64 pose, primary rays, radial bounds, its packed row.

Kept apart from the table packer: the camera changes every frame and is sent
as its own small record, while the packer follows the scene's change journal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from components import Camera, Transform
from engine import layout
from engine.layout import Precision
from engine.maths import quat_to_matrix
from engine.scene import Scene


@dataclass(frozen=True)
class CameraView:
    """The float64 camera a frame is rendered from."""

    position: np.ndarray  # (3,)
    rotation: np.ndarray  # (3, 3): columns are right, up, back
    fov_deg: float

    @staticmethod
    def from_components(transform: Transform, camera: Camera) -> CameraView:
        return CameraView(
            np.array(transform.position, dtype=np.float64), quat_to_matrix(transform.rotation), camera.fov_deg
        )

    def corner_directions(self, aspect: float) -> np.ndarray:
        """World directions of the rays through NDC (-1, -1) and (+1, +1) (rows)."""
        t = math.tan(math.radians(self.fov_deg) / 2.0)
        local = np.array([[-aspect * t, -t, -1.0], [aspect * t, t, -1.0]])
        local /= np.linalg.norm(local, axis=1, keepdims=True)
        return local @ self.rotation.T

    def sigma_bounds(self, aspect: float) -> tuple[np.ndarray, np.ndarray]:
        """The radial mode's ``m_k`` and ``M_k`` (DESIGN.md section 6)."""
        corners = self.corner_directions(aspect)
        return corners.min(axis=0), corners.max(axis=0)

    def primary_directions(self, width: int, height: int) -> np.ndarray:
        """Unit world directions (H, W, 3), float64, exactly per DESIGN.md section 3."""
        aspect = width / height
        t = math.tan(math.radians(self.fov_deg) / 2.0)
        x = (2.0 * (np.arange(width) + 0.5) / width - 1.0) * aspect * t
        y = (1.0 - 2.0 * (np.arange(height) + 0.5) / height) * t
        local = np.empty((height, width, 3))
        local[..., 0] = x[None, :]
        local[..., 1] = y[:, None]
        local[..., 2] = -1.0
        local /= np.linalg.norm(local, axis=2, keepdims=True)
        return local @ self.rotation.T


def scene_camera(scene: Scene) -> CameraView:
    """The scene's active camera."""
    if scene.camera_entity is None:
        scene.validate()  # raises the "no camera" error
    assert scene.camera_entity is not None
    return CameraView.from_components(scene.get(scene.camera_entity, Transform), scene.get(scene.camera_entity, Camera))


def pack_camera(view: CameraView, origin: np.ndarray, precision: Precision, width: int, height: int) -> np.ndarray:
    """One row of the camera table, relative to the packed origin."""
    row = np.zeros(1, dtype=layout.camera_dtype(precision))
    aspect = width / height
    row["position"][0, :3] = view.position - origin
    row["right"][0, :3] = view.rotation[:, 0]
    row["up"][0, :3] = view.rotation[:, 1]
    row["back"][0, :3] = view.rotation[:, 2]
    row["origin"][0, :3] = origin
    lo, hi = view.sigma_bounds(aspect)
    row["sigma_min"][0, :3] = lo
    row["sigma_max"][0, :3] = hi
    row["lens"][0, :2] = (math.tan(math.radians(view.fov_deg) / 2.0), aspect)
    row["size"][0, :2] = (width, height)
    return row
