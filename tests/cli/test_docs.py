"""``make docs``: the API reference builder fails on pdoc's warnings and on references that link to nothing."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _builder() -> ModuleType:
    spec = importlib.util.spec_from_file_location("build_api", ROOT / "docs" / "build_api.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _package(root: Path) -> Path:
    """A small package with one good reference, one broken, one in Sphinx's ``~`` form, and a bad ``__all__``."""
    package = root / "docs_check_sample"
    package.mkdir()
    (package / "__init__.py").write_text(
        '"""See :func:`docs_check_sample.parts.good`, :func:`missing` and :class:`~docs_check_sample.parts.Thing`."""\n'
    )
    (package / "parts.py").write_text(
        '"""Parts: :class:`Thing` links."""\n\n'
        '__all__ = ["Thing", "good", "nowhere"]\n\n\n'
        "class Thing:\n"
        '    """A thing."""\n\n\n'
        "def good() -> None:\n"
        '    """Good."""\n'
    )
    return package


def test_builder_reports_broken_references_and_warnings(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        problems = _builder().build(tmp_path / "api", [_package(tmp_path)])
    finally:
        for name in [n for n in sys.modules if n.startswith("docs_check_sample")]:
            del sys.modules[name]
    text = "\n".join(problems)
    assert "reference `missing` links to nothing in the docs of docs_check_sample" in text
    assert "reference `~docs_check_sample.parts.Thing`: pdoc does not know Sphinx's `~`" in text
    assert "'nowhere'" in text and "does not resolve" in text  # pdoc's own warning about __all__
    assert "good" not in text and "`Thing`" not in text, "references that resolve are not problems"
    assert len(problems) == 3, problems
    assert (tmp_path / "api" / "docs_check_sample" / "parts.html").is_file()
