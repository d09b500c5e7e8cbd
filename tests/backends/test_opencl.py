"""The OpenCL backend: device choice, PoCL settings, width by precision, layouts, work groups, GLSL parity.

The contract it shares with GLSL (errors, AOVs, uploads, traversal, specialisation) is in
tests/backends/test_backend_contract.py.

Accuracy against the reference (f32 and f64) lives in tests/backends/test_parity.py,
which lists ``opencl`` beside ``glsl``; here the OpenCL-specific behaviour.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import test_parity as parity
from conftest import require_backend
from scenes import TABLE_STRUCTS, boxes_scene, layout_members, random_rows, upload
from scenes import render_aovs as render

from backends import shared
from backends.base import AOVS
from backends.opencl import backend as ocl
from backends.opencl import devices
from backends.opencl.backend import OpenClBackend
from engine import layout
from engine.camera_view import scene_camera
from engine.errors import BackendUnavailable

ROOT = Path(__file__).resolve().parents[2]
PRECISIONS = ["f32", "f64"]
#: OpenCL f32 against GLSL f32: the same core, so nearly every pixel agrees.
GLSL_MISMATCH_MAX = 5e-4


@pytest.fixture
def opencl(backend_factory):
    """The session's f32 OpenCL backend (skipped, or failed when required, where it cannot run)."""
    return backend_factory("opencl", "f32")


@pytest.fixture
def fresh_opencl():
    """A private OpenCL backend (for counting builds and buffers)."""
    require_backend("opencl")
    backend = OpenClBackend()
    yield backend
    backend.release()


class _FakePlatform:
    """A platform whose driver sees no device."""

    name = "Fake Platform"
    version = "OpenCL 3.0 fake"

    def get_devices(self) -> list[object]:
        import pyopencl as cl

        raise cl.RuntimeError("clGetDeviceIDs failed: DEVICE_NOT_FOUND")


# --- width by precision, probe, device choice, PoCL -----------------------------------------------------------


@pytest.mark.parametrize("precision", PRECISIONS)
def test_bvh_width_follows_the_precision_and_f64_builds_without_compiler_warnings(backend_factory, precision):
    """8-wide nodes at f32 (float8: one AVX register), 4-wide at f64 (double4: one register; double8 is two
    and PoCL warns of its ABI on every build). A default build emits no compiler warning (where it builds:
    a kernel from the cache builds nothing)."""
    backend = backend_factory("opencl", precision)
    assert backend.bvh_width == {"f32": 8, "f64": 4}[precision] == ocl.BVH_WIDTH_BY_PRECISION[precision]
    scene = boxes_scene()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            frame = render(backend, scene)
    finally:
        scene.close()
    assert backend._bvh["BVH_WIDTH"] == backend.bvh_width
    assert (frame.instance >= 0).any()
    # pyopencl's CompilerWarning ("Non-empty compiler output") is how the double8 ABI warning shows.
    assert not [w for w in caught if type(w.message).__name__ == "CompilerWarning"], [str(w.message) for w in caught]


def test_no_platform_is_a_clear_error_naming_what_to_install(monkeypatch):
    cl = pytest.importorskip("pyopencl")
    monkeypatch.setattr(cl, "get_platforms", lambda: [])
    reason = OpenClBackend.probe()
    assert reason is not None and reason.startswith("no OpenCL platform found")
    assert "pocl-binary-distribution" in reason and "pocl-opencl-icd" in reason
    with pytest.raises(BackendUnavailable, match="no OpenCL platform found"):
        OpenClBackend()

    def no_icd() -> list[object]:
        raise cl.LogicError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")

    monkeypatch.setattr(cl, "get_platforms", no_icd)
    reason = OpenClBackend.probe()
    assert reason is not None and "no OpenCL platform found" in reason and "PLATFORM_NOT_FOUND_KHR" in reason
    monkeypatch.setattr(cl, "get_platforms", lambda: [_FakePlatform()])
    reason = OpenClBackend.probe()
    assert reason is not None and "Fake Platform" in reason and "no device" in reason


def test_no_pyopencl_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyopencl", None)  # makes `import pyopencl` raise ImportError
    reason = OpenClBackend.probe()
    assert reason is not None and "pyopencl is not installed" in reason and "pyopencl[pocl]" in reason


