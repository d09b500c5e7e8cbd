"""The packed layouts obey std430 (and OpenCL C) rules: asserted independently of engine.layout."""

from __future__ import annotations

import numpy as np
import pytest

from engine import layout, records
from engine.records import Precision

# Expected (offset, size) per field, written out by hand from the std430 rules:
# a vec4 of 4-byte scalars aligns to 16, a dvec4 to 32; a struct's size rounds
# up to its largest member alignment.
EXPECTED = {
    ("settings", "f32"): (
        {
            "background": 0,
            "light_dir": 16,
            "event_limit_color": 32,
            "shading": 48,
            "counts": 64,
            "space_roots": 80,
            "lights": 96,
        },
        112,
    ),
    ("triangles", "f32"): ({"v0": 0, "v1": 16, "v2": 32}, 48),
    ("triangle_uvs", "f32"): ({"uv01": 0, "uv2": 16}, 32),
    ("bvh_nodes", "f32"): ({"bounds_min": 0, "first": 12, "bounds_max": 16, "count": 28}, 32),
    ("space_nodes", "f32"): ({"bounds_min": 0, "first": 12, "bounds_max": 16, "count": 28}, 32),
    ("materials", "f32"): ({"color": 0, "flags": 16, "texture": 32}, 48),
    ("triangle_normals", "f32"): ({"n0": 0, "n1": 16, "n2": 32}, 48),
    ("texels", "f32"): ({"rgba": 0}, 16),
    ("triangle_blocks", "f32"): (
        {
            "v0x": 0,
            "v0y": 16,
            "v0z": 32,
            "v1x": 48,
            "v1y": 64,
            "v1z": 80,
            "v2x": 96,
            "v2y": 112,
            "v2z": 128,
            "index": 144,
        },
        160,
    ),
    ("instances", "f32"): ({"world_to_object": 0, "bounds_min": 48, "bounds_max": 64, "meta": 80}, 96),
    ("instances", "f64"): ({"world_to_object": 0, "bounds_min": 96, "bounds_max": 128, "meta": 160}, 192),
    ("aberrations", "f32"): ({"world_to_local": 0, "rotation": 48, "deformation": 96, "meta": 112}, 128),
    ("aberrations", "f64"): ({"world_to_local": 0, "rotation": 96, "deformation": 192, "meta": 224}, 256),
    ("portals", "f32"): ({"world_to_local": 0, "transfer": 48, "meta": 96}, 112),
    ("portals", "f64"): ({"world_to_local": 0, "transfer": 96, "meta": 192}, 224),
    ("lights", "f32"): ({"vector": 0, "color": 16, "meta": 32}, 48),
    ("lights", "f64"): ({"vector": 0, "color": 32, "meta": 48}, 64),
    ("camera", "f32"): (
        {
            "position": 0,
            "right": 16,
            "up": 32,
            "back": 48,
            "origin": 64,
            "sigma_min": 80,
            "sigma_max": 96,
            "lens": 112,
            "subpixel": 128,
            "size": 144,
        },
        160,
    ),
    ("camera", "f64"): (
        {
            "position": 0,
            "right": 32,
            "up": 64,
            "back": 96,
            "origin": 128,
            "sigma_min": 160,
            "sigma_max": 192,
            "lens": 224,
            "subpixel": 256,
            "size": 288,
        },
        320,
    ),
}


@pytest.mark.parametrize(("table", "precision"), sorted(EXPECTED))
def test_offsets_and_sizes(table: str, precision: Precision) -> None:
    offsets, itemsize = EXPECTED[(table, precision)]
    dtype = layout.table_dtype(table, precision)
    assert dtype.itemsize == itemsize
    assert {name: dtype.fields[name][1] for name in dtype.names} == offsets


