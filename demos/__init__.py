"""Demo levels, built as code.

Each demo is a module ``demos/<name>.py`` whose docstring's first line
describes it and whose ``build()`` returns a :class:`~engine.scene.Scene`.
Modules are imported only when a demo is described or built, so listing the
demos stays cheap and one broken demo cannot break the others.
"""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import TYPE_CHECKING

from engine.errors import AberrantError

if TYPE_CHECKING:
    from engine.scene import Scene

#: Demo name -> module path.
DEMOS: dict[str, str] = {
    "starter": "demos.starter",
    "aberration_room": "demos.aberration_room",
    "aberration_tunnels": "demos.aberration_tunnels",
    "geometry_room": "demos.geometry_room",
    "house": "demos.house",
    "endless_corridor": "demos.endless_corridor",
    "bigger_inside": "demos.bigger_inside",
    "nested_aberrations": "demos.nested_aberrations",
    "portal_in_aberration": "demos.portal_in_aberration",
    "hotel": "demos.hotel",
}


def demo_names() -> list[str]:
    """Every registered demo, in registry order."""
    return list(DEMOS)


def _module(name: str) -> ModuleType:
    try:
        target = DEMOS[name]
    except KeyError:
        raise AberrantError(f"unknown demo {name!r}; demos: {', '.join(DEMOS)}") from None
    return importlib.import_module(target)


def describe(name: str) -> str:
    """The demo's one-line description (its module docstring's first line)."""
    doc = _module(name).__doc__ or ""
    lines = [line.strip() for line in doc.strip().splitlines()]
    return lines[0] if lines else ""


def build_demo(name: str) -> Scene:
    """Build a fresh scene of the named demo."""
    return _module(name).build()


__all__ = ["DEMOS", "build_demo", "demo_names", "describe"]
