"""Tracer speed: 800x800 frames of three scenes, per backend, side by side (``make bench``).

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
import trimesh

from engine.packing import ScenePacker, scene_camera
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


def ten_boxes(folder: Path) -> Scene:
    """Ten boxes standing on a checkered floor."""
    scene = Scene("ten-boxes")
    scene.add_mesh("floor", "plane", scale=(40.0, 1.0, 40.0), checker=1.0)
    rng = np.random.default_rng(1)
    for k in range(10):
        scene.add_mesh(
            f"box{k}",
            "box",
            position=(-4.5 + k, 0.5 + 0.3 * (k % 3), -2.0 - 1.5 * (k % 4)),
            euler_deg=(0.0, 17.0 * k, 0.0),
            scale=0.8,
            color=tuple(rng.uniform(0.2, 1.0, 3)),
        )
    scene.set_camera((0.0, 2.5, 6.0), look_at=(0.0, 0.5, -2.0), fov_deg=60.0)
    return scene


def torus(folder: Path, major_sections: int, minor_sections: int) -> Scene:
    """One imported torus filling most of the view (2 * major * minor triangles)."""
    path = folder / f"torus-{major_sections}x{minor_sections}.obj"
    if not path.exists():
        trimesh.creation.torus(
            major_radius=1.0, minor_radius=0.4, major_sections=major_sections, minor_sections=minor_sections
        ).export(path)
    scene = Scene(f"torus-{2 * major_sections * minor_sections}")
    scene.add_asset("torus", path=path)
    scene.add_mesh("torus", "torus", euler_deg=(60.0, 0.0, 0.0), color=(0.9, 0.7, 0.3))
    scene.set_camera((0.0, 0.0, 2.2), look_at=(0.0, 0.0, 0.0), fov_deg=60.0)
    return scene


SCENES: dict[str, Callable[[Path], Scene]] = {
    "ten-boxes": ten_boxes,
    "mesh-10k": lambda folder: torus(folder, 100, 50),
    "mesh-200k": lambda folder: torus(folder, 500, 200),
}


@pytest.fixture(scope="module")
def assets(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("bench-assets")


def _bench(benchmark, backend, scene: Scene, rounds: int | None = None) -> None:
    """Upload once, then time whole frames (dispatch and read-back of the colour)."""
    packer = ScenePacker(precision=backend.precision, camera_relative=backend.camera_relative)
    updates = packer.sync(scene)
    assert packer.packed is not None
    backend.upload(packer.packed, updates)
    camera = scene_camera(scene)
    # Compiles the variants (a small frame where a frame is slow) and measures the coverage.
    size = (WIDTH, HEIGHT) if rounds is None else (64, 64)
    first = backend.render(camera, *size, ("color", "instance"))
    if rounds is None:
        benchmark(backend.render, camera, WIDTH, HEIGHT, AOVS)
    else:
        benchmark.pedantic(backend.render, args=(camera, WIDTH, HEIGHT, AOVS), rounds=rounds, iterations=1)
    median = benchmark.stats.stats.median
    benchmark.extra_info["mrays_per_s"] = round(WIDTH * HEIGHT / median / 1e6, 3)
    benchmark.extra_info["triangles"] = int(packer.packed.counts["triangles"])
    benchmark.extra_info["coverage"] = round(float(np.mean(first.instance >= 0)), 3)
    benchmark.extra_info["backend"] = f"{backend.name}-{backend.precision}"


@pytest.mark.parametrize(("backend_name", "precision"), BENCH_BACKENDS)
@pytest.mark.benchmark(group="800x800 ten boxes and a floor")
def test_bench_ten_boxes(benchmark, backend_factory, assets, backend_name, precision):
    _bench(benchmark, backend_factory(backend_name, precision), SCENES["ten-boxes"](assets))


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
