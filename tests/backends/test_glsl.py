"""The GLSL compute-shader backend: what only it does (image or SSBO tables, lane blocks, its texture, variants).

The contract it shares with OpenCL (errors, AOVs, uploads, traversal, specialisation) is in
tests/backends/test_backend_contract.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_backend
from scenes import TABLE_STRUCTS, boxes_scene, layout_members, random_rows, upload
from scenes import render_aovs as render

from backends import shared
from backends.base import AOVS
from backends.glsl.backend import GlslBackend, lane_block
from backends.glsl.tables import CAMERA_IMAGE, new_image, write_texels
from backends.shared import bvh_depth, stack_size
from backends.upload import SceneUploader
from components import Mesh
from engine import layout
from engine.camera_view import scene_camera
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


# --- layouts: the shader's records read exactly the packed bytes ---------------------------------

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
    "tlas_nodes": "TLAS_NODE(i)",
    "bvh4_nodes": "BVH_NODE(i)",
    "bvh_compact_nodes": "BVH_NODE(i)",
}


@pytest.mark.parametrize("store", ["ssbo", "image"])
@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("table", list(TABLE_STRUCTS))
def test_layout_h_records_read_the_packed_bytes(backend_factory, precision, table, store):
    """A shader copies every member of every row out bit for bit: offsets and strides agree with engine.layout.

    ``ssbo``: layout.h's struct in a std430 buffer; ``image``: the same bytes in an RGBA32UI image,
    read through bindings.glsl's fetch functions (what the backend does on llvmpipe).
    """
    backend = backend_factory("glsl", precision)
    struct = TABLE_STRUCTS[table]
    special = {"bvh4_nodes": layout.BVH4_NODE_DTYPE, "bvh_compact_nodes": layout.BVH_COMPACT_NODE_DTYPE}
    dtype = special[table] if table in special else layout.table_dtype(table, precision)
    single = table in ("settings", "camera")  # the core reads row 0 only
    rows = random_rows(dtype, 1 if single and store == "image" else 5, np.random.default_rng(7))
    stores, words = [], 0
    for kind, member in layout_members(struct):
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
        defines.update(TLAS_WIDTH=2, TLAS_NODES_STRIDE=layout.TLAS_NODE_DTYPE.itemsize // 16)  # the binary record
        defines.update(BOX_COUNT=-1)  # every row from the table, none held by main.comp
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
            src = new_image(ctx, len(rows) * dtype.itemsize // 16)
            write_texels(src, 0, rows.view(np.uint32).reshape(-1, 4))
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


def test_color_texture_holds_the_frame_top_row_first(glsl):
    scene = boxes_scene()
    frame = render(glsl, scene, 40, 30, aovs=("color",))
    texture = glsl.color_texture
    assert texture is not None and texture.size == (40, 30) and texture.components == 4
    with glsl.context:
        data = texture.read(alignment=1)
    np.testing.assert_array_equal(np.frombuffer(data, np.uint8).reshape(30, 40, 4), frame.color)
    assert render(glsl, scene, aovs=()).present() == []
    assert glsl.color_texture is not None  # the editor's path: the texture without a read-back


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


def test_a_checker_added_by_an_edit_is_drawn_as_in_a_fresh_upload(fresh_glsl):
    """Without a checker the kernel compiles its code out; a mesh edit that adds one brings it back."""
    scene = boxes_scene()
    floor = scene.entity("floor")
    scene.set(floor, Mesh("plane"))
    uploader = SceneUploader(fresh_glsl)
    uploader.sync(scene)
    camera = scene_camera(scene)
    plain = fresh_glsl.render(camera, 48, 36, ("color",)).color
    scene.set(floor, Mesh("plane", checker=0.5))
    uploader.sync(scene)
    edited = fresh_glsl.render(camera, 48, 36, ("color",)).color
    assert fresh_glsl.compile_count == 2 and not np.array_equal(edited, plain)
    fresh = render(fresh_glsl, boxes_scene(), aovs=("color",)).color
    assert np.array_equal(edited, fresh)


# --- uploads -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(("first", "count"), [(0, 5), (4090, 20), (4096, 4096), (100, 9000), (8191, 1)])
def test_texel_writes_split_across_image_rows(glsl, first, count):
    with glsl.context:
        image = new_image(glsl.context, first + count + 7)
        rows = image.size[1]
        before = np.arange(rows * image.size[0] * 4, dtype=np.uint32).reshape(-1, 4)
        image.write(before)
        texels = np.random.default_rng(first).integers(0, 2**32, (count, 4), dtype=np.uint32)
        write_texels(image, first, texels)
        after = np.frombuffer(image.read(alignment=1), np.uint32).reshape(-1, 4)
        image.release()
    expected = before.copy()
    expected[first : first + count] = texels
    np.testing.assert_array_equal(after, expected)


# --- stack depth -----------------------------------------------------------------------------------------


def test_bvh_depth_of_packed_tables():
    nodes = np.zeros(7, layout.BVH_NODE_DTYPE)
    # Tree A: 0 -> (1, 2), 2 -> (3, 4); tree B: a lone leaf at 5; tree C: 6 leaf.
    nodes["first"] = [1, 0, 3, 0, 0, 0, 0]
    nodes["count"] = [0, 2, 0, 1, 1, 3, 1]
    assert bvh_depth(nodes, 7) == 3
    assert bvh_depth(nodes, 0) == 0
    assert stack_size(nodes, 7) == 32


# --- specialisation: each feature set is its own variant --------------------------------------------


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


def test_a_frame_without_colour_skips_the_shading_and_keeps_the_hits(fresh_glsl):
    """Other AOVs without the colour compile the shading out (SHADE 0: what Embree's pairing times); the hits
    are the shaded variant's, and a frame with no AOVs still shades the texture the editor draws."""
    scene = boxes_scene()
    upload(fresh_glsl, scene)
    camera = scene_camera(scene)
    full = fresh_glsl.render(camera, 32, 24, aovs=("color", "depth", "instance"))
    hits = fresh_glsl.render(camera, 32, 24, aovs=("depth", "instance"))
    assert (full.aov("instance") >= 0).any()
    np.testing.assert_array_equal(hits.aov("instance"), full.aov("instance"))
    np.testing.assert_array_equal(hits.aov("depth"), full.aov("depth"))
    assert fresh_glsl._defines(("depth", "instance"))["SHADE"] == 0
    assert fresh_glsl._defines(())["SHADE"] == 1 and fresh_glsl._defines(("color",))["SHADE"] == 1
