"""The OpenCL backend: contract, device choice, clear errors, layouts, AOVs, variant cache, uploads, GLSL parity.

Accuracy against the reference (f32 and f64) lives in tests/test_parity.py,
which lists ``opencl`` beside ``glsl``; here the OpenCL-specific behaviour.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import test_parity as parity
from conftest import require_backend
from test_glsl import SPECIALISATIONS, compiled_functions, expected_functions

from backends import shared
from backends.base import AOVS, backend_class
from backends.opencl import backend as ocl
from backends.opencl.backend import OpenClBackend
from components import Transform
from engine import layout
from engine.camera_view import CameraView, scene_camera
from engine.errors import AberrantError, BackendUnavailable
from engine.packed import TableUpdate
from engine.packing import ScenePacker
from engine.scene import Scene

ROOT = Path(__file__).resolve().parent.parent
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


def upload(backend, scene: Scene) -> ScenePacker:
    packer = ScenePacker(
        precision=backend.precision, camera_relative=backend.camera_relative, bvh_width=backend.bvh_width
    )
    updates = packer.sync(scene)
    assert packer.packed is not None
    backend.upload(packer.packed, updates)
    return packer


def render(backend, scene: Scene, width: int = 48, height: int = 36, aovs=AOVS):
    upload(backend, scene)
    return backend.render(scene_camera(scene), width, height, aovs)


def boxes_scene() -> Scene:
    scene = Scene("boxes")
    scene.add_mesh("floor", "plane", scale=(20.0, 1.0, 20.0), checker=0.5)
    scene.add_mesh("a", "box", position=(-1.5, 0.5, 0.0), color=(0.9, 0.2, 0.2))
    scene.add_mesh("b", "box", position=(0.0, 0.5, -1.0), euler_deg=(0.0, 30.0, 0.0), color=(0.2, 0.9, 0.2))
    scene.add_mesh("c", "sphere", position=(1.5, 0.5, 0.0), color=(0.2, 0.2, 0.9))
    scene.set_camera((0.0, 2.0, 5.0), look_at=(0.0, 0.3, 0.0), fov_deg=60.0)
    return scene


class _FakePlatform:
    """A platform whose driver sees no device."""

    name = "Fake Platform"
    version = "OpenCL 3.0 fake"

    def get_devices(self) -> list[object]:
        import pyopencl as cl

        raise cl.RuntimeError("clGetDeviceIDs failed: DEVICE_NOT_FOUND")


# --- contract, probe, device choice -----------------------------------------------------------


def test_contract_probe_and_info(opencl):
    assert backend_class("opencl") is OpenClBackend
    assert OpenClBackend.name == "opencl"
    assert OpenClBackend.precisions == ("f32", "f64")
    assert OpenClBackend.camera_relative is True
    assert OpenClBackend.probe() is None
    info = opencl.info()
    for key in ("platform", "device", "type", "opencl", "compute units", "fp64", "precision", "work group"):
        assert info[key], key
    assert re.search(r"OpenCL \d+\.\d+", info["opencl"])
    assert info["fp64"] in ("yes", "no")
    assert int(info["compute units"]) >= 1
    if "Portable Computing Language" in info["platform"]:
        assert re.match(r"\d+\.\d+", info["pocl"])


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
    chosen = ocl.select_device()
    kinds = [d.type for p in cl.get_platforms() for d in ocl._devices(p)]
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
    assert ocl.select_device() is gpu
    assert ocl.select_device(prefer_fp64=True) is cpu
    monkeypatch.setattr(cl, "get_platforms", lambda: [Platform(gpu)])
    assert ocl.select_device(prefer_fp64=True) is gpu  # none has doubles: the constructor names the extension


def test_caches_go_under_the_project_cache_dir_without_clobbering(monkeypatch, tmp_path):
    monkeypatch.setenv("ABERRANT_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("POCL_CACHE_DIR", raising=False)
    assert ocl.configure_caches() == str(tmp_path / "opencl" / "pyopencl")
    assert os.environ["POCL_CACHE_DIR"] == str(tmp_path / "opencl" / "pocl")
    monkeypatch.setenv("POCL_CACHE_DIR", "/somewhere/else")
    ocl.configure_caches()
    assert os.environ["POCL_CACHE_DIR"] == "/somewhere/else"
    monkeypatch.delenv("ABERRANT_CACHE_DIR")
    assert ocl.configure_caches() is None


def test_pocl_defaults_apply_only_where_the_user_set_nothing(monkeypatch):
    monkeypatch.delenv("POCL_AFFINITY", raising=False)
    ocl.configure_runtime()
    assert os.environ["POCL_AFFINITY"] == "1"
    monkeypatch.setenv("POCL_AFFINITY", "0")
    ocl.configure_runtime()
    assert os.environ["POCL_AFFINITY"] == "0"


def test_pocl_defaults_reach_a_fresh_process_before_pocl_starts():
    """Importing pyopencl through the backend sets them (PoCL reads them once, at its first platform query)."""
    require_backend("opencl")
    env = {k: v for k, v in os.environ.items() if k != "POCL_AFFINITY"}
    code = "import os; from backends.opencl import backend as b; b.platforms(); print(os.environ.get('POCL_AFFINITY'))"
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "1"


def test_cli_renders_at_f64_and_fills_the_kernel_cache(tmp_path):
    """A fresh process: ``aberrant render --backend opencl --precision f64``; PoCL's cache lands in the project's."""
    require_backend("opencl")
    env = {k: v for k, v in os.environ.items() if k != "POCL_CACHE_DIR"}
    env["ABERRANT_CACHE_DIR"] = str(tmp_path / "cache")
    out = tmp_path / "frame.png"
    command = [sys.executable, "-m", "engine.cli", "render", "starter", "--backend", "opencl", "--precision", "f64"]
    result = subprocess.run(
        [*command, "--size", "48x36", "--out", str(out)], cwd=ROOT, env=env, capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr
    assert "with the opencl backend" in result.stdout and out.stat().st_size > 0
    if ocl.pocl_version(ocl.select_device().platform) is not None:
        assert any((tmp_path / "cache" / "opencl" / "pocl").rglob("*")), "PoCL cached nothing"


def test_render_before_upload_and_bad_arguments_are_clear_errors(fresh_opencl):
    with pytest.raises(AberrantError, match="upload"):
        fresh_opencl.render(CameraView(np.zeros(3), np.eye(3), 60.0), 4, 4)
    scene = boxes_scene()
    upload(fresh_opencl, scene)
    with pytest.raises(AberrantError, match="AOV"):
        fresh_opencl.render(scene_camera(scene), 4, 4, aovs=("colour",))
    with pytest.raises(AberrantError, match="positive"):
        fresh_opencl.render(scene_camera(scene), 0, 4)
    packer = ScenePacker(precision="f64")
    packer.sync(scene)
    assert packer.packed is not None
    with pytest.raises(AberrantError, match="f64"):
        fresh_opencl.upload(packer.packed, [])


def test_release_is_idempotent_and_final():
    require_backend("opencl")
    backend = OpenClBackend()
    backend.release()
    backend.release()
    with pytest.raises(AberrantError, match="release"):
        upload(backend, boxes_scene())


@pytest.mark.parametrize(("modes", "portals"), SPECIALISATIONS)
def test_a_variant_compiles_only_the_machinery_its_scene_uses(modes, portals):
    """A plain scene's kernel has no aberration or portal code at all; each mode brings only its own rules."""
    from engine.packed import Features

    for precision in (0, 1):
        defines = {**Features(portals, frozenset(modes)).defines(), "REAL_IS_DOUBLE": precision}
        assert compiled_functions(OpenClBackend.source(defines)) == expected_functions(modes, portals)


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


