"""The kernels' layout.h is written from engine.layout's records: its structs read the dtypes' bytes.

Offsets are recomputed here from the std430 / OpenCL C rules for the vector members the text
declares, independently of engine.layout's builder. test_glsl.py and test_opencl.py compile the
same text and copy every member out on the device.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from scenes import layout_members

from backends import shared
from engine import layout, records

#: Bytes and scalar type of each kernel vector type, by precision (real4 follows it).
_VECTORS = {
    "float4": (16, "f4"),
    "int4": (16, "i4"),
    "float8": (32, "f4"),
    "int8": (32, "i4"),
}


def _vector(kind: str, precision: str) -> tuple[int, str]:
    if kind == "real4":
        return (32, "f8") if precision == "f64" else (16, "f4")
    return _VECTORS[kind]


def _byte_types(dtype: np.dtype) -> list[str]:
    """The scalar type of each byte of a record ('' for padding), from its dtype's fields."""
    types = [""] * dtype.itemsize
    for name in dtype.names:
        field, offset = dtype.fields[name][:2]
        code = f"{field.base.kind}{field.base.itemsize}"
        types[offset : offset + field.itemsize] = [code] * field.itemsize
    return types


@pytest.mark.parametrize("precision", records.PRECISIONS)
@pytest.mark.parametrize("record", layout.RECORDS, ids=[r.struct for r in layout.RECORDS])
def test_each_struct_covers_its_dtype_byte_for_byte(record: records.Record, precision: str) -> None:
    """Member by member at std430 offsets, the struct's scalars are the dtype's, and its size is the dtype's."""
    dtype = record.dtype(precision)  # type: ignore[arg-type]
    types = _byte_types(dtype)
    offset, align = 0, 16
    for kind, name in layout_members(record.struct):
        size, scalar = _vector(kind, precision)
        align = max(align, size)
        offset = -(-offset // size) * size
        got = types[offset : offset + size]
        width = int(scalar[1])
        lanes = [got[k : k + width] for k in range(0, size, width)]
        for lane, lane_types in enumerate(lanes):
            # A float4's w may hold int32 bits (BvhNode's first / count, read with AS_INT).
            allowed = {scalar, "i4"} if kind == "float4" and lane == 3 else {scalar}
            assert set(lane_types) <= allowed and len(set(lane_types)) == 1, (name, lane, lane_types)
        offset += size
    assert -(-offset // align) * align == dtype.itemsize


def test_every_table_has_its_record() -> None:
    """Each table's dtype, and each bvh_nodes variant's, is a declared record's: no table lacks its struct."""
    dtypes = {(record.dtype(p), p) for record in layout.RECORDS for p in records.PRECISIONS}
    for table in (*layout.TABLES, "camera"):
        for precision in records.PRECISIONS:
            assert (layout.table_dtype(table, precision), precision) in dtypes, table
    for dtype in (*layout.BVH_WIDTHS.values(), layout.BVH_COMPACT_NODE_DTYPE):
        assert (dtype, "f32") in dtypes
    assert len({record.struct for record in layout.RECORDS}) == len(layout.RECORDS)


def test_constants_and_records_are_declared_only_in_the_generated_text() -> None:
    """The host's codes appear with their values, and no stored kernel file declares a record or constant again."""
    text = shared.read("layout.h")
    for name, value in layout.KERNEL_CONSTANTS.items():
        assert f"#define {name} {value}\n" in text
    assert layout.KERNEL_CONSTANTS["BVH_LINK_MASK"] == (1 << layout.BVH_LINK_SHIFT) - 1
    assert {f"MODE_{m.upper()}" for m in layout.ABERRATION_MODES} <= set(layout.KERNEL_CONSTANTS)
    stored = [
        *(shared.read(name) for name in ("prelude_cl.h", "bindings_cl.h", *shared.TRACER_FILES)),
        *(shared.read(name, "backends.glsl") for name in ("prelude.glsl", "bindings.glsl", "main.comp")),
        shared.read("trace.cl", "backends.opencl"),
    ]
    for source in stored:
        for name in layout.KERNEL_CONSTANTS:
            assert not re.search(rf"#define {name}\b", source), name
        for record in layout.RECORDS:
            assert f"STRUCT_BEGIN({record.struct})" not in source, record.struct


def test_texel_readers_step_by_vector_and_real_size() -> None:
    """GLSL's image readers: one texel per 32-bit 4-vector, R4_TEXELS_ per real4, in member order."""
    text = shared.read("layout.h")
    reader = re.search(r"#define Instance_from_texels\(img, b\) Instance\((.*?)\)\n", text, re.S)
    assert reader is not None
    loads = re.findall(r"(\w+)\(img, ([^)]*\)?[^,)]*)\)", reader.group(1))
    assert loads == [
        ("R4_AT_", "b"),
        ("R4_AT_", "(b) + 1 * R4_TEXELS_"),
        ("R4_AT_", "(b) + 2 * R4_TEXELS_"),
        ("R4_AT_", "(b) + 3 * R4_TEXELS_"),
        ("R4_AT_", "(b) + 4 * R4_TEXELS_"),
        ("I4_AT_", "(b) + 5 * R4_TEXELS_"),
    ]
    assert "Bvh8Node_from_texels" not in text  # GLSL has no 8-vectors


@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_texel_readers_skip_the_padding_before_a_real4_at_f64(precision: str) -> None:
    """A real4 after an odd number of 16-byte vectors starts at the next 32 bytes at f64: its reader looks there."""
    from backends.shared.layout_h import texel_reader

    fields = [
        records.Field(name, kind) for name, kind in zip("abcd", ("int4", "real4", "float4", "real4"), strict=True)
    ]
    record = records.Record("Probe", tuple(fields))
    r4_texels = 2 if precision == "f64" else 1
    texels = []
    for part in texel_reader(record).split("_AT_(img, ")[1:]:
        depth, end = 0, 0
        while depth >= 0:  # the argument runs to the parenthesis that closes the load
            depth += {"(": 1, ")": -1}.get(part[end], 0)
            end += 1
        expression = part[: end - 1].replace("(b)", "0").replace("b", "0").replace("R4_TEXELS_", str(r4_texels))
        texels.append(eval(expression))
    dtype = record.dtype(precision)  # the packer's bytes
    assert texels == [dtype.fields[name][1] // 16 for name in "abcd"]
