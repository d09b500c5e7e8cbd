"""The command line's argument checks, shared by its commands: each bad value is a :class:`UsageError`,
one line and exit status 2, raised before anything is opened or rendered."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from engine.errors import AberrantError, shorten

#: The largest image side ``render`` accepts (guards against typos like 80000x600).
MAX_SIDE = 16384


class UsageError(AberrantError):
    """A command-line argument is wrong."""


def parse_size(text: str) -> tuple[int, int]:
    """``"640x480"`` -> ``(640, 480)``; both sides in [1, MAX_SIDE]."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", text)
    if not match:
        raise UsageError(f"--size must be WIDTHxHEIGHT in pixels, e.g. 640x480; got {text!r}")
    width, height = int(match.group(1)), int(match.group(2))
    for side, value in (("width", width), ("height", height)):
        if not 1 <= value <= MAX_SIDE:
            raise UsageError(f"--size {side} must lie in [1, {MAX_SIDE}] pixels; got {text!r}")
    return width, height


def parse_spp(value: int) -> int:
    """``--spp`` checked before anything is opened: samples a pixel, 1 to MAX_SPP."""
    from backends.samples import MAX_SPP

    if not 1 <= value <= MAX_SPP:
        raise UsageError(f"--spp (samples per pixel) must lie in [1, {MAX_SPP}]; got {value}")
    return value


def check_target(option: str, path: Path) -> None:
    """Fail before rendering when ``path`` cannot be written (so no render time is wasted).

    What is already there must be a writable regular file, or a symlink to one
    (written through); a device, FIFO, socket or folder is refused, never replaced.
    """
    from engine.atomic_files import UnsafeTarget, check_writable

    try:
        check_writable(path)
    except UnsafeTarget as e:
        raise UsageError(f"{option} {shorten(path)}: {e.strerror}") from None


def check_cluster_args(args: argparse.Namespace) -> None:
    """``--workers N`` or ``--scheduler ADDR``, not both, and N at least 1."""
    if args.workers is not None and args.scheduler is not None:
        raise UsageError("give --workers (a cluster started here) or --scheduler (a running one), not both")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")
