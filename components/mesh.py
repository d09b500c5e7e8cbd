"""A rendered triangle mesh: which asset, and its small material."""

from __future__ import annotations

from dataclasses import dataclass

from components.validation import Color, ValidationError, boolean, color, real


@dataclass(frozen=True)
class Mesh:
    """An instance of a mesh asset (many entities may share one asset).

    ``checker`` is the checker cell size in UV units (or world units when the
    asset has no UVs); 0 means a plain colour. Dark cells are half as bright.
    """

    asset: str
    color: Color = (0.8, 0.8, 0.8)
    checker: float = 0.0
    cull_backfaces: bool = False
    texture: str = ""
    smooth: bool = False
    crease_deg: float = 30.0

    def __post_init__(self) -> None:
        if not isinstance(self.asset, str) or not self.asset:
            raise ValidationError("asset", f"expected the name of an asset, got {self.asset!r}")
        object.__setattr__(self, "color", color(self.color, "color"))
        checker = real(self.checker, "checker")
        if checker < 0.0:
            raise ValidationError("checker", f"checker cell size must be >= 0 (0: none), got {checker}")
        object.__setattr__(self, "checker", checker)
        boolean(self.cull_backfaces, "cull_backfaces")
        if not isinstance(self.texture, str) or "\0" in self.texture:
            raise ValidationError("texture", f"expected an image file path (or empty), got {self.texture!r}")
        boolean(self.smooth, "smooth")
        crease = real(self.crease_deg, "crease_deg")
        if not 0.0 <= crease <= 180.0:
            raise ValidationError("crease_deg", f"crease angle must lie in [0, 180] degrees, got {crease}")
        object.__setattr__(self, "crease_deg", crease)
