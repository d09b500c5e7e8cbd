"""Frame cost against the number of portals or aberration boxes, in view and out of view.

An interleaved A/B in one process: a floor and 30 boxes in view, with N portals (N / 2 linked pairs) or N
metric boxes added out of view (behind the camera), in view (a grid in front of the boxes) or hidden (in
the camera's pyramid, behind a wall), against the same scene without them; samples of a few frames of the
two alternate on two backends of one kind, and the cost is the median of the paired ratios of CPU time
(the process's, every driver thread included: on a shared machine less noisy than wall time, which is
reported too). Also checks that an out-of-view set leaves the image as it was.

    python scripts/space_scale.py --backends opencl glsl --counts 0 4 16 64 256 1024 --pairs 15
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from backends.base import Backend, backend_class
from engine.camera_view import scene_camera
from engine.packing import ScenePacker
from engine.scene import Scene

#: Frames per timed sample (one sample of each scene per pair).
FRAMES = 3
#: A backend's kernel source of a variant's defines (``Backend.source``): another revision's kernels.
Source = Callable[[dict[str, int]], str]


def base_scene(name: str) -> Scene:
    """A checkered floor and 30 boxes in view."""
    scene = Scene(name)
    scene.add_mesh("floor", "plane", scale=(60.0, 1.0, 60.0), checker=1.0)
    rng = np.random.default_rng(1)
    for k in range(30):
        scene.add_mesh(
            f"box{k}",
            "box",
            position=(-7.0 + (k % 10) * 1.5, 0.4 + 0.3 * (k % 3), -2.0 - 2.0 * (k // 10)),
            euler_deg=(0.0, 17.0 * k, 0.0),
            scale=0.7,
            color=tuple(rng.uniform(0.2, 1.0, 3)),
        )
    scene.set_camera((0.0, 3.0, 7.0), look_at=(0.0, 0.5, -3.0), fov_deg=60.0)
    return scene


#: Where the N portals or boxes go: a wall of cells in front of the boxes ("in"), behind the camera ("out"),
#: or in view but behind a wall that hides them ("hidden": the camera's pyramid holds them, no ray reaches them).
VIEWS = ("in", "out", "hidden")


def grid(n: int, view: str) -> list[tuple[float, float, float]]:
    """n places for the view."""
    side = max(1, int(np.ceil(np.sqrt(n))))
    cell = 10.0 / side
    places = []
    for k in range(n):
        i, j = k % side, k // side
        x, y = -5.0 + (i + 0.5) * cell, 0.2 + (j + 0.5) * cell * 0.6
        z = {"in": 1.5, "out": 14.0 + 0.01 * k, "hidden": -14.0 - 0.01 * k}[view]
        places.append((x, y + (2.0 if view == "out" else 0.0), z))
    return places


def space_scene(kind: str, n: int, view: str) -> Scene:
    """The base scene with n portals (linked in pairs) or n metric boxes."""
    scene = base_scene(f"{kind}-{n}-{view}")
    if view == "hidden":
        scene.add_mesh("wall", "box", position=(0.0, 5.0, -10.0), scale=(80.0, 12.0, 0.5))
    places = grid(n, view)
    side = max(1, int(np.ceil(np.sqrt(n))))
    size = 0.3 * 10.0 / side
    if kind == "portals":
        for k in range(0, n - 1, 2):
            a, b = places[k], places[k + 1]
            scene.add_portal_pair(
                f"p{k}", f"p{k + 1}", a=dict(position=a, scale=(size, size * 0.6, 1.0)),
                b=dict(position=b, scale=(size, size * 0.6, 1.0)),
            )  # fmt: skip
    else:
        for k, place in enumerate(places):
            scene.add_aberration(f"a{k}", (0.3, -0.2, 0.1), position=place, scale=(size, size * 0.6, size))
    return scene


def loaded(
    name: str,
    precision: str,
    scene: Scene,
    extra: dict[str, int],
    source: Source | None = None,
    **packer_options: int,
) -> tuple[Backend, object]:
    """A backend of ``name`` with ``scene`` uploaded (packed as it asks, ``packer_options`` overriding), its
    kernels given the ``extra`` defines (``source``: its kernel source in place of the working tree's); and
    the scene's camera."""
    backend = backend_class(name)(precision=precision)
    backend.extra_defines = dict(extra)  # type: ignore[attr-defined]
    if source is not None:
        backend.source = source  # type: ignore[attr-defined]
    options = {"bvh_width": backend.bvh_width, "bvh_compact": backend.bvh_compact, "tlas_width": backend.tlas_width}
    options.update(packer_options)
    packer = ScenePacker(precision=backend.precision, camera_relative=backend.camera_relative, **options)
    camera = scene_camera(scene)
    updates = packer.sync(scene, camera.position)
    assert packer.packed is not None
    backend.upload(packer.packed, updates)
    return backend, camera


def paired(
    name: str,
    precision: str,
    scene: Scene,
    plain: Scene,
    size: tuple[int, int],
    pairs: int,
    extra: dict[str, int],
    plain_source: Source | None = None,
) -> dict:
    """Median ratio of frame times, scene over plain, frames alternating; and whether the images match.
    plain_source: the plain side's kernel source (another revision's kernels against the working tree's)."""
    a, camera_a = loaded(name, precision, scene, extra)
    b, camera_b = loaded(name, precision, plain, extra, plain_source)
    try:
        fa = a.render(camera_a, *size, ("color",))
        fb = b.render(camera_b, *size, ("color",))
        wall: list[tuple[float, float]] = []
        cpu: list[tuple[float, float]] = []
        for _ in range(pairs):
            spans = []
            for backend, camera in ((a, camera_a), (b, camera_b)):
                start, start_cpu = time.perf_counter(), time.process_time()
                for _ in range(FRAMES):
                    backend.render(camera, *size, ("color",))
                spans.append((time.perf_counter() - start, time.process_time() - start_cpu))
            wall.append((spans[0][0], spans[1][0]))
            cpu.append((spans[0][1], spans[1][1]))
        return {
            "cpu_ratio": float(np.median([x / y for x, y in cpu])),
            "wall_ratio": float(np.median([x / y for x, y in wall])),
            "cpu_ms": float(np.median([x for x, _ in cpu]) * 1e3 / FRAMES),
            "plain_cpu_ms": float(np.median([y for _, y in cpu]) * 1e3 / FRAMES),
            "wall_ms": float(np.median([x for x, _ in wall]) * 1e3 / FRAMES),
            "same_image": bool(np.array_equal(fa.color, fb.color)),
        }
    finally:
        a.release()
        b.release()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backends", nargs="+", default=["opencl", "glsl"])
    parser.add_argument("--precision", default="f32")
    parser.add_argument("--kinds", nargs="+", default=["portals", "boxes"])
    parser.add_argument("--views", nargs="+", default=list(VIEWS), choices=VIEWS)
    parser.add_argument("--counts", nargs="+", type=int, default=[0, 4, 16, 64, 256, 1024])
    parser.add_argument("--size", type=int, default=320)
    parser.add_argument("--pairs", type=int, default=15)
    parser.add_argument("--json", type=Path, help="also write the rows here")
    parser.add_argument("--define", action="append", default=[], help="NAME=VALUE for every variant (A/B levers)")
    args = parser.parse_args()
    extra = {k: int(v) for k, v in (d.split("=") for d in args.define)}
    rows = []
    size = (args.size, args.size)
    for name in args.backends:
        for kind in args.kinds:
            for view in args.views:
                for n in args.counts:
                    scene, plain = space_scene(kind, n, view), space_scene(kind, 0, view)
                    try:
                        row = {"backend": name, "kind": kind, "view": view, "n": n}
                        row.update(paired(name, args.precision, scene, plain, size, args.pairs, extra))
                    finally:
                        scene.close()
                        plain.close()
                    rows.append(row)
                    print(json.dumps(row), flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
