"""Quaternions (x, y, z, w), rotation matrices and affine transforms, float64.

Column vectors: ``p_world = M @ p_local`` with ``M = T(p) R(q) S(s)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

ArrayLike = Sequence[float] | np.ndarray


def normalize(v: ArrayLike, eps: float = 1e-300) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    n = float(np.linalg.norm(a))
    if n <= eps:
        raise ValueError("cannot normalise a zero-length vector")
    return a / n


def quat_normalize(q: ArrayLike) -> np.ndarray:
    return normalize(q)


def quat_multiply(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Hamilton product ``a * b`` (apply b, then a)."""
    ax, ay, az, aw = (float(c) for c in a)
    bx, by, bz, bw = (float(c) for c in b)
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def quat_conjugate(q: ArrayLike) -> np.ndarray:
    x, y, z, w = (float(c) for c in q)
    return np.array([-x, -y, -z, w])


def quat_from_axis_angle(axis: ArrayLike, angle_rad: float) -> np.ndarray:
    a = normalize(axis)
    h = 0.5 * angle_rad
    return np.array([*(a * math.sin(h)), math.cos(h)])


def quat_to_matrix(q: ArrayLike) -> np.ndarray:
    """The 3x3 rotation of a unit quaternion (normalised first, for safety)."""
    x, y, z, w = quat_normalize(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quat_from_matrix(m: ArrayLike) -> np.ndarray:
    """A unit quaternion with ``w >= 0`` from a rotation matrix (Shepperd's method)."""
    r = np.asarray(m, dtype=np.float64)[:3, :3]
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s]
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s, (r[1, 0] - r[0, 1]) / s]
    out = quat_normalize(q)
    return -out if out[3] < 0 else out


def quat_from_euler_deg(euler: ArrayLike) -> np.ndarray:
    """Rotate about world X, then world Y, then world Z: ``R = Rz Ry Rx``."""
    ex, ey, ez = (math.radians(float(a)) for a in euler)
    qx = quat_from_axis_angle((1, 0, 0), ex)
    qy = quat_from_axis_angle((0, 1, 0), ey)
    qz = quat_from_axis_angle((0, 0, 1), ez)
    return quat_multiply(qz, quat_multiply(qy, qx))


def quat_to_euler_deg(q: ArrayLike) -> np.ndarray:
    """Inverse of :func:`quat_from_euler_deg` (Y in [-90, 90])."""
    r = quat_to_matrix(q)
    sy = -r[2, 0]
    if abs(sy) < 1.0 - 1e-9:
        ey = math.asin(sy)
        ex = math.atan2(r[2, 1], r[2, 2])
        ez = math.atan2(r[1, 0], r[0, 0])
    else:  # gimbal lock: put all of the remaining rotation in X
        ey = math.copysign(math.pi / 2, sy)
        ez = 0.0
        ex = math.atan2(-r[1, 2], r[1, 1])
    return np.degrees([ex, ey, ez])


def look_at_quat(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 1.0, 0.0)) -> np.ndarray:
    """Orientation of a camera at ``eye`` looking at ``target`` (local -Z forward)."""
    forward = normalize(np.asarray(target, dtype=np.float64) - np.asarray(eye, dtype=np.float64))
    up_v = np.asarray(up, dtype=np.float64)
    right = np.cross(forward, up_v)
    if np.linalg.norm(right) < 1e-9:  # looking straight along up: pick any right
        right = np.cross(forward, (1.0, 0.0, 0.0) if abs(forward[0]) < 0.9 else (0.0, 0.0, 1.0))
    right = normalize(right)
    true_up = np.cross(right, forward)
    return quat_from_matrix(np.column_stack([right, true_up, -forward]))


def rotate(q: ArrayLike, v: ArrayLike) -> np.ndarray:
    return quat_to_matrix(q) @ np.asarray(v, dtype=np.float64)


def trs_matrix(position: ArrayLike, rotation: ArrayLike, scale: ArrayLike) -> np.ndarray:
    """The 4x4 ``T(p) R(q) S(s)``."""
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(rotation) * np.asarray(scale, dtype=np.float64)[None, :]
    m[:3, 3] = np.asarray(position, dtype=np.float64)
    return m


def trs_inverse(position: ArrayLike, rotation: ArrayLike, scale: ArrayLike) -> np.ndarray:
    """``(T R S)^-1 = S^-1 R^T T^-1`` computed directly (better than a general inverse)."""
    rt = quat_to_matrix(rotation).T
    inv_s = 1.0 / np.asarray(scale, dtype=np.float64)
    m = np.eye(4)
    m[:3, :3] = inv_s[:, None] * rt
    m[:3, 3] = -(m[:3, :3] @ np.asarray(position, dtype=np.float64))
    return m


def transform_points(m: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ m[:3, :3].T + m[:3, 3]


def transform_vectors(m: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    return vectors @ m[:3, :3].T