def test_f64_on_a_device_without_fp64_is_refused_and_f32_still_builds(monkeypatch):
    require_backend("opencl")
    monkeypatch.setattr(ocl, "device_has_fp64", lambda device: False)
    with pytest.raises(BackendUnavailable, match="cl_khr_fp64"):
        OpenClBackend("f64")
    with OpenClBackend("f32") as backend:  # the float tracer's double helpers are compiled out
        assert backend.info()["fp64"] == "no"
        frame = render(backend, boxes_scene(), 32, 24, aovs=("instance", "depth"))
        defines = backend._defines()
        assert defines["EDGE_FALLBACK_FP64"] == 0 and defines["WORLD_FP64"] == 0
        assert (frame.instance >= 0).any()


def test_device_choice_by_option_and_pyopencl_ctx(monkeypatch):
    require_backend("opencl")
    import pyopencl as cl

    first = cl.get_platforms()[0].get_devices()[0]
    monkeypatch.setenv("PYOPENCL_CTX", "0:0")
    assert OpenClBackend.probe() is None
    with OpenClBackend() as backend:
        assert backend.device == first
    monkeypatch.setenv("PYOPENCL_CTX", "99:0")
    reason = OpenClBackend.probe()
    assert reason is not None and "'99:0'" in reason and "PYOPENCL_CTX" in reason
    with pytest.raises(BackendUnavailable, match="no-such-device"):
        OpenClBackend(device="0:no-such-device")
    with OpenClBackend(device="0:0") as backend:  # the option overrides the environment
        assert backend.device == first
    monkeypatch.delenv("PYOPENCL_CTX")
    chosen = devices.select_device()
    kinds = [d.type for p in cl.get_platforms() for d in devices._devices(p)]
    if any(k & cl.device_type.GPU for k in kinds):
        assert chosen.type & cl.device_type.GPU
    elif any(k & cl.device_type.CPU for k in kinds):
        assert chosen.type & cl.device_type.CPU


def test_default_device_prefers_a_gpu_and_for_f64_one_with_doubles(monkeypatch):
    cl = pytest.importorskip("pyopencl")

    class Device:
        def __init__(self, name: str, kind: int, extensions: str) -> None:
            self.name, self.type, self.extensions = name, kind, extensions

    class Platform:
        name = "Fake"

        def __init__(self, *devices: Device) -> None:
            self.devices = list(devices)

        def get_devices(self) -> list[Device]:
            return self.devices

    gpu = Device("gpu", cl.device_type.GPU, "cl_khr_byte_addressable_store")
    cpu = Device("cpu", cl.device_type.CPU, "cl_khr_fp64 cl_khr_byte_addressable_store")
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    monkeypatch.setattr(cl, "get_platforms", lambda: [Platform(cpu), Platform(gpu)])
    assert devices.select_device() is gpu
    assert devices.select_device(prefer_fp64=True) is cpu
    monkeypatch.setattr(cl, "get_platforms", lambda: [Platform(gpu)])
    assert devices.select_device(prefer_fp64=True) is gpu  # none has doubles: the constructor names the extension


def test_caches_go_under_the_project_cache_dir_without_clobbering(monkeypatch, tmp_path):
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("POCL_CACHE_DIR", raising=False)
    assert ocl.configure_caches() == str(tmp_path / "opencl" / "pyopencl")
    assert os.environ["POCL_CACHE_DIR"] == str(tmp_path / "opencl" / "pocl")
    monkeypatch.setenv("POCL_CACHE_DIR", "/somewhere/else")
    ocl.configure_caches()
    assert os.environ["POCL_CACHE_DIR"] == "/somewhere/else"
    monkeypatch.delenv("ABERRANT_CACHE_DIR")  # the default, as for the BVH cache
    assert ocl.configure_caches() == str(Path.home() / ".cache" / "aberrant" / "opencl" / "pyopencl")


def test_pocl_defaults_apply_only_where_the_user_set_nothing(monkeypatch):
    monkeypatch.delenv("POCL_AFFINITY", raising=False)
    devices.configure_runtime()
    assert os.environ["POCL_AFFINITY"] == "1"
    monkeypatch.setenv("POCL_AFFINITY", "0")
    devices.configure_runtime()
    assert os.environ["POCL_AFFINITY"] == "0"