def test_kernel_source_is_assembled_from_the_shared_core():
    source = OpenClBackend.source({"MAX_EVENTS": 16, "REAL_IS_DOUBLE": 0})
    order = ("prelude_cl.h", "layout.h", "bindings_cl.h", *shared.TRACER_FILES, "trace.cl")
    marks = [source.index(f"// ---- {name}") for name in order]
    assert marks == sorted(marks)  # each file builds on those before it
    for name in shared.TRACER_FILES:
        assert shared.read(name) in source, name
    assert "#define MAX_EVENTS 16\n" in source
    assert "#include" not in source  # one self-contained string: the whole cache key


def test_kernel_arguments_follow_the_table_order():
    text = shared.read("trace.cl", "backends.opencl")
    signature = re.search(r"__kernel void trace\((.*?)\)", text, re.S)
    assert signature is not None
    names = re.findall(r"(\w+)\s*(?:,|$)", signature.group(1).strip())
    assert tuple(names) == ocl.KERNEL_ARGS


# --- layouts: the kernel's records read exactly the packed bytes ------------------------------------

_TABLE_STRUCTS = {
    "settings": "Settings",
    "triangles": "Triangle",
    "triangle_uvs": "TriangleUv",
    "bvh_nodes": "BvhNode",
    "instances": "Instance",
    "materials": "Material",
    "aberrations": "Aberration",
    "portals": "Portal",
    "triangle_blocks": "TriangleBlock",
    "camera": "Camera",
    "bvh4_nodes": "Bvh4Node",  # bvh_nodes packed with bvh_width=4
    "bvh_compact_nodes": "BvhCompactNode",  # bvh_nodes packed with bvh_compact=True
    "bvh8_nodes": "Bvh8Node",  # bvh_nodes packed with bvh_width=8 (float8 / int8 members)
}
_SPECIAL_NODES = {
    "bvh4_nodes": layout.BVH4_NODE_DTYPE,
    "bvh8_nodes": layout.BVH8_NODE_DTYPE,
    "bvh_compact_nodes": layout.BVH_COMPACT_NODE_DTYPE,
}


