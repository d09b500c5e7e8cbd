"""The space trees' walk in a kernel variant against another (by default OpenCL's 4-wide form against the
binary trees): an interleaved A/B in one process.

Each scene (``space-<kind>-<in|out>-<n>`` or ``hotel-view-<view>``, as scripts/space_walk.py names them) is
loaded twice per backend, with ``--after``'s defines (none: as the backend is) and with ``--before``'s
(``SPACE_WIDE=0``);
their frames alternate, and the ratio is the median of the paired ratios of CPU time (the process's, every
driver thread included), after over before. Also says whether the two frames are the same to the bit.
``--shut``: a hotel view's twin with its doors shut (no portal) joins the alternation, and both variants'
times are also given over its time (what the portals cost in each).

    python scripts/space_tree_ab.py space-portals-in-16 hotel-view-start --backends opencl glsl --pairs 11
    python scripts/space_tree_ab.py hotel-view-start hotel-view-room --before VIEW_TILES=0 --after "" --shut
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from space_cost import variant
from space_scale import loaded
from space_walk import build

from aberrant.bench.architecture import hotel_views


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--backends", nargs="+", default=["opencl", "glsl"])
    parser.add_argument("--size", type=int, default=320)
    parser.add_argument("--pairs", type=int, default=11)
    parser.add_argument("--frames", type=int, default=2, help="frames per timed sample")
    parser.add_argument("--before", default="SPACE_WIDE=0", help="DEFINE=VALUE,... of the base")
    parser.add_argument("--after", default="", help="DEFINE=VALUE,... of the other")
    parser.add_argument("--shut", action="store_true", help="hotel views: also time the doors-shut twin")
    args = parser.parse_args()
    before, after = variant(f"before:{args.before}")[1], variant(f"after:{args.after}")[1]
    shut = {view: twin for view, _, twin, _ in hotel_views()}
    for name in args.backends:
        for scene in args.scenes:
            units = [loaded(name, "f32", build(scene), defines) for defines in (before, after)]
            if args.shut and scene in shut:
                units.append(loaded(name, "f32", shut[scene](Path(".")), before))
            try:
                images = [b.render(c, args.size, args.size, ("color",)).color for b, c in units]
                times: list[list[float]] = [[] for _ in units]
                for _ in range(args.pairs):
                    for k, (backend, camera) in enumerate(units):
                        start = time.process_time()
                        for _ in range(args.frames):
                            backend.render(camera, args.size, args.size, ("color",))
                        times[k].append((time.process_time() - start) / args.frames)
                base, other = np.array(times[0]), np.array(times[1])
                against = ""
                if len(units) > 2:
                    plain = np.array(times[2])
                    against = (
                        f"before/shut {np.median(base / plain):.3f}x, after/shut {np.median(other / plain):.3f}x, "
                    )
                print(
                    f"{name} {scene}: before {np.median(base) * 1e3:.1f} ms, after {np.median(other) * 1e3:.1f} ms, "
                    f"after/before {np.median(other / base):.3f}x, {against}({args.pairs} pairs), "
                    f"frames identical: {np.array_equal(images[0], images[1])}",
                    flush=True,
                )
            finally:
                for backend, _ in units:
                    backend.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
