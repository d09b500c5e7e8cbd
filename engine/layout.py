"""GPU data layouts, declared once.

Every table the tracers read is a NumPy structured dtype whose bytes go
unchanged into a std430 shader storage buffer and an OpenCL buffer. Each record
is declared here once, as a :class:`engine.records.Record` of 4-vector fields (``real4`` /
``float4`` / ``int4``; 8-vectors for the 8-wide BVH, OpenCL only), the subset
on which std430 and OpenCL C agree. Both sides come from that declaration: the
host's dtype (:meth:`engine.records.Record.dtype`) and the kernels' struct, which
``backends/shared/layout_h.py`` writes into the kernel source as ``layout.h``,
so host and kernel cannot drift apart. Tests assert offsets and sizes against
the std430 rules, and that the written structs read the dtypes' bytes.

Two families exist:

* precision-independent tables (``triangles``, ``triangle_uvs``,
  ``bvh_nodes``, ``materials``, ``settings``, ``tlas_nodes``, ``triangle_blocks``, ``space_nodes``,
  ``triangle_normals``, ``texels``):
  always 32-bit. Vertices are float32 in the assets, so a float64 tracer loses nothing
  by reading them as float32; BVH bounds are rounded outward so any precision
  may traverse them. ``bvh_nodes`` has one of four dtypes, chosen by the
  packer's ``bvh_width`` and ``bvh_compact`` (the backend's): binary
  :data:`BVH_NODE_DTYPE`, compact binary :data:`BVH_COMPACT_NODE_DTYPE` (GLSL),
  4-wide :data:`BVH4_NODE_DTYPE` or 8-wide :data:`BVH8_NODE_DTYPE` (OpenCL
  only), whose leaves name rows of ``triangle_blocks`` (empty with binary trees).
* real tables (``instances``, ``aberrations``, ``portals``, ``lights``, ``camera``):
  their ``real`` fields are float32 (``f32``) or float64 (``f64``). A record
  is padded to the alignment of its widest vector (16 bytes for f32, 32 bytes
  for f64), as std430 and OpenCL C both do.

A new record is one :class:`engine.records.Record` added to :data:`RECORDS` (its kernel struct
follows), plus the table's row in :data:`TABLES` and :func:`table_dtype`.
"""

from __future__ import annotations

import numpy as np

from components.light import MAX_LIGHTS
from engine.records import Field, Precision, Record, vectors

# --- 32-bit tables -----------------------------------------------------------

#: One triangle of a mesh asset, object space. ``w`` components are unused.
TRIANGLE = Record("Triangle", vectors("float4", "v0", "v1", "v2"))
TRIANGLE_DTYPE = TRIANGLE.dtype()

#: Texture coordinates of a triangle: ``uv01 = (u0, v0, u1, v1)``, ``uv2 = (u2, v2, 0, 0)``.
TRIANGLE_UV = Record("TriangleUv", vectors("float4", "uv01", "uv2"))
TRIANGLE_UV_DTYPE = TRIANGLE_UV.dtype()

#: Object-space vertex normals of a triangle (``w`` unused), for smooth shading: packed only for the assets
#: a smooth mesh uses, row ``triangle + material.texture.w`` (``engine.normals``).
TRIANGLE_NORMAL = Record("TriangleNormal", vectors("float4", "n0", "n1", "n2"))
TRIANGLE_NORMAL_DTYPE = TRIANGLE_NORMAL.dtype()

#: One texel of the scene's texture atlas: linear ``rgba`` in [0, 1] (8-bit values / 255). Each texture is
#: ``width * height`` consecutive rows, its top image row first (``engine.textures``).
TEXEL = Record("Texel", (Field("rgba", "float4"),))
TEXEL_DTYPE = TEXEL.dtype()

#: A BVH node, 32 bytes, read by kernels as two 4-vectors whose ``w`` holds an
#: int32 bit pattern: ``lo = (bounds_min.xyz, first)``, ``hi = (bounds_max.xyz,
#: count)``. ``count > 0``: a leaf over triangles ``[first, first + count)``;
#: ``count == 0``: an interior node whose children are ``first`` and
#: ``first + 1``. Bounds are rounded outward to float32. Indices are absolute in
#: the packed scene (the packer adds each asset's offsets).
BVH_NODE = Record(
    "BvhNode",
    (Field("bounds_min", "float4", member="lo", w="first"), Field("bounds_max", "float4", member="hi", w="count")),
)
BVH_NODE_DTYPE = BVH_NODE.dtype()

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
BVH4_NODE = Record(
    "Bvh4Node",
    (*vectors("float4", "lo_x", "lo_y", "lo_z", "hi_x", "hi_y", "hi_z"), *vectors("int4", "child", "count")),
)
BVH4_NODE_DTYPE = BVH4_NODE.dtype()

