"""The portal legs' lists (engine/portal_legs.py): every instance whose exact bounds the leg after a camera ray's
first portal enters is in the list of (that portal, its tile), no nearer than its bound in the leg's t; and where
the lists say so, no such leg meets a portal. Checked ray by ray in float64 on the bench scene (cameras moved
about behind its view-filling door) and on the hotel's views."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_view_tiles import first_leg_hits

from aberrant.bench.scenes import ten_boxes_portals
from backends.reference.directions import affine_points, linear_vectors
from engine.box_clearance import instance_bounds
from engine.camera_view import CameraView, scene_camera
from engine.packing import ScenePacker
from engine.portal_legs import portal_legs
from engine.tlas_wide import TlasLanes
from engine.view_tiles import PortalLegs, tile_grid, view_tiles


def second_legs(
    view: CameraView, width: int, height: int, origin: np.ndarray, portals: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each pixel whose primary ray meets a portal: the nearest one's row, and the ray after it (start on the
    exit quad, unit direction), as portals.teleport maps it."""
    (pixels, rows), t = first_leg_hits(view, width, height, origin, portals)
    nearest = np.lexsort((t, pixels))
    pixels, rows, t = pixels[nearest], rows[nearest], t[nearest]
    first = np.concatenate([[True], pixels[1:] != pixels[:-1]])
    pixels, rows, t = pixels[first], rows[first], t[first]
    r = view.primary_directions(width, height).reshape(-1, 3)[pixels]
    transfer = portals["transfer"].astype(np.float64)[rows]
    o = view.position - origin + t[:, None] * r
    o = np.stack([affine_points(m, p[None])[0] for m, p in zip(transfer, o, strict=True)])
    d = np.stack([linear_vectors(m, v[None])[0] for m, v in zip(transfer, r, strict=True)])
    return pixels, rows, o, d / np.linalg.norm(d, axis=1, keepdims=True)


def check_legs(view: CameraView, width: int, height: int, packed) -> tuple[int, PortalLegs]:
    """Asserts that every instance a second leg enters is in its list; returns how many there were."""
    origin = np.asarray(packed.origin, dtype=np.float64)
    portals = packed.tables["portals"][: packed.counts["portals"]]
    lo, hi = instance_bounds(packed)
    legs = portal_legs(view, width, height, origin, portals, (TlasLanes.of(packed.tables["tlas_nodes"]), lo, hi), 3)
    entry = view_tiles(view, width, height, origin, legs=(legs, len(portals)))["entry"]
    tiles_x, tiles_y = tile_grid(width, height)
    pixels, rows, o, d = second_legs(view, width, height, origin, portals)
    with np.errstate(all="ignore"):
        t0, t1 = (lo[:, None] - o[None]) / d[None], (hi[:, None] - o[None]) / d[None]
        enter = np.nanmax(np.minimum(t0, t1), axis=2)
        leave = np.nanmin(np.maximum(t0, t1), axis=2)
    hits = 0
    for k, (p, row) in enumerate(zip(pixels, rows, strict=True)):
        assert row in legs.rows, f"pixel {p}: its first portal {row} has no slot"
        tx, ty = p % width >> 3, p // width >> 3
        slot = entry[tiles_x * tiles_y + row]
        x0, x1, y0, y1 = slot[1] & 0xFFFF, slot[1] >> 16, slot[2] & 0xFFFF, slot[2] >> 16
        assert x0 <= tx <= x1 and y0 <= ty <= y1, f"pixel {p}: outside portal {row}'s rect"
        head = entry[slot[0] + (ty - y0) * (x1 - x0 + 1) + tx - x0]
        listed = entry[head[0] : head[0] + head[1]]
        assert head[1] >= 0 and np.all(np.diff(listed[:, 1].view(np.float32)) >= 0.0)
        for inst in np.flatnonzero((leave[:, k] >= np.maximum(enter[:, k], 0.0)) & (leave[:, k] > 0.0)):
            where = np.flatnonzero(listed[:, 0] == inst)
            assert where.size == 1, f"pixel {p}: instance {inst} missing from portal {row}'s list"
            bound = listed[where[0], 1:2].view(np.float32)[0]
            assert bound <= max(enter[inst, k], 0.0), f"pixel {p}: instance {inst} at {enter[inst, k]}, {bound}"
            hits += 1
    if legs.complete:  # no second leg meets a linked portal other than the one it leaves
        for row, start, direction in zip(rows, o, d, strict=True):
            exit_row = int(portals["meta"][row, 0])
            for other in np.flatnonzero(portals["meta"][:, 0] >= 0):
                if other == exit_row:
                    continue
                m = portals["world_to_local"][other].astype(np.float64)
                a, v = affine_points(m, start[None])[0], linear_vectors(m, direction[None])[0]
                t = -a[2] / v[2] if v[2] != 0.0 else -1.0
                assert not (t > 0.0 and abs(a[0] + t * v[0]) <= 1.0 and abs(a[1] + t * v[1]) <= 1.0)
    return hits, legs


@pytest.mark.parametrize("seed", range(3))
def test_the_bench_doors_second_legs_are_listed(tmp_path: Path, seed: int) -> None:
    """Cameras about the bench camera, turned a little: the door fills the view, the lists serve alone."""
    rng = np.random.default_rng(300 + seed)
    scene = ten_boxes_portals(tmp_path)
    packer = ScenePacker("f32")
    packer.sync(scene)
    base = scene_camera(scene)
    complete = []
    for _ in range(3):
        angle = rng.uniform(-0.15, 0.15)
        turn = np.array([[np.cos(angle), 0.0, np.sin(angle)], [0.0, 1.0, 0.0], [-np.sin(angle), 0.0, np.cos(angle)]])
        position = base.position + rng.uniform([-0.5, -0.3, 0.0], [0.5, 0.3, 2.0])
        view = CameraView(position, turn @ base.rotation, base.fov_deg, tuple(rng.uniform(0, 1, 2)))
        hits, legs = check_legs(view, int(rng.integers(20, 70)), int(rng.integers(20, 70)), packer.packed)
        assert hits > 0
        complete.append(legs.complete)
    assert any(complete)
    scene.close()


@pytest.mark.parametrize("view_name", ["start", "room"])
def test_the_hotels_second_legs_are_listed(view_name: str) -> None:
    from demos.hotel import build, views

    scene = build()
    packer = ScenePacker("f32")
    packer.sync(scene)
    eye, look_at = views()[view_name]
    scene.set_camera(eye, look_at=look_at)
    hits, _ = check_legs(scene_camera(scene), 48, 40, packer.packed)
    assert hits > 0
    scene.close()
