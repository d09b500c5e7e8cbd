"""A corrupt or unusable OpenCL kernel cache costs a rebuild and one warning line, never the render.

PoCL trusts its cache: a truncated ``trace.so`` or garbage in ``program.bc``
aborts the process inside PoCL (exit 134) on every build. These tests corrupt a
real cache and run the CLI in child processes (an abort would take the test
runner with it): the corrupt entry is found before PoCL reads it, removed with
one warning and rebuilt; the same corruption with the check switched off shows
that PoCL really aborts on it. A cache directory that cannot be used (a file,
``/dev/null``, read-only) gives a private temporary cache and a warning, and
``--backend opencl`` still renders with OpenCL.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import require_backend

from backends.opencl import cache

ROOT = Path(__file__).resolve().parents[2]
ARGV = ["render", "starter", "--backend", "opencl", "--size", "16x12"]
#: A child whose PoCL cache check is switched off: what PoCL does with the corrupt files on its own.
UNCHECKED = (
    "import sys; import backends.opencl.cache as c; c.verify = lambda root: []; "
    "from aberrant.cli import main; sys.exit(main(sys.argv[1:]))"
)


@pytest.fixture(scope="module", autouse=True)
def opencl() -> None:
    require_backend("opencl")
    from backends.opencl.devices import pocl_version, select_device

    if pocl_version(select_device().platform) is None:
        pytest.skip("the OpenCL device is not PoCL: its kernel cache is the driver's own")


def aberrant(cache_dir: Path | str, *argv: str, code: str | None = None) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("POCL_CACHE_DIR", "ABERRANT_BACKEND")}
    env["ABERRANT_CACHE_DIR"] = str(cache_dir)
    command = [sys.executable, "-c", code, *argv] if code else [sys.executable, "-m", "aberrant.cli", *argv]
    return subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def filled(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A cache that one render filled (and recorded): copied by each test before it corrupts it."""
    root = tmp_path_factory.mktemp("filled")
    result = aberrant(root, *ARGV, "--out", str(root / "frame.png"))
    assert result.returncode == 0, result.stderr
    assert list((root / "opencl" / "pocl").rglob(cache.RECORD)), "nothing was recorded after the frame"
    return root


def copy_of(filled: Path, tmp_path: Path) -> Path:
    target = tmp_path / "cache"
    shutil.copytree(filled, target)
    return target


def corrupt(root: Path, how: str) -> Path:
    """Damage the cached program as ``how`` says; returns the damaged file."""
    pocl = root / "opencl" / "pocl"
    [library] = pocl.rglob("trace.so")
    [bitcode] = pocl.rglob("program.bc")
    if how == "truncated trace.so":
        os.truncate(library, 100)
        return library
    if how == "garbage in program.bc":
        bitcode.write_bytes(os.urandom(1000))
        return bitcode
    if how == "truncated trace.so, never recorded":  # a cache from before records were kept
        (library.parents[2] / cache.RECORD).unlink()
        os.truncate(library, library.stat().st_size // 2)
        return library
    raise ValueError(how)


CORRUPTIONS = ["truncated trace.so", "garbage in program.bc", "truncated trace.so, never recorded"]


@pytest.mark.parametrize("how", CORRUPTIONS)
def test_a_corrupt_cache_entry_is_removed_and_rebuilt_with_one_warning(filled, tmp_path, how):
    root = copy_of(filled, tmp_path)
    damaged = corrupt(root, how)
    out = tmp_path / "frame.png"
    result = aberrant(root, *ARGV, "--out", str(out))
    assert result.returncode == 0, result.stderr
    [line] = [line for line in result.stderr.splitlines() if line.startswith("aberrant:")]
    assert line.startswith("aberrant: warning: removed a corrupt OpenCL kernel cache entry ") and "rebuilding" in line
    assert damaged.name in line
    assert "with the opencl backend" in result.stdout and out.is_file()
    again = aberrant(root, *ARGV, "--out", str(out))  # rebuilt whole: no warning the second time
    assert again.returncode == 0 and "aberrant: warning" not in again.stderr, again.stderr


@pytest.mark.parametrize("how", CORRUPTIONS[:2])
def test_pocl_itself_aborts_on_the_corrupt_entry(filled, tmp_path, how):
    """Why the check exists: with it switched off the same files abort the process inside PoCL."""
    root = copy_of(filled, tmp_path)
    corrupt(root, how)
    result = aberrant(root, *ARGV, "--out", str(tmp_path / "frame.png"), code=UNCHECKED)
    assert result.returncode in (-6, 134), (result.returncode, result.stderr[-500:])


def test_backends_lists_opencl_as_available_with_a_corrupt_cache(filled, tmp_path):
    root = copy_of(filled, tmp_path)
    corrupt(root, "truncated trace.so")
    result = aberrant(root, "backends")
    assert result.returncode == 0 and "opencl: available" in result.stdout, result.stderr


@contextlib.contextmanager
def read_only(folder: Path) -> Iterator[None]:
    """``folder`` unwritable even for root: a read-only tmpfs mounted on it (skips where none can be mounted)."""
    if os.access(folder, os.W_OK):  # root ignores the permission bits
        if shutil.which("mount") is None:
            pytest.skip("this user can write into a read-only folder and there is no mount(8) to make one")
        mounted = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(folder)], capture_output=True
        )
        if mounted.returncode != 0:
            pytest.skip(f"this user can write into a read-only folder and cannot mount one: {mounted.stderr!r}")
        try:
            yield
        finally:
            subprocess.run(["umount", str(folder)], check=True)
        return
    yield


