"""A light (docs/semantics.md, "Lights and shadows")."""

from __future__ import annotations

from dataclasses import dataclass

from components.validation import MAX_MAGNITUDE, Color, ValidationError, at_most, boolean, choice, color, real

LIGHT_KINDS = ("sun", "point")

#: Lights a scene may hold: the kernels loop over a short fixed-size table.
MAX_LIGHTS = 8


@dataclass(frozen=True)
class Light:
    """A ``sun`` shines along its Transform's -Z (the way a camera looks, as glTF's KHR_lights_punctual
    says); a ``point`` light shines from its Transform's position, falling off with the inverse square of
    the distance, to nothing at ``range`` when one is given. ``shadows``: its light is blocked by meshes,
    along shadow rays that travel deformed space as camera rays do."""

    kind: str = "sun"
    color: Color = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    shadows: bool = True
    range: float | None = None

    def __post_init__(self) -> None:
        kind = choice(self.kind, LIGHT_KINDS, "kind")
        object.__setattr__(self, "color", color(self.color, "color"))
        intensity = at_most(real(self.intensity, "intensity"), "intensity", "an intensity")
        if intensity < 0.0:
            raise ValidationError("intensity", f"must be >= 0, got {intensity}")
        object.__setattr__(self, "intensity", intensity)
        boolean(self.shadows, "shadows")
        if self.range is not None:
            if kind != "point":
                raise ValidationError("range", "only a point light has a range; give null for a sun")
            reach = real(self.range, "range")
            if not 0.0 < reach <= MAX_MAGNITUDE:
                raise ValidationError("range", f"must be > 0 and at most {MAX_MAGNITUDE:g}, got {reach}")
            object.__setattr__(self, "range", reach)
