"""The viewpoint: lens and walking speed (its pose is the entity's Transform)."""

from __future__ import annotations

from dataclasses import dataclass

from components.validation import ValidationError, at_most, real


@dataclass(frozen=True)
class Camera:
    """A pinhole camera looking along its local -Z, +Y up.

    ``speed`` is the perceived walking speed in units per second; aberrations
    scale the world displacement it produces (docs/semantics.md, "The camera's walk").
    """

    fov_deg: float = 60.0
    speed: float = 3.0

    def __post_init__(self) -> None:
        fov = real(self.fov_deg, "fov_deg")
        if not 1.0 <= fov <= 179.0:
            raise ValidationError("fov_deg", f"vertical field of view must lie in [1, 179] degrees, got {fov}")
        speed = real(self.speed, "speed")
        if speed <= 0.0:
            raise ValidationError("speed", f"must be positive, got {speed}")
        at_most(speed, "speed", "a speed")
        object.__setattr__(self, "fov_deg", fov)
        object.__setattr__(self, "speed", speed)