#: Four triangles of one wide-BVH leaf, SoA (lane i = triangle i): ``v0x = (v0.x of each)``, ... so the
#: watertight test runs on four at once. ``index`` holds each lane's row in ``triangles`` (shading and
#: ties use it), -1 for a padding lane. Only built with ``bvh_width=4``, whose leaves point at blocks.
TRIANGLE_BLOCK = Record(
    "TriangleBlock", (*vectors("float4", *(f"v{k}{axis}" for k in range(3) for axis in "xyz")), Field("index", "int4"))
)
TRIANGLE_BLOCK_DTYPE = TRIANGLE_BLOCK.dtype()

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
BVH_COMPACT_NODE = Record("BvhCompactNode", vectors("int4", "child0", "child1"))
BVH_COMPACT_NODE_DTYPE = BVH_COMPACT_NODE.dtype()

#: Bits of a compact link below its index: leaf counts up to 64 (``BvhParams.max_leaf_size``).
BVH_LINK_SHIFT = 7
#: The largest 16-bit grid coordinate of a compact record's box.
BVH_GRID_MAX = 65535

#: An 8-wide BVH node (``ScenePacker(bvh_width=8)``, OpenCL only: GLSL has no 8-vectors), 256 bytes:
#: :data:`BVH4_NODE_DTYPE` with eight lanes, each field two 4-vector rows (row 0 = lanes 0-3), which
#: are the bytes of the ``float8`` / ``int8`` the kernel reads (32-byte aligned: every offset is a
#: multiple of 32). Leaves name ``ceil(count / 4)`` rows of ``triangle_blocks``, as with width 4.
BVH8_NODE = Record(
    "Bvh8Node",
    (*vectors("float8", "lo_x", "lo_y", "lo_z", "hi_x", "hi_y", "hi_z"), *vectors("int8", "child", "count")),
)
BVH8_NODE_DTYPE = BVH8_NODE.dtype()

#: The ``bvh_nodes`` record of each supported BVH width (binary: :data:`BVH_COMPACT_NODE` when compact).
BVH_RECORDS: dict[int, Record] = {2: BVH_NODE, 4: BVH4_NODE, 8: BVH8_NODE}
#: The ``bvh_nodes`` dtype of each supported BVH width.
BVH_WIDTHS: dict[int, np.dtype] = {width: record.dtype() for width, record in BVH_RECORDS.items()}


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
#: instance's world bounds grown by a margin (the exact ones are on the instance row). Root at row 0.
#: A packer with ``tlas_width`` 4 or 8 stores the tree collapsed into :data:`BVH_WIDTHS` records instead
#: (``engine.tlas_wide``: a leaf lane's ``count`` is 1 and its ``child`` the instance row).
TLAS_NODE = Record("TlasNode", BVH_NODE.fields)
TLAS_NODE_DTYPE = BVH_NODE_DTYPE

#: A node of the trees over portal quads and aberration boxes (``engine.packing_space``), the BVH node's 32
#: bytes, as :data:`TLAS_NODE_DTYPE`: ``count == 1``, a leaf over portal or aberration row ``first``;
#: ``count == 0``, an interior node whose children are ``first`` and ``first + 1``. One table holds both
#: trees, the portals' from row 0, the boxes' from the settings' ``space_roots.y``. A leaf's bounds hold its
#: quad's or box's world bounds, grown by a margin and by :data:`engine.tlas.SPACE_SLACK` of their size. After
#: them come the two trees' 4-wide forms for the kernels' ray walks (:mod:`engine.space_wide`), in rows of
#: the same size.
SPACE_NODE = Record("SpaceNode", BVH_NODE.fields)
SPACE_NODE_DTYPE = BVH_NODE_DTYPE

#: Material of a mesh instance: ``color = (r, g, b, checker_scale)`` with
#: ``checker_scale == 0`` meaning no checker; ``flags = (cull_backfaces, 0, 0, 0)``; ``texture = (first
#: texel, width, height, normal offset)``, width 0 meaning untextured, the offset taking a triangle's row to
#: its ``triangle_normals`` row (read only when the instance has :data:`INSTANCE_FLAG_SMOOTH`).
MATERIAL = Record("Material", (Field("color", "float4"), Field("flags", "int4"), Field("texture", "int4")))
MATERIAL_DTYPE = MATERIAL.dtype()

