"""What one shadowing sun costs: frames with it against the same scene with no Light entity.

An interleaved A/B in one process (``space_scale.paired``: samples of a few frames of the two scenes
alternate on two backends of one kind, the cost the median of the paired ratios of CPU time): the
space-count sweep's floor and 30 boxes, each with one sun casting shadows against the implicit sun without
shadows, and any demo from its start (``house``: portals in view, the sun's shadow rays pass them) with its
Light entities against none (its implicit sun).

    python scripts/light_cost.py --backends opencl glsl --pairs 15
    python scripts/light_cost.py --scenes aberration_tunnels --size 320 --height 240
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from space_scale import base_scene, paired

from components import Light
from demos import build_demo, demo_names
from engine.scene import Scene


def boxes(sun: bool) -> Scene:
    scene = base_scene("boxes")
    if sun:
        scene.add_light("sun", "sun", look_at=(-0.4, -0.8, -0.3))
    return scene


def demo(name: str) -> Callable[[bool], Scene]:
    def build(sun: bool) -> Scene:
        scene = build_demo(name)
        if not sun:
            for entity, _ in scene.query(Light):
                scene.delete(entity)
        return scene

    return build


SCENES: dict[str, Callable[[bool], Scene]] = {"boxes": boxes, **{name: demo(name) for name in demo_names()}}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backends", nargs="+", default=["opencl", "glsl"])
    parser.add_argument("--precision", default="f32")
    parser.add_argument("--scenes", nargs="+", default=["boxes", "house"], choices=list(SCENES))
    parser.add_argument("--size", type=int, default=320, help="width (and height, unless --height)")
    parser.add_argument("--height", type=int, default=None)
    parser.add_argument("--pairs", type=int, default=15)
    args = parser.parse_args()
    for name in args.backends:
        for scene_name in args.scenes:
            lit, plain = SCENES[scene_name](True), SCENES[scene_name](False)
            try:
                row = {"backend": name, "scene": scene_name}
                size = (args.size, args.height or args.size)
                row.update(paired(name, args.precision, lit, plain, size, args.pairs, {}))
            finally:
                lit.close()
                plain.close()
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