def _members(struct: str) -> list[tuple[str, str]]:
    text = shared.read("layout.h")
    body = re.search(rf"STRUCT_BEGIN\({struct}\)(.*?)STRUCT_END\({struct}\)", text, re.S)
    assert body is not None, struct
    return re.findall(r"^\s*(\w+)\s+(\w+);", body.group(1), re.M)


def _random_rows(dtype: np.dtype, n: int, rng: np.random.Generator) -> np.ndarray:
    rows = np.zeros(n, dtype)
    for name in dtype.names:
        field = rows[name]
        if np.issubdtype(field.dtype, np.floating):
            rows[name] = rng.normal(size=field.shape) * 100.0
        else:
            rows[name] = rng.integers(-1000, 1000, size=field.shape)
    return rows


@pytest.mark.parametrize("precision", PRECISIONS)
def test_layout_h_records_read_the_packed_bytes(backend_factory, precision):
    """A kernel copies every member of every row out bit for bit: offsets and strides agree with engine.layout."""
    backend = backend_factory("opencl", precision)
    import pyopencl as cl

    for table, struct in _TABLE_STRUCTS.items():
        dtype = _SPECIAL_NODES[table] if table in _SPECIAL_NODES else layout.table_dtype(table, precision)
        rows = _random_rows(dtype, 5, np.random.default_rng(7))
        stores, words = [], 0
        for kind, member in _members(struct):
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


# --- AOVs ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("precision", PRECISIONS)
def test_aov_shapes_dtypes_and_no_nan(backend_factory, precision):
    backend = backend_factory("opencl", precision)
    scene = boxes_scene()
    frame = render(backend, scene, 40, 30)
    assert frame.present() == list(AOVS)
    assert frame.color.shape == (30, 40, 4) and frame.color.dtype == np.uint8
    for name, dtype in (("depth", np.float32), ("perceived", np.float32), ("instance", np.int32), ("events", np.uint8)):
        assert frame.aov(name).shape == (30, 40) and frame.aov(name).dtype == dtype, name
    hit = frame.instance >= 0
    assert hit.any() and (~hit).any()
    for name in ("depth", "perceived"):
        value = frame.aov(name)
        assert not np.isnan(value).any()
        assert np.all(np.isfinite(value[hit])) and np.all(value[hit] > 0)
        assert np.all(value[~hit] == np.inf)
    assert np.all(frame.color[..., 3] == 255)
    assert np.all(frame.events == 0)
    entities = {scene.entity(n) for n in ("floor", "a", "b", "c")}
    assert set(np.unique(frame.instance[hit]).tolist()) <= entities
    for key in ("dispatch", "readback", "render"):
        assert frame.timings_ms[key] > 0


def test_row_zero_is_top(opencl):
    scene = Scene()
    scene.add_mesh("floor", "plane", scale=(50.0, 1.0, 50.0))
    scene.set_camera((0.0, 1.0, 0.0), rotation=(0.0, 0.0, 0.0, 1.0), fov_deg=90.0)
    instance = render(opencl, scene, 16, 16, aovs=("instance",)).instance
    assert np.all(instance[:8] == -1) and np.all(instance[8:] >= 0)  # the floor is below the horizon


