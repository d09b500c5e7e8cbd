"""Atomic file writes: a crash leaves the old file or the new one, never half of one.

Each file is written to a hidden temporary beside its target (named after the
writing process), fsynced, then renamed over the target; a save killed midway
leaves at most that temporary, which the next save of the same file removes.
Scene files, imported Tello levels and the bench's results all save this way.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TypeVar

#: A temporary older than this is stale even if a process with its PID exists (the PID was reused).
STALE_TEMP_SECONDS = 3600.0
_TEMP_SUFFIX = re.compile(r"(\d+)-[0-9a-f]{8}\.tmp")


def temp_path(path: Path) -> Path:
    """The temporary sibling a save of ``path`` writes first: ``.NAME.PID-RANDOM.tmp`` (hidden, owner named)."""
    return path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp")


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

    A temporary is stale when the process named in it is gone (or it is
    older than :data:`STALE_TEMP_SECONDS`); a save in progress in another
    live process keeps its file.
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
    """
    staged: list[tuple[str, Path]] = []
    try:
        for target, data in outputs.items():
            path = Path(target)
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
        while staged:
            tmp_name, path = staged[0]
            os.replace(tmp_name, path)
            staged.pop(0)
            _fsync_dir(path.parent)
    finally:
        for tmp_name, _ in staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp_name)


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
