"""The contract every fast backend keeps (GLSL and OpenCL alike): errors, AOVs, uploads, variants, traversal.

One test per promise, parametrised over the fast backends (and precisions, and GLSL's two table stores,
where a promise depends on them); what only one backend does lives in tests/backends/test_glsl.py and
tests/backends/test_opencl.py. Backend-specific expectations are explicit parameters here.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from conftest import require_backend
from scenes import FAST, boxes_scene, upload, write_obj
from scenes import render_aovs as render

from backends import shared
from backends.base import AOVS, backend_class
from backends.glsl.backend import GlslBackend
from backends.opencl.backend import OpenClBackend
from components import Transform
from engine.camera_view import CameraView, scene_camera
from engine.errors import AberrantError
from engine.packed import Features, TableUpdate
from engine.packing import ScenePacker
from engine.scene import Scene

#: The fast backends by name: the session's f32 backend of each (``fast``).
NAMES = ["glsl", "opencl"]
#: Private backends (``fresh``): GLSL holds its tables in images or in storage buffers, and both must keep it.
FRESH = [
    pytest.param(("glsl", {"tables": "image"}), id="glsl-image"),
    pytest.param(("glsl", {"tables": "ssbo"}), id="glsl-ssbo"),
    pytest.param(("opencl", {}), id="opencl"),
]


@pytest.fixture(params=NAMES)
def fast(request, backend_factory):
    """The session's f32 backend of each fast kind (skipped, or failed when required, where it cannot run)."""
    return backend_factory(request.param, "f32")


@pytest.fixture(params=FRESH)
def fresh_options(request) -> tuple[str, dict[str, Any]]:
    """(name, constructor options) of a private backend; a second one made alike must render alike."""
    name, options = request.param
    require_backend(name)
    return name, options


@pytest.fixture
def fresh(fresh_options) -> Iterator[Any]:
    """A private backend (for counting compiles and buffer objects)."""
    name, options = fresh_options
    backend = backend_class(name)(**options)
    yield backend
    backend.release()


# --- contract and probe ------------------------------------------------------------------------------


def _opencl_info(info: dict[str, str]) -> None:
    """What OpenCL's info adds: whether doubles exist, how many compute units, PoCL's version on PoCL."""
    assert info["fp64"] in ("yes", "no")
    assert int(info["compute units"]) >= 1
    if "Portable Computing Language" in info["platform"]:
        assert re.match(r"\d+\.\d+", info["pocl"])


INFO = {
    "glsl": (
        ("renderer", "version", "vendor", "max compute work-group size", "max compute work-group invocations"),
        ("version", r"^\d+\.\d+"),
        None,
    ),
    "opencl": (
        ("platform", "device", "type", "opencl", "compute units", "fp64", "precision", "work group"),
        ("opencl", r"OpenCL \d+\.\d+"),
        _opencl_info,
    ),
}


@pytest.mark.parametrize("name", NAMES)
def test_contract_probe_and_info(backend_factory, name):
    """The class is found by name, probes clean (once per process) and its info fills every key it names."""
    backend = backend_factory(name, "f32")
    keys, (versioned, pattern), extra = INFO[name]
    cls = backend_class(name)
    assert cls is {"glsl": GlslBackend, "opencl": OpenClBackend}[name]
    assert cls.name == name
    assert cls.precisions == ("f32", "f64")
    assert cls.camera_relative is True
    assert cls.probe() is None
    assert cls.probe() is cls.probe()  # cached per process
    info = backend.info()
    for key in keys:
        assert info[key] and info[key] != "?", key
    assert re.search(pattern, info[versioned])
    if extra is not None:
        extra(info)


