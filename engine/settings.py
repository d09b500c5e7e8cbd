"""Scene-wide settings: background, light, ambient, the event limit (docs/semantics.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from components.validation import Color, ValidationError, Vec3, color, integer, real, vec3


@dataclass(frozen=True)
class Settings:
    """What a ray sees when it finds nothing, how it is lit, and when it gives up."""

    background: Color = (0.06, 0.07, 0.09)
    light_dir: Vec3 = (0.4, 0.8, 0.3)
    max_events: int = 16
    event_limit_color: Color = (1.0, 0.0, 1.0)
    ambient: float = 0.35

    def __post_init__(self) -> None:
        object.__setattr__(self, "background", color(self.background, "background"))
        light = vec3(self.light_dir, "light_dir")
        if math.sqrt(sum(c * c for c in light)) < 1e-9:
            raise ValidationError("light_dir", "must not be the zero vector (it is the direction towards the light)")
        object.__setattr__(self, "light_dir", light)
        events = integer(self.max_events, "max_events")
        if not 1 <= events <= 1024:
            raise ValidationError("max_events", f"must lie in [1, 1024], got {events}")
        object.__setattr__(self, "event_limit_color", color(self.event_limit_color, "event_limit_color"))
        ambient = real(self.ambient, "ambient")
        if not 0.0 <= ambient <= 1.0:
            raise ValidationError("ambient", f"must lie in [0, 1], got {ambient}")
        object.__setattr__(self, "ambient", ambient)
