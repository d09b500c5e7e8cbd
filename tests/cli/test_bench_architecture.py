"""The bench's level-like Euclidean scenes and the hotel's views against its doors shut."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import require_backend

from aberrant.bench.architecture import closed_portals, strips_mesh
from aberrant.bench.scenes import bench_scenes, resolve_scenes
from aberrant.bench.targets import best_ratio
from aberrant.cli import main
from components import Aberration, Mesh, Portal, Transform
from demos import build_demo


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("bench-assets")


def test_architecture_scenes_are_euclidean_and_built_like_levels(folder):
    specs = {s.name: s for s in resolve_scenes(["architecture"])}
    assert set(specs) == {"ground-grid", "long-triangles", "village", "house-open", "hotel-closed"}
    facts = {}
    for name, spec in specs.items():
        scene = spec.build(folder)
        try:
            assert not scene.query(Portal) and not scene.query(Aberration), name
            meshes = scene.query(Mesh)
            facts[name] = (len(meshes), sum(scene.asset(m.asset).triangle_count for _, m in meshes))
        finally:
            scene.close()
    assert facts["ground-grid"][1] >= 2 * 128 * 128  # the tessellated ground alone
    assert facts["village"][0] >= 500  # many instances
    hotel = build_demo("hotel")
    try:
        assert facts["hotel-closed"][0] == len(hotel.query(Mesh)) + len(hotel.query(Portal))  # a quad per portal
    finally:
        hotel.close()


def test_the_planks_are_long_thin_triangles_whose_boxes_overlap(folder):
    import trimesh

    mesh = trimesh.load(strips_mesh(folder, 400, 60.0, 0.25, 35.0), process=False)
    edges = np.linalg.norm(mesh.vertices[mesh.faces] - np.roll(mesh.vertices[mesh.faces], 1, axis=1), axis=2)
    assert len(mesh.faces) == 800 and (edges.max(axis=1) / edges.min(axis=1)).min() > 200
    boxes = mesh.vertices[mesh.faces].max(axis=1) - mesh.vertices[mesh.faces].min(axis=1)
    assert np.median(boxes[:, 0] * boxes[:, 2]) > 100 * np.median(mesh.area_faces)  # diagonal: boxes far too big


def test_shut_portals_keep_every_other_surface(backend_factory):
    """Closing the hotel's doors changes only what was seen through them (no event in the open level)."""
    from systems.app import render_once

    backend = backend_factory("reference")
    hotel, shut = build_demo("hotel"), closed_portals(build_demo("hotel"))
    try:
        portals = {hotel.name_of(e): hotel.get(e, Transform) for e, _ in hotel.query(Portal)}
        for name, transform in portals.items():
            assert shut.get(shut.entity(f"{name}_shut"), Transform) == transform
        frame, plain = render_once(hotel, backend, (64, 48)), render_once(shut, backend, (64, 48))
    finally:
        hotel.close()
        shut.close()
    direct = frame.events == 0
    assert 0.05 < 1.0 - direct.mean() < 0.5
    np.testing.assert_array_equal(frame.instance[direct], plain.instance[direct])
    assert (plain.events == 0).all()


def test_each_hotel_view_is_inside_the_level_and_sees_portals(backend_factory, folder):
    from systems.app import render_once

    backend = backend_factory("reference")
    specs = [s for s in bench_scenes().values() if s.group == "hotel"]
    assert len(specs) >= 4 and all(s.base_only and s.baseline is not None for s in specs)
    for spec in specs:
        scene, plain = spec.build(folder), spec.baseline(folder)
        try:
            assert scene.get(scene.camera_entity, Transform) == plain.get(plain.camera_entity, Transform)
            frame = render_once(scene, backend, (32, 24))
        finally:
            scene.close()
            plain.close()
        assert (frame.instance >= 0).all(), spec.name  # closed rooms: every ray meets a surface
        assert (frame.events > 0).mean() > 0.02, spec.name


@pytest.mark.slow
def test_a_tiny_run_reports_the_hotel_and_the_embree_ratio_of_a_level(tmp_path):
    out = tmp_path / "report"
    argv = ["bench", "--scenes", "hotel-view-start", "ground-grid", "--size", "24x24", "--repeat", "1"]
    assert main([*argv, "--sweeps", "none", "--no-overhead", "--out", str(out)]) == 0
    results = json.loads((out / "results.json").read_text())
    report = (out / "report.md").read_text()
    assert "## The hotel against its doors shut" in report
    for row in results["rows"]:
        assert row["status"] == "ok" or row["status"].startswith("unsupported: "), row["status"]
        if row["status"] == "ok" and row["scene"] == "hotel-view-start":
            assert row["baseline_paired"]["inverse"] > 0
        if (
            row["status"] == "ok"
            and row["scene"] == "ground-grid"
            and results["embree"]["ground-grid"]["status"] == "ok"
        ):
            assert row["embree_paired"]["ratio"] > 0
            assert row["embree_paired"]["shadows_off"] is False  # no light: the frame is the one timed
            # ... and again as the hits alone, Embree's outputs: the same hits, the ratio the targets read
            trace = row["embree_trace_paired"]
            assert trace["ratio"] > 0 and trace["same_hits"] is True
            assert best_ratio(row) == trace["ratio"]


@pytest.mark.slow
def test_a_scene_casting_shadows_meets_embree_on_its_frame_without_them(tmp_path):
    pytest.importorskip("embreex")
    require_backend("opencl")
    out = tmp_path / "report"
    argv = ["bench", "--scenes", "starter", "--backends", "opencl", "--size", "24x24", "--repeat", "2"]
    assert main([*argv, "--sweeps", "none", "--no-overhead", "--out", str(out)]) == 0
    results = json.loads((out / "results.json").read_text())
    (row,) = [r for r in results["rows"] if r["scene"] == "starter"]
    assert row["status"] == "ok", row["status"]
    paired = row["embree_paired"]
    assert paired["shadows_off"] is True
    assert row["embree_note"] == "shadows off for the pairing"
    embree_mrays = results["embree"]["starter"]["sizes"]["24x24"]["mrays_per_s"]
    assert row["embree_ratio"] == pytest.approx(24 * 24 / (1e3 * paired["frame_ms"]) / embree_mrays)
    assert "x*)" in (out / "report.md").read_text()