def test_render_before_upload_and_bad_arguments_are_clear_errors(fresh):
    with pytest.raises(AberrantError, match="upload"):
        fresh.render(CameraView(np.zeros(3), np.eye(3), 60.0), 4, 4)
    scene = boxes_scene()
    upload(fresh, scene)
    with pytest.raises(AberrantError, match="AOV"):
        fresh.render(scene_camera(scene), 4, 4, aovs=("colour",))
    with pytest.raises(AberrantError, match="positive"):
        fresh.render(scene_camera(scene), 0, 4)
    packer = ScenePacker(precision="f64")
    packer.sync(scene)
    assert packer.packed is not None
    with pytest.raises(AberrantError, match="f64"):
        fresh.upload(packer.packed, [])


#: What a released backend refuses: both refuse uploads; GLSL's info needs its live context too.
REFUSED_AFTER_RELEASE: dict[str, tuple[str, ...]] = {"glsl": ("info", "upload"), "opencl": ("upload",)}


@pytest.mark.parametrize("name", NAMES)
def test_release_is_idempotent_and_final(name):
    require_backend(name)
    backend = backend_class(name)()
    backend.release()
    backend.release()
    calls = {"info": backend.info, "upload": lambda: upload(backend, boxes_scene())}
    for call in REFUSED_AFTER_RELEASE[name]:
        with pytest.raises(AberrantError, match="release"):
            calls[call]()


# --- AOVs ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "precision"), FAST)
def test_aov_shapes_dtypes_and_no_nan(backend_factory, name, precision):
    backend = backend_factory(name, precision)
    scene = boxes_scene()
    frame = render(backend, scene, 40, 30)
    assert frame.present() == list(AOVS)
    assert frame.color.shape == (30, 40, 4) and frame.color.dtype == np.uint8
    for aov, dtype in (("depth", np.float32), ("perceived", np.float32), ("instance", np.int32), ("events", np.uint8)):
        assert frame.aov(aov).shape == (30, 40) and frame.aov(aov).dtype == dtype, aov
    hit = frame.instance >= 0
    assert hit.any() and (~hit).any()
    for aov in ("depth", "perceived"):
        value = frame.aov(aov)
        assert not np.isnan(value).any()
        assert np.all(np.isfinite(value[hit])) and np.all(value[hit] > 0)
        assert np.all(value[~hit] == np.inf)
    assert np.all(frame.color[..., 3] == 255)
    assert np.all(frame.events == 0)
    entities = {scene.entity(n) for n in ("floor", "a", "b", "c")}
    assert set(np.unique(frame.instance[hit]).tolist()) <= entities
    for key in ("dispatch", "readback", "render"):
        assert frame.timings_ms[key] > 0


def test_row_zero_is_top(fast):
    scene = Scene()
    scene.add_mesh("floor", "plane", scale=(50.0, 1.0, 50.0))
    scene.set_camera((0.0, 1.0, 0.0), rotation=(0.0, 0.0, 0.0, 1.0), fov_deg=90.0)
    instance = render(fast, scene, 16, 16, aovs=("instance",)).instance
    assert np.all(instance[:8] == -1) and np.all(instance[8:] >= 0)  # the floor is below the horizon


def test_only_requested_aovs_are_read_back_and_agree_with_a_full_frame(fast):
    scene = boxes_scene()
    full = render(fast, scene)
    frame = render(fast, scene, aovs=("depth",))
    assert frame.present() == ["depth"]
    np.testing.assert_array_equal(frame.depth, full.depth)
    frame = render(fast, scene, aovs=("events", "color"))
    assert frame.present() == ["color", "events"]
    np.testing.assert_array_equal(frame.color, full.color)
    assert render(fast, scene, aovs=()).present() == []


# --- the per-frame path ------------------------------------------------------------------------------------

#: Per-frame objects besides the AOV output buffers that a same-size frame must reuse.
HELD: dict[str, Callable[[Any], object]] = {
    "glsl": lambda backend: backend.color_texture,
    "opencl": lambda backend: backend._camera,
}
#: The AOVs with an output buffer: GLSL writes colour to its texture instead.
OUTPUT_BUFFERS = {"glsl": set(AOVS) - {"color"}, "opencl": set(AOVS)}
#: Each backend's output buffers by AOV.
BUFFERS: dict[str, Callable[[Any], dict[str, object]]] = {
    "glsl": lambda backend: backend._outputs.buffers,
    "opencl": lambda backend: backend._outputs,
}