#: Scene-wide settings, one row. ``light_dir`` is unit and points towards the
#: light; ``shading = (ambient, 0, 0, 0)``; ``counts = (instances,
#: aberrations, portals, max_events)``; ``space_roots = (portal tree root, box tree root, portal 4-wide root,
#: box 4-wide root)``, rows of ``space_nodes``; ``lights = (rows of the lights table, 0, 0, 0)``.
SETTINGS = Record(
    "Settings",
    (
        *vectors("float4", "background", "light_dir", "event_limit_color", "shading"),
        Field("counts", "int4"),
        Field("space_roots", "int4"),
        Field("lights", "int4"),
    ),
)
SETTINGS_DTYPE = SETTINGS.dtype()


# --- real tables (float32 or float64) ----------------------------------------

#: A mesh entity placed in the scene: ``world_to_object`` rows (3x4 affine, camera-relative world to
#: object space), world-space bounds (camera-relative; ``w`` unused) and ``meta = (bvh_root, material,
#: entity, flags)`` with flags bit 0 (:data:`INSTANCE_FLAG_HAS_UVS`): the asset has UVs, bit 1
#: (:data:`INSTANCE_FLAG_SMOOTH`): shaded with interpolated vertex normals.
INSTANCE = Record(
    "Instance",
    (
        Field("world_to_object", "real4", 3, member="w2o"),
        *vectors("real4", "bounds_min", "bounds_max"),
        Field("meta", "int4"),
    ),
)

#: An aberration box: ``world_to_local`` rows map camera-relative world points into the unit box
#: [-1/2, 1/2]^3; ``rotation`` rows are the box's rotation R (``w`` of row 0: the box's clearance to
#: every instance, of row 1: its gap to every other box, engine/box_clearance.py); ``deformation.xyz``
#: is D; ``meta = (mode, exit, priority, entity)``. Rows are sorted by (priority, entity): the active
#: box at a point is the *last* row that contains it.
ABERRATION = Record(
    "Aberration",
    (
        Field("world_to_local", "real4", 3, member="w2l"),
        Field("rotation", "real4", 3, member="rot"),
        Field("deformation", "real4"),
        Field("meta", "int4"),
    ),
)

#: A portal quad: ``world_to_local`` rows map camera-relative world points into the quad's space
#: ([-1, 1]^2 at z = 0); ``transfer`` rows are ``X = M_target M_self^-1`` in camera-relative
#: coordinates (its 3x3 part is the direction map L); ``meta = (target_row, entity, gap, 0)``,
#: target_row -1 when unlinked, gap the float32 bits of a lower bound on the world distance from the quad
#: to every other quad (a leg leaving it walks the portal tree from there on: ``LEFT_PORTAL_GAP``).
PORTAL = Record(
    "Portal",
    (
        Field("world_to_local", "real4", 3, member="w2l"),
        Field("transfer", "real4", 3),
        Field("meta", "int4"),
    ),
)

#: The per-frame camera, one row: ``position.xyz`` is camera-relative (the packed origin subtracted);
#: ``right``, ``up``, ``back`` are the columns of R_cam; ``origin.xyz`` is the packed origin (for
#: world-space checkers); ``sigma_min``/``sigma_max`` are the radial mode's corner-ray bounds m_k, M_k;
#: ``lens = (tan(fov/2), aspect, clearance, 0)``, the camera's distance to every instance's bounds
#: (``box_clearance``); ``size = (width, height, camera box, 0)``, the camera box being every primary
#: ray's active box or -2 for a per-ray look-up (``camera_view.camera_box``); ``subpixel = (x, y, 0, 0)`` is
#: where in its pixel each primary ray starts (0.5, 0.5 the centre; another point for one more sample).
CAMERA = Record(
    "Camera",
    (
        *vectors("real4", "position", "right", "up", "back", "origin", "sigma_min", "sigma_max", "lens", "subpixel"),
        Field("size", "int4"),
    ),
)


#: The per-frame view tiles (:mod:`engine.view_tiles`): the portal rows and the instance rows the first leg of a
#: primary ray through each screen tile may meet, as CSR. Rows ``[0, tiles)``, one per tile in row-major order
#: (tile row 0 at the image's top): ``entry = (first portal entry, count, first instance entry, count)``; each
#: row after them holds a portal or instance row in ``entry.x`` and its box's distance from the camera
#: (float32 bits, a lower bound of any hit's t) in ``entry.y``, each tile's nearest first; the portals' rows
#: come first. With the portal legs' lists (:mod:`engine.portal_legs`, PORTAL_LEGS) the tiles' headers are
#: followed by a slot map, one row per portal row: ``(first header, x0 | x1 << 16, y0 | y1 << 16, 0)``, the
#: tile rect its first legs can cross it in, first header -1 for none; then each slot's headers, one per tile of
#: its rect in row-major order, ``(first entry, count, 0, 0)`` (count -1: the tree); their rows (instance row,
#: a lower bound of the second leg's t) come after the instances'.
VIEW_TILE = Record("ViewTile", (Field("entry", "int4"),))
VIEW_TILE_DTYPE = VIEW_TILE.dtype()


