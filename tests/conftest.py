"""Shared fixtures: backends honour ABERRANT_REQUIRE_BACKENDS (fail, not skip, when required)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from backends.base import Backend, backend_class, probe
from engine.bvh_cache import clear_memory_cache
from engine.records import Precision
from engine.scene import Scene

os.environ.setdefault("ABERRANT_CACHE_DIR", str(Path(__file__).resolve().parent.parent / ".cache" / "aberrant"))


def required_backends() -> list[str]:
    """Backends that must run here (``ABERRANT_REQUIRE_BACKENDS``, comma-separated): CI sets it."""
    raw = os.environ.get("ABERRANT_REQUIRE_BACKENDS", "")
    return [name.strip() for name in raw.split(",") if name.strip()]


def require_backend(name: str) -> None:
    """Skip (with the probed reason) when ``name`` cannot run here, or fail when CI requires it."""
    reason = probe(name)
    if reason is None:
        return
    if name in required_backends():
        pytest.fail(f"{name} backend is required (ABERRANT_REQUIRE_BACKENDS) but cannot run: {reason}")
    pytest.skip(f"{name} backend cannot run here: {reason}")


_live: dict[tuple[str, str], Backend] = {}


@pytest.fixture
def scenes() -> Iterator[list[Scene]]:
    """Scenes a test makes; their esper worlds are closed afterwards."""
    made: list[Scene] = []
    yield made
    for scene in made:
        scene.close()


@pytest.fixture
def fresh_memory() -> Iterator[None]:
    """The in-memory BVH cache empty before and after the test."""
    clear_memory_cache()
    yield
    clear_memory_cache()


@pytest.fixture(scope="session")
def backend_factory():
    """``make(name, precision=None)``: one live backend per (name, precision) for the whole session."""

    def make(name: str, precision: Precision | None = None):
        require_backend(name)
        key = (name, precision or "")
        if key not in _live:
            _live[key] = backend_class(name)(precision=precision)
        return _live[key]

    yield make
    for backend in _live.values():
        backend.release()
    _live.clear()