def test_frames_of_one_size_reuse_their_buffers(fresh, fresh_options):
    scene = boxes_scene()
    upload(fresh, scene)
    camera = scene_camera(scene)
    fresh.render(camera, 32, 24)
    held, buffers = HELD[fresh_options[0]], BUFFERS[fresh_options[0]]
    outputs, kept = dict(buffers(fresh)), held(fresh)
    first = fresh.render(camera, 32, 24)
    second = fresh.render(camera, 32, 24)
    assert kept is not None and held(fresh) is kept
    assert set(outputs) == OUTPUT_BUFFERS[fresh_options[0]]
    assert all(buffers(fresh)[name] is buffer for name, buffer in outputs.items())
    for name in AOVS:
        np.testing.assert_array_equal(first.aov(name), second.aov(name))
        assert first.aov(name) is not second.aov(name)  # frames own their arrays
    fresh.render(camera, 16, 24)
    assert all(buffers(fresh)[name] is not buffer for name, buffer in outputs.items())


# --- uploads ---------------------------------------------------------------------------------------------


def test_row_range_upload_writes_only_those_rows(fresh, fresh_options):
    scene = boxes_scene()
    packer = upload(fresh, scene)
    packed = packer.packed
    assert packed is not None
    itemsize = packed.tables["instances"].dtype.itemsize
    entity = scene.entity("b")
    t = scene.get(entity, Transform)
    scene.set(entity, replace(t, position=(0.01, 0.5, -1.01)))  # a first move: its tight TLAS leaf grows fat
    fresh.upload(packed, packer.sync(scene))
    before = fresh.read_table("instances")
    buffer = fresh._tables["instances"]
    scene.set(entity, replace(t, position=(0.05, 0.5, -1.05)))  # within its fat TLAS leaf: one row
    updates = packer.sync(scene)
    row = int(np.flatnonzero(packed.instance_entities == entity)[0])
    assert [(u.table, u.rows) for u in updates] == [("instances", range(row, row + 1))]
    # Scribble over every other host row: an upload that wrote them would carry the scribbles.
    table = packed.tables["instances"]
    saved = table.copy()
    others = [r for r in range(len(table)) if r != row]
    table["meta"][others] = -12345
    assert fresh.upload(packed, updates) == itemsize
    after = fresh.read_table("instances")
    assert fresh._tables["instances"] is buffer  # no reallocation
    for r in range(len(table)):
        span = slice(r * itemsize, (r + 1) * itemsize)
        if r == row:
            assert after[span] == table[r : r + 1].tobytes() != before[span]
        else:
            assert after[span] == before[span]
    table[others] = saved[others]
    assert packer.sync(scene) == []  # the static tick after it uploads nothing
    assert fresh.upload(packed, []) == 0
    # The moved box is where a fresh backend sees it.
    moved = fresh.render(scene_camera(scene), 48, 36)
    name, options = fresh_options
    with backend_class(name)(**options) as other:
        expected = render(other, scene, 48, 36)
    for aov in AOVS:
        np.testing.assert_array_equal(moved.aov(aov), expected.aov(aov), err_msg=aov)


