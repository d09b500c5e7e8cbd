"""The memory budget: a render or flythrough that would not fit is refused up front, in one line.

The budget is ``$ABERRANT_MEMORY_BUDGET`` (bytes, or with a unit: ``512M``, ``8G``, ``1.5GiB``)
when set, else :data:`AVAILABLE_FRACTION` of what this process can still get: the least of the
memory the system has available, the address-space limit (``ulimit -v``, less what the process
already maps) and the cgroup's limit (less what the group uses). Nothing is reserved: an estimate
is checked (:func:`check_fits`), so a request that would be OOM-killed an hour in fails at once,
saying what it would need and what to do instead.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from engine.errors import AberrantError

BUDGET_ENV = "ABERRANT_MEMORY_BUDGET"
#: The share of the available memory a render may plan to use (the rest: the OS, other programs, slack).
AVAILABLE_FRACTION = 0.8
_UNITS = {"": 1, "k": 1e3, "m": 1e6, "g": 1e9, "t": 1e12, "ki": 2**10, "mi": 2**20, "gi": 2**30, "ti": 2**40}


def parse_bytes(text: str) -> int:
    """``"8G"`` -> 8e9, ``"512MiB"`` -> 512 * 2**20, ``"1000"`` -> 1000; a :class:`AberrantError` otherwise."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d*)?)\s*([kmgt]i?)?b?\s*", text, re.IGNORECASE)
    if not match:
        raise AberrantError(f"${BUDGET_ENV} must be a size in bytes such as 4G or 512M; got {text[:40]!r}")
    return int(float(match.group(1)) * _UNITS[(match.group(2) or "").lower()])


def format_bytes(n: float) -> str:
    """``1.3 GB``: decimal units, three significant digits."""
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} bytes"


def _meminfo_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    if hasattr(os, "sysconf"):
        try:
            return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (OSError, ValueError):
            pass
    return None


def _address_space_left() -> int | None:
    """What ``ulimit -v`` (RLIMIT_AS) still allows this process to map, or ``None`` without a limit."""
    try:
        import resource
    except ImportError:
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    mapped = 0
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                mapped = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return max(0, soft - mapped)


def _cgroup_left() -> int | None:
    """What the cgroup (v2) memory limit still allows, or ``None`` without one."""
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit == "max":
            return None
        used = int(Path("/sys/fs/cgroup/memory.current").read_text())
        return max(0, int(limit) - used)
    except (OSError, ValueError):
        return None


def memory_budget() -> tuple[int, str]:
    """The budget in bytes and where it comes from (for messages)."""
    raw = os.environ.get(BUDGET_ENV, "").strip()
    if raw:
        return parse_bytes(raw), f"${BUDGET_ENV}"
    limits = [(n, why) for n, why in (
        (_meminfo_available(), "available memory"),
        (_address_space_left(), "the address-space limit (ulimit -v)"),
        (_cgroup_left(), "the cgroup memory limit"),
    ) if n is not None]  # fmt: skip
    if not limits:
        return 2**62, "no known limit"
    left, why = min(limits)
    return int(left * AVAILABLE_FRACTION), f"{AVAILABLE_FRACTION:.0%} of {why}; set ${BUDGET_ENV} to change it"


def check_fits(need: int, what: str, advice: str) -> None:
    """Raise a one-line :class:`AberrantError` when ``need`` bytes exceed the budget: what, how much, what to do."""
    budget, source = memory_budget()
    if need > budget:
        raise AberrantError(
            f"{what} needs about {format_bytes(need)} of memory, more than the budget of {format_bytes(budget)} "
            f"({source}); {advice}"
        )
