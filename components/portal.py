"""One end of a portal (docs/semantics.md, "Portals")."""

from __future__ import annotations

from dataclasses import dataclass

from components.validation import Color, ValidationError, boolean, color


@dataclass(frozen=True)
class Portal:
    """The quad [-1, 1]^2 in local XY (normal +Z), placed by the Transform.

    ``target`` names the portal entity rays continue from; ``None`` makes the
    portal inert and invisible. A one-way link is allowed.
    """

    target: str | None = None
    color: Color = (0.2, 0.6, 1.0)
    debug_draw: bool = True

    def __post_init__(self) -> None:
        if self.target is not None and (not isinstance(self.target, str) or not self.target):
            raise ValidationError("target", f"expected the name of a portal entity or null, got {self.target!r}")
        object.__setattr__(self, "color", color(self.color, "color"))
        boolean(self.debug_draw, "debug_draw")
