"""Running a command's render on a backend: the named one or the fallback, checked against the memory budget.

A backend named with ``--backend`` (or ``$ABERRANT_BACKEND``) is what runs, or the
command fails with its real reason. ``auto`` picks the fastest that starts and,
when that one's kernel cannot be built on the first frame, falls back to the
reference backend with one line saying why.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, TypeVar

from engine.errors import QUOTE_LIMIT, AberrantError, shorten

if TYPE_CHECKING:
    from backends.base import Backend

PROG = "aberrant"
#: The backend a render falls back to when the chosen one fails while rendering (it traces everything).
FALLBACK_BACKEND = "reference"

T = TypeVar("T")
#: The longest error line printed: one overlong word (a quoted 200 MB name) is cut to its start first.
MAX_LINE = 1000


def one_line(text: str) -> str:
    """``text`` on one line, each overlong word shortened and the whole at most :data:`MAX_LINE` characters."""
    line = " ".join(shorten(word, QUOTE_LIMIT) for word in str(text).split())
    return line if len(line) <= MAX_LINE else shorten(line, MAX_LINE)


def brief(message: str, errors: int = 2) -> str:
    """A backend failure in one line: its first line plus the first ``errors`` lines that say "error"
    (a compiler log can run to hundreds of lines; the first errors are the ones to read)."""
    lines = [line.strip() for line in message.splitlines() if line.strip()]
    if not lines:
        return ""
    found = [line for line in lines[1:] if "error" in line.lower()][:errors]
    return one_line(" | ".join([lines[0], *found]))


def _raised_by_backend(error: BaseException, backend: Backend) -> bool:
    """Whether ``error`` is the backend's own failure (raised in its package), not the scene's or the caller's."""
    from engine.errors import BackendUnavailable

    if isinstance(error, BackendUnavailable):
        return True
    package = type(backend).__module__.rpartition(".")[0] or type(backend).__module__
    tb = error.__traceback__
    while tb is not None:
        module = str(tb.tb_frame.f_globals.get("__name__", ""))
        if module == package or module.startswith(f"{package}."):
            return True
        tb = tb.tb_next
    return False


def with_fallback(args: argparse.Namespace, render: Callable[[Backend], T]) -> tuple[T, str]:
    """``render(backend)`` on the chosen backend; with ``auto``, falling back to the reference when it fails.

    A backend named with ``--backend`` (or ``$ABERRANT_BACKEND``) is what runs,
    or the command fails with its real reason: it never quietly renders with
    another. ``auto`` (the default) picks the fastest backend that starts here,
    and a fast backend can still fail on its first frame, when its kernel is
    built: a driver that cannot compile it, a scene feature it does not trace.
    The scene itself is fine (it loaded), so the reference, which traces
    everything, renders it instead, after a one-line message saying which
    backend failed and the compiler's first errors.
    """
    from backends.base import create_backend, default_backend_name
    from engine.errors import BackendUnavailable

    name = args.backend or default_backend_name()
    named = name != "auto"
    try:
        backend = create_backend(name, precision=args.precision, fallback=not named)
    except BackendUnavailable as e:
        raise BackendUnavailable(f"{brief(str(e))}; --backend auto picks one that can") from None
    try:
        return render(backend), backend.name
    except AberrantError as e:
        if backend.name == FALLBACK_BACKEND or not _raised_by_backend(e, backend):
            raise
        failure = brief(str(e))
        if named:
            raise BackendUnavailable(f"{failure}; --backend auto falls back to one that can") from None
    finally:
        backend.release()
    print(
        f"{PROG}: the {backend.name} backend failed ({failure}); falling back to the {FALLBACK_BACKEND} backend",
        file=sys.stderr,
    )
    reference = create_backend(FALLBACK_BACKEND, fallback=False)
    try:
        return render(reference), reference.name
    finally:
        reference.release()


def check_frame_memory(backend: Backend, size: tuple[int, int], aovs: Sequence[str], other: str) -> None:
    """Refuse up front a frame that would not fit in the memory budget (aberrant/memory.py)."""
    from aberrant.memory import check_fits

    width, height = size
    check_fits(
        backend.frame_bytes(width, height, aovs),
        f"a {width}x{height} frame with the {backend.name} backend",
        f"choose a smaller --size{f', or {other}' if other else ''}",
    )
