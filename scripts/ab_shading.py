"""Interleaved A/B: the starter demo textured and smooth-shaded against the same frame flat and untextured.

Both variants are packed and uploaded once on their own backend instance; frames then alternate A, B, A,
B, ... and the figure is the median of the paired ratios B/A, so load on the machine cancels out
(``--cpu``: the process's CPU time over all threads, steadier on a shared machine than the wall).
Run from the repository root: ``python scripts/ab_shading.py [--pairs 9] [--size 480x300]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from backends.base import backend_class
from backends.upload import SceneUploader
from components import Mesh
from demos import starter
from engine.camera_view import scene_camera
from engine.scene import Scene


def without(scene: Scene, textures: bool = True, smooth: bool = True) -> Scene:
    """The scene with its textures and/or smooth flags taken off (both: the frame before either existed)."""
    for entity, mesh in scene.query(Mesh):
        scene.set(entity, dataclasses.replace(mesh, texture="" if textures else mesh.texture,
                                              smooth=mesh.smooth and not smooth))  # fmt: skip
    return scene


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--pairs", type=int, default=9)
    parser.add_argument("--size", default="480x300")
    parser.add_argument("--backends", default="glsl,opencl")
    parser.add_argument("--cpu", action="store_true", help="time the process's CPU (all threads), not the wall")
    parser.add_argument("--split", action="store_true", help="also textures alone and smooth normals alone")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    for name in args.backends.split(","):
        variants = {"flat": without(starter.build()), "shaded": starter.build()}
        if args.split:
            variants["textures"] = without(starter.build(), textures=False)
            variants["smooth"] = without(starter.build(), smooth=False)
        backends = {}
        for label, scene in variants.items():
            backends[label] = backend_class(name)()
            SceneUploader(backends[label]).sync(scene)
            backends[label].render(scene_camera(scene), width, height, ("color",))  # compile, warm up
        ratios = []
        for _ in range(args.pairs):
            times = {}
            for label, scene in variants.items():
                start = time.process_time() if args.cpu else time.perf_counter()
                backends[label].render(scene_camera(scene), width, height, ("color",))
                times[label] = (time.process_time() if args.cpu else time.perf_counter()) - start
            ratios.append({label: t / times["flat"] for label, t in times.items() if label != "flat"})
        for label in ratios[0]:
            r = [pair[label] for pair in ratios]
            print(f"{name}: {label} / flat = {statistics.median(r):.3f}x (median of {args.pairs} interleaved pairs, "
                  f"{width}x{height}; range {min(r):.3f}-{max(r):.3f})")  # fmt: skip
        for backend in backends.values():
            backend.release()
    return 0


if __name__ == "__main__":
    sys.exit(main())
