"""``aberrant bench``: metrics on hand-made arrays, the reference cache, arguments, and a quick run.

The quick run is the smoke test ``make test`` runs: the report, the results
and the plot exist and are complete (every scene x backend cell measured or
marked unsupported with a reason), and every measured cell is within the
parity thresholds. It asserts nothing about time.
"""

from __future__ import annotations

import io
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import require_backend
from PIL import Image

from aberrant.bench import embree, metrics, plot, reference
from aberrant.bench.facts import cpu_generation
from aberrant.bench.metrics import Timing, compare, geometric_mean, instance_mismatch, pareto_front, relative_error
from aberrant.bench.results import write_outputs
from aberrant.bench.runner import make_config, run_bench
from aberrant.bench.scenes import QUICK_SCENES, bench_scenes, ten_boxes
from aberrant.bench.sweeps import check_sweeps, settings_for
from aberrant.cli import main
from aberrant.progress import Progress, clock
from engine.camera_view import scene_camera
from engine.errors import AberrantError
from engine.settings import Settings

# --- metrics ------------------------------------------------------------------------------------------------


def test_instance_mismatch_counts_differing_pixels():
    ref = np.array([[0, 1, -1, 2]], np.int32)
    assert instance_mismatch(ref.copy(), ref) == 0.0
    assert instance_mismatch(np.array([[0, 1, 1, -1]], np.int32), ref) == 0.5
    with pytest.raises(ValueError, match="shape"):
        instance_mismatch(np.zeros((2, 2), np.int32), ref)


def test_relative_error_median_and_p99_over_the_mask_only():
    ref = np.array([1.0, 2.0, 4.0, 8.0, np.inf], np.float32)
    fast = np.array([1.0, 2.2, 4.0, 0.0, 5.0], np.float32)  # errors 0, 0.1, 0, masked out, a miss
    mask = np.array([True, True, True, False, True])
    median, p99 = relative_error(fast, ref, mask)
    assert median == 0.0
    assert p99 == pytest.approx(np.percentile([0.0, 0.1, 0.0], 99), rel=1e-6)
    assert relative_error(fast, ref, np.zeros(5, bool)) == (0.0, 0.0)


def test_relative_error_counts_a_non_finite_value_as_infinite():
    ref = np.array([1.0, 1.0, 1.0], np.float32)
    _, p99 = relative_error(np.array([1.0, np.nan, 1.0], np.float32), ref, np.ones(3, bool))
    assert p99 == math.inf


def test_compare_uses_same_instance_hits_and_counts_nan():
    ref = {
        "instance": np.array([[3, 3, -1, 4]], np.int32),
        "depth": np.array([[1.0, 2.0, np.inf, 4.0]], np.float32),
        "perceived": np.array([[1.0, 2.0, np.inf, 4.0]], np.float32),
    }
    instance = np.array([[3, 3, -1, 5]], np.int32)
    depth = np.array([[1.0, 2.002, np.inf, 1.0]], np.float32)
    perceived = np.array([[1.0, 2.0, np.nan, 4.0]], np.float32)
    e = compare(instance, depth, perceived, ref)
    assert e.mismatch == 0.25 and e.compared == 2 and e.nan_count == 1
    assert e.depth_p99 == pytest.approx(np.percentile([0.0, 0.001], 99), rel=1e-3)
    assert e.perceived_p99 == 0.0
    assert math.isnan(compare(instance, depth, None, ref).perceived_median)


def test_color_error_is_mae_and_psnr_over_rgb():
    target = np.zeros((2, 2, 4), np.uint8)
    image = target.copy()
    image[0, 0, :3] = 4  # alpha is not compared
    image[..., 3] = 255
    e = metrics.color_error(image, target)
    assert e["mae"] == pytest.approx(1.0) and e["psnr"] == pytest.approx(10 * math.log10(255**2 / 4.0))
    assert metrics.color_error(target, target) == {"mae": 0.0, "psnr": math.inf}


