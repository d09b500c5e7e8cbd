"""A box of deformed space (docs/semantics.md, "Aberrations")."""

from __future__ import annotations

from dataclasses import dataclass

from components.validation import Color, ValidationError, Vec3, boolean, choice, color, integer, vec3

ABERRATION_MODES = ("metric", "radial", "additive")
ABERRATION_EXITS = ("restore", "repeat", "invert")


@dataclass(frozen=True)
class Aberration:
    """The unit box [-1/2, 1/2]^3 placed by the entity's Transform.

    ``metric`` (default) scales space along the box's axes by ``s = 1 + D``;
    ``radial`` and ``additive`` are the thesis's world-axis ray bends, with an
    ``exit`` rule. The highest ``priority`` wins where boxes overlap.
    """

    deformation: Vec3 = (0.0, 0.0, 0.0)
    mode: str = "metric"
    exit: str = "restore"
    priority: int = 0
    debug_draw: bool = True
    color: Color = (1.0, 0.55, 0.1)

    def __post_init__(self) -> None:
        deformation = vec3(self.deformation, "deformation")
        mode = choice(self.mode, ABERRATION_MODES, "mode")
        if mode == "metric":
            for i, d in enumerate(deformation):
                if d <= -1.0:
                    raise ValidationError(
                        f"deformation[{i}]",
                        f"metric mode needs every component > -1 (space scale 1 + D must be positive), got {d}",
                    )
        object.__setattr__(self, "deformation", deformation)
        choice(self.exit, ABERRATION_EXITS, "exit")
        integer(self.priority, "priority")
        boolean(self.debug_draw, "debug_draw")
        object.__setattr__(self, "color", color(self.color, "color"))
