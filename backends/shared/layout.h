/* layout.h -- the packed scene records of engine/layout.py, shared by GLSL and OpenCL C.
 *
 * Every record is built from 4-component vectors only, the subset on which
 * std430 and OpenCL C agree: a record's size is a multiple of its widest
 * vector (16 bytes, or 32 with REAL_IS_DOUBLE), with no hidden padding.
 * tests/backends/test_glsl.py checks these sizes against the NumPy dtypes.
 *
 * Types (from the prelude): float4 / int4 are always 32-bit; real4 is float4
 * or, with REAL_IS_DOUBLE, a 4-vector of doubles. STRUCT_BEGIN/STRUCT_END
 * declare a struct usable by its bare name in both languages.
 */

/* settings: one row. shading = (ambient, 0, 0, 0);
 * counts = (instances, aberrations, portals, max_events);
 * space_roots = (portal tree root, box tree root, 0, 0), rows of space_nodes. */
STRUCT_BEGIN(Settings)
    float4 background;
    float4 light_dir;
    float4 event_limit_color;
    float4 shading;
    int4 counts;
    int4 space_roots;
STRUCT_END(Settings)

/* triangles: object-space vertices of every mesh asset (w unused). */
STRUCT_BEGIN(Triangle)
    float4 v0;
    float4 v1;
    float4 v2;
STRUCT_END(Triangle)

/* triangle_uvs: uv01 = (u0, v0, u1, v1), uv2 = (u2, v2, 0, 0). */
STRUCT_BEGIN(TriangleUv)
    float4 uv01;
    float4 uv2;
STRUCT_END(TriangleUv)

/* bvh_nodes: lo.xyz / hi.xyz bounds (rounded outward); AS_INT(lo.w) = first,
 * AS_INT(hi.w) = count. count > 0: a leaf over triangles [first, first + count);
 * count == 0: an interior node whose children are first and first + 1. */
STRUCT_BEGIN(BvhNode)
    float4 lo;
    float4 hi;
STRUCT_END(BvhNode)

/* bvh_nodes with BVH_WIDTH 4: a wide node, its four children's boxes SoA (lane i = child i).
 * count[i] > 0: a leaf of count[i] triangles in (count[i] + 3) / 4 triangle_blocks rows from
 * child[i]; count[i] == 0: the wide node child[i]; count[i] < 0: an empty slot. */
STRUCT_BEGIN(Bvh4Node)
    float4 lo_x;
    float4 lo_y;
    float4 lo_z;
    float4 hi_x;
    float4 hi_y;
    float4 hi_z;
    int4 child;
    int4 count;
STRUCT_END(Bvh4Node)

/* bvh_nodes with BVH_COMPACT: an interior node as both children's boxes, 16-bit grid coordinates
 * over the asset's frame in child{i}.xyz (lo.x | lo.y << 16, lo.z | hi.x << 16, hi.y | hi.z << 16),
 * decoded origin + q * scale; child{i}.w a link (index << BVH_LINK_SHIFT | count): count > 0, a leaf
 * of triangles [index, index + count); count == 0, the record index. An asset's first record is a
 * header: child0 = (origin bits, root link), child1 = (scale bits, -1). */
STRUCT_BEGIN(BvhCompactNode)
    int4 child0;
    int4 child1;
STRUCT_END(BvhCompactNode)
#define BVH_LINK_SHIFT 7
#define BVH_LINK_MASK 127
#define BVH_GRID_MAX 65535

/* The record of the bvh_nodes table: BVH_WIDTH (2, 4, or 8 in OpenCL only) is the packer's bvh_width, BVH_COMPACT its
 * bvh_compact. */
#ifndef BVH_WIDTH
#define BVH_WIDTH 2
#endif
#ifndef BVH_COMPACT
#define BVH_COMPACT 0
#endif
#if BVH_WIDTH == 8
/* bvh_nodes with BVH_WIDTH 8 (OpenCL C only: GLSL has no 8-vectors, its host refuses the width):
 * Bvh4Node with eight lanes (an AVX2 register of floats per bound component). */
