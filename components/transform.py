"""Where an entity is: position, rotation, scale (``M = T(p) R(q) S(s)``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from components.validation import Quat, ValidationError, Vec3, at_most, unit_quaternion, vec3


@dataclass(frozen=True, init=False)
class Transform:
    """A world transform; entities are flat, so this is always world space.

    Frozen: an edit is a new value handed to the scene, which is how the scene
    knows which GPU table rows to re-upload.
    """

    position: Vec3
    rotation: Quat
    scale: Vec3

    def __init__(
        self,
        position: Sequence[float] = (0.0, 0.0, 0.0),
        rotation: Sequence[float] = (0.0, 0.0, 0.0, 1.0),
        scale: Sequence[float] = (1.0, 1.0, 1.0),
    ) -> None:
        """Any sequences of 3, 4 and 3 numbers (the maths hands over tuples of any length); stored checked as tuples."""
        object.__setattr__(self, "position", vec3(position, "position"))
        object.__setattr__(self, "rotation", unit_quaternion(rotation, "rotation"))
        checked = vec3(scale, "scale")
        for i, s in enumerate(checked):
            if abs(s) < 1e-12:
                raise ValidationError(
                    f"scale[{i}]", "a scale component of zero collapses the entity; use a small non-zero value"
                )
            at_most(s, f"scale[{i}]", "a scale")
        object.__setattr__(self, "scale", checked)