def test_pocl_defaults_reach_a_fresh_process_before_pocl_starts():
    """Importing pyopencl through the backend sets them (PoCL reads them once, at its first platform query)."""
    require_backend("opencl")
    env = {k: v for k, v in os.environ.items() if k != "POCL_AFFINITY"}
    code = "import os; from backends.opencl import devices as b; b.platforms(); print(os.environ.get('POCL_AFFINITY'))"
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "1"


def test_cli_renders_at_f64_and_fills_the_kernel_cache(tmp_path):
    """A fresh process: ``aberrant render --backend opencl --precision f64``; PoCL's cache lands in the project's."""
    require_backend("opencl")
    env = {k: v for k, v in os.environ.items() if k != "POCL_CACHE_DIR"}
    env["ABERRANT_CACHE_DIR"] = str(tmp_path / "cache")
    out = tmp_path / "frame.png"
    command = [sys.executable, "-m", "aberrant.cli", "render", "starter", "--backend", "opencl", "--precision", "f64"]
    result = subprocess.run(
        [*command, "--size", "48x36", "--out", str(out)], cwd=ROOT, env=env, capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr
    assert "with the opencl backend" in result.stdout and out.stat().st_size > 0
    if devices.pocl_version(devices.select_device().platform) is not None:
        assert any((tmp_path / "cache" / "opencl" / "pocl").rglob("*")), "PoCL cached nothing"


def test_each_feature_set_is_its_own_cached_variant(fresh_opencl):
    """Plain, radial and portal-with-aberration scenes build one variant each, with the defines they need."""
    radial = boxes_scene()
    radial.add_aberration("bend", (0.3, 0.0, 0.0), mode="radial", scale=2.0)
    both = boxes_scene()
    both.add_aberration("squash", (0.5, 0.0, 0.0), scale=2.0)
    both.add_portal_pair("door_a", "door_b", a={"position": (0.0, 1.0, 2.0)}, b={"position": (50.0, 1.0, 0.0)})
    for scene in (boxes_scene(), radial, both, boxes_scene(), radial):
        render(fresh_opencl, scene, 16, 12, aovs=("color",))
    assert fresh_opencl.compile_count == 3
    names = ("HAS_ABERRATIONS", "HAS_METRIC", "HAS_RADIAL", "HAS_ADDITIVE", "HAS_PORTALS")
    assert [tuple(dict(key)[n] for n in names) for key in fresh_opencl._kernels] == [
        (0, 0, 0, 0, 0),
        (1, 0, 1, 0, 0),
        (1, 1, 0, 0, 1),
    ]


def test_kernel_arguments_follow_the_table_order():
    text = shared.read("trace.cl", "backends.opencl")
    signature = re.search(r"__kernel void trace\((.*?)\)", text, re.S)
    assert signature is not None
    names = re.findall(r"(\w+)\s*(?:,|$)", signature.group(1).strip())
    assert tuple(names) == ocl.KERNEL_ARGS


# --- layouts: the kernel's records read exactly the packed bytes ------------------------------------

_TABLE_STRUCTS = {
    **TABLE_STRUCTS,
    "bvh8_nodes": "Bvh8Node",  # bvh_nodes packed with bvh_width=8 (float8 / int8 members)
}
_SPECIAL_NODES = {
    "bvh4_nodes": layout.BVH4_NODE_DTYPE,
    "bvh8_nodes": layout.BVH8_NODE_DTYPE,
    "bvh_compact_nodes": layout.BVH_COMPACT_NODE_DTYPE,
}


@pytest.mark.parametrize("precision", PRECISIONS)
def test_layout_h_records_read_the_packed_bytes(backend_factory, precision):
    """A kernel copies every member of every row out bit for bit: offsets and strides agree with engine.layout."""
    backend = backend_factory("opencl", precision)
    import pyopencl as cl

    for table, struct in _TABLE_STRUCTS.items():
        dtype = _SPECIAL_NODES[table] if table in _SPECIAL_NODES else layout.table_dtype(table, precision)
        rows = random_rows(dtype, 5, np.random.default_rng(7))
        stores, words = [], 0
        for kind, member in layout_members(struct):
            lanes = [f"s{k}" for k in range(8)] if kind.endswith("8") else list("xyzw")
            for c in lanes:
                value = f"rows[i].{member}.{c}"
                if kind in ("int4", "int8"):
                    stores.append(f"words[base + {words}] = (uint)({value});")
                    words += 1
                elif kind in ("float4", "float8") or precision == "f32":
                    stores.append(f"words[base + {words}] = as_uint({value});")
                    words += 1
                else:
                    stores.append(f"uint2 w{member}{c} = as_uint2({value});")
                    stores.append(
                        f"words[base + {words}] = w{member}{c}.x; words[base + {words + 1}] = w{member}{c}.y;"
                    )
                    words += 2
        source = (
            shared.defines_block({"REAL_IS_DOUBLE": int(precision == "f64"), "BVH_WIDTH": 8})
            + shared.read("prelude_cl.h")
            + shared.read("layout.h")
            + f"__kernel void copy(__global const {struct}* rows, __global uint* words) {{\n"
            + f"  int i = get_global_id(0);\n  int base = i * {words};\n  "
            + "\n  ".join(stores)
            + "\n}\n"
        )
        ctx, queue = backend.context, backend.queue
        kernel = cl.Kernel(cl.Program(ctx, source).build(), "copy")
        mf = cl.mem_flags
        src = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=rows)
        out = cl.Buffer(ctx, mf.WRITE_ONLY, len(rows) * words * 4)
        kernel.set_arg(0, src)
        kernel.set_arg(1, out)
        cl.enqueue_nd_range_kernel(queue, kernel, (len(rows),), None)
        got = np.empty((len(rows), words), np.uint32)
        cl.enqueue_copy(queue, got, out)
        raw = rows.view(np.uint8).reshape(len(rows), dtype.itemsize)
        expected = raw[:, : words * 4].copy().view(np.uint32)
        assert dtype.itemsize - words * 4 < (32 if precision == "f64" else 16), table  # only tail padding
        np.testing.assert_array_equal(got, expected, err_msg=table)