@pytest.mark.parametrize("kind", ["a file", "/dev/null", "read-only"])
def test_an_unusable_cache_directory_compiles_without_one(tmp_path, kind):
    if kind == "a file":
        where: Path | str = tmp_path / "cache"
        Path(where).write_text("not a folder")
    elif kind == "/dev/null":
        where = "/dev/null"
    else:
        where = tmp_path / "cache"
        Path(where).mkdir()
        Path(where).chmod(0o555)
    with read_only(Path(where)) if kind == "read-only" else contextlib.nullcontext():
        out = tmp_path / "frame.png"
        result = aberrant(where, *ARGV, "--out", str(out))
    assert result.returncode == 0, result.stderr
    [line] = [line for line in result.stderr.splitlines() if line.startswith("aberrant:")]
    assert line.startswith("aberrant: warning: the OpenCL kernel cache ") and "cannot be used" in line
    assert "with the opencl backend" in result.stdout and out.is_file()


def test_configure_caches_falls_back_to_a_private_directory(tmp_path, monkeypatch, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(blocker))
    monkeypatch.delenv("POCL_CACHE_DIR", raising=False)
    private = cache.configure_caches()
    assert private is not None and not private.startswith(str(blocker))
    assert os.environ["POCL_CACHE_DIR"].startswith(str(Path(private).parent)) and os.path.isdir(
        os.environ["POCL_CACHE_DIR"]
    )
    assert "cannot be used (Not a directory)" in capsys.readouterr().err


def test_recorded_files_must_keep_their_hash_and_unrecorded_ones_be_whole(filled, tmp_path, capsys):
    root = copy_of(filled, tmp_path) / "opencl" / "pocl"
    assert cache.verify(root) == []  # a good cache is left alone
    [record] = root.rglob(cache.RECORD)
    assert set(json.loads(record.read_text())) == {"program.bc", "trace/16-16-1-goffs0-smallgrid/trace.so"}
    [bitcode] = root.rglob("program.bc")
    data = bytearray(bitcode.read_bytes())
    data[len(data) // 2] ^= 0xFF  # one flipped byte: still well-formed, but not what ran
    bitcode.write_bytes(bytes(data))
    assert cache.verify(root) == [record.parent]
    assert not record.parent.exists()
    assert "program.bc: changed since it was verified" in capsys.readouterr().err


def test_file_checks_catch_truncation_and_foreign_files(filled):
    pocl = filled / "opencl" / "pocl"
    for path in (*pocl.rglob("program.bc"), *pocl.rglob("trace.so")):
        data = path.read_bytes()
        assert cache.file_problem(path, data) is None
        for cut in (1, 100, len(data) // 2, len(data) - 4):
            assert cache.file_problem(path, data[:cut]) is not None, (path.name, cut)
        assert cache.file_problem(path, b"\0" * len(data)) is not None


def test_a_build_that_fails_from_a_cache_entry_removes_it_and_tries_again(monkeypatch, tmp_path, capsys):
    """A cl.Error while building after PoCL touched an entry: the entry goes, the build runs once more."""
    import pyopencl as cl

    from backends.opencl.backend import OpenClBackend

    entry = tmp_path / "pocl" / "AB" / "CDEF"
    entry.mkdir(parents=True)
    (entry / "program.bc").write_bytes(b"BC\xc0\xde")
    real_build = cl.Program.build
    calls: list[int] = []

    def build(self: cl.Program, *args: object, **kwargs: object) -> cl.Program:
        calls.append(1)
        if len(calls) == 1:
            raise cl.RuntimeError("clBuildProgram failed: BUILD_PROGRAM_FAILURE (simulated)")
        return real_build(self, *args, **kwargs)

    monkeypatch.setattr(cl.Program, "build", build)
    backend = OpenClBackend()
    monkeypatch.setattr(cache, "_ours", str(tmp_path / "pocl"))  # the cache this process checks
    try:
        kernel = backend._build("__kernel void trace(__global int *x) { x[0] = 1; }")
    finally:
        backend.release()
    assert kernel is not None and len(calls) == 2
    assert not entry.exists()
    assert "did not build from its cache entry" in capsys.readouterr().err


def test_an_error_in_the_source_leaves_the_cache_entries_touched_meanwhile(tmp_path, capsys):
    """Another process's entry, used while this build failed on its own source, stays: only a failure that a
    cache entry may have caused removes what was touched."""
    from backends.opencl.backend import OpenClBackend
    from engine.errors import BackendUnavailable

    entry = tmp_path / "pocl" / "AB" / "CDEF"
    entry.mkdir(parents=True)
    (entry / "program.bc").write_bytes(b"BC\xc0\xde")
    backend = OpenClBackend()
    try:
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(cache, "_ours", str(tmp_path / "pocl"))
            with pytest.raises(BackendUnavailable, match="boom"):
                backend._build("__kernel void trace(__global int *x) { x[0] = 1; }\n#error boom\n")
    finally:
        backend.release()
    assert (entry / "program.bc").exists()
    assert "did not build from its cache entry" not in capsys.readouterr().err