def test_whole_table_updates_reallocate_only_on_a_size_change(fresh):
    scene = boxes_scene()
    packer = upload(fresh, scene)
    packed = packer.packed
    assert packed is not None
    buffer = fresh._tables["instances"]
    mesh_buffers = {name: fresh._tables[name] for name in ("triangles", "bvh_nodes")}
    written = fresh.upload(packed, [TableUpdate("instances")])
    assert written == packed.tables["instances"].nbytes
    assert fresh._tables["instances"] is buffer  # same size: written in place
    assert all(fresh._tables[name] is b for name, b in mesh_buffers.items())  # mesh data untouched
    scene.add_mesh("d", "box", position=(0.0, 2.0, 0.0))
    updates = packer.sync(scene)
    assert packer.packed is not None
    fresh.upload(packer.packed, updates)
    assert fresh._tables["instances"] is not buffer
    assert fresh.read_table("instances") == packer.packed.tables["instances"].tobytes()
    frame = fresh.render(scene_camera(scene), 32, 24, aovs=("instance",))
    assert scene.entity("d") in frame.instance


# --- traversal ---------------------------------------------------------------------------------------------

#: ``_defines`` arguments: GLSL's variants depend on the AOVs, OpenCL's do not.
DEFINES_ARGS: dict[str, tuple[Any, ...]] = {"glsl": (("instance",),), "opencl": ()}


def test_deep_bvh_gets_a_deep_enough_stack_and_matches_brute_force(fresh, fresh_options, tmp_path):
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
    scene = Scene()
    scene.add_asset("strip", path=write_obj(tmp_path / "strip.obj", verts, faces))
    scene.add_mesh("strip", "strip")
    scene.set_camera((2.5, 0.0, 3.0), look_at=(2.5, 0.0, 0.0), fov_deg=70.0)
    packer = upload(fresh, scene)
    assert packer.packed is not None
    nodes, count = packer.packed.tables["bvh_nodes"], packer.packed.counts["bvh_nodes"]
    need = shared.stack_entries(nodes, count)  # (width - 1) * depth + 1 for wide nodes
    if fresh.bvh_width == 2:
        assert need == shared.bvh_depth(nodes, count)  # binary nodes: one entry per level
    assert need > 33
    assert fresh._defines(*DEFINES_ARGS[fresh_options[0]])["BVH_STACK_SIZE"] >= need
    frame = fresh.render(scene_camera(scene), 64, 48, aovs=("instance", "depth"))
    fresh.extra_defines = {"BRUTE_FORCE": 1}
    brute = fresh.render(scene_camera(scene), 64, 48, aovs=("instance", "depth"))
    assert (frame.instance >= 0).sum() > 200
    np.testing.assert_array_equal(frame.instance, brute.instance)
    np.testing.assert_array_equal(frame.depth, brute.depth)


def test_brute_force_variant_agrees_with_the_bvh(fresh):
    scene = boxes_scene()
    upload(fresh, scene)
    camera = scene_camera(scene)
    bvh = fresh.render(camera, 64, 48)
    fresh.extra_defines = {"BRUTE_FORCE": 1}
    brute = fresh.render(camera, 64, 48)
    for name in AOVS:
        np.testing.assert_array_equal(bvh.aov(name), brute.aov(name), err_msg=name)


def test_backface_culling(fast):
    scene = Scene()
    scene.add_mesh("shell", "box", scale=4.0, cull_backfaces=True, color=(1.0, 0.0, 0.0))
    scene.add_mesh("inner", "box", position=(0.0, 0.0, -1.0), scale=0.5)
    scene.set_camera((0.0, 0.0, 1.0), look_at=(0.0, 0.0, -1.0), fov_deg=60.0)
    instance = render(fast, scene, 32, 32, aovs=("instance",)).instance
    # From inside, the culled shell's faces all face away: only the inner box is seen.
    assert set(np.unique(instance).tolist()) == {-1, scene.entity("inner")}
    scene.set_camera((0.0, 0.0, 6.0), look_at=(0.0, 0.0, 0.0), fov_deg=60.0)
    instance = render(fast, scene, 32, 32, aovs=("instance",)).instance
    assert np.all(instance[8:24, 8:24] == scene.entity("shell"))


