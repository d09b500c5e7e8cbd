"""``import aberrant``: cheap to import, every exported name documented, and ``render()`` opening, falling back
and releasing as it promises."""

from __future__ import annotations

import doctest
import importlib
import inspect
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

import aberrant
import backends.base
from aberrant.cli import main
from backends.reference.backend import ReferenceBackend
from engine.errors import AberrantError, BackendUnavailable
from systems.app import App, render_once

ROOT = Path(__file__).resolve().parents[2]
SIZE = (16, 12)
#: What a user scripts with: the names the package must export.
REQUIRED = {
    "Scene", "Settings", "load_scene", "save_scene", "create_backend", "App", "Frame", "render",
    "ScriptedInput", "InputState", "CameraPath", "Keyframe", "Stop", "route", "build_demo", "demo_names",
    "Transform", "Mesh", "Aberration", "Portal", "Camera",
}  # fmt: skip


class RecordingReference(ReferenceBackend):
    """The reference backend, remembering every instance opened and how often each was released."""

    opened: ClassVar[list[RecordingReference]] = []

    def __init__(self, precision: str | None = None) -> None:
        super().__init__(precision)  # type: ignore[arg-type]
        self.releases = 0
        RecordingReference.opened.append(self)

    def release(self) -> None:
        self.releases += 1
        super().release()


@pytest.fixture
def recording(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[RecordingReference]]:
    """Backends opened by name are RecordingReference instances; ``$ABERRANT_BACKEND`` is ``reference``."""
    real = backends.base.backend_class
    monkeypatch.setattr(backends.base, "backend_class", lambda n: RecordingReference if n == "reference" else real(n))
    monkeypatch.setenv("ABERRANT_BACKEND", "reference")
    RecordingReference.opened = []
    yield RecordingReference.opened


@pytest.fixture
def no_fast_backends(monkeypatch: pytest.MonkeyPatch) -> None:
    """GLSL and OpenCL cannot start (as on a machine without their drivers); the reference still can."""
    real = backends.base.probe
    reasons = {"glsl": "no EGL display (test)", "opencl": "no OpenCL platform (test)"}
    monkeypatch.setattr(backends.base, "probe", lambda name: reasons.get(name) or real(name))


@pytest.fixture
def scene() -> Iterator[aberrant.Scene]:
    scene = aberrant.build_demo("starter")
    yield scene
    scene.close()


def test_import_loads_no_gpu_opencl_or_editor_module() -> None:
    heavy = ("moderngl", "glcontext", "pyopencl", "imgui_bundle", "glfw", "matplotlib")
    code = f"import sys, aberrant; print(sorted(m for m in {heavy!r} if m in sys.modules))"
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "[]"


def test_every_exported_name_is_importable_and_documented_with_an_example() -> None:
    assert set(aberrant.__all__) >= REQUIRED
    assert len(set(aberrant.__all__)) == len(aberrant.__all__)
    package_doc = inspect.getdoc(aberrant) or ""
    example_lines = [line for line in package_doc.splitlines() if line.startswith((">>> ", "... "))]
    for name in aberrant.__all__:
        value = getattr(importlib.import_module("aberrant"), name)
        assert inspect.getdoc(value), f"aberrant.{name} has no docstring"
        assert f"`{name}`" in package_doc, f"the package docstring does not describe {name}"
        assert any(f"aberrant.{name}" in line for line in example_lines), f"no example uses aberrant.{name}"


def test_docstring_examples_run() -> None:
    """The package's and render()'s examples are doctests: what they show is what the code does."""
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for module in (aberrant, importlib.import_module("aberrant.rendering")):
        for test in doctest.DocTestFinder().find(module, module.__name__):
            runner.run(test)
    results = runner.summarize(verbose=False)
    assert results.attempted > 40 and results.failed == 0


def test_render_without_a_backend_opens_one_and_releases_it(recording: list[RecordingReference], scene) -> None:
    frame = aberrant.render(scene, size=SIZE)
    assert [b.releases for b in recording] == [1]
    assert (frame.width, frame.height) == SIZE and frame.present() == list(backends.base.AOVS)
    with ReferenceBackend() as backend:  # the same frame as the upload path everything else renders through
        expected = render_once(scene, backend, SIZE)
    for name in backends.base.AOVS:
        np.testing.assert_array_equal(frame.aov(name), expected.aov(name))


