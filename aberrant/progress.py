"""A progress bar on stderr: done/total, rate, elapsed, ETA and what runs now (bench, flythroughs).

On a terminal it redraws one line; elsewhere (CI logs, captured test output)
it prints a line at most every few seconds, so a long run still shows that
it lives without flooding the log.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

BAR = 24


def clock(seconds: float) -> str:
    """``m:ss`` (or ``h:mm:ss``) for a duration."""
    seconds = max(0, round(seconds))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


class Progress:
    """``step(label)`` after each unit of work; ``note(text)`` for a line of its own."""

    def __init__(
        self,
        total: int,
        stream: TextIO | None = None,
        interval_s: float = 5.0,
        label: str = "bench",
        unit: str = "",
    ) -> None:
        self.label, self.unit = label, unit
        self.total = max(1, total)
        self.done = 0
        self.stream = stream if stream is not None else sys.stderr
        self.start = time.perf_counter()
        self.interval_s = interval_s
        self._last = -1e9
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._width = 0

    def line(self, label: str = "") -> str:
        elapsed = time.perf_counter() - self.start
        filled = int(BAR * self.done / self.total)
        eta = elapsed / self.done * (self.total - self.done) if self.done else float("nan")
        eta_text = clock(eta) if self.done else "?"
        bar = "#" * filled + "." * (BAR - filled)
        rate = f" {self.done / elapsed:.2f} {self.unit}/s," if self.unit and elapsed > 0 else ""
        counts = f"{self.done}/{self.total}{' ' + self.unit if self.unit else ''}"
        return f"{self.label} [{bar}] {counts}{rate} {clock(elapsed)} elapsed, ETA {eta_text}  {label}".rstrip()

    def step(self, label: str = "", count: int = 1) -> None:
        self.done = min(self.total, self.done + count)
        self.show(label)

    def show(self, label: str = "") -> None:
        now = time.perf_counter()
        text = self.line(label)
        if self._tty:
            pad = max(0, self._width - len(text))
            self.stream.write("\r" + text + " " * pad)
            self._width = len(text)
            self.stream.flush()
        elif now - self._last >= self.interval_s or self.done == self.total:
            self.stream.write(text + "\n")
            self.stream.flush()
            self._last = now

    def note(self, text: str) -> None:
        if self._tty and self._width:
            self.stream.write("\r" + " " * self._width + "\r")
            self._width = 0
        self.stream.write(text + "\n")
        self.stream.flush()

    def finish(self) -> None:
        if self._tty and self._width:
            self.stream.write("\n")
            self._width = 0
        self.stream.flush()