def test_pareto_front_keeps_only_undominated_points():
    points = [(1.0, 5.0), (2.0, 3.0), (3.0, 4.0), (4.0, 1.0), (2.0, 3.0), (0.5, 9.0), (5.0, 1.0), (math.nan, 0.0)]
    assert pareto_front(points) == [5, 0, 1, 4, 3]
    assert pareto_front([]) == []
    assert pareto_front([(1.0, 1.0)]) == [0]


def test_timing_and_geometric_mean():
    t = Timing.of([4.0, 2.0, 3.0])
    assert (t.median_ms, t.min_ms, t.max_ms, t.runs) == (3.0, 2.0, 4.0, 3)
    assert t.mrays_per_s(3_000_000) == pytest.approx(1000.0)
    assert geometric_mean([1.0, 100.0]) == pytest.approx(10.0)
    assert math.isnan(geometric_mean([]))


def test_progress_line_shows_done_total_elapsed_and_eta():
    stream = io.StringIO()
    progress = Progress(4, stream, interval_s=0.0)
    progress.step("scene: glsl f32")
    line = stream.getvalue().strip().splitlines()[-1]
    assert "1/4" in line and "elapsed" in line and "ETA" in line and "scene: glsl f32" in line
    assert clock(61) == "1:01" and clock(3725) == "1:02:05"


def test_sweeps_have_unique_labels_and_reject_unknown_names():
    settings = settings_for("glsl", ["f32", "f64"], check_sweeps(["all"]), quick=False)
    labels = [s.label for s in settings]
    assert len(labels) == len(set(labels)) and labels[0] == "glsl f32" and "glsl f64" in labels
    assert {s.sweep for s in settings} >= {"precision", "leaf", "workgroup", "tables", "size", "max_events", "spp"}
    at_four = settings_for("glsl", ["f32"], ["leaf", "spp"], quick=True, spp=4)
    assert [s.spp for s in at_four if s.sweep != "spp"] == [4] * (1 + len([s for s in at_four if s.sweep == "leaf"]))
    assert sorted(s.spp for s in at_four if s.sweep == "spp") == [1, 2, 8, 16]
    with pytest.raises(AberrantError, match="unknown sweep"):
        check_sweeps(["colour"])


def test_the_machine_line_names_the_cpu_generation_and_its_widest_vectors():
    """Machines of one model name ("AMD EPYC") differ by generation, and the report must tell them apart."""
    zen4 = {"cpu family": "25", "model": "17", "flags": "fpu sse2 avx2 avx512f avx512bw"}
    assert cpu_generation(zen4) == "family 25 model 17, AVX-512"
    assert cpu_generation({"cpu family": "25", "model": "1", "flags": "sse2 avx avx2"}) == "family 25 model 1, AVX2"
    assert cpu_generation({"cpu family": "6", "model": "85", "flags": "sse2"}) == "family 6 model 85, SSE"


# --- the reference cache ------------------------------------------------------------------------------------


def test_reference_cache_renders_once_then_reads_the_disk(tmp_path, monkeypatch):
    scene = ten_boxes(tmp_path)
    try:
        camera = scene_camera(scene)
        first = reference.ReferenceCache(tmp_path / "cache").get(scene, camera, (24, 16))
        assert not first.cached and first.aovs["instance"].shape == (16, 24)

        def refuse(*args, **kwargs):
            raise AssertionError("the reference should come from the disk cache")

        monkeypatch.setattr(reference, "render_reference", refuse)
        cache = reference.ReferenceCache(tmp_path / "cache")
        second = cache.get(scene, camera, (24, 16))
        assert second.cached and cache.hits == 1 and cache.misses == 0
        for name, value in first.aovs.items():
            np.testing.assert_array_equal(second.aovs[name], value)
        key = reference.scene_key(scene, camera, (24, 16))
        assert reference.scene_key(scene, camera, (24, 18)) != key
        scene.settings = Settings(max_events=4)
        assert reference.scene_key(scene, camera, (24, 16)) != key
        with pytest.raises(AssertionError, match="disk cache"):
            cache.get(scene, camera, (24, 16))  # a new key is rendered, not guessed
    finally:
        scene.close()