# --- work groups ----------------------------------------------------------------------------------


def test_odd_sizes_and_any_work_group_size_give_the_same_frame(opencl):
    """The global size is rounded up to the work group; the kernel drops the pixels outside the image."""
    scene = boxes_scene()
    reference = render(opencl, scene, 37, 23)
    for local_size in (None, (8, 8), (32, 4)):
        with OpenClBackend(local_size=local_size) as backend:
            frame = render(backend, scene, 37, 23)
        for name in AOVS:
            np.testing.assert_array_equal(frame.aov(name), reference.aov(name), err_msg=f"{local_size} {name}")


# --- variants and the per-frame path -------------------------------------------------------------


def test_a_variant_is_built_once_and_its_kernel_object_kept(fresh_opencl, monkeypatch):
    import pyopencl as cl

    made: list[object] = []
    launched: list[int] = []
    kernel_class, launch = cl.Kernel, cl.enqueue_nd_range_kernel

    def make_kernel(*args: object) -> object:
        kernel = kernel_class(*args)
        made.append(kernel)
        return kernel

    def enqueue(queue: object, kernel: object, *args: object, **kwargs: object) -> object:
        launched.append(id(kernel))
        return launch(queue, kernel, *args, **kwargs)

    monkeypatch.setattr(cl, "Kernel", make_kernel)
    monkeypatch.setattr(cl, "enqueue_nd_range_kernel", enqueue)
    scene = boxes_scene()
    upload(fresh_opencl, scene)
    camera = scene_camera(scene)
    assert fresh_opencl.compile_count == 0
    fresh_opencl.render(camera, 32, 24, aovs=("color", "depth"))
    fresh_opencl.render(camera, 32, 24, aovs=("color", "depth"))
    fresh_opencl.render(camera, 48, 24, aovs=("color", "instance"))  # other size and AOVs: the same program
    upload(fresh_opencl, boxes_scene())  # same features: the same variant
    fresh_opencl.render(camera, 32, 24)
    assert fresh_opencl.compile_count == 1
    first = launched[0]  # made now, or given back by a released backend (cache.take_kernel)
    assert len(made) <= 1 and launched == [first] * 4
    fresh_opencl.extra_defines = {"BRUTE_FORCE": 1}  # another variant: built once too
    fresh_opencl.render(camera, 32, 24)
    fresh_opencl.render(camera, 32, 24)
    fresh_opencl.extra_defines = {}
    fresh_opencl.render(camera, 32, 24)
    assert fresh_opencl.compile_count == 2 and len(made) <= 2
    second = launched[4]
    assert second != first and launched[4:] == [second, second, first]


