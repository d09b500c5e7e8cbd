"""The GLSL compute-shader backend: contract, layouts, AOVs, variant cache, uploads, texture, hard inputs."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import require_backend

from backends import shared
from backends.base import AOVS, backend_class
from backends.glsl.backend import CAMERA_IMAGE, GlslBackend, _write_texels, lane_block
from backends.shared import bvh_depth, stack_size
from components import Transform
from engine import layout
from engine.camera_view import CameraView, scene_camera
from engine.errors import AberrantError
from engine.packing import ScenePacker
from engine.scene import Scene

PRECISIONS = ["f32", "f64"]


@pytest.fixture
def glsl(backend_factory):
    """The session's f32 GLSL backend (skipped, or failed when required, where it cannot run)."""
    return backend_factory("glsl", "f32")


@pytest.fixture(params=["image", "ssbo"])
def fresh_glsl(request):
    """A private GLSL backend (for counting compiles and buffer objects), tables in images or buffers."""
    require_backend("glsl")
    backend = GlslBackend(tables=request.param)
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


def write_obj(path: Path, vertices, faces) -> Path:
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


# --- contract and probe --------------------------------------------------------------------------


def test_contract_probe_and_info(glsl):
    assert backend_class("glsl") is GlslBackend
    assert GlslBackend.name == "glsl"
    assert GlslBackend.precisions[0] == "f32"
    assert GlslBackend.camera_relative is True
    assert GlslBackend.probe() is None
    assert GlslBackend.probe() is GlslBackend.probe()  # cached per process
    info = glsl.info()
    for key in ("renderer", "version", "vendor", "max compute work-group size", "max compute work-group invocations"):
        assert info[key] and info[key] != "?", key
    assert re.match(r"\d+\.\d+", info["version"])


def test_render_before_upload_and_bad_arguments_are_clear_errors(fresh_glsl):
    with pytest.raises(AberrantError, match="upload"):
        fresh_glsl.render(CameraView(np.zeros(3), np.eye(3), 60.0), 4, 4)
    scene = boxes_scene()
    upload(fresh_glsl, scene)
    with pytest.raises(AberrantError, match="AOV"):
        fresh_glsl.render(scene_camera(scene), 4, 4, aovs=("colour",))
    with pytest.raises(AberrantError, match="positive"):
        fresh_glsl.render(scene_camera(scene), 0, 4)
    packer = ScenePacker(precision="f64")
    packer.sync(scene)
    assert packer.packed is not None
    with pytest.raises(AberrantError, match="f64"):
        fresh_glsl.upload(packer.packed, [])


def test_release_is_idempotent_and_final():
    require_backend("glsl")
    backend = GlslBackend()
    backend.release()
    backend.release()
    with pytest.raises(AberrantError, match="release"):
        backend.info()


# --- layouts: the shader's records read exactly the packed bytes ---------------------------------

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
}


def _members(struct: str) -> list[tuple[str, str]]:
    """(type, name) of a record's members, parsed from the shared layout.h."""
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


#: How the core reads one record of each table (image mode: through bindings.glsl's fetch functions).
_ACCESSORS = {
    "settings": "SETTINGS",
    "triangles": "TRIANGLE(i)",
    "triangle_uvs": "TRIANGLE_UV(i)",
    "bvh_nodes": "BVH_NODE(i)",
    "instances": "INSTANCE(i)",
    "materials": "MATERIAL(i)",
    "aberrations": "ABERRATION(i)",
    "portals": "PORTAL(i)",
    "triangle_blocks": "TRIANGLE_BLOCK(i)",
    "camera": "CAMERA_ROW",
    "bvh4_nodes": "BVH_NODE(i)",
    "bvh_compact_nodes": "BVH_NODE(i)",
}


