"""Components: plain frozen dataclasses, data and validation only."""

from __future__ import annotations

from components.aberration import ABERRATION_EXITS, ABERRATION_MODES, Aberration
from components.camera import Camera
from components.light import LIGHT_KINDS, MAX_LIGHTS, Light
from components.mesh import Mesh
from components.name import Name
from components.portal import Portal
from components.transform import Transform
from components.validation import ValidationError

__all__ = [
    "ABERRATION_EXITS",
    "ABERRATION_MODES",
    "LIGHT_KINDS",
    "MAX_LIGHTS",
    "Aberration",
    "Camera",
    "Light",
    "Mesh",
    "Name",
    "Portal",
    "Transform",
    "ValidationError",
]
