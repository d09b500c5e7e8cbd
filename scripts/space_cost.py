"""What deformed space costs a ray: the view-filling bench scenes against the plain one, per kernel variant.

An interleaved A/B in one process: ``ten-boxes`` and ``ten-boxes-aberration`` / ``ten-boxes-portals``
(aberrant/bench/scenes.py), each scene once per variant (extra defines, e.g. ``walk-off:SPACE_WALK=0``),
their frames alternating; each ratio is the median of the paired ratios of CPU time (the process's, every
driver thread included: steadier than wall time on a shared machine). Also says whether each variant's
image equals the base variant's, and the plain scene's (a part compiled out that leaves the rays straight).

    python scripts/space_cost.py --backends opencl glsl --variant walk-off:SPACE_WALK=0 --pairs 15
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aberrant.bench.runner import asset_dir
from aberrant.bench.scenes import ten_boxes, ten_boxes_aberration, ten_boxes_portals

sys.path.insert(0, str(Path(__file__).resolve().parent))
from space_scale import loaded

SCENES = {"aberration": ten_boxes_aberration, "portals": ten_boxes_portals}


def variant(text: str) -> tuple[str, dict[str, int]]:
    """``NAME:A=1,B=0`` as (name, defines)."""
    name, _, rest = text.partition(":")
    return name, {k: int(v) for k, v in (d.split("=") for d in rest.split(",") if d)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backends", nargs="+", default=["opencl", "glsl"])
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--variant", action="append", default=[], type=variant, help="NAME:DEFINE=VALUE,...")
    parser.add_argument("--size", type=int, default=400)
    parser.add_argument("--pairs", type=int, default=15)
    parser.add_argument("--frames", type=int, default=2, help="frames per timed sample")
    args = parser.parse_args()
    variants = [("base", {}), *args.variant]
    folder = asset_dir()
    for name in args.backends:
        units = [("plain", "base", *loaded(name, "f32", ten_boxes(folder), {}))]
        units += [(s, v, *loaded(name, "f32", SCENES[s](folder), d)) for s in args.scenes for v, d in variants]
        try:
            images = {(s, v): b.render(c, args.size, args.size, ("color",)).color for s, v, b, c in units}
            times: dict[tuple[str, str], list[float]] = {(s, v): [] for s, v, *_ in units}
            for _ in range(args.pairs):
                for s, v, backend, camera in units:
                    start = time.process_time()
                    for _ in range(args.frames):
                        backend.render(camera, args.size, args.size, ("color",))
                    times[(s, v)].append((time.process_time() - start) / args.frames)
            plain = np.array(times[("plain", "base")])
            print(f"{name}: plain {np.median(plain) * 1e3:.1f} ms CPU a frame, {args.pairs} pairs", flush=True)
            for s, v, *_ in units[1:]:
                t = np.array(times[(s, v)])
                same = np.array_equal(images[(s, v)], images[(s, "base")])
                plain_image = np.array_equal(images[(s, v)], images[("plain", "base")])
                print(
                    f"  {s:10s} {v:12s} {np.median(t / plain):.3f}x plain, "
                    f"{np.median(t / np.array(times[(s, 'base')])):.3f}x base, image as base: {same}, "
                    f"as the plain one: {plain_image}",
                    flush=True,
                )
        finally:
            for *_, backend, _ in units:
                backend.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
