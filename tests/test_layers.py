"""Every import points down the layers (docs/design.md section 1): a package imports only those below it."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Bottom to top.
LAYERS: tuple[str, ...] = ("components", "engine", "backends", "systems", "demos", "editor", "aberrant")


def imported_layers(path: Path) -> set[tuple[str, int]]:
    """``(layer, line)`` for every absolute import of one of our packages in a file, lazy imports included."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        found.update((name.split(".")[0], node.lineno) for name in names if name.split(".")[0] in LAYERS)
    return found


@pytest.mark.parametrize("layer", LAYERS)
def test_imports_point_down(layer: str) -> None:
    allowed = set(LAYERS[: LAYERS.index(layer) + 1])
    upward = [
        f"{path.relative_to(ROOT)}:{line} imports {target}"
        for path in sorted((ROOT / layer).rglob("*.py"))
        for target, line in sorted(imported_layers(path))
        if target not in allowed
    ]
    assert not upward, f"{layer}/ imports a layer above it:\n" + "\n".join(upward)
