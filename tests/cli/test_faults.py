"""Faults: no GL context, no OpenCL device, a kernel that does not build, a disk that fails mid-save.

Each gives a clear message and a fallback where one exists:

* a backend that cannot start is probed with a reason naming what to
  install; ``aberrant render --backend X`` fails with that reason in one line
  (exit 2: a named backend never quietly renders with another), ``--backend
  auto`` picks one that starts; ``aberrant backends`` and the editor's backend
  host show the reason without crashing;
* a kernel that does not build fails on the first frame (kernels are built
  lazily, per scene variant): a named backend fails in one line naming it and
  the compiler's first errors, ``auto`` falls back to the reference backend at
  render time with that line; the editor keeps the error and shows its raster
  preview;
* a save that cannot complete (folder removed, read-only, disk full) raises a
  SceneFileError naming the file, leaves the previous file intact and no
  temporary behind. Killing a process mid-save is tested in test_atomic_save.py.
"""

from __future__ import annotations

import errno
import io
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, ClassVar
from unittest import mock

import pytest
from conftest import require_backend

import backends.base
import systems.app
from aberrant.cli import main
from backends.base import BACKENDS, Frame, backend_class, create_backend, probe
from backends.glsl.backend import GlslBackend
from backends.opencl.backend import OpenClBackend
from backends.reference.backend import ReferenceBackend
from demos import build_demo
from editor.backend_host import BackendHost
from engine.camera_view import CameraView, scene_camera
from engine.errors import AberrantError
from engine.scene import Scene
from engine.scene_file import SceneFileError, load_scene, save_scene

ROOT = Path(__file__).resolve().parents[2]
SIZE = ["--size", "16x12"]
INJECTED = "aberrant injected fault"


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, list[str]]:
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err.splitlines()


@pytest.fixture
def starter() -> Iterator[tuple[Scene, CameraView]]:
    scene = build_demo("starter")
    yield scene, scene_camera(scene)
    scene.close()