def test_only_requested_aovs_are_read_back_and_agree_with_a_full_frame(opencl):
    scene = boxes_scene()
    full = render(opencl, scene)
    frame = render(opencl, scene, aovs=("depth",))
    assert frame.present() == ["depth"]
    np.testing.assert_array_equal(frame.depth, full.depth)
    frame = render(opencl, scene, aovs=("events", "color"))
    assert frame.present() == ["color", "events"]
    np.testing.assert_array_equal(frame.color, full.color)
    assert render(opencl, scene, aovs=()).present() == []


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
    fresh_opencl.render(camera, 48, 24, aovs=("instance",))  # other size and AOVs: the same program
    upload(fresh_opencl, boxes_scene())  # same features: the same variant
    fresh_opencl.render(camera, 32, 24)
    assert fresh_opencl.compile_count == 1
    assert len(made) == 1 and launched == [id(made[0])] * 4
    fresh_opencl.extra_defines = {"BRUTE_FORCE": 1}  # another variant: built once too
    fresh_opencl.render(camera, 32, 24)
    fresh_opencl.render(camera, 32, 24)
    fresh_opencl.extra_defines = {}
    fresh_opencl.render(camera, 32, 24)
    assert fresh_opencl.compile_count == 2 and len(made) == 2
    assert launched[4:] == [id(made[1]), id(made[1]), id(made[0])]


def test_frames_of_one_size_reuse_their_buffers(fresh_opencl):
    scene = boxes_scene()
    upload(fresh_opencl, scene)
    camera = scene_camera(scene)
    fresh_opencl.render(camera, 32, 24)
    outputs, camera_buffer = dict(fresh_opencl._outputs), fresh_opencl._camera
    first = fresh_opencl.render(camera, 32, 24)
    second = fresh_opencl.render(camera, 32, 24)
    assert fresh_opencl._camera is camera_buffer
    assert set(outputs) == set(AOVS)
    assert all(fresh_opencl._outputs[name] is buffer for name, buffer in outputs.items())
    for name in AOVS:
        np.testing.assert_array_equal(first.aov(name), second.aov(name))
        assert first.aov(name) is not second.aov(name)  # frames own their arrays
    fresh_opencl.render(camera, 16, 24)
    assert all(fresh_opencl._outputs[name] is not buffer for name, buffer in outputs.items())


# --- uploads ---------------------------------------------------------------------------------------


def test_row_range_upload_writes_only_those_rows(fresh_opencl):
    scene = boxes_scene()
    packer = upload(fresh_opencl, scene)
    packed = packer.packed
    assert packed is not None
    itemsize = packed.tables["instances"].dtype.itemsize
    before = fresh_opencl.read_table("instances")
    buffer = fresh_opencl._tables["instances"]
    entity = scene.entity("b")
    t = scene.get(entity, Transform)
    scene.set(entity, replace(t, position=(0.05, 0.5, -1.05)))  # within its fat TLAS leaf: one row
    updates = packer.sync(scene)
    row = int(np.flatnonzero(packed.instance_entities == entity)[0])
    assert [(u.table, u.rows) for u in updates] == [("instances", range(row, row + 1))]
    # Scribble over every other host row: an upload that wrote them would carry the scribbles.
    table = packed.tables["instances"]
    saved = table.copy()
    others = [r for r in range(len(table)) if r != row]
    table["meta"][others] = -12345
    assert fresh_opencl.upload(packed, updates) == itemsize
    after = fresh_opencl.read_table("instances")
    assert fresh_opencl._tables["instances"] is buffer  # no reallocation
    for r in range(len(table)):
        span = slice(r * itemsize, (r + 1) * itemsize)
        if r == row:
            assert after[span] == table[r : r + 1].tobytes() != before[span]
        else:
            assert after[span] == before[span]
    table[others] = saved[others]
    assert packer.sync(scene) == []  # the static tick after it uploads nothing
    assert fresh_opencl.upload(packed, []) == 0
    # The moved box is where a fresh backend sees it.
    moved = fresh_opencl.render(scene_camera(scene), 48, 36)
    with OpenClBackend() as other:
        expected = render(other, scene, 48, 36)
    for name in AOVS:
        np.testing.assert_array_equal(moved.aov(name), expected.aov(name), err_msg=name)


