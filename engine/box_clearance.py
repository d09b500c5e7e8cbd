"""How far each aberration box is from every instance and from every other box (docs/semantics.md section 14).

The kernels use both to skip work that provably finds nothing: a mesh search along a segment inside a box
whose clearance exceeds the segment's reach past the box (the tie window), and the ``containing_box`` loop
after a face of a box whose gap to every other box exceeds the nudge. Both are lower bounds on the world
distance (separating-axis test on the face normals of the two solids, less a rounding slack), so a value
that is too small only costs speed; a value that is too large would be a bug, hence the slack. Here: the
geometry of the pairs and the camera's clearance; the boxes' values are found in :mod:`engine.clearances`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from engine.packed import PackedScene

#: Subtracted from every distance, relative to the size of the terms the kernels compute with: far above
#: float32 rounding of a box's local coordinates (a few 1e-7 of the box's size plus its distance).
CLEARANCE_SLACK = 1e-4


def box_solids(world_to_local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres (n, 3), half-edge vectors (n, 3 edges, 3) and unit face normals (n, 3, 3) of packed boxes."""
    m = np.asarray(world_to_local, dtype=np.float64)
    linear = np.linalg.inv(m[:, :, :3])  # local -> world; columns are the box's edges
    centre = -dot(linear, m[:, None, :, 3])
    half = 0.5 * np.transpose(linear, (0, 2, 1))
    normals = m[:, :, :3] / np.linalg.norm(m[:, :, :3], axis=2, keepdims=True)
    return centre, half, normals


def separation(c1: np.ndarray, h1: np.ndarray, c2: np.ndarray, h2: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """The largest gap between two solids along any of ``axes`` (a lower bound on their distance; <= 0 when
    no axis separates them). Shapes broadcast: centres (..., 3), half edges (..., 3, 3), axes (..., k, 3)."""
    along = np.abs(dot(axes, (c2 - c1)[..., None, :]))
    r1 = abs_sum(dot(axes[..., :, None, :], h1[..., None, :, :]))
    r2 = abs_sum(dot(axes[..., :, None, :], h2[..., None, :, :]))
    return (along - r1 - r2).max(axis=-1)


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products over the last axis (3), summed left to right whatever the shapes and memory layout (the
    same bits for a pair alone or among many; np.einsum's order depends on both)."""
    return (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]) + a[..., 2] * b[..., 2]


def abs_sum(v: np.ndarray) -> np.ndarray:
    """|v_0| + |v_1| + |v_2| over the last axis, left to right."""
    a = np.abs(v)
    return (a[..., 0] + a[..., 1]) + a[..., 2]


def solid_slack(centre: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Each box's rounding slack: CLEARANCE_SLACK of the size of its terms."""
    return CLEARANCE_SLACK * (1.0 + np.linalg.norm(centre, axis=1) + 2.0 * np.linalg.norm(half, axis=(1, 2)))


#: Above this many instances the camera's clearance is not computed (0: every first search runs); the
#: per-frame cost stays below a millisecond.
CAMERA_CLEARANCE_MAX_INSTANCES = 65536


def instance_bounds(packed: PackedScene) -> tuple[np.ndarray, np.ndarray]:
    """The live instances' packed world bounds (camera-relative, float64 copies)."""
    table = packed.tables["instances"][: packed.counts.get("instances", 0)]
    return table["bounds_min"][:, :3].astype(np.float64), table["bounds_max"][:, :3].astype(np.float64)


def camera_clearance(position: np.ndarray, bounds: tuple[np.ndarray, np.ndarray] | None) -> float:
    """World distance from the camera (camera-relative ``position``) to the nearest instance's bounds, less
    the rounding slack, or 0 (unknown, or too many instances). The kernels skip the first mesh search
    when it ends nearer than this (docs/semantics.md section 14)."""
    if bounds is None:
        return 0.0
    lo, hi = bounds
    if len(lo) > CAMERA_CLEARANCE_MAX_INSTANCES:
        return 0.0
    p = np.asarray(position, dtype=np.float64)
    if len(lo) == 0:
        return 1e30
    outside = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    distance = float(np.sqrt((outside * outside).sum(axis=1)).min())
    slack = CLEARANCE_SLACK * (1.0 + float(np.linalg.norm(p)) + float(np.abs(np.concatenate([lo, hi])).max()))
    return max(distance - slack, 0.0) if np.isfinite(distance) else 0.0