def only_reference_after(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    """``auto`` tries ``name`` and then the reference only, so a fallback is fast and deterministic."""
    monkeypatch.setattr(backends.base, "AUTO_ORDER", (name, "reference"))


# --- no GL context ----------------------------------------------------------------------------------


@pytest.fixture
def no_gl_context(monkeypatch: pytest.MonkeyPatch) -> str:
    """EGL finds no device: what a machine without Mesa's EGL drivers (or a GPU driver) says."""
    moderngl = pytest.importorskip("moderngl")
    from backends.glsl.backend import GlslBackend

    def refuse(*args: object, **kwargs: object) -> None:
        raise Exception("requested device index 0, but found 0 devices (simulated)")

    monkeypatch.setattr(moderngl, "create_standalone_context", refuse)
    monkeypatch.setattr(GlslBackend, "_probe_cache", None)  # probed once per process: forget the real answer
    return "glsl"


def test_probe_without_a_gl_context_says_why_and_what_to_install(no_gl_context):
    reason = probe("glsl")
    assert reason is not None
    assert "no headless OpenGL 4.3 context" in reason and "simulated" in reason
    assert "apt-get install" in reason and "libegl-mesa0" in reason


def test_render_without_a_gl_context_fails_in_one_line(no_gl_context, tmp_path, capsys, monkeypatch):
    only_reference_after(monkeypatch, "glsl")
    out = tmp_path / "frame.png"
    code, _, stderr = run(capsys, "render", "starter", "--backend", "glsl", *SIZE, "--out", str(out))
    assert code == 2
    assert len(stderr) == 1, stderr
    assert stderr[0].startswith("aberrant: error: glsl backend cannot run here: no headless OpenGL 4.3 context")
    assert stderr[0].endswith("; --backend auto picks one that can")
    assert not out.exists()
    code, stdout, stderr = run(capsys, "render", "starter", "--backend", "auto", *SIZE, "--out", str(out))
    assert (code, stderr) == (0, ["aberrant: auto chose the reference backend"])
    assert out.is_file() and "with the reference backend" in stdout


def test_create_backend_without_fallback_raises_the_reason(no_gl_context):
    with pytest.raises(AberrantError, match="glsl backend cannot run here: no headless OpenGL"):
        create_backend("glsl", fallback=False)


def test_backends_listing_shows_why_glsl_is_unavailable(no_gl_context, capsys):
    code, stdout, _ = run(capsys, "backends")
    assert code == 0
    [line] = [line for line in stdout.splitlines() if line.startswith("glsl:")]
    assert line.startswith("glsl: unavailable: no headless OpenGL 4.3 context") and "apt-get" in line
    assert "reference: available" in stdout


def test_editor_backend_host_reports_no_gl_context_and_goes_on(no_gl_context, starter):
    scene, view = starter
    messages: list[str] = []
    host = BackendHost(None, messages.append)
    assert "no headless OpenGL 4.3 context" in (host.reasons(refresh=True)["glsl"] or "")
    assert host.select("glsl") is False
    assert host.backend is None and host.error is not None
    assert "glsl" in host.error and "no headless OpenGL 4.3 context" in host.error
    assert messages == [host.error]
    assert host.render_view(scene, view, (8, 6)) is False  # nothing to trace with: the raster preview shows
    assert host.select_first(["glsl", "reference"]) is True
    assert host.name == "reference" and host.error is None
    assert host.render_view(scene, view, (8, 6)) is True
    host.close()


def test_a_process_whose_egl_finds_no_device_says_so(tmp_path):
    """The real thing, in a subprocess: glvnd given a vendor list that does not exist loads no EGL driver."""
    pytest.importorskip("moderngl")
    env = {**os.environ, "__EGL_VENDOR_LIBRARY_FILENAMES": str(tmp_path / "no-such-vendor.json")}
    env.pop("ABERRANT_BACKEND", None)
    out = tmp_path / "frame.png"
    argv = ["render", "starter", "--backend", "glsl", *SIZE, "--out", str(out)]
    result = subprocess.run(
        [sys.executable, "-m", "aberrant.cli", *argv], env=env, cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    [line] = result.stderr.splitlines()
    assert line.startswith("aberrant: error: glsl backend cannot run here: no headless OpenGL 4.3 context"), line
    assert not out.exists()


# --- no OpenCL device ----------------------------------------------------------------------------------


class _PlatformWithoutDevices:
    """What an ICD whose driver sees no hardware looks like to pyopencl."""

    name = "Simulated Platform"

    def get_devices(self) -> list[object]:
        import pyopencl

        raise pyopencl.RuntimeError("clGetDeviceIDs failed: DEVICE_NOT_FOUND")


def _no_platforms() -> list[object]:
    return []


def _loader_error() -> list[object]:
    import pyopencl

    raise pyopencl.LogicError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")


def _deviceless_platform() -> list[object]:
    return [_PlatformWithoutDevices()]


@pytest.fixture(params=["no platform", "ICD loader error", "platform without devices"])
def no_opencl_device(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    cl = pytest.importorskip("pyopencl")
    fake = {
        "no platform": _no_platforms,
        "ICD loader error": _loader_error,
        "platform without devices": _deviceless_platform,
    }
    monkeypatch.setattr(cl, "get_platforms", fake[request.param])
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    return request.param


def test_probe_without_an_opencl_device_says_what_to_install(no_opencl_device):
    reason = probe("opencl")
    assert reason is not None
    assert "install PoCL" in reason and "pocl-opencl-icd" in reason
    if no_opencl_device == "platform without devices":
        assert "Simulated Platform" in reason and "no device" in reason
    else:
        assert reason.startswith("no OpenCL platform found")
    if no_opencl_device == "ICD loader error":
        assert "PLATFORM_NOT_FOUND_KHR" in reason


def test_render_without_an_opencl_device_fails_in_one_line(no_opencl_device, tmp_path, capsys, monkeypatch):
    only_reference_after(monkeypatch, "opencl")
    out = tmp_path / "frame.png"
    code, _, stderr = run(capsys, "render", "starter", "--backend", "opencl", *SIZE, "--out", str(out))
    assert code == 2
    assert len(stderr) == 1, stderr
    assert stderr[0].startswith("aberrant: error: opencl backend cannot run here: ")
    assert "install PoCL" in stderr[0] and stderr[0].endswith("; --backend auto picks one that can")
    assert not out.exists()
    code, stdout, stderr = run(capsys, "render", "starter", *SIZE, "--out", str(out))  # auto, the default
    assert (code, stderr) == (0, ["aberrant: auto chose the reference backend"])
    assert out.is_file() and "with the reference backend" in stdout


def test_backends_listing_and_editor_without_an_opencl_device(no_opencl_device, capsys, starter):
    code, stdout, _ = run(capsys, "backends")
    assert code == 0
    [line] = [line for line in stdout.splitlines() if line.startswith("opencl:")]
    assert line.startswith("opencl: unavailable: ") and "install PoCL" in line
    host = BackendHost(None)
    assert host.select("opencl") is False
    assert host.error is not None and "opencl" in host.error and "install PoCL" in host.error
    assert host.select_first(["opencl", "reference"]) and host.name == "reference"
    assert host.render_view(*starter, (8, 6))
    host.close()


# --- a kernel that does not build ------------------------------------------------------------------------


@pytest.fixture(params=["glsl", "opencl"])
def broken_kernel(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """The backend's assembled source ends in ``#error``: a preprocessor error in GLSL and OpenCL C alike."""
    name = request.param
    require_backend(name)
    cls = backend_class(name)
    assert issubclass(cls, GlslBackend | OpenClBackend)  # the backends that assemble kernel source
    original = cls.source
    monkeypatch.setattr(cls, "source", staticmethod(lambda defines: original(defines) + f"\n#error {INJECTED}\n"))
    return name


def test_a_kernel_that_does_not_build_names_the_backend_and_the_compiler_error(broken_kernel, starter):
    scene, _ = starter
    backend = create_backend(broken_kernel, fallback=False)  # kernels are built on the first frame, not here
    try:
        with pytest.raises(AberrantError) as failure:
            systems.app.render_once(scene, backend, (8, 6), ("color",))
    finally:
        backend.release()
    message = str(failure.value)
    assert message.startswith(f"{broken_kernel} backend: ")
    assert "does not" in message.splitlines()[0]  # "does not compile" / "does not build"
    assert INJECTED in message and "error" in message


def test_cli_falls_back_to_the_reference_when_the_kernel_does_not_build(broken_kernel, tmp_path, capsys, monkeypatch):
    only_reference_after(monkeypatch, broken_kernel)
    out = tmp_path / "frame.png"
    code, stdout, stderr = run(capsys, "render", "starter", "--backend", "auto", *SIZE, "--out", str(out))
    assert code == 0
    assert stderr[0] == f"aberrant: auto chose the {broken_kernel} backend"
    assert len(stderr) == 2, stderr  # (PoCL's own "1 error generated." goes to the C-level stderr, not sys.stderr)
    line = stderr[1]
    assert line.startswith(f"aberrant: the {broken_kernel} backend failed ({broken_kernel} backend: ")
    assert INJECTED in line and "error" in line
    assert line.endswith("); falling back to the reference backend")
    assert out.is_file() and "with the reference backend" in stdout


def test_cli_with_a_named_backend_whose_kernel_does_not_build_fails_in_one_line(broken_kernel, tmp_path, capsys):
    out = tmp_path / "frame.png"
    code, _, stderr = run(capsys, "render", "starter", "--backend", broken_kernel, *SIZE, "--out", str(out))
    assert code == 2
    [line] = stderr
    assert line.startswith(f"aberrant: error: {broken_kernel} backend: ") and INJECTED in line
    assert line.endswith("; --backend auto falls back to one that can")
    assert not out.exists()


def test_editor_keeps_a_build_error_and_can_switch_backend(broken_kernel, starter):
    scene, view = starter
    host = BackendHost(None)
    assert host.select(broken_kernel) is True  # it starts; its first frame is what fails
    assert host.render_view(scene, view, (8, 6)) is False
    assert host.error is not None
    assert host.error.startswith(f"{broken_kernel}: ") and INJECTED in host.error
    assert host.select("reference") and host.render_view(scene, view, (8, 6))
    host.close()


class FakeBackend(ReferenceBackend):
    """A fast backend whose kernel never builds, so the fallback is tested on machines without GPU drivers."""

    name: ClassVar[str] = "fake"
    renders: ClassVar[int] = 0

    def render(self, camera: CameraView, width: int, height: int, aovs: Sequence[str] = ("color",)) -> Frame:
        FakeBackend.renders += 1
        raise AberrantError(
            "fake backend: the kernel does not build: clBuildProgram failed\n\nBuild log:\n"
            "  warning: something harmless\n  error: first problem\n  note: context\n  error: second problem\n"
            "  error: third problem\n" + "  more log\n" * 200
        )


@pytest.fixture
def fake_backend(monkeypatch: pytest.MonkeyPatch) -> str:
    """``auto`` chooses the fake backend (and the reference after it)."""
    monkeypatch.setitem(BACKENDS, "fake", f"{__name__}:FakeBackend")
    monkeypatch.setattr(FakeBackend, "renders", 0)
    only_reference_after(monkeypatch, "fake")
    return "auto"


def test_fallback_message_keeps_the_first_line_and_first_two_errors(fake_backend, tmp_path, capsys):
    out = tmp_path / "frame.png"
    code, _, stderr = run(capsys, "render", "starter", "--backend", "auto", *SIZE, "--out", str(out))
    assert code == 0 and out.is_file()
    assert stderr == [
        "aberrant: auto chose the fake backend",
        "aberrant: the fake backend failed (fake backend: the kernel does not build: clBuildProgram failed | "
        "error: first problem | error: second problem); falling back to the reference backend",
    ]


def test_a_flythrough_falls_back_too(fake_backend, tmp_path, capsys):
    out = tmp_path / "walk.gif"
    argv = ["render", "starter", "--path", "--frames", "2", "--backend", "auto", *SIZE, "--out", str(out)]
    code, stdout, stderr = run(capsys, *argv)
    assert code == 0, stderr
    assert sum(line.startswith("aberrant: the fake backend failed (") for line in stderr) == 1
    assert out.is_file() and "with the reference backend" in stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["walk.gif"]  # the failed attempt left nothing


def test_a_failure_outside_the_backend_is_an_error_not_a_fallback(fake_backend, tmp_path, capsys, monkeypatch):
    """Only the backend's own failures fall back: a scene or argument problem would fail on the reference too."""
    monkeypatch.setattr(systems.app, "render_once", mock.Mock(side_effect=AberrantError("the scene is broken")))
    out = tmp_path / "frame.png"
    code, _, stderr = run(capsys, "render", "starter", "--backend", "auto", *SIZE, "--out", str(out))
    assert code == 2
    assert stderr == ["aberrant: auto chose the fake backend", "aberrant: error: the scene is broken"]
    assert not out.exists()


def test_the_reference_failing_is_an_error_without_a_second_attempt(tmp_path, capsys, monkeypatch):
    calls: list[Any] = []

    def broken(self: ReferenceBackend, *args: object, **kwargs: object) -> Frame:
        calls.append(args)
        raise AberrantError("reference backend: out of memory (simulated)")

    monkeypatch.setattr(ReferenceBackend, "render", broken)
    out = tmp_path / "frame.png"
    code, _, stderr = run(capsys, "render", "starter", "--backend", "reference", *SIZE, "--out", str(out))
    assert (code, stderr) == (2, ["aberrant: error: reference backend: out of memory (simulated)"])
    assert len(calls) == 1 and not out.exists()


# --- a lost file, a read-only folder or a full disk during save ------------------------------------------


@pytest.fixture
def saved(tmp_path: Path) -> Iterator[tuple[Scene, Path, bytes]]:
    """The starter demo loaded from ``folder/scene.json`` and renamed, so a save would change the file."""
    folder = tmp_path / "folder"
    folder.mkdir()
    path = folder / "scene.json"
    demo = build_demo("starter")
    save_scene(demo, path)
    demo.close()
    scene = load_scene(path)
    scene.name = "edited"
    yield scene, path, path.read_bytes()
    scene.close()


def assert_untouched(path: Path, before: bytes) -> None:
    assert path.read_bytes() == before
    assert sorted(p.name for p in path.parent.iterdir()) == [path.name]  # no temporary left behind


def test_saving_into_a_folder_removed_since_loading(saved):
    scene, path, _ = saved
    shutil.rmtree(path.parent)
    with pytest.raises(SceneFileError) as failure:
        save_scene(scene, path)
    message = str(failure.value)
    assert message.startswith(str(path)) and "does not exist" in message
    assert not path.parent.exists()  # nothing recreated


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="needs POSIX permissions, not root's")
def test_saving_into_a_folder_made_read_only(saved):
    scene, path, before = saved
    path.parent.chmod(0o500)
    try:
        with pytest.raises(SceneFileError, match="Permission denied"):
            save_scene(scene, path)
    finally:
        path.parent.chmod(0o700)
    assert_untouched(path, before)


@pytest.mark.parametrize(
    ("code", "words"), [(errno.EACCES, "Permission denied"), (errno.EROFS, "Read-only file system")]
)
def test_saving_where_the_file_system_refuses_new_files(saved, monkeypatch, code, words):
    """The same as a read-only folder, for any user (root ignores permission bits)."""
    scene, path, before = saved
    real_open = os.open

    def refuse(file: Any, flags: int, *args: Any, **kwargs: Any) -> int:
        if str(file).endswith(".tmp"):
            raise OSError(code, os.strerror(code), str(file))
        return real_open(file, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", refuse)
    with pytest.raises(SceneFileError) as failure:
        save_scene(scene, path)
    assert str(failure.value).startswith(str(path)) and words in str(failure.value)
    monkeypatch.undo()
    assert_untouched(path, before)


def disk_full_on_fsync(monkeypatch: pytest.MonkeyPatch) -> None:
    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", full)


def disk_full_mid_write(monkeypatch: pytest.MonkeyPatch) -> None:
    """The first half of the data reaches the disk, then ENOSPC: a half-written temporary exists."""
    real_fdopen = os.fdopen

    class Filling(io.RawIOBase):
        def __init__(self, f: Any) -> None:
            self.f = f

        def write(self, data: Any) -> int:
            self.f.write(bytes(data)[: len(data) // 2])
            self.f.flush()
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def __getattr__(self, name: str) -> Any:
            return getattr(self.f, name)

        def __exit__(self, *exc: object) -> None:
            self.f.close()

    monkeypatch.setattr(os, "fdopen", lambda fd, *a, **k: Filling(real_fdopen(fd, *a, **k)))


@pytest.mark.parametrize("fill", [disk_full_on_fsync, disk_full_mid_write], ids=["on fsync", "mid-write"])
def test_a_full_disk_keeps_the_previous_file_and_no_temporary(saved, monkeypatch, fill):
    scene, path, before = saved
    fill(monkeypatch)
    with pytest.raises(SceneFileError) as failure:
        save_scene(scene, path)
    monkeypatch.undo()
    message = str(failure.value)
    assert message.startswith(str(path)) and "No space left on device" in message
    assert_untouched(path, before)


def test_cli_render_onto_a_full_disk_is_one_line_and_keeps_the_old_image(tmp_path, capsys, monkeypatch):
    out = tmp_path / "frame.png"
    out.write_bytes(b"the old image")
    disk_full_on_fsync(monkeypatch)
    code, _, stderr = run(capsys, "render", "starter", "--backend", "reference", *SIZE, "--out", str(out))
    monkeypatch.undo()
    assert code == 2
    assert len(stderr) == 1 and stderr[0].startswith("aberrant: error: ") and "No space left on device" in stderr[0]
    assert out.read_bytes() == b"the old image"
    assert [p.name for p in tmp_path.iterdir()] == ["frame.png"]


def test_saving_into_a_folder_that_is_a_file(saved):
    scene, path, before = saved
    blocker = path.parent / "not_a_folder"
    blocker.write_text("x")
    with pytest.raises(SceneFileError, match="cannot save"):
        save_scene(scene, blocker / "scene.json")
    assert path.read_bytes() == before


def test_write_atomically_is_what_every_writer_shares():
    """Every writer goes through the one atomic writer (so these faults cover them all): the scene files
    (and with them the Tello importer's meshes), the CLI's images, flythrough GIFs."""
    import aberrant.importers.tello
    import aberrant.render_command
    import aberrant.sinks
    import engine.atomic_files
    import engine.scene_file

    assert aberrant.sinks.write_atomically is engine.scene_file.write_atomically is engine.atomic_files.write_atomically
    assert "with_files=" in Path(aberrant.importers.tello.__file__).read_text()
    assert "write_atomically" in Path(aberrant.render_command.__file__).read_text()