# --- creating and releasing backends ------------------------------------------------------------------

#: A child process: 10 warm-up cycles, then 50 measured ones of create, upload, render, release.
CHURN = """
import ctypes, gc, json, sys, tracemalloc
from backends.opencl.backend import OpenClBackend
from demos import build_demo
from engine.camera_view import scene_camera
from engine.packing import ScenePacker

libc = ctypes.CDLL("libc.so.6")

def rss():
    libc.malloc_trim(0)  # hand freed heap back first: what stays resident is what is still held
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096

scene = build_demo("starter")
first = OpenClBackend()
packer = ScenePacker(precision=first.precision, bvh_width=first.bvh_width)
updates = packer.sync(scene)
first.release()
camera = scene_camera(scene)

def cycle():
    backend = OpenClBackend()
    backend.upload(packer.packed, updates)
    backend.render(camera, 16, 12, ("color",))
    backend.release()

tracemalloc.start()  # before the warm-up: its own bookkeeping is resident memory too
for _ in range(10):
    cycle()
gc.collect()
before, resident = tracemalloc.get_traced_memory()[0], rss()
for _ in range(50):
    cycle()
gc.collect()
print(json.dumps({"python": tracemalloc.get_traced_memory()[0] - before, "resident": rss() - resident}))
"""


def test_creating_and_releasing_backends_does_not_grow_memory():
    """50 backends, each rendering a frame: their programs are built once per process (a PoCL program
    build leaves ~12 KB behind, a kernel object ~1.7 KB) and kernels handed on, so resident memory stays
    put (it grew ~28 KB a cycle when each backend built its own)."""
    require_backend("opencl")
    if not Path("/proc/self/statm").exists() or not sys.platform.startswith("linux"):
        pytest.skip("resident memory is read from /proc/self/statm, freed heap returned by glibc's malloc_trim")
    result = subprocess.run([sys.executable, "-c", CHURN], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    grown = json.loads(result.stdout.splitlines()[-1])
    assert grown["python"] < 64 * 1024, grown
    assert grown["resident"] < 256 * 1024, grown  # 50 cycles: 12-60 KB in all here, 1.4 MB before


# --- against the GLSL backend: the same core, so the same picture ---------------------------------


@pytest.mark.parametrize("case", ["starter", "random-boxes", "imported-mesh", "watertight-sphere"])
def test_f32_agrees_with_glsl_f32(backend_factory, tmp_path_factory, case):
    opencl = backend_factory("opencl", "f32")
    glsl = backend_factory("glsl", "f32")
    folder = tmp_path_factory.mktemp("opencl-glsl")
    frames = []
    for backend in (opencl, glsl):
        scene = parity.CASES[case].build(folder)
        try:
            frames.append(parity.render(backend, scene, parity.CASES[case].size))
        finally:
            scene.close()
    mine, theirs = frames
    mismatch = float(np.mean(mine.instance != theirs.instance))
    assert mismatch <= GLSL_MISMATCH_MAX, f"instance mismatch {mismatch:.4%}"
    same = (mine.instance == theirs.instance) & (mine.instance >= 0)
    rel = np.abs(mine.depth[same].astype(np.float64) - theirs.depth[same]) / theirs.depth[same]
    assert float(np.percentile(rel, 99)) <= 1e-5


def test_a_frame_without_colour_skips_the_shading_and_keeps_the_hits(fresh_opencl):
    """The hits-only variant (SHADE 0: what Embree's pairing times) is a program of its own with the same hits."""
    scene = boxes_scene()
    upload(fresh_opencl, scene)
    camera = scene_camera(scene)
    full = fresh_opencl.render(camera, 32, 24, aovs=("color", "depth", "instance"))
    hits = fresh_opencl.render(camera, 32, 24, aovs=("depth", "instance"))
    assert fresh_opencl.compile_count == 2
    assert (full.aov("instance") >= 0).any()
    np.testing.assert_array_equal(hits.aov("instance"), full.aov("instance"))
    np.testing.assert_array_equal(hits.aov("depth"), full.aov("depth"))
