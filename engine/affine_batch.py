"""Affine maps of many entities at once, as (n, 3, 4) float64 arrays.

The packer turns every transform of a table into world-to-object rows in one
pass; a per-entity Python loop would dominate a 1,000-entity tick.
"""

from __future__ import annotations

import numpy as np

from components import Transform

__all__ = ["compose_affine", "rotation_batch", "transform_arrays", "trs_forward", "trs_inverse_batch"]


def rotation_batch(q: np.ndarray) -> np.ndarray:
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    r = np.empty((len(q), 3, 3))
    r[:, 0] = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=1)
    r[:, 1] = np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=1)
    r[:, 2] = np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1)
    return r


def transform_arrays(transforms: list[Transform], origin: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Relative positions (n, 3), rotations (n, 3, 3), scales (n, 3)."""
    p = np.array([t.position for t in transforms], dtype=np.float64).reshape(-1, 3) - origin
    r = rotation_batch(np.array([t.rotation for t in transforms], dtype=np.float64).reshape(-1, 4))
    s = np.array([t.scale for t in transforms], dtype=np.float64).reshape(-1, 3)
    return p, r, s


def trs_forward(p: np.ndarray, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Batched ``T R S`` as (n, 3, 4)."""
    m = np.empty((len(p), 3, 4))
    m[:, :, :3] = r * s[:, None, :]
    m[:, :, 3] = p
    return m


def trs_inverse_batch(p: np.ndarray, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Batched ``(T R S)^-1 = S^-1 R^T T^-1`` as (n, 3, 4)."""
    m = np.empty((len(p), 3, 4))
    m[:, :, :3] = np.transpose(r, (0, 2, 1)) / s[:, :, None]
    m[:, :, 3] = -np.einsum("nij,nj->ni", m[:, :, :3], p)
    return m


def compose_affine(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched affine product ``a @ b`` of (n, 3, 4) matrices."""
    m = np.empty_like(a)
    m[:, :, :3] = a[:, :, :3] @ b[:, :, :3]
    m[:, :, 3] = np.einsum("nij,nj->ni", a[:, :, :3], b[:, :, 3]) + a[:, :, 3]
    return m
