"""Where an entity is: position, rotation, scale (``M = T(p) R(q) S(s)``)."""

from __future__ import annotations

from dataclasses import dataclass

from components.validation import Quat, ValidationError, Vec3, at_most, unit_quaternion, vec3


@dataclass(frozen=True)
class Transform:
    """A world transform; entities are flat, so this is always world space.

    Frozen: an edit is a new value handed to the scene, which is how the scene
    knows which GPU table rows to re-upload.
    """

    position: Vec3 = (0.0, 0.0, 0.0)
    rotation: Quat = (0.0, 0.0, 0.0, 1.0)
    scale: Vec3 = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", vec3(self.position, "position"))
        object.__setattr__(self, "rotation", unit_quaternion(self.rotation, "rotation"))
        scale = vec3(self.scale, "scale")
        for i, s in enumerate(scale):
            if abs(s) < 1e-12:
                raise ValidationError(
                    f"scale[{i}]", "a scale component of zero collapses the entity; use a small non-zero value"
                )
            at_most(s, f"scale[{i}]", "a scale")
        object.__setattr__(self, "scale", scale)
