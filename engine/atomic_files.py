"""Atomic file writes: a crash leaves the old file or the new one, never half of one.

Each file is written to a hidden temporary beside its target (named after the
writing process), fsynced, then renamed over the target; a save killed midway
leaves at most that temporary, which the next save of the same file removes.
Scene files, imported Tello levels, rendered images and the bench's results
all save this way, so all get the same target rules (:func:`check_target`):
a target that exists must be a writable regular file (a device, FIFO, socket
or folder is refused, never replaced), and a symlink is written through, to
the file it names, keeping the link. Reads of files a user names go through
:func:`read_regular`, which refuses a FIFO or device instead of blocking on it.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import secrets
import shutil
import stat
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TypeVar

from engine.errors import shorten

#: A temporary older than this is stale even if a process with its PID exists (the PID was reused).
STALE_TEMP_SECONDS = 3600.0
#: ``.NAME.`` + this: a temporary of NAME (a file, or a folder of frames), optionally with an extension.
_TEMP_SUFFIX = re.compile(r"(\d+)-[0-9a-f]{8}\.tmp(?:\.[A-Za-z0-9]{1,8})?")
_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


class UnsafeTarget(OSError):
    """A path that must not be written or read as a plain file (what it is, and why it is refused)."""


def node_kind(mode: int) -> str:
    """What a ``st_mode`` is, in words (``"a FIFO"``), for messages."""
    return next((words for test, words in _KINDS if test(mode)), "not a regular file")


def temp_path(path: Path, suffix: str = "") -> Path:
    """The temporary sibling a save of ``path`` writes first: ``.NAME.PID-RANDOM.tmp`` (hidden, owner named).

    ``suffix`` (``".mp4"``) keeps an extension a writer needs; :func:`clean_stale_temps` knows both forms.
    """
    return path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp{suffix}")


def check_target(path: str | os.PathLike[str]) -> Path:
    """The file a write of ``path`` replaces: ``path`` itself, or the file a symlink there names.

    Raises :class:`UnsafeTarget` (an ``OSError`` naming ``path``) when what is
    there is not a regular file, or is read-only: renaming over it would
    silently swap a device, FIFO or protected file for ours.
    """
    target = Path(path)
    try:
        st = os.lstat(target)
    except FileNotFoundError:
        return target
    if stat.S_ISLNK(st.st_mode):
        try:
            st = os.stat(target)
        except FileNotFoundError:  # a dangling link: writing through it creates the file it names
            return Path(os.path.realpath(target))
        except OSError as e:  # a link loop (ELOOP) or a path through a non-folder
            raise UnsafeTarget(e.errno, f"a symlink that cannot be followed ({e.strerror})", str(path)) from None
        target = Path(os.path.realpath(target))
    if not stat.S_ISREG(st.st_mode):
        raise UnsafeTarget(errno.EEXIST, f"exists and is {node_kind(st.st_mode)}; refusing to replace it", str(path))
    if not st.st_mode & 0o222 or not os.access(target, os.W_OK):
        raise UnsafeTarget(
            errno.EACCES, "the file is read-only; refusing to replace it (make it writable or choose another name)",
            str(path),
        )  # fmt: skip
    return target


def check_writable(path: str | os.PathLike[str], *, folder: bool = False) -> Path:
    """:func:`check_target` (unless ``folder``: the output is a folder, checked by its writer), and the
    folder it goes in exists and is writable: what a command checks before spending time on the output;
    raises :class:`UnsafeTarget` saying which."""
    target = Path(path) if folder else check_target(path)
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise UnsafeTarget(errno.ENOENT, f"the directory {shorten(parent)!r} does not exist", str(path))
    if not os.access(parent, os.W_OK):
        raise UnsafeTarget(errno.EACCES, f"the directory {shorten(parent)!r} is not writable", str(path))
    return target


def read_regular(path: str | os.PathLike[str]) -> bytes:
    """The bytes of the regular file at ``path`` (symlinks followed).

    A FIFO, device or socket raises :class:`UnsafeTarget` at once: it is opened
    non-blocking, so a FIFO with no writer cannot hang the read, and checked
    with ``fstat`` on the open descriptor, so it cannot be swapped in between.
    """
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise UnsafeTarget(errno.EINVAL, f"is {node_kind(mode)}, not a regular file", str(path))
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        with os.fdopen(fd, "rb", closefd=False) as f:
            return f.read()
    finally:
        os.close(fd)


def _process_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists on this machine (assume so where that cannot be asked safely)."""
    if pid == os.getpid():
        return True
    if os.name != "posix":  # os.kill(pid, 0) would terminate the process on Windows
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: it exists, owned by someone else
        return True
    return True


