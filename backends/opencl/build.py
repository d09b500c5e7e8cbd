"""Building the OpenCL kernel's programs: the options every variant is built with, and a build that recovers
from a corrupt entry of PoCL's or pyopencl's binary caches (:mod:`backends.opencl.cache`) by removing it and
trying once more, while an error in the source itself fails at once with the compiler's log."""

from __future__ import annotations

import re
import sys
import time
from typing import TYPE_CHECKING

from backends.opencl import cache
from backends.opencl.devices import first_line
from engine.errors import BackendUnavailable

if TYPE_CHECKING:  # pyopencl is imported lazily: importing this module must not need it
    import pyopencl as cl

#: Build options of every variant. ``-cl-denorms-are-zero`` lets the driver flush float denormals
#: (GPUs mostly do anyway, so the core never relies on them): on PoCL 3.0 a torus of 10,000
#: triangles at f32 took 30 % less time per frame with it, with bit-identical parity results.
#: The gain is not from subnormal data: with the camera off every splitting plane, the packed
#: bounds' subnormals (0 rounded outward) replaced by the smallest normal float, and the core's
#: one subnormal product (the box widening of exits near 0) removed, PoCL 3.1 still spends about
#: 45 % more CPU time on the 10k torus without it (161 vs 238 ms a 800x800 frame): its code
#: generation, not the scene's numbers, depends on the flag.
#: No ``-cl-fast-relaxed-math`` or ``-cl-mad-enable``: the core needs inf/NaN semantics and unfused
#: products for its watertight edge functions.
BUILD_OPTIONS: tuple[str, ...] = ("-cl-denorms-are-zero",)
#: A compiler diagnostic on the source in a build log (``error: /path/file.cl:LINE:COL: ...``): the source's own
#: error, which no cache entry caused.
SOURCE_ERROR = re.compile(r"^(?:fatal )?error: \S+\.cl:\d+:\d+: ", re.MULTILINE)


def build_program(context: cl.Context, source: str, options: tuple[str, ...], cache_dir: str | None) -> cl.Program:
    """Build one program in ``context``; a failure that came from a cached entry removes that entry and tries
    once more. The backend has imported pyopencl (``devices.import_cl``: its caches set up) before."""
    import pyopencl as cl

    for attempt in (1, 2):
        started = time.time() - 1.0  # file times are coarse on some file systems
        try:
            return cl.Program(context, source).build(options=list(options), cache_dir=cache_dir)
        except cl.Error as e:  # its message carries the build log
            # An error on the source leaves the cache alone: the entries touched meanwhile are other
            # processes' (parallel test workers, a cluster's workers sharing the cache), still in use.
            retry = attempt == 1 and SOURCE_ERROR.search(str(e)) is None
            removed = cache.forget_touched(started) if retry else []
            if not removed:
                raise BackendUnavailable(f"opencl backend: the kernel does not build: {e}") from e
            print(
                f"aberrant: warning: the OpenCL kernel did not build from its cache entry {removed[0]} "
                f"({first_line(str(e))}); removed it, rebuilding",
                file=sys.stderr,
            )
    raise AssertionError("unreachable")  # pragma: no cover
