"""``layout.h``, the kernels' packed records, written from ``engine.layout``'s declarations.

Each record is declared once, on the host (:class:`engine.records.Record`); its dtype and its kernel
struct both come from that declaration, so the bytes the packer writes are the bytes the kernels
read by construction. The text is the same for both languages and precisions (``real4`` is the
prelude's); GLSL's RGBA32UI image readers sit behind ``TABLES_IN_IMAGES``, which only GLSL defines.
"""

from __future__ import annotations

from functools import cache

from engine import layout
from engine.records import Record

_HEADER = """\
/* layout.h -- the packed scene records, written by backends/shared/layout_h.py from engine/layout.py's
 * Record declarations (what each field means is documented there). Shared by GLSL and OpenCL C.
 *
 * Every record is built from 4-component vectors only, the subset on which std430 and OpenCL C
 * agree: a record's size is a multiple of its widest vector (16 bytes, or 32 with REAL_IS_DOUBLE),
 * with no hidden padding. Types (from the prelude): float4 / int4 are always 32-bit; real4 is
 * float4 or, with REAL_IS_DOUBLE, a 4-vector of doubles; float8 / int8 are OpenCL C only.
 * STRUCT_BEGIN/STRUCT_END declare a struct usable by its bare name in both languages.
 */
"""

#: The image-texel readers of bindings.glsl (TABLES_IN_IMAGES), by the kernel type of a member.
_TEXEL_READERS = {"float4": "F4_AT_", "int4": "I4_AT_", "real4": "R4_AT_"}


def _opencl_only(record: Record) -> bool:
    """Whether a record has 8-vector members, which GLSL lacks."""
    return any(kind.endswith("8") for kind, _ in record.kernel_members())


def struct(record: Record) -> str:
    """The record's ``STRUCT_BEGIN`` ... ``STRUCT_END`` declaration."""
    members = "".join(f"    {kind} {name};\n" for kind, name in record.kernel_members())
    return f"STRUCT_BEGIN({record.struct})\n{members}STRUCT_END({record.struct})\n"


def texel_reader(record: Record) -> str:
    """``<struct>_from_texels(img, b)``: the record whose first texel is ``b`` in an RGBA32UI image, one
    texel per 32-bit 4-vector and ``R4_TEXELS_`` per ``real4`` (bindings.glsl's helpers).

    Each member's texel offset is read from the record's dtype at both precisions, so the padding that
    aligns a ``real4`` to 32 bytes at f64 is skipped as the packer wrote it."""
    offsets = {}
    for precision in ("f32", "f64"):
        members = record.dtype(precision).fields
        assert members is not None  # a record's dtype is structured
        texels = []
        for field in record.fields:
            start = members[field.name][1]
            size = members[field.name][0].itemsize // field.rows if field.rows > 1 else 0
            texels += [(start + row * size) // 16 for row in range(field.rows)]
        offsets[precision] = texels
    loads = []
    fixed = reals = 0
    for k, (kind, _) in enumerate(record.kernel_members()):
        # f64 pads a real4 after an odd number of 16-byte vectors to 32 bytes: one texel more from there on
        pads = offsets["f64"][k] - (fixed + 2 * reals)
        if offsets["f32"][k] != fixed + reals:  # pragma: no cover - a Record this file cannot lay out
            raise ValueError(f"{record.struct}: member {k} is not where the texel reader would look")
        terms = [str(fixed)] if fixed else []
        terms += [f"{reals} * R4_TEXELS_"] if reals else []
        terms += [f"{pads} * (R4_TEXELS_ - 1)"] if pads else []
        offset = " + ".join(terms)
        loads.append(f"{_TEXEL_READERS[kind]}(img, {f'(b) + {offset}' if offset else 'b'})")
        if kind == "real4":
            reals += 1
        else:
            fixed += 1
    args = ", \\\n    ".join(loads)
    return f"#define {record.struct}_from_texels(img, b) {record.struct}( \\\n    {args})\n"


def _row_choice(name: str, choices: list[tuple[str, Record]]) -> list[str]:
    """``#define name`` (and ``name_from_texels``) as the record of the first ``(condition, record)`` that
    holds (an empty condition: the last, the default)."""
    lines = []
    for index, (condition, record) in enumerate(choices):
        lines.append(f"#if {condition}" if index == 0 else f"#elif {condition}" if condition else "#else")
        lines.append(f"#define {name} {record.struct}")
        if not _opencl_only(record):
            lines.append(f"#define {name}_from_texels {record.struct}_from_texels")
    return [*lines, "#endif"]


def _bvh_row() -> str:
    """``BvhRow``, the ``bvh_nodes`` record of this variant's ``BVH_WIDTH`` / ``BVH_COMPACT`` (the packer's
    ``bvh_width`` and ``bvh_compact``, read back from the table's dtype by ``layout.bvh_width``); and
    ``TlasRow``, the ``tlas_nodes`` record of its ``TLAS_WIDTH`` (:mod:`engine.tlas_wide`: the wide asset
    trees' records)."""
    wide = [(f"BVH_WIDTH == {width}", layout.BVH_RECORDS[width]) for width in sorted(layout.BVH_RECORDS)[:0:-1]]
    choices = [*wide, ("BVH_COMPACT", layout.BVH_COMPACT_NODE), ("", layout.BVH_RECORDS[2])]
    lines = [
        "#ifndef BVH_WIDTH",
        "#define BVH_WIDTH 2",
        "#endif",
        "#ifndef BVH_COMPACT",
        "#define BVH_COMPACT 0",
        "#endif",
        "#ifndef TLAS_WIDTH",
        "#define TLAS_WIDTH 2",
        "#endif",
    ]
    lines += _row_choice("BvhRow", choices)
    tlas = [(f"TLAS_WIDTH == {width}", layout.BVH_RECORDS[width]) for width in (8, 4)]
    lines += _row_choice("TlasRow", [*tlas, ("", layout.TLAS_NODE)])
    return "\n".join(lines) + "\n"


@cache
def layout_h() -> str:
    """The whole ``layout.h``: every record of :data:`engine.layout.RECORDS`, the kernel constants, the
    image readers (GLSL), ``BvhRow`` and ``TlasRow``."""
    names = {id(value): name for name, value in vars(layout).items() if isinstance(value, Record)}
    parts = [_HEADER]
    for name, value in layout.KERNEL_CONSTANTS.items():
        parts.append(f"#define {name} {value}\n")
    for record in layout.RECORDS:
        only = ", 8-vectors: OpenCL C only" if _opencl_only(record) else ""
        parts.append(f"/* {record.struct}: engine.layout.{names[id(record)]}{only} */\n")
        if _opencl_only(record):
            parts.append("#ifdef __OPENCL_VERSION__\n")
            parts.append(struct(record))
            parts.append("#endif\n")
        else:
            parts.append(struct(record))
    parts.append("/* GLSL with the tables in RGBA32UI images (bindings.glsl): each record from its texels. */\n")
    parts.append("#if TABLES_IN_IMAGES\n")
    parts.extend(texel_reader(record) for record in layout.RECORDS if not _opencl_only(record))
    parts.append("#endif\n")
    parts.append(_bvh_row())
    return "".join(parts)
