"""What the top-level tree's layout costs a frame: the level-like bench scenes per ``tlas_width`` (and kernel
defines), as an interleaved A/B in one process.

Each scene once per variant (``NAME:tlas_width=4`` packs the instance tree 4-wide, other keys are kernel
defines), their frames alternating; each ratio is the median of the paired ratios of CPU time (the
process's, every driver thread included) against the first variant. Also says whether each variant's image
equals the first one's (it must: the tree's layout is unseen in frames).

    python scripts/tlas_cost.py --backends opencl glsl --variant binary:tlas_width=2 --variant w4:tlas_width=4
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aberrant.bench.runner import asset_dir
from aberrant.bench.scenes import bench_scenes

sys.path.insert(0, str(Path(__file__).resolve().parent))
from space_cost import variant
from space_scale import loaded

#: The packer's options a variant may set; its other keys are kernel defines.
PACKER_KEYS = ("tlas_width",)
SCENES = ("village", "hotel-closed", "starter", "house-open")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backends", nargs="+", default=["opencl", "glsl"])
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--variant", action="append", default=[], type=variant, help="NAME:KEY=VALUE,...")
    parser.add_argument("--precision", default="f32", choices=["f32", "f64"])
    parser.add_argument("--size", type=int, default=320)
    parser.add_argument("--pairs", type=int, default=11)
    parser.add_argument("--frames", type=int, default=2, help="frames per timed sample")
    args = parser.parse_args()
    variants = args.variant or [("binary", {"tlas_width": 2}), ("wide4", {"tlas_width": 4})]
    specs, folder = bench_scenes(), asset_dir()
    for name in args.backends:
        for scene_name in args.scenes:
            scene = specs[scene_name].build(folder)
            units = []
            for v, keys in variants:
                options = {k: keys[k] for k in keys if k in PACKER_KEYS}
                defines = {k: keys[k] for k in keys if k not in PACKER_KEYS}
                units.append((v, *loaded(name, args.precision, scene, defines, **options)))
            try:
                images = [b.render(c, args.size, args.size, ("color", "instance")) for _, b, c in units]
                times: list[list[float]] = [[] for _ in units]
                for _ in range(args.pairs):
                    for k, (_, backend, camera) in enumerate(units):
                        start = time.process_time()
                        for _ in range(args.frames):
                            backend.render(camera, args.size, args.size, ("color",))
                        times[k].append((time.process_time() - start) / args.frames)
                base = np.array(times[0])
                head = f"{name} {args.precision} {scene_name}: {units[0][0]}"
                print(f"{head} {np.median(base) * 1e3:.1f} ms CPU a frame", flush=True)
                for k, (v, *_) in enumerate(units[1:], 1):
                    same = all(np.array_equal(images[k].aov(a), images[0].aov(a)) for a in ("color", "instance"))
                    ratio = np.median(np.array(times[k]) / base)
                    print(f"  {v:12s} {ratio:.3f}x {units[0][0]}, image as it: {same}", flush=True)
            finally:
                for _, backend, _ in units:
                    backend.release()
            scene.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