def test_whole_table_updates_reallocate_only_on_a_size_change(fresh_opencl):
    scene = boxes_scene()
    packer = upload(fresh_opencl, scene)
    packed = packer.packed
    assert packed is not None
    buffer = fresh_opencl._tables["instances"]
    mesh_buffers = {name: fresh_opencl._tables[name] for name in ("triangles", "bvh_nodes")}
    written = fresh_opencl.upload(packed, [TableUpdate("instances")])
    assert written == packed.tables["instances"].nbytes
    assert fresh_opencl._tables["instances"] is buffer  # same size: written in place
    assert all(fresh_opencl._tables[name] is b for name, b in mesh_buffers.items())  # mesh data untouched
    scene.add_mesh("d", "box", position=(0.0, 2.0, 0.0))
    updates = packer.sync(scene)
    assert packer.packed is not None
    fresh_opencl.upload(packer.packed, updates)
    assert fresh_opencl._tables["instances"] is not buffer
    assert fresh_opencl.read_table("instances") == packer.packed.tables["instances"].tobytes()
    frame = fresh_opencl.render(scene_camera(scene), 32, 24, aovs=("instance",))
    assert scene.entity("d") in frame.instance


# --- traversal -------------------------------------------------------------------------------------


def test_deep_bvh_gets_a_deep_enough_stack_and_matches_brute_force(fresh_opencl, tmp_path):
    """Triangles at distances 16^k along each axis make the SAH builder peel one per level: a deep tree."""
    verts, faces = [], []
    for axis in range(3):
        for k in range(1, 30):
            p, e1, e2 = np.zeros(3), np.zeros(3), np.zeros(3)
            p[axis], e1[(axis + 1) % 3], e2[(axis + 2) % 3] = 16.0**k, 0.4, 0.4
            faces.append((len(verts), len(verts) + 1, len(verts) + 2))
            verts += [tuple(p), tuple(p + e1), tuple(p + e2)]
    for k in range(10):  # what the camera sees, at the bottom of the tree
        faces.append((len(verts), len(verts) + 1, len(verts) + 2))
        verts += [(k * 0.5, -0.5, 0.0), (k * 0.5 + 0.4, -0.5, 0.0), (k * 0.5, 0.5, 0.0)]
    path = tmp_path / "strip.obj"
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in verts]
    path.write_text("\n".join(lines + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]) + "\n")
    scene = Scene()
    scene.add_asset("strip", path=path)
    scene.add_mesh("strip", "strip")
    scene.set_camera((2.5, 0.0, 3.0), look_at=(2.5, 0.0, 0.0), fov_deg=70.0)
    packer = upload(fresh_opencl, scene)
    assert packer.packed is not None
    need = shared.stack_entries(packer.packed.tables["bvh_nodes"], packer.packed.counts["bvh_nodes"])
    assert need > 33
    assert fresh_opencl._defines()["BVH_STACK_SIZE"] >= need
    frame = fresh_opencl.render(scene_camera(scene), 64, 48, aovs=("instance", "depth"))
    fresh_opencl.extra_defines = {"BRUTE_FORCE": 1}
    brute = fresh_opencl.render(scene_camera(scene), 64, 48, aovs=("instance", "depth"))
    assert (frame.instance >= 0).sum() > 200
    np.testing.assert_array_equal(frame.instance, brute.instance)
    np.testing.assert_array_equal(frame.depth, brute.depth)


def test_degenerate_triangles_and_edge_on_views_give_no_nan(opencl, tmp_path):
    verts = [(0, 0, 0), (1, 1, 0), (2, 2, 0), (-1, -1, 0.5), (1, -1, 0.5), (0, 1, 0.5)]
    faces = [(0, 1, 2), (0, 0, 1), (3, 4, 5), (1, 1, 1)]
    path = tmp_path / "bad.obj"
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in verts]
    path.write_text("\n".join(lines + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]) + "\n")
    scene = Scene()
    scene.add_asset("bad", path=path)
    entity = scene.add_mesh("bad", "bad", checker=0.3)
    scene.add_mesh("edge_on", "quad", position=(0.0, 0.0, -2.0), euler_deg=(90.0, 0.0, 0.0), checker=0.1)
    scene.set_camera((0.0, 0.0, 3.0), look_at=(0.0, 0.0, 0.0), fov_deg=60.0)
    frame = render(opencl, scene, 33, 33)  # the middle row looks exactly along the edge-on quad's plane
    assert set(np.unique(frame.instance).tolist()) == {-1, entity}
    for name in ("depth", "perceived"):
        value = frame.aov(name)
        assert not np.isnan(value).any() and np.all(np.isfinite(value[frame.instance >= 0]))


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
