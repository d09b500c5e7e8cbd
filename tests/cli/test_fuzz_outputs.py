"""Hostile output targets: whatever already sits at an output path is never silently replaced.

Every writer (``render --out``/``--aovs``, flythroughs, ``save_scene``,
``import-tello``) goes through ``engine.atomic_files``: a target that exists
must be a writable regular file. A device node, FIFO, socket or directory is
refused in one line (exit 2) and left exactly as it was; a read-only file is
refused rather than replaced; a symlink is written through (the link stays, the
file it names gets the new bytes); a link that cannot be followed is refused.
No temporary is left beside any of them.
"""

from __future__ import annotations

import contextlib
import errno
import os
import socket
import stat
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from aberrant.cli import main
from demos import build_demo
from engine.atomic_files import UnsafeTarget, check_target, read_regular, write_atomically
from engine.scene_file import SceneFileError, save_scene

SIZE = ["--size", "8x6", "--backend", "reference"]
PNG_MAGIC = b"\x89PNG"

pytestmark = pytest.mark.skipif(os.name != "posix", reason="device nodes, FIFOs and sockets are POSIX")


def make_device(path: Path) -> None:
    """A character device like /dev/null (1, 3); skips where this process may not make one (no CAP_MKNOD)."""
    try:
        os.mknod(path, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    except PermissionError as e:
        pytest.skip(f"cannot make a device node here: {e}")


def make_socket(path: Path) -> Iterator[None]:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    cwd = os.getcwd()
    os.chdir(path.parent)  # a relative name: AF_UNIX paths are limited to ~108 bytes
    try:
        sock.bind(path.name)
    finally:
        os.chdir(cwd)
    try:
        yield
    finally:
        sock.close()


@contextlib.contextmanager
def node(kind: str, path: Path) -> Iterator[None]:
    """``path`` made into a node of ``kind`` for the duration."""
    if kind == "device":
        make_device(path)
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "directory":
        path.mkdir()
    elif kind == "socket":
        yield from make_socket(path)
        return
    elif kind == "symlink to a device":
        make_device(path.with_name("dev"))
        path.symlink_to("dev")
    elif kind == "symlink loop":
        path.symlink_to(path.name)
    elif kind == "read-only file":
        path.write_bytes(b"keep me")
        path.chmod(0o444)
    yield


def snapshot(path: Path) -> tuple[int, int, int, bytes]:
    """What a node is, without opening it (a FIFO would block): mode, device, inode, a symlink's target."""
    st = os.lstat(path)
    target = os.readlink(path).encode() if stat.S_ISLNK(st.st_mode) else b""
    data = path.read_bytes() if stat.S_ISREG(st.st_mode) else b""
    return st.st_mode, st.st_rdev, st.st_ino, target + data


REFUSED = ["device", "fifo", "directory", "socket", "symlink to a device", "symlink loop", "read-only file"]
WORDS = {
    "device": "a character device",
    "fifo": "a FIFO",
    "directory": "a directory",
    "socket": "a socket",
    "symlink to a device": "a character device",
    "symlink loop": "symlink",
    "read-only file": "read-only",
}


def cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, list[str]]:
    code = main(list(argv))
    return code, capsys.readouterr().err.splitlines()


def writers(tmp_path: Path) -> dict[str, Callable[[Path], list[str]]]:
    """Each way an output is named: argv for the CLI (or a call, for save_scene) writing ``target``."""
    other = tmp_path / "other"
    other.mkdir()
    return {
        "render --out": lambda t: ["render", "starter", *SIZE, "--out", str(t)],
        "render --aovs": lambda t: ["render", "starter", *SIZE, "--out", str(other / "f.png"), "--aovs", str(t)],
        "flythrough gif": lambda t: ["render", "starter", "--path", "--frames", "2", *SIZE, "--out", str(t)],
    }


@pytest.mark.parametrize("kind", REFUSED)
@pytest.mark.parametrize("writer", ["render --out", "render --aovs", "flythrough gif"])
def test_cli_refuses_a_target_that_is_not_a_writable_regular_file(tmp_path, capsys, kind, writer):
    folder = tmp_path / "out"
    folder.mkdir()
    suffix = {"render --out": ".png", "render --aovs": ".npz", "flythrough gif": ".gif"}[writer]
    target = folder / f"target{suffix}"
    with node(kind, target):
        before = snapshot(target)
        code, err = cli(capsys, *writers(tmp_path)[writer](target))
        assert code == 2, err
        assert len(err) == 1 and err[0].startswith("aberrant: error: "), err
        assert WORDS[kind] in err[0] and str(target) in err[0], err
        assert snapshot(target) == before
        assert sorted(p.name for p in folder.iterdir()) == sorted({target.name, "dev"} & set(os.listdir(folder)))


@pytest.mark.parametrize("kind", REFUSED)
def test_save_scene_refuses_the_same_targets(tmp_path, kind):
    target = tmp_path / "scene.json"
    scene = build_demo("starter")
    try:
        with node(kind, target):
            before = snapshot(target)
            with pytest.raises(SceneFileError) as failure:
                save_scene(scene, target)
            assert str(failure.value).startswith(str(target)) and WORDS[kind] in str(failure.value)
            assert snapshot(target) == before
    finally:
        scene.close()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_a_symlink_is_written_through_and_stays_a_link(tmp_path, capsys):
    real = tmp_path / "real" / "frame.png"
    real.parent.mkdir()
    real.write_bytes(b"old")
    link = tmp_path / "link.png"
    link.symlink_to(real)
    code, err = cli(capsys, "render", "starter", *SIZE, "--out", str(link))
    assert code == 0, err
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert real.read_bytes().startswith(PNG_MAGIC)
    assert sorted(p.name for p in real.parent.iterdir()) == ["frame.png"]  # the temporary lived beside the file


def test_a_dangling_symlink_creates_the_file_it_names(tmp_path, capsys):
    link = tmp_path / "link.png"
    link.symlink_to("made.png")
    code, err = cli(capsys, "render", "starter", *SIZE, "--out", str(link))
    assert code == 0, err
    assert link.is_symlink() and (tmp_path / "made.png").read_bytes().startswith(PNG_MAGIC)


def test_a_writable_file_keeps_its_mode_when_replaced(tmp_path):
    target = tmp_path / "a.bin"
    target.write_bytes(b"old")
    target.chmod(0o640)
    write_atomically({target: b"new"})
    assert target.read_bytes() == b"new" and stat.S_IMODE(target.stat().st_mode) == 0o640


def test_check_target_names_the_path_and_is_an_os_error(tmp_path):
    fifo = tmp_path / "f"
    os.mkfifo(fifo)
    with pytest.raises(UnsafeTarget) as failure:
        check_target(fifo)
    assert isinstance(failure.value, OSError) and failure.value.filename == str(fifo)
    assert check_target(tmp_path / "new.png") == tmp_path / "new.png"


def test_read_regular_refuses_a_fifo_without_blocking(tmp_path):
    fifo = tmp_path / "f"
    os.mkfifo(fifo)  # no writer: a plain open() would block forever
    with pytest.raises(UnsafeTarget, match="a FIFO"):
        read_regular(fifo)
    regular = tmp_path / "r"
    regular.write_bytes(b"x" * 100_000)
    assert read_regular(regular) == b"x" * 100_000


def test_full_disk_errors_name_the_file(tmp_path, monkeypatch):
    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError) as failure:
        write_atomically({tmp_path / "a.png": b"data"})
    assert failure.value.errno == errno.ENOSPC and failure.value.filename == str(tmp_path / "a.png")
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []
