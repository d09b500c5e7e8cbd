"""Gizmo maths: between a Transform and the float32 4x4 matrix ImGuizmo edits.

ImGuizmo hands back a whole matrix in float32. Turning that straight into
a Transform would smear float32 noise over every field, so only the part
the operation edits is taken (translate: position, rotate: rotation,
scale: scale), and components it did not move keep their exact old value.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from components import Transform
from engine.maths import quat_from_matrix, trs_matrix

OPERATIONS = ("translate", "rotate", "scale")
MODES = ("world", "local")


@dataclass
class GizmoSettings:
    """What the gizmo does: operation, space, and snapping steps (units, degrees, scale factor)."""

    operation: str = "translate"
    mode: str = "world"
    snap: bool = False
    steps: dict[str, float] = field(default_factory=lambda: {"translate": 0.25, "rotate": 15.0, "scale": 0.1})

    @property
    def step(self) -> float:
        return self.steps[self.operation]


def transform_matrix(transform: Transform) -> np.ndarray:
    """``T R S`` as a float64 4x4."""
    return trs_matrix(transform.position, transform.rotation, transform.scale)


def _keep_unmoved(new: np.ndarray, old: tuple[float, ...], rel: float = 1e-5) -> tuple[float, ...]:
    """``new`` with each component that moved less than float32 noise replaced by its exact old value."""
    out = []
    for n, o in zip(new, old, strict=True):
        out.append(float(o) if abs(n - o) <= rel * max(1.0, abs(o)) else float(n))
    return tuple(out)


def matrix_to_transform(matrix: np.ndarray, old: Transform, operation: str) -> Transform:
    """The Transform a gizmo ``operation`` produced, changing only what that operation edits."""
    m = np.asarray(matrix, dtype=np.float64)
    if operation == "translate":
        return Transform(_keep_unmoved(m[:3, 3], old.position), old.rotation, old.scale)
    columns = m[:3, :3]
    lengths = np.linalg.norm(columns, axis=0)
    signs = np.sign(np.asarray(old.scale, dtype=np.float64))
    if operation == "scale":
        scale = _keep_unmoved(np.maximum(lengths, 1e-6) * signs, old.scale)
        return Transform(old.position, old.rotation, scale)
    if operation != "rotate":
        raise ValueError(f"unknown gizmo operation {operation!r}")
    rotation = columns / (np.maximum(lengths, 1e-12) * signs)
    q = quat_from_matrix(rotation)
    if np.dot(q, old.rotation) < 0:  # the same rotation either way; keep the sign the entity had
        q = -q
    if np.allclose(q, old.rotation, atol=1e-6):
        return old
    return Transform(old.position, tuple(float(c) for c in q / np.linalg.norm(q)), old.scale)
