"""GPU data layouts, declared once.

Every table the tracers read is a NumPy structured dtype whose bytes go
unchanged into a std430 shader storage buffer and an OpenCL buffer. The
kernels declare the same records in ``backends/shared/layout.h`` built from
4-component vectors only (``real4`` / ``int4``), which is the subset on which
std430 and OpenCL C agree. Tests assert offsets and sizes against the std430
rules, so a drift between host and kernel is caught on the host.

Two families exist:

* precision-independent tables (``triangles``, ``triangle_uvs``,
  ``bvh_nodes``, ``materials``, ``settings``, ``tlas_nodes``, ``triangle_blocks``, ``space_nodes``):
  always 32-bit. Vertices are float32 in the assets, so a float64 tracer loses nothing
  by reading them as float32; BVH bounds are rounded outward so any precision
  may traverse them. ``bvh_nodes`` has one of four dtypes, chosen by the
  packer's ``bvh_width`` and ``bvh_compact`` (the backend's): binary
  :data:`BVH_NODE_DTYPE`, compact binary :data:`BVH_COMPACT_NODE_DTYPE` (GLSL),
  4-wide :data:`BVH4_NODE_DTYPE` or 8-wide :data:`BVH8_NODE_DTYPE` (OpenCL
  only), whose leaves name rows of ``triangle_blocks`` (empty with binary trees).
* real tables (``instances``, ``aberrations``, ``portals``, ``camera``):
  their ``real`` fields are float32 (``f32``) or float64 (``f64``). A record
  is padded to the alignment of its widest vector (16 bytes for f32, 32 bytes
  for f64), as std430 and OpenCL C both do.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

Precision = Literal["f32", "f64"]
PRECISIONS: tuple[Precision, ...] = ("f32", "f64")

# (field name, kind, rows): kind is "real4", "int4" or "float4" (always
# 32-bit); rows > 1 makes a matrix of that many 4-vector rows.
FieldSpec = tuple[str, str, int]


def _build(fields: list[FieldSpec], precision: Precision) -> np.dtype:
    """A dtype of 4-vectors with std430 offsets, padded to its alignment."""
    real = np.float64 if precision == "f64" else np.float32
    names: list[str] = []
    formats: list[object] = []
    offsets: list[int] = []
    offset = 0
    align = 16
    for name, kind, rows in fields:
        if kind == "real4":
            base = np.dtype(real)
        elif kind == "float4":
            base = np.dtype(np.float32)
        elif kind == "int4":
            base = np.dtype(np.int32)
        else:  # pragma: no cover - a programming error in this file
            raise ValueError(f"unknown field kind {kind!r}")
        size = 4 * base.itemsize
        align = max(align, size)
        offset = -(-offset // size) * size
        names.append(name)
        formats.append((base, (rows, 4) if rows > 1 else (4,)))
        offsets.append(offset)
        offset += size * rows
    itemsize = -(-offset // align) * align
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": itemsize})


# --- 32-bit tables -----------------------------------------------------------

#: One triangle of a mesh asset, object space. ``w`` components are unused.
TRIANGLE_DTYPE = _build([("v0", "float4", 1), ("v1", "float4", 1), ("v2", "float4", 1)], "f32")

#: Texture coordinates of a triangle: ``uv01 = (u0, v0, u1, v1)``, ``uv2 = (u2, v2, 0, 0)``.
TRIANGLE_UV_DTYPE = _build([("uv01", "float4", 1), ("uv2", "float4", 1)], "f32")

#: A BVH node, 32 bytes, read by kernels as two 4-vectors whose ``w`` holds an
#: int32 bit pattern: ``bounds_min.xyz`` + ``first``, ``bounds_max.xyz`` +
#: ``count``. ``count > 0``: a leaf over triangles ``[first, first + count)``;
#: ``count == 0``: an interior node whose children are ``first`` and
#: ``first + 1``. Bounds are rounded outward to float32. Indices are absolute in
#: the packed scene (the packer adds each asset's offsets).
BVH_NODE_DTYPE = np.dtype(
    {
        "names": ["bounds_min", "first", "bounds_max", "count"],
        "formats": [(np.float32, (3,)), np.int32, (np.float32, (3,)), np.int32],
        "offsets": [0, 12, 16, 28],
        "itemsize": 32,
    }
)

#: A 4-wide BVH node (``ScenePacker(bvh_width=4)``), 128 bytes: the boxes of its
#: four children stored SoA, one ``float4`` per bound component (lane i = child
#: i), so a visit is a few 4-vector min/max operations. ``child[i]`` and
#: ``count[i]`` say what child i is: ``count > 0``, a leaf of ``count`` triangles
#: (in the tree from :func:`engine.bvh_wide.collapse`: triangles ``[child, child + count)``;
#: packed: ``ceil(count / 4)`` rows of ``triangle_blocks`` from ``child``);
#: ``count == 0``, the wide node ``child``;
#: ``count < 0``, an empty slot (its box is a point at the origin: the count,
#: not the box, rules it out). Children keep the binary tree's left-to-right
#: order. Bounds are rounded outward; indices are absolute in the packed scene.
BVH4_NODE_DTYPE = _build(
    [
        ("lo_x", "float4", 1),
        ("lo_y", "float4", 1),
        ("lo_z", "float4", 1),
        ("hi_x", "float4", 1),
        ("hi_y", "float4", 1),
        ("hi_z", "float4", 1),
        ("child", "int4", 1),
        ("count", "int4", 1),
    ],
    "f32",
)

#: Four triangles of one wide-BVH leaf, SoA (lane i = triangle i): ``v0x = (v0.x of each)``, ... so the
#: watertight test runs on four at once. ``index`` holds each lane's row in ``triangles`` (shading and
#: ties use it), -1 for a padding lane. Only built with ``bvh_width=4``, whose leaves point at blocks.
TRIANGLE_BLOCK_DTYPE = _build(
    [(f"v{k}{axis}", "float4", 1) for k in range(3) for axis in "xyz"] + [("index", "int4", 1)], "f32"
)

#: A compact binary BVH record (``ScenePacker(bvh_compact=True)``, GLSL): an interior node as the
#: boxes of BOTH its children, 32 bytes, so a visit is 2 texel loads instead of 4 (two children's
#: :data:`BVH_NODE_DTYPE` rows) and a pop is none. ``child{i}.xyz`` packs child i's box as six
#: 16-bit grid coordinates ``(lo.x | lo.y << 16, lo.z | hi.x << 16, hi.y | hi.z << 16)`` over the
#: asset's frame; the decoded float box ``origin + q * scale`` (lo rounded down, hi up, checked on
#: the host for fused and unfused arithmetic) contains the exact one. ``child{i}.w`` is a link:
#: ``index << 7 | count``; ``count > 0``, a leaf of triangles ``[index, index + count)``;
#: ``count == 0``, the record ``index``. Each asset's records start with a header:
#: ``child0 = (origin.xyz bits, root link)``, ``child1 = (scale.xyz bits, -1)``; its root box is
#: the whole grid. Indices are absolute in the packed scene.
BVH_COMPACT_NODE_DTYPE = _build([("child0", "int4", 1), ("child1", "int4", 1)], "f32")

#: Bits of a compact link below its index: leaf counts up to 64 (``BvhParams.max_leaf_size``).
BVH_LINK_SHIFT = 7

#: An 8-wide BVH node (``ScenePacker(bvh_width=8)``, OpenCL only: GLSL has no 8-vectors), 256 bytes:
#: :data:`BVH4_NODE_DTYPE` with eight lanes, each field two 4-vector rows (row 0 = lanes 0-3), which
#: are the bytes of the ``float8`` / ``int8`` the kernel reads (32-byte aligned: every offset is a
#: multiple of 32). Leaves name ``ceil(count / 4)`` rows of ``triangle_blocks``, as with width 4.
BVH8_NODE_DTYPE = _build(
    [
        ("lo_x", "float4", 2),
        ("lo_y", "float4", 2),
        ("lo_z", "float4", 2),
        ("hi_x", "float4", 2),
        ("hi_y", "float4", 2),
        ("hi_z", "float4", 2),
        ("child", "int4", 2),
        ("count", "int4", 2),
    ],
    "f32",
)

#: The ``bvh_nodes`` dtype of each supported BVH width.
BVH_WIDTHS: dict[int, np.dtype] = {2: BVH_NODE_DTYPE, 4: BVH4_NODE_DTYPE, 8: BVH8_NODE_DTYPE}


def bvh_width(nodes: np.ndarray) -> int:
    """The BVH width of a ``bvh_nodes`` table, from its dtype (compact records are binary)."""
    if nodes.dtype == BVH_COMPACT_NODE_DTYPE:
        return 2
    for width, dtype in BVH_WIDTHS.items():
        if nodes.dtype == dtype:
            return width
    raise ValueError(f"not a BVH node table: dtype {nodes.dtype}")


def bvh_compact(nodes: np.ndarray) -> bool:
    """Whether a ``bvh_nodes`` table holds compact records (:data:`BVH_COMPACT_NODE_DTYPE`)."""
    bvh_width(nodes)  # raises on a foreign table
    return nodes.dtype == BVH_COMPACT_NODE_DTYPE


#: A node of the top-level tree over instances (``engine.tlas``), the BVH node's 32 bytes:
#: ``count == 1``: a leaf over instance row ``first``; ``count == 0``: an interior node whose
#: children are ``first`` and ``first + 1``. Bounds are float32 rounded outward, a leaf's the
#: instance's world bounds grown by a margin (the exact ones are on the instance row).
TLAS_NODE_DTYPE = BVH_NODE_DTYPE

#: A node of the trees over portal quads and aberration boxes (``engine.packing_space``), the BVH node's 32
#: bytes, as :data:`TLAS_NODE_DTYPE`: ``count == 1``, a leaf over portal or aberration row ``first``;
#: ``count == 0``, an interior node whose children are ``first`` and ``first + 1``. One table holds both
#: trees, the portals' from row 0, the boxes' from the settings' ``space_roots.y``. A leaf's bounds hold its
#: quad's or box's world bounds, grown by a margin and by :data:`engine.tlas.SPACE_SLACK` of their size.
SPACE_NODE_DTYPE = BVH_NODE_DTYPE

#: Material of a mesh instance: ``color = (r, g, b, checker_scale)`` with
#: ``checker_scale == 0`` meaning no checker; ``flags = (cull_backfaces, 0, 0, 0)``.
MATERIAL_DTYPE = _build([("color", "float4", 1), ("flags", "int4", 1)], "f32")

#: Scene-wide settings, one row. ``light_dir`` is unit and points towards the
#: light; ``shading = (ambient, 0, 0, 0)``; ``counts = (instances,
#: aberrations, portals, max_events)``; ``space_roots = (portal tree root, box tree root, 0, 0)``,
#: rows of ``space_nodes``.
SETTINGS_DTYPE = _build(
    [
        ("background", "float4", 1),
        ("light_dir", "float4", 1),
        ("event_limit_color", "float4", 1),
        ("shading", "float4", 1),
        ("counts", "int4", 1),
        ("space_roots", "int4", 1),
    ],
    "f32",
)


# --- real tables (float32 or float64) ----------------------------------------


def instance_dtype(precision: Precision) -> np.dtype:
    """A mesh entity placed in the scene.

    ``world_to_object`` rows (3x4 affine, camera-relative world to object
    space), world-space bounds (camera-relative; ``w`` unused) and
    ``meta = (bvh_root, material, entity, flags)`` with flags bit 0: the asset
    has UVs.
    """
    return _build(
        [
            ("world_to_object", "real4", 3),
            ("bounds_min", "real4", 1),
            ("bounds_max", "real4", 1),
            ("meta", "int4", 1),
        ],
        precision,
    )


def aberration_dtype(precision: Precision) -> np.dtype:
    """An aberration box.

    ``world_to_local`` rows map camera-relative world points into the unit box
    [-1/2, 1/2]^3; ``rotation`` rows are the box's rotation R (``w`` of row 0: the box's
    clearance to every instance, of row 1: its gap to every other box, engine/box_clearance.py);
    ``deformation.xyz`` is D; ``meta = (mode, exit, priority, entity)``.
    Rows are sorted by (priority, entity): the active box at a point is the
    *last* row that contains it.
    """
    return _build(
        [
            ("world_to_local", "real4", 3),
            ("rotation", "real4", 3),
            ("deformation", "real4", 1),
            ("meta", "int4", 1),
        ],
        precision,
    )


def portal_dtype(precision: Precision) -> np.dtype:
    """A portal quad.

    ``world_to_local`` rows map camera-relative world points into the quad's
    space ([-1, 1]^2 at z = 0); ``transfer`` rows are ``X = M_target M_self^-1``
    in camera-relative coordinates (its 3x3 part is the direction map L);
    ``meta = (target_row, entity, 0, 0)``, target_row -1 when unlinked.
    """
    return _build(
        [
            ("world_to_local", "real4", 3),
            ("transfer", "real4", 3),
            ("meta", "int4", 1),
        ],
        precision,
    )


def camera_dtype(precision: Precision) -> np.dtype:
    """Per-frame camera.

    ``position.xyz`` is camera-relative (the packed origin subtracted);
    ``right``, ``up``, ``back`` are the columns of R_cam; ``origin.xyz`` is the
    packed origin (for world-space checkers); ``sigma_min``/``sigma_max`` are
    the radial mode's corner-ray bounds m_k, M_k; ``lens = (tan(fov/2),
    aspect, clearance, 0)``, the camera's distance to every instance's bounds
    (``box_clearance``); ``size = (width, height, camera box, 0)``, the camera box being
    every primary ray's active box or -2 for a per-ray look-up (``camera_view.camera_box``).
    """
    return _build(
        [
            ("position", "real4", 1),
            ("right", "real4", 1),
            ("up", "real4", 1),
            ("back", "real4", 1),
            ("origin", "real4", 1),
            ("sigma_min", "real4", 1),
            ("sigma_max", "real4", 1),
            ("lens", "real4", 1),
            ("size", "int4", 1),
        ],
        precision,
    )


# Mode and exit codes shared by the packer and every kernel.
ABERRATION_MODES: dict[str, int] = {"metric": 0, "radial": 1, "additive": 2}
ABERRATION_EXITS: dict[str, int] = {"restore": 0, "repeat": 1, "invert": 2}

INSTANCE_FLAG_HAS_UVS = 1

#: Names of the packed tables, in the binding order every backend uses.
TABLES: tuple[str, ...] = (
    "settings",
    "triangles",
    "triangle_uvs",
    "bvh_nodes",
    "instances",
    "materials",
    "aberrations",
    "portals",
    "tlas_nodes",
    "triangle_blocks",
    "space_nodes",
)


def table_dtype(name: str, precision: Precision) -> np.dtype:
    """The dtype of a named table at a precision (32-bit tables ignore it; ``bvh_nodes``: the binary one)."""
    fixed = {
        "settings": SETTINGS_DTYPE,
        "triangles": TRIANGLE_DTYPE,
        "triangle_uvs": TRIANGLE_UV_DTYPE,
        "bvh_nodes": BVH_NODE_DTYPE,
        "materials": MATERIAL_DTYPE,
        "tlas_nodes": TLAS_NODE_DTYPE,
        "triangle_blocks": TRIANGLE_BLOCK_DTYPE,
        "space_nodes": SPACE_NODE_DTYPE,
    }
    if name in fixed:
        return fixed[name]
    real = {
        "instances": instance_dtype,
        "aberrations": aberration_dtype,
        "portals": portal_dtype,
        "camera": camera_dtype,
    }
    try:
        return real[name](precision)
    except KeyError:
        raise KeyError(f"unknown table {name!r}; tables are {', '.join(TABLES)} and camera") from None
