"""Tracer speed: 800x800 frames of several scenes, per backend, side by side (``make bench``).

pytest-benchmark groups the results by scene, so the backends (and the
brute-force kernel, which tests every triangle, beside the BVH) compare
directly. Each result carries ``mrays_per_s`` (primary rays per second at the
median frame time), the scene's triangle count and its coverage in
``extra_info``. Skipped by ``make test`` (``--benchmark-skip`` in pyproject).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from aberrant.bench.scenes import mesh_10k, mesh_200k, ten_boxes, ten_boxes_aberration, ten_boxes_portals
from backends.upload import SceneUploader
from engine.camera_view import scene_camera
from engine.scene import Scene

#: (backend, precision) pairs benchmarked. The OpenCL backend slots in here.
BENCH_BACKENDS = [
    pytest.param("glsl", "f32", id="glsl-f32"),
    pytest.param("glsl", "f64", id="glsl-f64"),
    pytest.param("opencl", "f32", id="opencl-f32"),
    pytest.param("opencl", "f64", id="opencl-f64"),
]
WIDTH = HEIGHT = 800
AOVS = ("color",)  # what the CLI and the app read back


def ten_boxes_bending(folder: Path) -> Scene:
    """Ten boxes seen through three overlapping boxes of every mode (the aberration worst case).

    Two rotated metric boxes and a radial one of higher priority overlapping both: nearly every
    ray crosses two to six box faces, changing its direction at each, before it hits something.
    """
    scene = ten_boxes(folder)
    scene.name = "ten-boxes-bending"
    scene.add_aberration("left", (0.6, 0.0, 0.8), position=(-2.5, 1.0, -2.0), euler_deg=(0, 20, 0), scale=(5, 4, 6))
    scene.add_aberration("right", (-0.3, 0.5, 0.4), position=(2.5, 1.0, -2.0), euler_deg=(0, -15, 5), scale=(5, 4, 6))
    scene.add_aberration(
        "middle", (0.2, -0.15, 0.1), mode="radial", position=(0.0, 1.5, 1.0), scale=(6, 5, 4), priority=1
    )
    return scene


SCENES: dict[str, Callable[[Path], Scene]] = {
    "ten-boxes": ten_boxes,
    "ten-boxes-aberration": ten_boxes_aberration,
    "ten-boxes-bending": ten_boxes_bending,
    "ten-boxes-portals": ten_boxes_portals,
    "mesh-10k": mesh_10k,
    "mesh-200k": mesh_200k,
}
#: The plain scene and its deformed variants (same geometry): the medians' ratios are the price of
#: the non-Euclidean machinery (aberrations <= 1.3x, portals <= 1.2x wanted).
SPACE_VARIANTS = ("ten-boxes", "ten-boxes-aberration", "ten-boxes-bending", "ten-boxes-portals")


@pytest.fixture(scope="module")
def assets(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("bench-assets")


def _bench(benchmark, backend, scene: Scene, rounds: int | None = None) -> None:
    """Upload once, then time whole frames (dispatch and read-back of the colour)."""
    uploader = SceneUploader(backend)
    uploader.sync(scene)
    assert uploader.packed is not None
    camera = scene_camera(scene)
    # Compiles the variants (a small frame where a frame is slow) and measures the coverage.
    size = (WIDTH, HEIGHT) if rounds is None else (64, 64)
    first = backend.render(camera, *size, ("color", "instance", "events"))
    if rounds is None:
        benchmark(backend.render, camera, WIDTH, HEIGHT, AOVS)
    else:
        benchmark.pedantic(backend.render, args=(camera, WIDTH, HEIGHT, AOVS), rounds=rounds, iterations=1)
    median = benchmark.stats.stats.median
    benchmark.extra_info["mrays_per_s"] = round(WIDTH * HEIGHT / median / 1e6, 3)
    benchmark.extra_info["triangles"] = int(uploader.packed.counts["triangles"])
    benchmark.extra_info["coverage"] = round(float(np.mean(first.instance >= 0)), 3)
    benchmark.extra_info["events"] = round(float(np.mean(first.events)), 3)
    benchmark.extra_info["backend"] = f"{backend.name}-{backend.precision}"


@pytest.mark.parametrize(("backend_name", "precision"), BENCH_BACKENDS)
@pytest.mark.benchmark(group="800x800 ten boxes and a floor")
def test_bench_ten_boxes(benchmark, backend_factory, assets, backend_name, precision):
    _bench(benchmark, backend_factory(backend_name, precision), SCENES["ten-boxes"](assets))


@pytest.mark.parametrize("variant", SPACE_VARIANTS)
@pytest.mark.parametrize(("backend_name", "precision"), BENCH_BACKENDS)
@pytest.mark.benchmark(group="800x800 ten boxes: plain, through aberrations, through portals")
def test_bench_space_overhead(benchmark, backend_factory, assets, backend_name, precision, variant):
    """The same geometry plain, behind aberrations and through portals covering most of the view.

    ``events`` in ``extra_info`` is the mean event count per pixel.
    """
    _bench(benchmark, backend_factory(backend_name, precision), SCENES[variant](assets))


@pytest.mark.parametrize(("backend_name", "precision"), BENCH_BACKENDS)
@pytest.mark.benchmark(group="800x800 mesh of 10,000 triangles")
def test_bench_mesh_10k(benchmark, backend_factory, assets, backend_name, precision):
    _bench(benchmark, backend_factory(backend_name, precision), SCENES["mesh-10k"](assets))


@pytest.mark.parametrize(("backend_name", "precision"), BENCH_BACKENDS)
@pytest.mark.benchmark(group="800x800 mesh of 200,000 triangles")
def test_bench_mesh_200k(benchmark, backend_factory, assets, backend_name, precision):
    _bench(benchmark, backend_factory(backend_name, precision), SCENES["mesh-200k"](assets))


@pytest.mark.parametrize(("backend_name", "precision"), [p for p in BENCH_BACKENDS if p.values[1] == "f32"])
@pytest.mark.benchmark(group="800x800 mesh of 10,000 triangles")
def test_bench_mesh_10k_brute_force(benchmark, backend_factory, assets, backend_name, precision):
    """Every triangle against every ray (the BRUTE_FORCE kernel variant): what the BVH saves."""
    backend = backend_factory(backend_name, precision)
    if not hasattr(backend, "extra_defines"):
        pytest.skip(f"the {backend_name} backend has no BRUTE_FORCE kernel variant")
    backend.extra_defines = {**backend.extra_defines, "BRUTE_FORCE": 1}
    try:
        _bench(benchmark, backend, SCENES["mesh-10k"](assets), rounds=1)
    finally:
        backend.extra_defines = {k: v for k, v in backend.extra_defines.items() if k != "BRUTE_FORCE"}
    benchmark.extra_info["backend"] += "-brute-force"