def clean_stale_temps(path: Path) -> list[Path]:
    """Remove the temporaries of ``path`` that a killed save left behind; returns what was removed.

    A temporary (a file, or a flythrough's folder of frames) is stale when the
    process named in it is gone (or it is older than :data:`STALE_TEMP_SECONDS`);
    a save in progress in another live process keeps its file.
    """
    prefix = f".{path.name}."
    removed: list[Path] = []
    try:
        entries = list(os.scandir(path.parent if str(path.parent) else "."))
    except OSError:
        return removed
    now = time.time()
    for entry in entries:
        if not entry.name.startswith(prefix):
            continue
        match = _TEMP_SUFFIX.fullmatch(entry.name[len(prefix) :])
        if match is None:
            continue
        try:
            old = now - entry.stat(follow_symlinks=False).st_mtime > STALE_TEMP_SECONDS
            if old or not _process_alive(int(match.group(1))):
                if entry.is_dir(follow_symlinks=False):
                    shutil.rmtree(entry.path)
                else:
                    os.unlink(entry.path)
                removed.append(Path(entry.path))
        except OSError:  # gone meanwhile, or not ours to remove: leave it
            continue
    return removed


#: A target path: callers hand over mappings keyed by ``Path`` or by ``str`` (Mapping keys are invariant).
PathT = TypeVar("PathT", bound=str | os.PathLike[str])


def write_atomically(outputs: Mapping[PathT, bytes]) -> None:
    """Write each file via a temporary sibling, fsync, then rename over the target.

    All temporaries are written before any rename, so an error while writing
    leaves every target untouched and no temporary behind. A process killed
    mid-save leaves the old file and at most a hidden ``.NAME.PID-RANDOM.tmp``,
    which the next save of that file removes (:func:`clean_stale_temps`).
    Targets are checked first (:func:`check_target`); every ``OSError`` names
    the file it was about (a full disk's ``fsync`` says none by itself).
    """
    staged: list[tuple[str, Path]] = []
    try:
        for target, data in outputs.items():
            path = check_target(target)
            try:
                clean_stale_temps(path)
                tmp = temp_path(path)
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # umask applies, like a normal file
                staged.append((str(tmp), path))
                with os.fdopen(fd, "wb") as f:
                    f.write(data)
                    f.flush()
                    os.fsync(f.fileno())
                with contextlib.suppress(FileNotFoundError):  # keep an existing file's permissions
                    os.chmod(tmp, os.stat(path).st_mode & 0o7777)
            except OSError as e:
                raise named(e, target) from e
        while staged:
            tmp_name, path = staged[0]
            try:
                os.replace(tmp_name, path)
            except OSError as e:
                raise named(e, path) from e
            staged.pop(0)
            _fsync_dir(path.parent)
    finally:
        for tmp_name, _ in staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp_name)


def named(error: OSError, path: str | os.PathLike[str]) -> OSError:
    """``error`` naming ``path`` when it names no file (or only our hidden temporary), same errno."""
    if error.filename is not None and not str(error.filename).endswith(".tmp") and error.filename2 is None:
        return error
    return OSError(error.errno, error.strerror or str(error), str(path))


def _fsync_dir(directory: Path) -> None:
    """Make a rename durable (POSIX); a no-op where directories cannot be opened."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
