"""What one shadowing sun costs: frames with it against the same scene with no Light entity.

An interleaved A/B in one process (``space_scale.paired``: samples of a few frames of the two scenes
alternate on two backends of one kind, the cost the median of the paired ratios of CPU time): the
space-count sweep's floor and 30 boxes, and a floor under a canopy of overlapping boxes (most shadow rays
blocked), each with one sun casting shadows against the implicit sun without shadows, and any demo from its
start (``house``: portals in view, the sun's shadow rays pass them) with its Light entities against none
(its implicit sun). ``--against REV``: instead, the lit frame with the working
tree's kernels against the same frame with git revision REV's (the kernel files read from git, the generated
layout.h as now), and whether the two images are bit-identical.

    python scripts/light_cost.py --backends opencl glsl --pairs 15
    python scripts/light_cost.py --scenes aberration_tunnels --size 320 --height 240
    python scripts/light_cost.py --against main --scenes canopy starter house
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from space_scale import Source, base_scene, paired

from aberrant.bench.features import unlit
from backends import shared
from backends.base import backend_class
from demos import build_demo, demo_names
from engine.scene import Scene


def boxes(sun: bool) -> Scene:
    scene = base_scene("boxes")
    if sun:
        scene.add_light("sun", "sun", look_at=(-0.4, -0.8, -0.3))
    return scene


def canopy(sun: bool) -> Scene:
    """A floor under a canopy of 150 overlapping boxes: most shadow rays are blocked, inside many instances'
    bounds at once (where stopping at the first hit saves the most)."""
    scene = Scene("canopy")
    scene.add_mesh("floor", "plane", scale=(30.0, 1.0, 30.0), checker=1.0)
    rng = np.random.default_rng(3)
    for k in range(150):
        scene.add_mesh(
            f"leaf{k}",
            "box",
            position=(rng.uniform(-6.0, 6.0), rng.uniform(2.0, 4.0), rng.uniform(-8.0, 2.0)),
            euler_deg=tuple(rng.uniform(0.0, 90.0, 3)),
            scale=tuple(rng.uniform(0.3, 1.5, 3)),
        )
    if sun:
        scene.add_light("sun", "sun", look_at=(-0.3, -1.0, -0.2))
    scene.set_camera((0.0, 1.5, 6.0), look_at=(0.0, 0.0, -3.0), fov_deg=60.0)
    return scene


def demo(name: str) -> Callable[[bool], Scene]:
    def build(sun: bool) -> Scene:
        scene = build_demo(name)
        return scene if sun else unlit(scene)

    return build


SCENES: dict[str, Callable[[bool], Scene]] = {
    "boxes": boxes,
    "canopy": canopy,
    **{name: demo(name) for name in demo_names()},
}


def kernels_at(revision: str, backend: str) -> Source:
    """The backend's kernel source as of a git revision: its kernel files from git, generated ones as now."""
    root = Path(__file__).resolve().parents[1]

    def read_at(name: str, package: str = shared.__name__) -> str:
        if package == shared.__name__ and name in shared.GENERATED:
            return shared.GENERATED[name]()
        path = f"{revision}:{package.replace('.', '/')}/{name}"
        return subprocess.run(["git", "show", path], cwd=root, check=True, capture_output=True, text=True).stdout

    def source(defines: dict[str, int]) -> str:
        with mock.patch.object(shared, "read", read_at):
            return backend_class(backend).source(defines)  # type: ignore[attr-defined]

    return source


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backends", nargs="+", default=["opencl", "glsl"])
    parser.add_argument("--precision", default="f32")
    parser.add_argument("--scenes", nargs="+", default=["boxes", "house"], choices=list(SCENES))
    parser.add_argument("--size", type=int, default=320, help="width (and height, unless --height)")
    parser.add_argument("--height", type=int, default=None)
    parser.add_argument("--pairs", type=int, default=15)
    parser.add_argument("--against", metavar="REV", help="the lit frame against itself with REV's kernels")
    args = parser.parse_args()
    for name in args.backends:
        for scene_name in args.scenes:
            lit, plain = SCENES[scene_name](True), SCENES[scene_name](args.against is not None)
            try:
                row = {"backend": name, "scene": scene_name, "against": args.against}
                size = (args.size, args.height or args.size)
                source = kernels_at(args.against, name) if args.against else None
                row.update(paired(name, args.precision, lit, plain, size, args.pairs, {}, source))
            finally:
                lit.close()
                plain.close()
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