@pytest.mark.parametrize("table", [*layout.TABLES, "camera"])
@pytest.mark.parametrize("precision", records.PRECISIONS)
def test_records_are_whole_vectors(table: str, precision: str) -> None:
    """Every record is a multiple of its vector alignment, so arrays of them need no padding."""
    dtype = layout.table_dtype(table, precision)
    assert (
        dtype.itemsize
        % (32 if precision == "f64" and table in ("instances", "aberrations", "portals", "camera") else 16)
        == 0
    )
    for name in dtype.names:
        base = dtype.fields[name][0].base
        assert base in (np.dtype(np.float32), np.dtype(np.float64), np.dtype(np.int32))


def test_bvh4_node_offsets() -> None:
    """The 4-wide node (bvh_nodes of ScenePacker(bvh_width=4)): six float4 bounds, then child and count int4s."""
    dtype = layout.BVH4_NODE_DTYPE
    assert dtype.itemsize == 128
    names = ("lo_x", "lo_y", "lo_z", "hi_x", "hi_y", "hi_z", "child", "count")
    assert {name: dtype.fields[name][1] for name in dtype.names} == {n: 16 * i for i, n in enumerate(names)}
    assert {2: layout.BVH_NODE_DTYPE, 4: dtype, 8: layout.BVH8_NODE_DTYPE} == layout.BVH_WIDTHS
    assert layout.bvh_width(np.zeros(3, dtype)) == 4 and layout.bvh_width(np.zeros(3, layout.BVH_NODE_DTYPE)) == 2
    with pytest.raises(ValueError, match="not a BVH node table"):
        layout.bvh_width(np.zeros(3, layout.TRIANGLE_DTYPE))


def test_bvh8_node_offsets() -> None:
    """The 8-wide node (bvh_width=8, OpenCL float8 / int8 members): each field two 4-vector rows, 32 bytes apart."""
    dtype = layout.BVH8_NODE_DTYPE
    assert dtype.itemsize == 256
    names = ("lo_x", "lo_y", "lo_z", "hi_x", "hi_y", "hi_z", "child", "count")
    assert {name: dtype.fields[name][1] for name in dtype.names} == {n: 32 * i for i, n in enumerate(names)}
    assert all(dtype.fields[name][0].shape == (2, 4) for name in names)
    assert layout.bvh_width(np.zeros(3, dtype)) == 8


def test_bvh_compact_node_offsets() -> None:
    """The compact binary record (bvh_nodes of ScenePacker(bvh_compact=True)): two int4s, 32 bytes."""
    dtype = layout.BVH_COMPACT_NODE_DTYPE
    assert dtype.itemsize == 32
    assert {name: dtype.fields[name][1] for name in dtype.names} == {"child0": 0, "child1": 16}
    assert all(dtype.fields[name][0].base == np.dtype(np.int32) for name in dtype.names)
    nodes = np.zeros(3, dtype)
    assert layout.bvh_width(nodes) == 2 and layout.bvh_compact(nodes)
    assert not layout.bvh_compact(np.zeros(3, layout.BVH_NODE_DTYPE))
    assert not layout.bvh_compact(np.zeros(3, layout.BVH4_NODE_DTYPE))
    with pytest.raises(ValueError, match="not a BVH node table"):
        layout.bvh_compact(np.zeros(3, layout.TRIANGLE_DTYPE))


def test_precision_only_changes_real_tables() -> None:
    for table in ("settings", "triangles", "triangle_uvs", "bvh_nodes", "materials"):
        assert layout.table_dtype(table, "f32") == layout.table_dtype(table, "f64")
    for table in ("instances", "aberrations", "portals", "camera"):
        assert layout.table_dtype(table, "f64").itemsize > layout.table_dtype(table, "f32").itemsize


def test_unknown_table_is_named() -> None:
    with pytest.raises(KeyError, match="unknown table 'nope'"):
        layout.table_dtype("nope", "f32")


def test_codes_are_distinct() -> None:
    assert sorted(layout.ABERRATION_MODES.values()) == [0, 1, 2]
    assert sorted(layout.ABERRATION_EXITS.values()) == [0, 1, 2]