STRUCT_BEGIN(Bvh8Node)
    float8 lo_x;
    float8 lo_y;
    float8 lo_z;
    float8 hi_x;
    float8 hi_y;
    float8 hi_z;
    int8 child;
    int8 count;
STRUCT_END(Bvh8Node)
#define BvhRow Bvh8Node
#elif BVH_WIDTH == 4
#define BvhRow Bvh4Node
#elif BVH_COMPACT
#define BvhRow BvhCompactNode
#else
#define BvhRow BvhNode
#endif

/* triangle_blocks (BVH_WIDTH 4 and 8): four triangles of a leaf SoA, lane i = triangle i; index = their
 * rows in triangles (-1: a padding lane). */
STRUCT_BEGIN(TriangleBlock)
    float4 v0x;
    float4 v0y;
    float4 v0z;
    float4 v1x;
    float4 v1y;
    float4 v1z;
    float4 v2x;
    float4 v2y;
    float4 v2z;
    int4 index;
STRUCT_END(TriangleBlock)

/* materials: color = (r, g, b, checker cell size, 0 = none); flags.x = cull back faces. */
STRUCT_BEGIN(Material)
    float4 color;
    int4 flags;
STRUCT_END(Material)

/* instances: world_to_object rows (camera-relative world -> object space),
 * world bounds (camera-relative), meta = (bvh root, material row, entity, flags);
 * flags bit 0: the asset has UVs. */
STRUCT_BEGIN(Instance)
    real4 w2o0;
    real4 w2o1;
    real4 w2o2;
    real4 bounds_min;
    real4 bounds_max;
    int4 meta;
STRUCT_END(Instance)

/* aberrations: world_to_local rows (into the unit box [-1/2, 1/2]^3), rotation
 * rows R (rot0.w: clearance to every instance, rot1.w: gap to every other box, world
 * lower bounds from engine/box_clearance.py), deformation.xyz = D, meta = (mode, exit,
 * priority, entity). */
STRUCT_BEGIN(Aberration)
    real4 w2l0;
    real4 w2l1;
    real4 w2l2;
    real4 rot0;
    real4 rot1;
    real4 rot2;
    real4 deformation;
    int4 meta;
STRUCT_END(Aberration)

/* portals: world_to_local rows (quad [-1, 1]^2 at z = 0), transfer rows X,
 * meta = (target row or -1, entity, 0, 0). */
STRUCT_BEGIN(Portal)
    real4 w2l0;
    real4 w2l1;
    real4 w2l2;
    real4 transfer0;
    real4 transfer1;
    real4 transfer2;
    int4 meta;
STRUCT_END(Portal)

/* tlas_nodes: the top-level tree over instances (engine/tlas.py), the BvhNode's layout:
 * AS_INT(hi.w) = count; count == 1: a leaf over instance row AS_INT(lo.w); count == 0: an
 * interior node whose children are AS_INT(lo.w) and AS_INT(lo.w) + 1. Root at row 0. */
STRUCT_BEGIN(TlasNode)
    float4 lo;
    float4 hi;
STRUCT_END(TlasNode)

/* space_nodes: the trees over portal quads and aberration boxes (engine/packing_space.py), the
 * TlasNode's layout: AS_INT(hi.w) = count; count == 1: a leaf over portal or aberration row
 * AS_INT(lo.w); count == 0: an interior node whose children are AS_INT(lo.w) and AS_INT(lo.w) + 1.
 * The portals' tree from row space_roots.x, the boxes' from space_roots.y (settings). */
STRUCT_BEGIN(SpaceNode)
    float4 lo;
    float4 hi;
STRUCT_END(SpaceNode)

/* camera: one row per frame. position is camera-relative; right/up/back are the
 * columns of R_cam; origin is the packed origin (for world-space checkers);
 * lens = (tan(fov/2), aspect, clearance to every instance's bounds or 0, 0); size = (width, height, camera box, 0): the camera box is every
 * primary ray's active box, or -2 where each ray looks it up (engine.camera_view.camera_box). */
STRUCT_BEGIN(Camera)
    real4 position;
    real4 right;
    real4 up;
    real4 back;
    real4 origin;
    real4 sigma_min;
    real4 sigma_max;
    real4 lens;
    int4 size;
STRUCT_END(Camera)
