"""The bench's ``space-count`` sweep: its scenes hold what they say where they say, and a tiny sweep runs end to end."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from PIL import Image

from aberrant.bench import space
from aberrant.bench.paired import space_series
from aberrant.bench.scenes import resolve_scenes
from aberrant.cli import main
from components import Aberration, Portal, Transform
from engine.camera_view import scene_camera
from engine.maths import quat_to_matrix
from engine.scene import Scene


def _corners(scene: Scene, entity: int, kind: str) -> np.ndarray:
    """World corners of a portal quad ([-1, 1]^2 scaled) or an aberration box ([-1/2, 1/2]^3 scaled)."""
    t = scene.get(entity, Transform)
    if kind == "portals":
        local = np.array([[x, y, 0.0] for x in (-1, 1) for y in (-1, 1)])
    else:
        local = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    return (local * np.asarray(t.scale)) @ quat_to_matrix(t.rotation).T + np.asarray(t.position)


def _in_frustum(scene: Scene, points: np.ndarray, aspect: float) -> np.ndarray:
    """Per point: inside the camera's view frustum (in front of it, within the image's sides)."""
    camera = scene_camera(scene)
    local = (points - camera.position) @ camera.rotation  # columns of rotation: right, up, back
    depth = -local[:, 2]
    t = math.tan(math.radians(camera.fov_deg) / 2.0)
    return (depth > 0) & (np.abs(local[:, 0]) <= depth * t * aspect) & (np.abs(local[:, 1]) <= depth * t)


@pytest.mark.parametrize("kind", space.KINDS)
@pytest.mark.parametrize("placement", space.PLACEMENTS)
def test_space_scenes_hold_the_count_in_or_out_of_the_frustum(kind, placement):
    component = Portal if kind == "portals" else Aberration
    for count in space.COUNTS:
        scene = space.space_scene(kind, placement, count)
        try:
            found = scene.query(component)
            assert len(found) == count, (kind, placement, count)
            assert len(scene.query(Aberration if kind == "portals" else Portal)) == 0
            if kind == "portals":  # every portal is linked to its neighbour, and back
                for _, portal in found:
                    assert portal.target is not None
                    assert scene.get(scene.entity(portal.target), Portal).target is not None
            for entity, _ in found:
                corners = _corners(scene, entity, kind)
                if placement == "out":  # not in the frustum of any image shape
                    assert not _in_frustum(scene, corners, aspect=100.0).any(), (count, scene.name_of(entity))
                else:  # wholly in view of a square (or wider) image
                    assert _in_frustum(scene, corners, aspect=1.0).all(), (count, scene.name_of(entity))
        finally:
            scene.close()


@pytest.mark.parametrize("kind", space.KINDS)
def test_rays_meet_the_in_view_ones_and_never_the_out_of_view_ones(kind, backend_factory):
    """The reference's events per pixel: none out of view; in view, on about the grid's covered share."""
    from systems.app import render_once

    backend = backend_factory("reference")
    plain = space.thirty_boxes()
    try:
        plain_frame = render_once(plain, backend, (48, 48))
    finally:
        plain.close()
    for placement in space.PLACEMENTS:
        scene = space.space_scene(kind, placement, 16)
        try:
            frame = render_once(scene, backend, (48, 48))
        finally:
            scene.close()
        passed = float((frame.events > 0).mean())
        if placement == "out":
            assert passed == 0.0
            np.testing.assert_array_equal(frame.instance, plain_frame.instance)
        else:  # the grid spans 80 % of the view's height, a quarter of it covered (a box's sides show too)
            share = 0.64 * space.COVERAGE
            assert 0.5 * share < passed < (1.2 if kind == "portals" else 2.0) * share
            assert frame.events.max() == (1 if kind == "portals" else 2)


def test_the_space_count_group_is_every_kind_placement_and_count():
    specs = resolve_scenes(["space-count"])
    names = {s.name for s in specs}
    assert space.PLAIN in names and len(specs) == 1 + len(space.KINDS) * len(space.PLACEMENTS) * len(space.COUNTS)
    assert all(s.base_only for s in specs)
    assert all(s.baseline is not None for s in specs if s.name != space.PLAIN)
    assert space.parse_space_name("space-boxes-in-64") == ("boxes", "in", 64)
    assert space.parse_space_name("space-0") is None and space.parse_space_name("ten-boxes-portals") is None


@pytest.mark.slow
def test_a_tiny_space_sweep_runs_end_to_end(tmp_path):
    """Each scene is measured on each fast backend's base setting against N = 0; table and plot follow it."""
    out = tmp_path / "report"
    scenes = ["space-0", "space-portals-out-4", "space-portals-in-16", "space-boxes-out-4", "space-boxes-in-4"]
    argv = ["bench", "--scenes", *scenes, "--size", "32x32", "--repeat", "1", "--no-overhead", "--out", str(out)]
    assert main(argv) == 0
    results = json.loads((out / "results.json").read_text())
    rows = [r for r in results["rows"] if r["scene"] != "space-0"]
    assert {r["setting"]["sweep"] for r in results["rows"]} == {""}  # base settings only, though all sweeps ran
    assert len(rows) == 4 * len(results["config"]["backends"])
    for row in rows:
        assert row["status"] == "ok" or row["status"].startswith("unsupported: "), row["status"]
        if row["status"] == "ok":
            assert row["baseline_paired"]["pairs"] == 1 and row["baseline_paired"]["inverse"] > 0
    series = space_series(results)
    assert {(k, p) for k, p, _ in series} <= {("portals", "out"), ("portals", "in"), ("boxes", "out"), ("boxes", "in")}
    report = (out / "report.md").read_text()
    assert "## Space count" in report and "](space_count.png)" in report
    assert report.count("| portals | in view |") == len(results["config"]["backends"])
    with Image.open(out / "space_count.png") as image:
        assert image.format == "PNG" and image.size[0] > 300
    # A later run without the sweep into the same folder leaves no stale plot beside its report.
    again = ["bench", "--scenes", "space-0", "--size", "16x16", "--repeat", "1", "--sweeps", "none"]
    assert main([*again, "--backends", "reference", "--no-overhead", "--out", str(out)]) == 0
    assert not (out / "space_count.png").exists()
    assert "## Space count" not in (out / "report.md").read_text()