def test_reference_cache_dir_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path))
    assert reference.cache_dir() == tmp_path / "reference"


# --- command-line errors ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--scenes", "nowhere"], "unknown scene 'nowhere'"),
        (["--backends", "vulkan"], "unknown backend 'vulkan'"),
        (["--size", "80x"], "--size must be WIDTHxHEIGHT"),
        (["--size", "0x10"], "--size width must lie in"),
        (["--repeat", "0"], "--repeat must lie in"),
        (["--sweeps", "colour"], "unknown sweep 'colour'"),
        (["--jobs", "0"], "--jobs must lie in"),
        (["--time-limit", "0"], "--time-limit must be positive"),
        (["--spp", "0"], "--spp (samples per pixel) must lie in [1, 256]"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(capsys, tmp_path, argv, message):
    code = main(["bench", "--quick", "--out", str(tmp_path / "out"), *argv])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("aberrant: error: ") and message in err
    assert not (tmp_path / "out").exists()


# --- the quick run (the smoke test of make test) ------------------------------------------------------------


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bench") / "report"
    assert main(["bench", "--quick", "--out", str(out)]) == 0
    return out


@pytest.mark.slow
def test_quick_run_writes_a_complete_report(quick_run):
    results = json.loads((quick_run / "results.json").read_text())
    report = (quick_run / "report.md").read_text()
    with Image.open(quick_run / "speed_vs_error.png") as image:
        assert image.format == "PNG" and image.size[0] > 300
    assert results["config"]["quick"] and list(results["scenes"]) == list(QUICK_SCENES)
    backends = results["config"]["backends"]
    assert backends == ["glsl", "opencl"]
    for scene in QUICK_SCENES:
        assert f"### {scene}" in report
        for backend in backends:
            rows = [r for r in results["rows"] if r["scene"] == scene and r["backend"] == backend]
            assert rows, f"no cell for {scene} x {backend}"
            for row in rows:
                status = row["status"]
                assert status == "ok" or (status.startswith("unsupported: ") and len(status) > 14), (scene, status)
    for section in ("## Targets", "## Headline", "## Engine overhead", "## Embree anchor", "## What was"):
        assert section in report
    assert len(results["overhead"]) == len(backends)
    # The mover stays within its fat TLAS leaf: no tick re-uploads tree rows.
    assert all(e["tlas_upload_ticks"] == 0 for e in results["overhead"] if "median_ms" in e)


@pytest.mark.slow
def test_quick_run_errors_are_within_the_parity_thresholds(quick_run):
    results = json.loads((quick_run / "results.json").read_text())
    measured = [r for r in results["rows"] if r["status"] == "ok"]
    for row in measured:
        euclidean = results["scenes"][row["scene"]]["euclidean"]
        limit = metrics.MISMATCH_MAX_EUCLIDEAN if euclidean else metrics.MISMATCH_MAX_NON_EUCLIDEAN
        e = row["errors"]
        where = f"{row['scene']} {row['label']}: {e}"
        assert e["mismatch"] <= limit, where
        assert e["depth_p99"] <= metrics.DEPTH_P99_MAX, where
        assert e["nan_count"] == 0, where
        assert row["tick_static_bytes"] == 0 and row["tick_moved_bytes"] > 0, where
    for scene, anchor in results["embree"].items():  # the anchor agrees with the reference too
        for entry in anchor.get("sizes", {}).values():
            assert entry["status"] == "ok", (scene, entry)
            assert entry["errors"]["mismatch"] <= 1e-2, (scene, entry["errors"])


def test_without_matplotlib_the_plot_is_a_notice(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # makes ``import matplotlib`` raise ImportError
    png, note = plot.plot_png({})
    assert "pip install '.[bench]'" in note
    with Image.open(io.BytesIO(png)) as image:
        assert image.format == "PNG"


def test_without_embreex_every_row_says_so(monkeypatch, tmp_path):
    real = embree.importlib.util.find_spec
    monkeypatch.setattr(
        embree.importlib.util, "find_spec", lambda name, *a: None if name == "embreex" else real(name, *a)
    )
    assert embree.available() == embree.NOT_INSTALLED
    config = make_config(scenes=["ten-boxes"], backends=["reference"], size=(16, 12), repeat=1, out=tmp_path,
                         sweeps=["none"], overhead=False)  # fmt: skip
    results = run_bench(config, io.StringIO())
    assert results["embree"]["ten-boxes"]["status"] == embree.NOT_INSTALLED
    (row,) = results["rows"]
    assert row["status"] == "ok" and row["embree_ratio"] is None and row["embree_note"] == embree.NOT_INSTALLED
    write_outputs(results, tmp_path)
    assert embree.NOT_INSTALLED in (tmp_path / "report.md").read_text()


def test_jobs_render_every_reference_frame_before_measuring(monkeypatch, tmp_path):
    """With --jobs, worker processes fill the disk cache first: the measuring finds every frame there."""
    require_backend("glsl")
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path / "cache"))
    config = make_config(scenes=["ten-boxes"], backends=["glsl"], size=(16, 12), repeat=1, out=tmp_path,
                         sweeps=["max_events", "size"], overhead=False, jobs=2)  # fmt: skip
    results = run_bench(config, io.StringIO())
    keys = {(r["max_events"], tuple(r["size"])) for r in results["rows"] if r["status"] == "ok"}
    assert len(keys) >= 3
    assert results["reference_cache"]["misses"] == 0 and results["reference_cache"]["hits"] == len(keys)


