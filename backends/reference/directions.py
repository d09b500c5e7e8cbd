"""Small vector rules shared by aberrations and portals, vectorised over rays (rows).

They exist so that the "no NaN ever" rule (docs/semantics.md rule 11) is written
once: a normalisation that would divide by (almost) zero, or whose input
overflowed, keeps the previous direction instead of producing NaN or inf.
"""

from __future__ import annotations

import numpy as np

#: A vector shorter than this is "zero length": its normalisation keeps the previous direction.
MIN_NORM = 1e-12


def normalize_or_keep(v: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """Rows of ``v`` scaled to unit length; ``previous`` where ``|v| < MIN_NORM`` or ``|v|`` is not finite."""
    with np.errstate(all="ignore"):
        norm = np.linalg.norm(v, axis=1)
        ok = np.isfinite(norm) & (norm >= MIN_NORM)
        unit = v / np.where(ok, norm, 1.0)[:, None]
    return np.where(ok[:, None], unit, previous)


def affine_points(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``m @ [p, 1]`` for one 3x4 affine ``m`` and points ``p`` (N, 3), or per-row matrices ``m`` (N, 3, 4)."""
    if m.ndim == 2:
        return p @ m[:, :3].T + m[:, 3]
    return np.einsum("nij,nj->ni", m[:, :, :3], p) + m[:, :, 3]


def linear_vectors(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The linear part of ``m`` (3x3 of a 3x4, or per row (N, 3, 3|4)) applied to vectors ``v`` (N, 3)."""
    if m.ndim == 2:
        return v @ m[:, :3].T
    return np.einsum("nij,nj->ni", m[:, :, :3], v)
