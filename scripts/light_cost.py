"""What one shadowing sun costs: frames with it against the same scene with no Light entity.

An interleaved A/B in one process (``space_scale.paired``: samples of a few frames of the two scenes
alternate on two backends of one kind, the cost the median of the paired ratios of CPU time): the
space-count sweep's floor and 30 boxes, and the ``house`` demo from its start (portals in view, the sun's
shadow rays pass them), each with one sun casting shadows against the implicit sun without shadows.

    python scripts/light_cost.py --backends opencl glsl --pairs 15
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
from demos import build_demo
from engine.scene import Scene


def boxes(sun: bool) -> Scene:
    scene = base_scene("boxes")
    if sun:
        scene.add_light("sun", "sun", look_at=(-0.4, -0.8, -0.3))
    return scene


def house(sun: bool) -> Scene:
    scene = build_demo("house")
    if not sun:
        for entity, _ in scene.query(Light):
            scene.delete(entity)
    return scene


SCENES: dict[str, Callable[[bool], Scene]] = {"boxes": boxes, "house": house}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backends", nargs="+", default=["opencl", "glsl"])
    parser.add_argument("--precision", default="f32")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--size", type=int, default=320)
    parser.add_argument("--pairs", type=int, default=15)
    args = parser.parse_args()
    for name in args.backends:
        for scene_name in args.scenes:
            lit, plain = SCENES[scene_name](True), SCENES[scene_name](False)
            try:
                row = {"backend": name, "scene": scene_name}
                row.update(paired(name, args.precision, lit, plain, (args.size, args.size), args.pairs, {}))
            finally:
                lit.close()
                plain.close()
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