def test_the_spp_sweep_measures_image_errors(monkeypatch, tmp_path):
    """Each sample count's colour against 64 samples: its own backend's and the reference's, in report and plot."""
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path / "cache"))
    config = make_config(scenes=["starter"], backends=["reference"], size=(24, 18), repeat=1, out=tmp_path,
                         sweeps=["spp"], overhead=False)  # fmt: skip
    results = run_bench(config, io.StringIO())
    rows = {r["setting"]["spp"]: r for r in results["rows"]}
    assert sorted(rows) == [1, 2, 4, 8, 16] and all(r["status"] == "ok" for r in rows.values())
    errors = {n: r["image_errors"] for n, r in rows.items()}
    assert all(e["target_spp"] == 64 and e["own_mae"] == e["ref_mae"] for e in errors.values())  # it is the reference
    assert errors[16]["ref_mae"] < errors[4]["ref_mae"] < errors[1]["ref_mae"]
    assert errors[16]["ref_psnr"] > errors[1]["ref_psnr"]
    assert all(r["errors"]["mismatch"] == 0 for r in rows.values())  # the AOVs come from the pixel centre
    assert all(math.isfinite(p.color_mae) for p in plot.points(results)[0] if p.backend != "embree")
    write_outputs(results, tmp_path)
    report = (tmp_path / "report.md").read_text()
    assert "## Image error: samples per pixel" in report and "| starter | reference f64 | 16 |" in report


def test_a_run_past_its_time_limit_skips_the_rest_and_still_reports(tmp_path):
    config = make_config(scenes=["ten-boxes", "far-ten-boxes"], backends=["reference"], size=(16, 12), repeat=1,
                         out=tmp_path, sweeps=["none"], overhead=False, time_limit_s=1e-9)  # fmt: skip
    results = run_bench(config, io.StringIO())
    assert [r["status"] for r in results["rows"]] == ["skipped: the run's time limit (1e-09 s) was reached"] * 2
    write_outputs(results, tmp_path)
    report = (tmp_path / "report.md").read_text()
    assert "## Cells that did not run" in report and "| ten-boxes |" in report


def test_every_quick_scene_is_registered():
    specs = bench_scenes()
    assert set(QUICK_SCENES) <= set(specs)
    assert {"ten-boxes", "mesh-10k", "mesh-200k", "far-ten-boxes", "facing-portals"} <= set(specs)
    assert any(s.group == "demos" for s in specs.values())