def test_render_by_name_releases_the_backend_it_opened(recording: list[RecordingReference], scene) -> None:
    frame = aberrant.render(scene, "reference", SIZE, "instance")
    assert frame.present() == ["instance"]
    assert [b.releases for b in recording] == [1]


def test_render_releases_its_backend_when_the_render_fails(recording: list[RecordingReference], scene) -> None:
    with pytest.raises(AberrantError, match="unknown AOV"):
        aberrant.render(scene, size=SIZE, aovs=("colour",))
    assert [b.releases for b in recording] == [1]


def test_render_with_a_backend_uses_it_and_leaves_it_open(recording: list[RecordingReference], scene) -> None:
    backend = RecordingReference()
    first = aberrant.render(scene, backend, SIZE, "color")
    second = aberrant.render(scene, backend, SIZE, "color")
    assert recording == [backend] and backend.releases == 0
    np.testing.assert_array_equal(first.color, second.color)
    with App(scene, backend, size=SIZE) as app:  # render() closed its App: the scene's world is free again
        assert app.tick(0.0) is not None
    backend.release()


def test_render_refuses_a_precision_its_given_backend_does_not_trace(scene) -> None:
    with ReferenceBackend() as backend, pytest.raises(AberrantError, match="precision 'f32'"):
        aberrant.render(scene, backend, SIZE, precision="f32")


def test_an_asked_for_backend_that_cannot_start_fails_with_its_reason_as_the_cli_does(
    no_fast_backends: None, scene, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An explicit choice is never swapped for another backend: render() and the CLI both say why it cannot run."""
    with pytest.raises(BackendUnavailable, match="opencl backend cannot run here: no OpenCL platform") as caught:
        aberrant.render(scene, "opencl", SIZE, "color")
    assert "\n" not in str(caught.value)
    assert capsys.readouterr().err == ""
    out = tmp_path / "frame.png"
    assert main(["render", "starter", "--backend", "opencl", "--size", "16x12", "--out", str(out)]) == 2
    assert "opencl backend cannot run here" in capsys.readouterr().err
    assert not out.exists()
    messages: list[str] = []
    with pytest.raises(BackendUnavailable, match="glsl backend cannot run here"):
        aberrant.render(scene, "glsl", SIZE, "color", log=messages.append)
    assert messages == []


def test_auto_says_which_backend_it_chose(no_fast_backends: None, scene, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ABERRANT_BACKEND", raising=False)
    messages: list[str] = []
    aberrant.render(scene, size=SIZE, aovs="color", log=messages.append)
    assert messages == ["aberrant: auto chose the reference backend"]


def test_an_unknown_backend_name_is_one_error(scene) -> None:
    with pytest.raises(AberrantError, match="unknown backend 'vulkan'"):
        aberrant.render(scene, "vulkan", SIZE)


BAD_SIZES = [
    ((0, 10), "got 0x10"),
    ((10, -1), "got 10x-1"),
    ((640,), "got (640,)"),
    ((640, 480, 3), "got (640, 480, 3)"),
    ("640x480", "got '640x480'"),
    ((1.5, 2), "got (1.5, 2)"),
    ((True, 2), "got (True, 2)"),
    ((None, 2), "got (None, 2)"),
    (640, "got 640"),
    (None, "got None"),
]


@pytest.mark.parametrize(("size", "said"), BAD_SIZES, ids=[repr(size) for size, _ in BAD_SIZES])
def test_a_bad_size_is_one_clear_error_before_any_backend_opens(
    size: object, said: str, recording: list[RecordingReference], scene
) -> None:
    with pytest.raises(AberrantError, match=r"^size must be") as caught:
        aberrant.render(scene, size=size)  # type: ignore[arg-type]
    assert str(caught.value).endswith(said) and "\n" not in str(caught.value)
    assert recording == []
