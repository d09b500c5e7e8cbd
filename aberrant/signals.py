"""SIGTERM and SIGHUP end a command the way Ctrl-C does: as an exception, so every temporary is removed.

Python turns SIGINT into :class:`KeyboardInterrupt`, which unwinds through the
writers' cleanup (a flythrough's frames folder, an atomic write's temporary);
SIGTERM (``kill``, a service manager) and SIGHUP (a closed terminal) would end
the process on the spot instead. :func:`terminations_raise` makes them raise
:class:`Terminated` for the length of a command. A signal the parent set to be
ignored (``nohup``) stays ignored. SIGKILL cannot be caught: what it leaves is
named so that the next run into the same place removes it
(:func:`engine.atomic_files.clean_stale_temps`).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType

#: The signals turned into :class:`Terminated` (those this platform has).
SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))


class Terminated(BaseException):
    """The process was asked to stop (SIGTERM, SIGHUP); a BaseException, like KeyboardInterrupt."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


def _raise(signum: int, frame: FrameType | None) -> None:
    raise Terminated(signum)


@contextlib.contextmanager
def terminations_raise() -> Iterator[None]:
    """Within the block, SIGTERM and SIGHUP raise :class:`Terminated` (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {}
    for signum in SIGNALS:
        handler = signal.getsignal(signum)
        if handler is signal.SIG_IGN:
            continue
        previous[signum] = handler
        signal.signal(signum, _raise)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