@pytest.mark.parametrize("store", ["ssbo", "image"])
@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("table", list(_TABLE_STRUCTS))
def test_layout_h_records_read_the_packed_bytes(backend_factory, precision, table, store):
    """A shader copies every member of every row out bit for bit: offsets and strides agree with engine.layout.

    ``ssbo``: layout.h's struct in a std430 buffer; ``image``: the same bytes in an RGBA32UI image,
    read through bindings.glsl's fetch functions (what the backend does on llvmpipe).
    """
    backend = backend_factory("glsl", precision)
    struct = _TABLE_STRUCTS[table]
    special = {"bvh4_nodes": layout.BVH4_NODE_DTYPE, "bvh_compact_nodes": layout.BVH_COMPACT_NODE_DTYPE}
    dtype = special[table] if table in special else layout.table_dtype(table, precision)
    single = table in ("settings", "camera")  # the core reads row 0 only
    rows = _random_rows(dtype, 1 if single and store == "image" else 5, np.random.default_rng(7))
    stores, words = [], 0
    for kind, member in _members(struct):
        for c in "xyzw":
            value = f"record.{member}.{c}"
            if kind == "int4":
                stores.append(f"words[base + {words}] = uint({value});")
                words += 1
            elif kind == "float4" or precision == "f32":
                stores.append(f"words[base + {words}] = floatBitsToUint({value});")
                words += 1
            else:
                stores.append(f"uvec2 w{member}{c} = unpackDouble2x32({value});")
                stores.append(f"words[base + {words}] = w{member}{c}.x; words[base + {words + 1}] = w{member}{c}.y;")
                words += 2
    defines = {"REAL_IS_DOUBLE": int(precision == "f64")}
    if store == "image":
        defines.update(backend._defines(()), TABLES_IN_IMAGES=1, BVH_WIDTH=2, BVH_COMPACT=0)  # whatever it last drew
        if table == "bvh4_nodes":
            defines.update(BVH_WIDTH=4, BVH_NODES_STRIDE=dtype.itemsize // 16)
        if table == "bvh_compact_nodes":
            defines.update(BVH_COMPACT=1, BVH_NODES_STRIDE=dtype.itemsize // 16)
        head = shared.read("bindings.glsl", "backends.glsl")
        read = f"{struct} record = {_ACCESSORS[table]};"
    else:
        head = f"layout(std430, binding = 0) readonly buffer In {{ {struct} rows[]; }};\n"
        read = f"{struct} record = rows[i];"
    source = (
        "#version 430\n"
        + shared.defines_block(defines)
        + shared.read("prelude.glsl", "backends.glsl")
        + shared.read("layout.h")
        + head
        + "\nlayout(local_size_x = 1) in;\n"
        + "layout(std430, binding = 15) writeonly buffer Out { uint words[]; };\n"
        + "void main() {\n  int i = int(gl_GlobalInvocationID.x);\n"
        + f"  int base = i * {words};\n  {read}\n  "
        + "\n  ".join(stores)
        + "\n}\n"
    )
    ctx = backend.context
    with ctx:
        program = ctx.compute_shader(source)
        out = ctx.buffer(reserve=len(rows) * words * 4)
        out.bind_to_storage_buffer(15)
        if store == "image":
            src = backend._image(len(rows) * dtype.itemsize // 16)
            _write_texels(src, 0, rows.view(np.uint32).reshape(-1, 4))
            name = "bvh_nodes" if table in special else table
            unit = CAMERA_IMAGE if table == "camera" else layout.TABLES.index(name) + 1
            src.bind_to_image(unit, read=True, write=False)
        else:
            src = ctx.buffer(rows)
            src.bind_to_storage_buffer(0)
        program.run(len(rows), 1, 1)
        ctx.memory_barrier()
        got = np.frombuffer(out.read(), np.uint32).reshape(len(rows), words)
        for resource in (program, src, out):
            resource.release()
    raw = rows.view(np.uint8).reshape(len(rows), dtype.itemsize)
    expected = raw[:, : words * 4].copy().view(np.uint32)
    assert words * 4 <= dtype.itemsize
    assert dtype.itemsize - words * 4 < (32 if precision == "f64" else 16)  # only tail padding is left out
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("precision", PRECISIONS)
def test_tables_in_images_and_in_storage_buffers_render_the_same(precision):
    """The two ways of holding the tables give bit-identical frames."""
    require_backend("glsl")
    from demos import starter

    frames = []
    for store in ("ssbo", "image"):
        backend = GlslBackend(precision, tables=store)
        try:
            assert backend.table_store == store
            frames.append(render(backend, starter.build(), 64, 48))
        finally:
            backend.release()
    for name in AOVS:
        np.testing.assert_array_equal(frames[0].aov(name), frames[1].aov(name), err_msg=name)


@pytest.mark.parametrize("workgroup", [(8, 8), (16, 16), (12, 6), (6, 6)])
def test_lane_blocks_trace_every_pixel_once_and_match_rows(workgroup):
    """Consecutive invocations take 4x2 pixel blocks (rows where 4x2 does not tile the group): on an odd size
    with partial edge tiles every pixel is written, and the frame is the one of the plain row mapping."""
    require_backend("glsl")
    assert lane_block(workgroup) == ((4, 2) if workgroup != (6, 6) else (6, 1))
    frames = []
    for rows in (False, True):
        backend = GlslBackend(workgroup=workgroup)
        try:
            if rows:
                backend.extra_defines = {"LANE_BLOCK_X": workgroup[0], "LANE_BLOCK_Y": 1}
            frames.append(render(backend, boxes_scene(), 61, 37))
        finally:
            backend.release()
    assert np.all(frames[0].color[..., 3] == 255)  # written: an untouched texel of a new texture is 0
    for name in AOVS:
        np.testing.assert_array_equal(frames[0].aov(name), frames[1].aov(name), err_msg=name)


# --- AOVs ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("precision", PRECISIONS)
def test_aov_shapes_dtypes_and_no_nan(backend_factory, precision):
    backend = backend_factory("glsl", precision)
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
    assert frame.timings_ms["render"] > 0


def test_row_zero_is_top(glsl):
    scene = Scene()
    scene.add_mesh("floor", "plane", scale=(50.0, 1.0, 50.0))
    scene.set_camera((0.0, 1.0, 0.0), rotation=(0.0, 0.0, 0.0, 1.0), fov_deg=90.0)
    instance = render(glsl, scene, 16, 16, aovs=("instance",)).instance
    assert np.all(instance[:8] == -1) and np.all(instance[8:] >= 0)  # the floor is below the horizon


def test_only_requested_aovs_are_read_back(glsl):
    scene = boxes_scene()
    frame = render(glsl, scene, aovs=("depth",))
    assert frame.present() == ["depth"]
    frame = render(glsl, scene, aovs=())
    assert frame.present() == []
    assert glsl.color_texture is not None  # the editor's path: the texture without a read-back


def test_color_texture_holds_the_frame_top_row_first(glsl):
    scene = boxes_scene()
    frame = render(glsl, scene, 40, 30, aovs=("color",))
    texture = glsl.color_texture
    assert texture is not None and texture.size == (40, 30) and texture.components == 4
    with glsl.context:
        data = texture.read(alignment=1)
    np.testing.assert_array_equal(np.frombuffer(data, np.uint8).reshape(30, 40, 4), frame.color)


# --- variants and the per-frame path --------------------------------------------------------------


def test_a_variant_is_compiled_once_and_reused(fresh_glsl):
    scene = boxes_scene()
    upload(fresh_glsl, scene)
    camera = scene_camera(scene)
    assert fresh_glsl.compile_count == 0
    fresh_glsl.render(camera, 32, 24, aovs=("color", "depth"))
    assert fresh_glsl.compile_count == 1
    fresh_glsl.render(camera, 32, 24, aovs=("color", "depth"))
    fresh_glsl.render(camera, 48, 24, aovs=("depth", "color"))  # other size, same variant
    assert fresh_glsl.compile_count == 1
    fresh_glsl.render(camera, 32, 24, aovs=("instance",))  # other AOVs: another variant
    assert fresh_glsl.compile_count == 2
    upload(fresh_glsl, boxes_scene())  # same features: no new variant
    fresh_glsl.render(camera, 32, 24, aovs=("instance",))
    fresh_glsl.render(camera, 32, 24, aovs=("color", "depth"))
    assert fresh_glsl.compile_count == 2


def test_frames_of_one_size_reuse_their_buffers(fresh_glsl):
    scene = boxes_scene()
    upload(fresh_glsl, scene)
    camera = scene_camera(scene)
    fresh_glsl.render(camera, 32, 24)
    texture, outputs = fresh_glsl.color_texture, dict(fresh_glsl._outputs)
    first = fresh_glsl.render(camera, 32, 24)
    second = fresh_glsl.render(camera, 32, 24)
    assert fresh_glsl.color_texture is texture
    assert all(fresh_glsl._outputs[name] is buffer for name, buffer in outputs.items())
    for name in AOVS:
        np.testing.assert_array_equal(first.aov(name), second.aov(name))


# --- uploads -----------------------------------------------------------------------------------------


def test_row_range_upload_writes_only_those_rows(fresh_glsl):
    scene = boxes_scene()
    packer = upload(fresh_glsl, scene)
    packed = packer.packed
    assert packed is not None
    itemsize = packed.tables["instances"].dtype.itemsize
    before = fresh_glsl.read_table("instances")
    buffer = fresh_glsl._tables["instances"]
    entity = scene.entity("b")
    t = scene.get(entity, Transform)
    scene.set(entity, replace(t, position=(0.05, 0.5, -1.05)))  # within its fat TLAS leaf: one row
    updates = packer.sync(scene)
    row = int(np.flatnonzero(packed.instance_entities == entity)[0])
    assert [(u.table, u.rows) for u in updates] == [("instances", range(row, row + 1))]
    # Scribble over every other host row: an upload that wrote them would carry the scribbles.
    table = packed.tables["instances"]
    others = [r for r in range(len(table)) if r != row]
    table["meta"][others] = -12345
    assert fresh_glsl.upload(packed, updates) == itemsize
    after = fresh_glsl.read_table("instances")
    assert fresh_glsl._tables["instances"] is buffer  # no reallocation
    for r in range(len(table)):
        span = slice(r * itemsize, (r + 1) * itemsize)
        if r == row:
            assert after[span] == table[r : r + 1].tobytes() != before[span]
        else:
            assert after[span] == before[span]
    # The static tick after it uploads nothing.
    assert packer.sync(scene) == []


@pytest.mark.parametrize(("first", "count"), [(0, 5), (4090, 20), (4096, 4096), (100, 9000), (8191, 1)])
def test_texel_writes_split_across_image_rows(glsl, first, count):
    with glsl.context:
        image = glsl._image(first + count + 7)
        rows = image.size[1]
        before = np.arange(rows * image.size[0] * 4, dtype=np.uint32).reshape(-1, 4)
        image.write(before)
        texels = np.random.default_rng(first).integers(0, 2**32, (count, 4), dtype=np.uint32)
        _write_texels(image, first, texels)
        after = np.frombuffer(image.read(alignment=1), np.uint32).reshape(-1, 4)
        image.release()
    expected = before.copy()
    expected[first : first + count] = texels
    np.testing.assert_array_equal(after, expected)


def test_whole_table_updates_reallocate_only_on_a_size_change(fresh_glsl):
    scene = boxes_scene()
    packer = upload(fresh_glsl, scene)
    packed = packer.packed
    assert packed is not None
    buffer = fresh_glsl._tables["instances"]
    from engine.packed import TableUpdate

    written = fresh_glsl.upload(packed, [TableUpdate("instances")])
    assert written == packed.tables["instances"].nbytes
    assert fresh_glsl._tables["instances"] is buffer  # same size: written in place
    scene.add_mesh("d", "box", position=(0.0, 2.0, 0.0))
    updates = packer.sync(scene)
    assert packer.packed is not None
    fresh_glsl.upload(packer.packed, updates)
    assert fresh_glsl._tables["instances"] is not buffer
    assert fresh_glsl.read_table("instances") == packer.packed.tables["instances"].tobytes()
    frame = fresh_glsl.render(scene_camera(scene), 32, 24, aovs=("instance",))
    assert scene.entity("d") in frame.instance


# --- traversal -----------------------------------------------------------------------------------------


def test_bvh_depth_of_packed_tables():
    nodes = np.zeros(7, layout.BVH_NODE_DTYPE)
    # Tree A: 0 -> (1, 2), 2 -> (3, 4); tree B: a lone leaf at 5; tree C: 6 leaf.
    nodes["first"] = [1, 0, 3, 0, 0, 0, 0]
    nodes["count"] = [0, 2, 0, 1, 1, 3, 1]
    assert bvh_depth(nodes, 7) == 3
    assert bvh_depth(nodes, 0) == 0
    assert stack_size(nodes, 7) == 32


def test_deep_bvh_gets_a_deep_enough_stack_and_matches_brute_force(fresh_glsl, tmp_path):
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
    packer = upload(fresh_glsl, scene)
    assert packer.packed is not None
    depth = bvh_depth(packer.packed.tables["bvh_nodes"], packer.packed.counts["bvh_nodes"])
    assert depth > 33
    assert fresh_glsl._defines(("instance",))["BVH_STACK_SIZE"] >= depth
    frame = fresh_glsl.render(scene_camera(scene), 64, 48, aovs=("instance", "depth"))
    fresh_glsl.extra_defines = {"BRUTE_FORCE": 1}
    brute = fresh_glsl.render(scene_camera(scene), 64, 48, aovs=("instance", "depth"))
    assert (frame.instance >= 0).sum() > 200
    np.testing.assert_array_equal(frame.instance, brute.instance)
    np.testing.assert_array_equal(frame.depth, brute.depth)


def test_brute_force_variant_agrees_with_the_bvh(fresh_glsl):
    scene = boxes_scene()
    upload(fresh_glsl, scene)
    camera = scene_camera(scene)
    bvh = fresh_glsl.render(camera, 64, 48)
    fresh_glsl.extra_defines = {"BRUTE_FORCE": 1}
    brute = fresh_glsl.render(camera, 64, 48)
    for name in AOVS:
        np.testing.assert_array_equal(bvh.aov(name), brute.aov(name), err_msg=name)


def test_backface_culling(glsl):
    scene = Scene()
    scene.add_mesh("shell", "box", scale=4.0, cull_backfaces=True, color=(1.0, 0.0, 0.0))
    scene.add_mesh("inner", "box", position=(0.0, 0.0, -1.0), scale=0.5)
    scene.set_camera((0.0, 0.0, 1.0), look_at=(0.0, 0.0, -1.0), fov_deg=60.0)
    instance = render(glsl, scene, 32, 32, aovs=("instance",)).instance
    # From inside, the culled shell's faces all face away: only the inner box is seen.
    assert set(np.unique(instance).tolist()) == {-1, scene.entity("inner")}
    scene.set_camera((0.0, 0.0, 6.0), look_at=(0.0, 0.0, 0.0), fov_deg=60.0)
    instance = render(glsl, scene, 32, 32, aovs=("instance",)).instance
    assert np.all(instance[8:24, 8:24] == scene.entity("shell"))


def test_degenerate_triangles_and_edge_on_views_give_no_nan(glsl, tmp_path):
    verts = [(0, 0, 0), (1, 1, 0), (2, 2, 0), (-1, -1, 0.5), (1, -1, 0.5), (0, 1, 0.5)]
    faces = [(0, 1, 2), (0, 0, 1), (3, 4, 5), (1, 1, 1)]
    scene = Scene()
    scene.add_asset("bad", path=write_obj(tmp_path / "bad.obj", verts, faces))
    entity = scene.add_mesh("bad", "bad", checker=0.3)
    scene.add_mesh("edge_on", "quad", position=(0.0, 0.0, -2.0), euler_deg=(90.0, 0.0, 0.0), checker=0.1)
    scene.set_camera((0.0, 0.0, 3.0), look_at=(0.0, 0.0, 0.0), fov_deg=60.0)
    frame = render(glsl, scene, 33, 33)  # the middle row looks exactly along the edge-on quad's plane
    assert set(np.unique(frame.instance).tolist()) == {-1, entity}
    for name in ("depth", "perceived"):
        value = frame.aov(name)
        assert not np.isnan(value).any() and np.all(np.isfinite(value[frame.instance >= 0]))


# --- specialisation: a variant compiles only what its scene uses -------------------------------------

_DIRECTIVE = re.compile(r"^\s*#\s*(\w+)\s*(.*?)\s*$")


def preprocess(source: str) -> str:
    """The lines a compiler keeps after ``#if``/``#ifdef``/``#ifndef``/``#elif``/``#else``/``#endif``.

    A small C preprocessor for the conditions the kernels use: object-like ``#define``s with
    integer expressions, ``defined()``, ``!``, ``&&``, ``||`` and comparisons (undefined names are 0).
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
            holds = bool(evaluate(rest)) if word == "if" else (rest in defines) == (word == "ifdef")
            taken = active and holds
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


@pytest.mark.parametrize(("modes", "portals"), SPECIALISATIONS)
def test_a_variant_compiles_only_the_machinery_its_scene_uses(modes, portals):
    """A plain scene's shader has no aberration or portal code at all; each mode brings only its own rules."""
    from engine.packed import Features

    defines = {**Features(portals, frozenset(modes)).defines(), "CAMERA_BINDING": 8, "TABLES_IN_IMAGES": 0}
    assert compiled_functions(GlslBackend.source(defines)) == expected_functions(modes, portals)


def test_each_feature_set_is_its_own_cached_variant(fresh_glsl):
    """Plain, metric and portal scenes get variants whose defines say what they hold; each is compiled once."""
    for build in (boxes_scene, _metric_scene, _portal_scene, boxes_scene, _metric_scene):
        scene = build()
        frame = render(fresh_glsl, scene, 16, 12, aovs=("color",))
        assert frame.color is not None
    assert fresh_glsl.compile_count == 3
    defines = [dict(key) for key in fresh_glsl._programs]
    flags = [
        {k: d[k] for k in ("HAS_ABERRATIONS", "HAS_METRIC", "HAS_RADIAL", "HAS_ADDITIVE", "HAS_PORTALS")}
        for d in defines
    ]
    assert flags == [
        {"HAS_ABERRATIONS": 0, "HAS_METRIC": 0, "HAS_RADIAL": 0, "HAS_ADDITIVE": 0, "HAS_PORTALS": 0},
        {"HAS_ABERRATIONS": 1, "HAS_METRIC": 1, "HAS_RADIAL": 0, "HAS_ADDITIVE": 0, "HAS_PORTALS": 0},
        {"HAS_ABERRATIONS": 0, "HAS_METRIC": 0, "HAS_RADIAL": 0, "HAS_ADDITIVE": 0, "HAS_PORTALS": 1},
    ]


def _metric_scene() -> Scene:
    scene = boxes_scene()
    scene.add_aberration("squash", (0.5, 0.0, 0.0), scale=2.0)
    return scene


def _portal_scene() -> Scene:
    scene = boxes_scene()
    scene.add_portal_pair("door_a", "door_b", a={"position": (0.0, 1.0, 2.0)}, b={"position": (50.0, 1.0, 0.0)})
    scene.add_portal("loose", position=(1.0, 1.0, 1.0))  # unlinked: no portal code of its own
    return scene


def test_shader_source_is_assembled_from_the_shared_core():
    source = GlslBackend.source({"MAX_EVENTS": 16, "CAMERA_BINDING": 8})
    assert source.startswith("#version 430\n")
    order = ("prelude.glsl", "layout.h", "bindings.glsl", *shared.TRACER_FILES, "main.comp")
    marks = [source.index(f"// ---- {name}") for name in order]
    assert marks == sorted(marks)  # each file builds on those before it
    for name in shared.TRACER_FILES:
        assert shared.read(name) in source, name