def test_degenerate_triangles_and_edge_on_views_give_no_nan(fast, tmp_path):
    verts = [(0, 0, 0), (1, 1, 0), (2, 2, 0), (-1, -1, 0.5), (1, -1, 0.5), (0, 1, 0.5)]
    faces = [(0, 1, 2), (0, 0, 1), (3, 4, 5), (1, 1, 1)]
    scene = Scene()
    scene.add_asset("bad", path=write_obj(tmp_path / "bad.obj", verts, faces))
    entity = scene.add_mesh("bad", "bad", checker=0.3)
    scene.add_mesh("edge_on", "quad", position=(0.0, 0.0, -2.0), euler_deg=(90.0, 0.0, 0.0), checker=0.1)
    scene.set_camera((0.0, 0.0, 3.0), look_at=(0.0, 0.0, 0.0), fov_deg=60.0)
    frame = render(fast, scene, 33, 33)  # the middle row looks exactly along the edge-on quad's plane
    assert set(np.unique(frame.instance).tolist()) == {-1, entity}
    for name in ("depth", "perceived"):
        value = frame.aov(name)
        assert not np.isnan(value).any() and np.all(np.isfinite(value[frame.instance >= 0]))


# --- specialisation: a variant compiles only what its scene uses -------------------------------------------

_DIRECTIVE = re.compile(r"^\s*#\s*(\w+)\s*(.*?)\s*$")


def preprocess(source: str) -> str:
    """The lines a compiler keeps after ``#if``/``#ifdef``/``#ifndef``/``#elif``/``#else``/``#endif``.

    A small C preprocessor for the conditions the kernels use: object-like ``#define``s with
    integer expressions, ``defined()``, ``!``, ``&&``, ``||`` and comparisons (undefined names are 0); the
    conditions of skipped blocks are not evaluated.
    """
    defines: dict[str, str] = {}

    def evaluate(expr: str) -> int:
        expr = re.sub(r"defined\s*\(\s*(\w+)\s*\)|defined\s+(\w+)", lambda m: str(int((m[1] or m[2]) in defines)), expr)
        expr = expr.replace("&&", " and ").replace("||", " or ")
        expr = re.sub(r"!(?!=)", " not ", expr)

        def name(m: re.Match) -> str:
            word = m.group(0)
            if word in ("and", "or", "not"):
                return word
            return f"({evaluate(defines[word])})" if word in defines else "0"

        return int(eval(re.sub(r"\b[A-Za-z_]\w*\b", name, expr), {"__builtins__": {}}))

    kept: list[str] = []
    stack: list[tuple[bool, bool]] = []  # (enclosing block active, a branch of this #if was taken)
    active = True
    for line in source.splitlines():
        m = _DIRECTIVE.match(line)
        word, rest = (m.group(1), m.group(2)) if m else ("", "")
        if word in ("if", "ifdef", "ifndef"):
            # As a compiler does, a condition inside a skipped block is not evaluated (it may use what only the
            # enclosing condition proved defined, e.g. __has_builtin).
            holds = active and (bool(evaluate(rest)) if word == "if" else (rest in defines) == (word == "ifdef"))
            taken = holds
            stack.append((active, taken))
            active = taken
        elif word == "elif":
            outer, taken = stack[-1]
            active = outer and not taken and bool(evaluate(rest))
            stack[-1] = (outer, taken or active)
        elif word == "else":
            outer, taken = stack[-1]
            active = outer and not taken
            stack[-1] = (outer, True)
        elif word == "endif":
            active = stack.pop()[0]
        elif active:
            if word == "define":
                d = re.match(r"(\w+)(\(?)\s*(.*)$", rest)
                if d and not d.group(2):
                    defines[d.group(1)] = d.group(3) or "1"
            kept.append(line)
    assert not stack, "unbalanced #if"
    return "\n".join(kept)


#: Functions of the non-Euclidean machinery, by what needs them.
SPACE_FUNCTIONS = {
    "aberrations": ("nearest_box_face", "containing_box", "transition", "enter_box", "perceived_rate"),
    "metric": ("metric_direction", "metric_local"),
    "bending": ("bend",),
    "radial": ("sigma_axis",),
    "portals": ("nearest_portal", "teleport"),
}


