"""The bench's shadows sweep (image error against the shadowed targets) and its ``features`` costs."""

from __future__ import annotations

import io
import json
import math

from conftest import require_backend

from aberrant.bench import features, plot
from aberrant.bench.results import write_outputs
from aberrant.bench.runner import make_config, run_bench
from aberrant.bench.scenes import resolve_scenes
from aberrant.bench.sweeps import settings_for
from components import Light, Mesh


def test_the_shadows_sweep_is_one_point_with_every_shadow_off():
    settings = settings_for("opencl", ["f32"], ["shadows"], quick=False)
    assert [(s.sweep, s.shadows, s.spp) for s in settings] == [("", True, 1), ("shadows", False, 1)]
    assert settings[1].label == "opencl f32 shadows=off" and settings[1].as_dict()["shadows"] is False
    assert [s.sweep for s in settings_for("reference", ["f64"], ["shadows", "leaf"], quick=True)] == ["", "shadows"]


def test_the_features_group_is_each_case_against_its_twin(tmp_path):
    specs = {s.name: s for s in resolve_scenes(["features"])}
    assert list(specs) == [f.name for f in features.FEATURES]
    assert all(s.base_only and s.baseline is not None for s in specs.values())
    assert specs["features-spp4"].spp == (4, 1) and specs["features-shading"].spp is None
    scenes = {name: (s.build(tmp_path), s.baseline(tmp_path)) for name, s in specs.items() if s.baseline}
    try:
        shaded, flat = scenes["features-shading"]
        assert any(m.texture for _, m in shaded.query(Mesh)) and any(m.smooth for _, m in shaded.query(Mesh))
        assert not any(m.texture or m.smooth for _, m in flat.query(Mesh))
        assert len(flat.query(Light)) == len(shaded.query(Light)) >= 1  # the same lights on both sides
        for name, shadows in (("features-sun-shadows", True), ("features-sun", False)):
            lit, unlit = scenes[name]
            assert [(light.kind, light.shadows) for _, light in lit.query(Light)] == [("sun", shadows)]
            assert unlit.query(Light) == []
    finally:
        for pair in scenes.values():
            for scene in pair:
                scene.close()


def test_shadows_off_is_measured_against_the_shadowed_images(monkeypatch, tmp_path):
    """At 64 spp the shadows-on cell equals its own target exactly, so the shadows-off cell's error is the
    shadows alone; a scene without a shadowing light gets no such cell and its base frame stands in."""
    fast = "glsl"
    require_backend(fast)
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path / "cache"))
    config = make_config(scenes=["starter", "ten-boxes"], backends=["reference", fast], size=(16, 12), repeat=1,
                         out=tmp_path, sweeps=["shadows"], overhead=False, spp=64)  # fmt: skip
    results = run_bench(config, io.StringIO())
    rows = {(r["scene"], r["backend"], r["setting"]["shadows"]): r for r in results["rows"]}
    assert sorted(rows) == sorted([("starter", b, s) for b in ("reference", fast) for s in (True, False)]
                                  + [("ten-boxes", b, True) for b in ("reference", fast)])  # fmt: skip
    assert all(r["status"] == "ok" for r in rows.values())
    assert results["scenes"]["starter"]["shadows"] and results["scenes"]["ten-boxes"]["skipped_sweeps"] == ["shadows"]
    for backend in ("reference", fast):
        on, off = rows[("starter", backend, True)]["image_errors"], rows[("starter", backend, False)]["image_errors"]
        assert on["own_mae"] == 0.0 and math.isinf(on["own_psnr"])  # 64 spp against its own 64 spp
        assert on["ref_mae"] < 0.5  # and against the reference's: the lights were put back after each cell
        assert off["own_mae"] > 1.0 and off["ref_mae"] > 1.0 and off["ref_psnr"] < 40.0
        assert rows[("starter", backend, False)]["errors"]["mismatch"] == 0  # the geometry is unchanged
    on_reference = rows[("starter", "reference", False)]["image_errors"]
    assert on_reference["own_mae"] == on_reference["ref_mae"]  # the reference's own target is the reference
    pts = {p.label: p for p in plot.points(results)[0]}
    assert pts[f"{fast} f32 shadows=off"].color_mae > pts[f"{fast} f32"].color_mae  # over both scenes
    write_outputs(results, tmp_path)
    report = (tmp_path / "report.md").read_text()
    assert "## Image error: samples per pixel and shadows" in report
    assert f"| starter | {fast} f32 | 64 | off |" in report and "| ten-boxes | reference f64 | 64 | none |" in report
    assert "The shadows sweep skipped ten-boxes: no light there casts shadows." in report
    saved = json.loads((tmp_path / "results.json").read_text())
    assert {r["setting"]["shadows"] for r in saved["rows"]} == {True, False}
    assert "image_errors" in saved["rows"][1] and saved["config"]["sweeps"] == ["shadows"]


def test_the_features_run_pairs_each_case_with_its_twin(monkeypatch, tmp_path):
    require_backend("glsl")
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path / "cache"))
    config = make_config(scenes=["features"], backends=["glsl"], size=(24, 18), repeat=1, out=tmp_path,
                         sweeps=["spp", "shadows"], overhead=False)  # fmt: skip
    results = run_bench(config, io.StringIO())
    rows = {r["scene"]: r for r in results["rows"]}
    assert list(rows) == [f.name for f in features.FEATURES]
    for row in rows.values():
        assert row["status"] == "ok" and row["setting"]["sweep"] == "", row["status"]
        assert row["baseline_paired"]["pairs"] == 1 and row["baseline_paired"]["inverse"] > 0
        assert "image_errors" not in row  # what they cost, not how they look
    assert rows["features-spp4"]["setting"]["spp"] == 4 and rows["features-sun"]["setting"]["spp"] == 1
    write_outputs(results, tmp_path)
    report = (tmp_path / "report.md").read_text()
    assert "## What the image features cost" in report and "## Image error" not in report
    for f in features.FEATURES:
        goal = "–" if f.goal is None else f"<= {f.goal}x"
        assert f"| {f.what} | glsl f32 |" in report and f"x | {goal} |" in report
    saved = json.loads((tmp_path / "results.json").read_text())
    assert all("baseline_paired" in r for r in saved["rows"]) and saved["scenes"]["features-sun"]["shadows"] is False