#: A light (``components.Light``): ``vector.xyz`` is a sun's unit direction towards it, or a point light's
#: camera-relative position; ``color = (rgb x intensity, range)``, range 0 for none; ``meta = (kind, shadows,
#: entity, 0)``, kind :data:`LIGHT_KINDS`. At most ``components.MAX_LIGHTS`` rows are live.
LIGHT = Record("Light", (Field("vector", "real4"), Field("color", "float4"), Field("meta", "int4")))


def instance_dtype(precision: Precision) -> np.dtype:
    """The ``instances`` row at a precision (:data:`INSTANCE`)."""
    return INSTANCE.dtype(precision)


def aberration_dtype(precision: Precision) -> np.dtype:
    """The ``aberrations`` row at a precision (:data:`ABERRATION`)."""
    return ABERRATION.dtype(precision)


def portal_dtype(precision: Precision) -> np.dtype:
    """The ``portals`` row at a precision (:data:`PORTAL`)."""
    return PORTAL.dtype(precision)


def light_dtype(precision: Precision) -> np.dtype:
    """The ``lights`` row at a precision (:data:`LIGHT`)."""
    return LIGHT.dtype(precision)


def camera_dtype(precision: Precision) -> np.dtype:
    """The ``camera`` row at a precision (:data:`CAMERA`)."""
    return CAMERA.dtype(precision)


#: Every record the kernels declare, in the order ``layout.h`` declares them.
RECORDS: tuple[Record, ...] = (
    SETTINGS,
    TRIANGLE,
    TRIANGLE_UV,
    TRIANGLE_NORMAL,
    TEXEL,
    BVH_NODE,
    BVH4_NODE,
    BVH_COMPACT_NODE,
    BVH8_NODE,
    TRIANGLE_BLOCK,
    MATERIAL,
    INSTANCE,
    ABERRATION,
    PORTAL,
    TLAS_NODE,
    SPACE_NODE,
    LIGHT,
    CAMERA,
    VIEW_TILE,
)

# Mode and exit codes shared by the packer and every kernel.
ABERRATION_MODES: dict[str, int] = {"metric": 0, "radial": 1, "additive": 2}
ABERRATION_EXITS: dict[str, int] = {"restore": 0, "repeat": 1, "invert": 2}

INSTANCE_FLAG_HAS_UVS = 1
INSTANCE_FLAG_SMOOTH = 2

#: Light kinds shared by the packer and every kernel.
LIGHT_KINDS: dict[str, int] = {"sun": 0, "point": 1}

#: Integer constants of the records that the kernels see as ``#define``\ s (``layout.h``): link and grid
#: bits of compact BVH records, box modes and exit rules, instance flags.
KERNEL_CONSTANTS: dict[str, int] = {
    "BVH_LINK_SHIFT": BVH_LINK_SHIFT,
    "BVH_LINK_MASK": (1 << BVH_LINK_SHIFT) - 1,
    "BVH_GRID_MAX": BVH_GRID_MAX,
    **{f"MODE_{name.upper()}": code for name, code in ABERRATION_MODES.items()},
    **{f"EXIT_{name.upper()}": code for name, code in ABERRATION_EXITS.items()},
    "INSTANCE_FLAG_HAS_UVS": INSTANCE_FLAG_HAS_UVS,
    **{f"LIGHT_{name.upper()}": code for name, code in LIGHT_KINDS.items()},
    "MAX_LIGHTS": MAX_LIGHTS,
    "INSTANCE_FLAG_SMOOTH": INSTANCE_FLAG_SMOOTH,
}

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
    "lights",
    "triangle_normals",
    "texels",
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
        "triangle_normals": TRIANGLE_NORMAL_DTYPE,
        "texels": TEXEL_DTYPE,
    }
    if name in fixed:
        return fixed[name]
    real = {
        "instances": instance_dtype,
        "aberrations": aberration_dtype,
        "portals": portal_dtype,
        "lights": light_dtype,
        "camera": camera_dtype,
    }
    try:
        return real[name](precision)
    except KeyError:
        raise KeyError(f"unknown table {name!r}; tables are {', '.join(TABLES)} and camera") from None
