"""The OpenCL kernel caches: where they live, and that what PoCL loads from them is whole.

PoCL keeps each built program under ``$POCL_CACHE_DIR/XX/HASH/``: ``program.bc``
(LLVM bitcode) and, per work-group shape, ``KERNEL/SHAPE/KERNEL.so``. It trusts
those files: a truncated ``.so`` or garbage in ``program.bc`` makes it abort the
process (``dlopen failed``, or an assertion) on every build until the cache is
deleted by hand. So before PoCL reads the cache (once a process) every entry is
checked: files recorded after a frame rendered from them must still have the
recorded SHA-256 (``aberrant-verified.json`` in the entry); files not recorded yet
must at least be whole (bitcode whose top-level blocks end at the end of the file,
an ELF file whose headers and segments lie inside it). An entry that fails is
removed, with one warning line, and PoCL rebuilds it. A build that fails while it
used a cache entry gets that entry removed and one more try (:func:`forget_touched`); one that fails on an
error in its source leaves the cache alone.

A cache directory that cannot be used (a file, ``/dev/null``, read-only) costs
rebuilds, never the backend: the process compiles into a private temporary
directory instead, after one warning line.
"""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import json
import os
import shutil
import struct
import sys
import tempfile
import time
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterable
from pathlib import Path
from typing import Any

from engine.atomic_files import write_atomically
from engine.bvh_cache import default_cache_dir

#: The record of an entry's verified files (relative path -> SHA-256), beside PoCL's files.
RECORD = "aberrant-verified.json"
#: PoCL's leftover ``tempfile_*`` files older than this are removed (it leaves one or two per build).
STALE_TEMP_SECONDS = 3600.0
_CHECKED = (".bc", ".so")
_verified: set[str] = set()
_warned: set[str] = set()
#: The PoCL cache this process checks and records (``None``: a user's own, or a private temporary one).
_ours: str | None = None


def _warn(message: str) -> None:
    """One ``aberrant: warning:`` line on stderr, once per message and process."""
    if message not in _warned:
        _warned.add(message)
        print(f"aberrant: warning: {message}", file=sys.stderr)


