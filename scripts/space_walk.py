"""How much of the trees over portals and boxes a frame's primary rays walk: node boxes slabbed and leaves entered.

The kernels' walk (backends/shared/space.h) tests both children of every interior node a ray enters (the
binary trees: GLSL), or the four of every 4-wide node (OpenCL); a ray that finds no portal or box walks
every node whose box its line crosses. This counts, per primary ray of the packed scene (float32 tables,
the first leg: from the camera, unbounded, before any event), the node boxes slabbed and the leaves
entered, for the tree over portals and the tree over boxes, and the wide nodes visited (each slabs its
four children's boxes at once): what a frame's space search costs, before any leaf test. Scenes: the
bench's ``space-<kind>-<in|out>-<n>`` and ``hotel-view-<view>``.

    python scripts/space_walk.py space-boxes-in-4 space-boxes-in-1024 hotel-view-start --size 64
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aberrant.bench.architecture import hotel_views
from aberrant.bench.space import parse_space_name, space_scene
from backends.reference.intersect import safe_inverse
from engine.camera_view import scene_camera
from engine.packing import ScenePacker
from engine.scene import Scene
from engine.space_wide import ROWS, WIDTH


def walk(nodes: np.ndarray, root: int, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per ray (rows of ``d``, from ``o``): node boxes slabbed and leaves entered, walking from ``root``."""
    inv = safe_inverse(d)
    lo, hi = nodes["bounds_min"].astype(np.float64), nodes["bounds_max"].astype(np.float64)
    tests = np.zeros(len(d), np.int64)
    leaves = np.zeros(len(d), np.int64)
    ray, node = np.arange(len(d)), np.full(len(d), root, np.int64)
    while ray.size:
        np.add.at(tests, ray, 1)
        t0, t1 = (lo[node] - o) * inv[ray], (hi[node] - o) * inv[ray]
        enter = np.maximum(np.minimum(t0, t1).max(axis=1), 0.0) <= np.maximum(t0, t1).min(axis=1)
        ray, node = ray[enter], node[enter]
        leaf = nodes["count"][node] > 0
        np.add.at(leaves, ray[leaf], 1)
        first = nodes["first"][node[~leaf]].astype(np.int64)
        ray = np.repeat(ray[~leaf], 2)
        node = np.stack([first, first + 1], axis=1).reshape(-1)
    return tests, leaves


def walk_wide(nodes: np.ndarray, root: int, o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Per ray (rows of ``d``, from ``o``): wide nodes visited, walking the 4-wide form from row ``root``."""
    raw = nodes.view(np.float32).reshape(len(nodes), 8)
    inv = safe_inverse(d)
    visits = np.zeros(len(d), np.int64)
    ray, node = np.arange(len(d)), np.full(len(d), root, np.int64)
    while ray.size:
        np.add.at(visits, ray, 1)
        rows = np.concatenate([raw[node + k] for k in range(ROWS)], axis=1)
        lo = rows[:, 0:12].reshape(-1, 3, WIDTH).astype(np.float64)
        hi = rows[:, 12:24].reshape(-1, 3, WIDTH).astype(np.float64)
        child = rows[:, 24:28].view(np.int32)
        t0, t1 = (lo - o[None, :, None]) * inv[ray, :, None], (hi - o[None, :, None]) * inv[ray, :, None]
        enter = np.maximum(np.minimum(t0, t1).max(axis=1), 0.0) <= np.maximum(t0, t1).min(axis=1)
        at, lane = np.nonzero(enter & (child > 0))
        ray, node = ray[at], child[at, lane].astype(np.int64)
    return visits


def build(name: str) -> Scene:
    spec = parse_space_name(name)
    if spec is not None:
        return space_scene(*spec)
    views = {view: builder for view, builder, _, _ in hotel_views()}
    if name not in views:
        raise SystemExit(f"space_walk: unknown scene {name!r} (space-<kind>-<in|out>-<n> or hotel-view-<view>)")
    return views[name](Path("."))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--size", type=int, default=64, help="primary rays: SIZE x SIZE")
    args = parser.parse_args()
    print(
        "scene | tree | rows | nodes | boxes slabbed per ray: mean, p90, max | leaves entered per ray: mean, max"
        " | wide nodes visited per ray: mean, max"
    )
    for name in args.scenes:
        scene = build(name)
        camera = scene_camera(scene)
        packer = ScenePacker(precision="f32")
        packer.sync(scene, camera.position)
        packed = packer.packed
        assert packed is not None
        o = camera.position - np.asarray(packed.origin, np.float64)
        d = camera.primary_directions(args.size, args.size).reshape(-1, 3)
        nodes, roots = packed.tables["space_nodes"], packed.tables["settings"]["space_roots"][0]
        trees = (("portals", "portals", roots[0], roots[2]), ("boxes", "aberrations", roots[1], roots[3]))
        for tree, count, root, wide_root in trees:
            rows = packed.counts.get(count, 0)
            if rows:
                tests, leaves = walk(nodes, int(root), o, d)
                visits = walk_wide(nodes, int(wide_root), o, d)
                slabbed = f"{tests.mean():.1f}, {np.percentile(tests, 90):.0f}, {tests.max()}"
                print(
                    f"{name} | {tree} | {rows} | {2 * rows - 1} | {slabbed} | {leaves.mean():.2f}, {leaves.max()}"
                    f" | {visits.mean():.1f}, {visits.max()}"
                )
        scene.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