def compiled_functions(source: str) -> set[str]:
    """The SPACE_FUNCTIONS a preprocessed source defines."""
    text = re.sub(r"/\*.*?\*/|//[^\n]*", " ", preprocess(source), flags=re.S)
    return {f for group in SPACE_FUNCTIONS.values() for f in group if re.search(rf"\b{f}\s*\(", text)}


def expected_functions(modes: set[str], portals: bool) -> set[str]:
    groups = []
    if modes:
        groups.append("aberrations")
    if "metric" in modes:
        groups.append("metric")
    if modes & {"radial", "additive"}:
        groups.append("bending")
    if "radial" in modes:
        groups.append("radial")
    if portals:
        groups.append("portals")
    return {f for group in groups for f in SPACE_FUNCTIONS[group]}


def test_preprocess_keeps_only_the_taken_branches():
    text = preprocess(
        "#define A 1\n#define B (A && !C)\n#if B\nyes\n#if defined(C) || A == 2\nno\n#elif A\nyes2\n#else\nno\n"
        "#endif\n#else\nno\n#endif\n#ifndef C\nyes3\n#endif\n"
    )
    assert [line for line in text.splitlines() if not line.startswith("#")] == ["yes", "yes2", "yes3"]


SPECIALISATIONS = [
    pytest.param(set(), False, id="plain"),
    pytest.param({"metric"}, False, id="metric"),
    pytest.param({"radial"}, False, id="radial"),
    pytest.param({"additive"}, False, id="additive"),
    pytest.param({"metric", "radial", "additive"}, False, id="all-modes"),
    pytest.param(set(), True, id="portals"),
    pytest.param({"additive"}, True, id="additive-portals"),
]
#: The source of each fast backend, and the defines its assembly needs besides the features.
SOURCES: dict[str, tuple[Callable[[dict[str, int]], str], dict[str, int]]] = {
    "glsl": (GlslBackend.source, {"CAMERA_BINDING": 8, "TABLES_IN_IMAGES": 0}),
    "opencl": (OpenClBackend.source, {}),
}


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize(("modes", "portals"), SPECIALISATIONS)
def test_a_variant_compiles_only_the_machinery_its_scene_uses(modes, portals, name):
    """A plain scene's source has no aberration or portal code at all; each mode brings only its own rules."""
    source, needs = SOURCES[name]
    for precision in (0, 1):
        defines = {**Features(portals, frozenset(modes)).defines(), **needs, "REAL_IS_DOUBLE": precision}
        assert compiled_functions(source(defines)) == expected_functions(modes, portals)


#: Each backend's files in the order its source must hold them, how that source begins, what it is built from.
ASSEMBLY = {
    "glsl": (
        ("prelude.glsl", "layout.h", "bindings.glsl", *shared.TRACER_FILES, "main.comp"),
        "#version 430\n",
        {"MAX_EVENTS": 16, "CAMERA_BINDING": 8},
    ),
    "opencl": (
        ("prelude_cl.h", "layout.h", "bindings_cl.h", *shared.TRACER_FILES, "trace.cl"),
        "",
        {"MAX_EVENTS": 16, "REAL_IS_DOUBLE": 0},
    ),
}


@pytest.mark.parametrize("name", NAMES)
def test_source_is_assembled_from_the_shared_core(name):
    order, start, defines = ASSEMBLY[name]
    text = SOURCES[name][0](defines)
    assert text.startswith(start)
    marks = [text.index(f"// ---- {file}") for file in order]
    assert marks == sorted(marks)  # each file builds on those before it
    for file in shared.TRACER_FILES:
        assert shared.read(file) in text, file
    assert "#define MAX_EVENTS 16\n" in text
    assert "#include" not in text  # one self-contained string: the whole cache key