def _unusable(directory: str) -> str | None:
    """Why ``directory`` cannot hold a cache (it is made if missing), or ``None`` when a file can be written there."""
    try:
        os.makedirs(directory, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=directory, prefix=".aberrant-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        return e.strerror or str(e)
    return None


def _private_dir() -> str:
    """A temporary directory for this process's kernels, removed at exit."""
    path = tempfile.mkdtemp(prefix="aberrant-opencl-")
    atexit.register(shutil.rmtree, path, ignore_errors=True)
    return path


def configure_caches() -> str:
    """Point PoCL's kernel cache at ``$ABERRANT_CACHE_DIR/opencl`` (``~/.cache/aberrant`` by default, like
    the BVH cache; so CI runs are repeatable), checked.

    Must run before PoCL is first initialised (the first platform query of the
    process); a user's own ``POCL_CACHE_DIR`` wins, and is left to them (not
    checked: other programs' kernels may share it). Returns the directory for
    pyopencl's compiler cache (which has no environment variable: it is passed
    to each build). An unusable directory is replaced by a private temporary
    one, with a warning.
    """
    global _ours
    base = os.path.join(str(default_cache_dir()), "opencl")
    pocl = os.environ.setdefault("POCL_CACHE_DIR", os.path.join(base, "pocl"))
    if not pocl.startswith(base + os.sep):
        return os.path.join(base, "pyopencl")
    reason = _unusable(pocl)
    if reason is not None:
        private = _private_dir()
        _warn(f"the OpenCL kernel cache {pocl} cannot be used ({reason}); compiling into {private} instead")
        os.environ["POCL_CACHE_DIR"] = os.path.join(private, "pocl")
        os.makedirs(os.environ["POCL_CACHE_DIR"], exist_ok=True)
        return os.path.join(private, "pyopencl")
    _ours = pocl
    verify_once(pocl)
    return os.path.join(base, "pyopencl")


# --- in this process ----------------------------------------------------------------------------

#: Programs kept built, per context, most recently used last. Building a program, even from PoCL's
#: cache, leaves about 12 KB of PoCL's memory behind each time (bare contexts leave none): a process
#: that creates and releases backends (the editor switching, tests) reuses these instead.
PROGRAMS_KEPT = 32
_contexts: dict[int, Any] = {}
_programs: OrderedDict[tuple[int, Hashable], Any] = OrderedDict()


def shared_context(device: Any) -> Any:
    """The one context of ``device`` in this process (every backend on it shares it, and its programs)."""
    import pyopencl as cl

    key = device.int_ptr
    context = _contexts.get(key)
    if context is None:
        context = _contexts[key] = cl.Context([device])
    return context


#: Kernel objects a released backend gave back, per program (creating one leaves ~1.7 KB of PoCL's
#: memory behind): at most this many per program wait for the next backend.
KERNELS_KEPT = 4
_free_kernels: dict[tuple[int, Hashable], list[Any]] = {}


def kept_program(context: Any, key: Hashable, build: Callable[[], Any]) -> Any:
    """The program ``key`` built in ``context``: kept from an earlier ``build()``, or built now and kept."""
    full = (context.int_ptr, key)
    program = _programs.get(full)
    if program is None:
        program = _programs[full] = build()
        while len(_programs) > PROGRAMS_KEPT:
            evicted, _ = _programs.popitem(last=False)
            _free_kernels.pop(evicted, None)
    _programs.move_to_end(full)
    return program


def take_kernel(context: Any, key: Hashable, make: Callable[[], Any]) -> Any:
    """A kernel of program ``key`` for one backend's sole use: one given back earlier, or ``make()``'s.

    A kernel keeps the arguments its last user set: the taker sets every argument before its first launch.
    """
    free = _free_kernels.get((context.int_ptr, key))
    return free.pop() if free else make()


def give_back_kernels(context: Any, kernels: Iterable[tuple[Hashable, Any]]) -> None:
    """Kernels of a released backend, ``(program key, kernel)``, kept for the next one (while their program is)."""
    for key, kernel in kernels:
        full = (context.int_ptr, key)
        if full in _programs:
            free = _free_kernels.setdefault(full, [])
            if len(free) < KERNELS_KEPT:
                free.append(kernel)


# --- whole files -------------------------------------------------------------------------------


def _bitcode_problem(data: bytes) -> str | None:
    """Why ``data`` is not whole LLVM bitcode: its top-level blocks must end exactly at the end of the file."""
    if data[:4] == b"\xde\xc0\x17\x0b":  # the wrapper header: magic, version, offset, size, cputype
        if len(data) < 20:
            return "truncated bitcode wrapper"
        offset, size = struct.unpack_from("<II", data, 8)
        if offset + size > len(data):
            return "bitcode wrapper larger than the file"
        data = data[offset : offset + size]
    if data[:4] != b"BC\xc0\xde":
        return "not LLVM bitcode"
    if len(data) % 4:
        return "bitcode not a whole number of words"
    total = len(data) * 8

    def read(position: int, width: int) -> int:
        value = 0
        for i in range(width):
            bit = position + i
            value |= ((data[bit >> 3] >> (bit & 7)) & 1) << i
        return value

    def vbr(position: int, width: int) -> tuple[int, int]:
        value, shift = 0, 0
        while True:
            if position + width > total:
                raise IndexError
            chunk = read(position, width)
            position += width
            value |= (chunk & ((1 << (width - 1)) - 1)) << shift
            shift += width - 1
            if not chunk >> (width - 1):
                return value, position

    position = 32
    try:
        while total - position >= 32:
            if read(position, 2) != 1:  # at the top level only ENTER_SUBBLOCK may appear
                return "bitcode block structure broken"
            _, position = vbr(position + 2, 8)  # block id
            _, position = vbr(position, 4)  # abbreviation width
            position = (position + 31) & ~31
            if position + 32 > total:
                return "truncated bitcode"
            position += 32 + 32 * read(position, 32)
            if position > total:
                return "truncated bitcode"
    except IndexError:
        return "truncated bitcode"
    return None


def _elf_problem(data: bytes) -> str | None:
    """Why ``data`` is not a whole ELF file: its header tables and loaded segments must lie inside it."""
    if data[:4] != b"\x7fELF" or len(data) < 52:
        return "not an ELF file"
    wide, endian = data[4] == 2, "<" if data[5] == 1 else ">"
    if wide:
        if len(data) < 64:
            return "truncated ELF header"
        phoff, shoff = struct.unpack_from(endian + "QQ", data, 32)
        phentsize, phnum, shentsize, shnum = struct.unpack_from(endian + "HHHH", data, 54)
    else:
        phoff, shoff = struct.unpack_from(endian + "II", data, 28)
        phentsize, phnum, shentsize, shnum = struct.unpack_from(endian + "HHHH", data, 42)
    if phoff + phnum * phentsize > len(data) or shoff + shnum * shentsize > len(data):
        return "truncated ELF file (headers past its end)"
    word, offset_at, size_at = ("Q", 8, 32) if wide else ("I", 4, 16)  # p_offset and p_filesz in a program header
    for i in range(phnum):
        at = phoff + i * phentsize
        (offset,) = struct.unpack_from(endian + word, data, at + offset_at)
        (filesz,) = struct.unpack_from(endian + word, data, at + size_at)
        if offset + filesz > len(data):
            return "truncated ELF file (a segment past its end)"
    return None


def file_problem(path: Path, data: bytes) -> str | None:
    """Why a cached ``.bc`` or ``.so`` cannot be whole, or ``None``."""
    if not data:
        return "empty"
    return _bitcode_problem(data) if path.suffix == ".bc" else _elf_problem(data)


# --- entries -----------------------------------------------------------------------------------


def _entries(root: Path) -> list[Path]:
    """PoCL's entry folders: ``root/XX/HASH``."""
    try:
        return [entry for bucket in root.iterdir() if bucket.is_dir() for entry in bucket.iterdir() if entry.is_dir()]
    except OSError:
        return []


def _files(entry: Path) -> dict[str, Path]:
    return {str(p.relative_to(entry)): p for p in entry.rglob("*") if p.suffix in _CHECKED and p.is_file()}


def _record(entry: Path) -> dict[str, str]:
    try:
        record = json.loads((entry / RECORD).read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(record, dict):
        return {}
    return {k: v for k, v in record.items() if isinstance(k, str) and isinstance(v, str)}


def _entry_problem(entry: Path) -> str | None:
    record = _record(entry)
    for name, path in _files(entry).items():
        try:
            data = path.read_bytes()
        except OSError as e:
            return f"{name}: {e.strerror}"
        expected = record.get(name)
        if expected is not None:
            if hashlib.sha256(data).hexdigest() != expected:
                return f"{name}: changed since it was verified"
        else:
            problem = file_problem(path, data)
            if problem is not None:
                return f"{name}: {problem}"
    return None


def verify(root: str | os.PathLike[str]) -> list[Path]:
    """Remove every cache entry under ``root`` that is not whole (see the module docstring); returns them."""
    root = Path(root)
    removed: list[Path] = []
    for entry in _entries(root):
        problem = _entry_problem(entry)
        if problem is None:
            continue
        shutil.rmtree(entry, ignore_errors=True)
        removed.append(entry)
        _warn(f"removed a corrupt OpenCL kernel cache entry {entry} ({problem}); rebuilding it")
    now = time.time()
    with contextlib.suppress(OSError):
        for temp in root.glob("tempfile_*"):
            with contextlib.suppress(OSError):
                if now - temp.stat().st_mtime > STALE_TEMP_SECONDS:
                    temp.unlink()
    return removed


def verify_once(root: str) -> None:
    """:func:`verify` the first time this process sees ``root``."""
    if root not in _verified:
        _verified.add(root)
        verify(root)


def record(root: str | os.PathLike[str]) -> None:
    """Record the SHA-256 of every cached file not recorded yet (after a frame rendered: they worked)."""
    for entry in _entries(Path(root)):
        known = _record(entry)
        files = _files(entry)
        if set(files) <= set(known):
            continue
        for name, path in files.items():
            if name not in known:
                with contextlib.suppress(OSError):
                    known[name] = hashlib.sha256(path.read_bytes()).hexdigest()
        with contextlib.suppress(OSError):
            write_atomically({entry / RECORD: json.dumps(known, indent=0, sort_keys=True).encode()})


_recorded: set[Hashable] = set()


def record_once(ran: Hashable) -> None:
    """:func:`record` our cache after the first frame of each program and work-group shape ``ran`` in this
    process (PoCL writes a shape's code when it first runs: that frame is what proves the files good)."""
    if ran not in _recorded and _ours is not None:
        _recorded.add(ran)
        record(_ours)


def forget_touched(since: float) -> list[Path]:
    """Remove the cache entries PoCL used or wrote since ``since`` (a build from them failed); returns them.

    PoCL stamps ``last_accessed`` in an entry on every use, so these are the
    entries the failed build read. An entry holding only a build log (a real
    compile error) is no cache hit and is kept.
    """
    removed: list[Path] = []
    if _ours is None:
        return removed
    for entry in _entries(Path(_ours)):
        try:
            touched = max(p.stat().st_mtime for p in [entry, *entry.iterdir()])
        except (OSError, ValueError):
            continue
        if touched >= since and _files(entry):
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
    return removed
