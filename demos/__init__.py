"""Demo levels, built as code, found rather than listed.

A demo is any module ``demos/<name>.py`` that defines a top-level ``build()``
returning a :class:`engine.scene.Scene`; its docstring's first line
describes it. ``kit`` (building blocks), ``assets`` and private ``_`` modules
are not demos. Order: modules that set a module-level ``ORDER = <number>``
come first, by that number (the gallery order); the rest follow
alphabetically. Discovery reads the sources without importing them, so
listing the demos stays cheap, a new file is picked up on the next call, and
one broken demo cannot break the others.
"""

from __future__ import annotations

import ast
import importlib
import math
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from engine.errors import AberrantError

if TYPE_CHECKING:
    from engine.scene import Scene

#: Modules of this package that are not levels.
NOT_DEMOS = frozenset({"kit", "assets"})


def _order(source: str) -> tuple[float, bool] | None:
    """``(ORDER or inf, defines build())`` read from a module's source; ``None`` when it does not parse."""
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return None
    order = math.inf
    builds = False
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == "build":
            builds = True
        elif (
            isinstance(node, ast.Assign)
            and any(isinstance(t, ast.Name) and t.id == "ORDER" for t in node.targets)
            and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, int | float)
        ):
            order = float(node.value.value)
    return order, builds


def discover(folder: Path) -> list[str]:
    """The demo modules' names in ``folder``, in gallery order (see the module docstring).

    A module whose source does not parse is still listed (alphabetically), so
    building it reports its syntax error instead of the demo silently vanishing.
    """
    found: list[tuple[float, str]] = []
    for file in folder.glob("*.py"):
        name = file.stem
        if name.startswith("_") or name in NOT_DEMOS:
            continue
        read = _order(file.read_text(encoding="utf-8"))
        if read is None:
            found.append((math.inf, name))
        elif read[1]:
            found.append((read[0], name))
    return [name for _, name in sorted(found)]


def demo_modules() -> dict[str, str]:
    """Demo name -> module path, in gallery order, scanned afresh each call (a new demo file needs no edit)."""
    return {name: f"{__name__}.{name}" for name in discover(Path(__file__).parent)}


def demo_names() -> list[str]:
    """Every demo, in gallery order."""
    return list(demo_modules())


def demo_module(name: str) -> ModuleType:
    """The imported module of the named demo; an unknown name is an error listing the demos."""
    modules = demo_modules()
    try:
        target = modules[name]
    except KeyError:
        raise AberrantError(f"unknown demo {name!r}; demos: {', '.join(modules)}") from None
    return importlib.import_module(target)


def describe(name: str) -> str:
    """The demo's one-line description (its module docstring's first line)."""
    doc = demo_module(name).__doc__ or ""
    lines = [line.strip() for line in doc.strip().splitlines()]
    return lines[0] if lines else ""


def build_demo(name: str) -> Scene:
    """Build a fresh scene of the named demo."""
    return demo_module(name).build()


__all__ = ["build_demo", "demo_module", "demo_modules", "demo_names", "describe", "discover"]
