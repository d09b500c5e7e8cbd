"""Components: plain frozen dataclasses, data and validation only."""

from __future__ import annotations

from components.aberration import ABERRATION_EXITS, ABERRATION_MODES, Aberration
from components.camera import Camera
from components.mesh import Mesh
from components.name import Name
from components.portal import Portal
from components.transform import Transform
from components.validation import ValidationError

__all__ = [
    "ABERRATION_EXITS",
    "ABERRATION_MODES",
    "Aberration",
    "Camera",
    "Mesh",
    "Name",
    "Portal",
    "Transform",
    "ValidationError",
]
