/* bindings.glsl -- how the GLSL kernel reaches the packed tables (after layout.h).
 *
 * Two ways to hold the same bytes, picked by TABLES_IN_IMAGES:
 *
 * 0: std430 storage buffers, binding k = engine.layout.TABLES[k], the camera
 *    row at CAMERA_BINDING. The natural choice on a GPU.
 * 1: RGBA32UI images, one texel per 4-vector of a record (a record of stride
 *    S texels starts at texel i * S), TABLE_WIDTH texels per image row; image
 *    unit k + 1 = table k (unit 0 is the colour output), the camera at
 *    CAMERA_IMAGE. Mesa's llvmpipe loads storage buffers one SIMD lane at a
 *    time but images with vector gathers: about 13x faster there.
 *
 * Either way the core sees records through SETTINGS, TRIANGLE(i), ... The
 * OpenCL twin is backends/shared/bindings_cl.h.
 */

#if TABLES_IN_IMAGES

layout(rgba32ui, binding = 1) readonly restrict uniform uimage2D settings_img;
layout(rgba32ui, binding = 2) readonly restrict uniform uimage2D triangles_img;
layout(rgba32ui, binding = 3) readonly restrict uniform uimage2D triangle_uvs_img;
layout(rgba32ui, binding = 4) readonly restrict uniform uimage2D bvh_nodes_img;
layout(rgba32ui, binding = 5) readonly restrict uniform uimage2D instances_img;
layout(rgba32ui, binding = 6) readonly restrict uniform uimage2D materials_img;
layout(rgba32ui, binding = 7) readonly restrict uniform uimage2D aberrations_img;
layout(rgba32ui, binding = 8) readonly restrict uniform uimage2D portals_img;
layout(rgba32ui, binding = 9) readonly restrict uniform uimage2D tlas_nodes_img;
layout(rgba32ui, binding = 10) readonly restrict uniform uimage2D triangle_blocks_img;
layout(rgba32ui, binding = 11) readonly restrict uniform uimage2D space_nodes_img;
layout(rgba32ui, binding = CAMERA_IMAGE) readonly restrict uniform uimage2D camera_img;

#define TEXEL_(img, i) imageLoad(img, ivec2((i) & (TABLE_WIDTH - 1), (i) >> TABLE_WIDTH_LOG2))
#define F4_AT_(img, i) uintBitsToFloat(TEXEL_(img, i))
#define I4_AT_(img, i) ivec4(TEXEL_(img, i))
#if REAL_IS_DOUBLE
#define R4_TEXELS_ 2
dvec4 dvec4_from_texels_(uvec4 a, uvec4 b)
{
    return dvec4(packDouble2x32(a.xy), packDouble2x32(a.zw), packDouble2x32(b.xy), packDouble2x32(b.zw));
}
#define R4_AT_(img, i) dvec4_from_texels_(TEXEL_(img, i), TEXEL_(img, (i) + 1))
#else
#define R4_TEXELS_ 1
#define R4_AT_(img, i) uintBitsToFloat(TEXEL_(img, i))
#endif

Settings fetch_settings_()
{
    Settings s;
    s.background = F4_AT_(settings_img, 0);
    s.light_dir = F4_AT_(settings_img, 1);
    s.event_limit_color = F4_AT_(settings_img, 2);
    s.shading = F4_AT_(settings_img, 3);
    s.counts = I4_AT_(settings_img, 4);
    s.space_roots = I4_AT_(settings_img, 5);
    return s;
}

Triangle fetch_triangle_(int i)
{
    int b = i * TRIANGLES_STRIDE;
    Triangle t;
    t.v0 = F4_AT_(triangles_img, b);
    t.v1 = F4_AT_(triangles_img, b + 1);
    t.v2 = F4_AT_(triangles_img, b + 2);
    return t;
}

TriangleUv fetch_triangle_uv_(int i)
{
    int b = i * TRIANGLE_UVS_STRIDE;
    TriangleUv t;
    t.uv01 = F4_AT_(triangle_uvs_img, b);
    t.uv2 = F4_AT_(triangle_uvs_img, b + 1);
    return t;
}

#if BVH_WIDTH == 8
#error "BVH_WIDTH 8 is OpenCL only (GLSL has no 8-vectors)"
#elif BVH_WIDTH == 4
Bvh4Node fetch_bvh_node_(int i)
{
    int b = i * BVH_NODES_STRIDE;
    Bvh4Node n;
    n.lo_x = F4_AT_(bvh_nodes_img, b);
    n.lo_y = F4_AT_(bvh_nodes_img, b + 1);
    n.lo_z = F4_AT_(bvh_nodes_img, b + 2);
    n.hi_x = F4_AT_(bvh_nodes_img, b + 3);
    n.hi_y = F4_AT_(bvh_nodes_img, b + 4);
    n.hi_z = F4_AT_(bvh_nodes_img, b + 5);
    n.child = I4_AT_(bvh_nodes_img, b + 6);
    n.count = I4_AT_(bvh_nodes_img, b + 7);
    return n;
}
#elif BVH_COMPACT
BvhCompactNode fetch_bvh_node_(int i)
{
    int b = i * BVH_NODES_STRIDE;
    BvhCompactNode n;
    n.child0 = I4_AT_(bvh_nodes_img, b);
    n.child1 = I4_AT_(bvh_nodes_img, b + 1);
    return n;
}
#else
BvhNode fetch_bvh_node_(int i)
{
    int b = i * BVH_NODES_STRIDE;
    BvhNode n;
    n.lo = F4_AT_(bvh_nodes_img, b);
    n.hi = F4_AT_(bvh_nodes_img, b + 1);
    return n;
}
#endif

TriangleBlock fetch_triangle_block_(int i)
{
    int b = i * TRIANGLE_BLOCKS_STRIDE;
    TriangleBlock t;
    t.v0x = F4_AT_(triangle_blocks_img, b);
    t.v0y = F4_AT_(triangle_blocks_img, b + 1);
    t.v0z = F4_AT_(triangle_blocks_img, b + 2);
    t.v1x = F4_AT_(triangle_blocks_img, b + 3);
    t.v1y = F4_AT_(triangle_blocks_img, b + 4);
    t.v1z = F4_AT_(triangle_blocks_img, b + 5);
    t.v2x = F4_AT_(triangle_blocks_img, b + 6);
    t.v2y = F4_AT_(triangle_blocks_img, b + 7);
    t.v2z = F4_AT_(triangle_blocks_img, b + 8);
    t.index = I4_AT_(triangle_blocks_img, b + 9);
    return t;
}

Material fetch_material_(int i)
{
    int b = i * MATERIALS_STRIDE;
    Material m;
    m.color = F4_AT_(materials_img, b);
    m.flags = I4_AT_(materials_img, b + 1);
    return m;
}

Instance fetch_instance_(int i)
{
    int b = i * INSTANCES_STRIDE;
    Instance r;
    r.w2o0 = R4_AT_(instances_img, b);
    r.w2o1 = R4_AT_(instances_img, b + R4_TEXELS_);
    r.w2o2 = R4_AT_(instances_img, b + 2 * R4_TEXELS_);
    r.bounds_min = R4_AT_(instances_img, b + 3 * R4_TEXELS_);
    r.bounds_max = R4_AT_(instances_img, b + 4 * R4_TEXELS_);
    r.meta = I4_AT_(instances_img, b + 5 * R4_TEXELS_);
    return r;
}

Aberration fetch_aberration_(int i)
{
    int b = i * ABERRATIONS_STRIDE;
    Aberration r;
    r.w2l0 = R4_AT_(aberrations_img, b);
    r.w2l1 = R4_AT_(aberrations_img, b + R4_TEXELS_);
    r.w2l2 = R4_AT_(aberrations_img, b + 2 * R4_TEXELS_);
    r.rot0 = R4_AT_(aberrations_img, b + 3 * R4_TEXELS_);
    r.rot1 = R4_AT_(aberrations_img, b + 4 * R4_TEXELS_);
    r.rot2 = R4_AT_(aberrations_img, b + 5 * R4_TEXELS_);
    r.deformation = R4_AT_(aberrations_img, b + 6 * R4_TEXELS_);
    r.meta = I4_AT_(aberrations_img, b + 7 * R4_TEXELS_);
    return r;
}

Portal fetch_portal_(int i)
{
    int b = i * PORTALS_STRIDE;
    Portal r;
    r.w2l0 = R4_AT_(portals_img, b);
    r.w2l1 = R4_AT_(portals_img, b + R4_TEXELS_);
    r.w2l2 = R4_AT_(portals_img, b + 2 * R4_TEXELS_);
    r.transfer0 = R4_AT_(portals_img, b + 3 * R4_TEXELS_);
    r.transfer1 = R4_AT_(portals_img, b + 4 * R4_TEXELS_);
    r.transfer2 = R4_AT_(portals_img, b + 5 * R4_TEXELS_);
    r.meta = I4_AT_(portals_img, b + 6 * R4_TEXELS_);
    return r;
}

TlasNode fetch_tlas_node_(int i)
{
    int b = i * TLAS_NODES_STRIDE;
    TlasNode n;
    n.lo = F4_AT_(tlas_nodes_img, b);
    n.hi = F4_AT_(tlas_nodes_img, b + 1);
    return n;
}

SpaceNode fetch_space_node_(int i)
{
    int b = i * SPACE_NODES_STRIDE;
    SpaceNode n;
    n.lo = F4_AT_(space_nodes_img, b);
    n.hi = F4_AT_(space_nodes_img, b + 1);
    return n;
}

Camera fetch_camera_()
{
    Camera c;
    c.position = R4_AT_(camera_img, 0);
    c.right = R4_AT_(camera_img, R4_TEXELS_);
    c.up = R4_AT_(camera_img, 2 * R4_TEXELS_);
    c.back = R4_AT_(camera_img, 3 * R4_TEXELS_);
    c.origin = R4_AT_(camera_img, 4 * R4_TEXELS_);
    c.sigma_min = R4_AT_(camera_img, 5 * R4_TEXELS_);
    c.sigma_max = R4_AT_(camera_img, 6 * R4_TEXELS_);
    c.lens = R4_AT_(camera_img, 7 * R4_TEXELS_);
    c.size = I4_AT_(camera_img, 8 * R4_TEXELS_);
    return c;
}

/* Table access: a record (fetched whole; the compiler drops the loads of unused fields). */
#define SETTINGS (fetch_settings_())
#define TRIANGLE(i) (fetch_triangle_(i))
#define TRIANGLE_UV(i) (fetch_triangle_uv_(i))
#define BVH_NODE(i) (fetch_bvh_node_(i))
#define INSTANCE(i) (fetch_instance_(i))
#define MATERIAL(i) (fetch_material_(i))
#define ABERRATION(i) (fetch_aberration_(i))
#define PORTAL(i) (fetch_portal_(i))
#define TLAS_NODE(i) (fetch_tlas_node_(i))
#define TRIANGLE_BLOCK(i) (fetch_triangle_block_(i))
#define SPACE_NODE(i) (fetch_space_node_(i))
#define CAMERA_ROW (fetch_camera_())

#else /* storage buffers */

layout(std430, binding = 0) readonly restrict buffer SettingsTable { Settings settings_data[]; };
layout(std430, binding = 1) readonly restrict buffer TriangleTable { Triangle triangles_data[]; };
layout(std430, binding = 2) readonly restrict buffer TriangleUvTable { TriangleUv triangle_uvs_data[]; };
layout(std430, binding = 3) readonly restrict buffer BvhNodeTable { BvhRow bvh_nodes_data[]; };
layout(std430, binding = 4) readonly restrict buffer InstanceTable { Instance instances_data[]; };
layout(std430, binding = 5) readonly restrict buffer MaterialTable { Material materials_data[]; };
layout(std430, binding = 6) readonly restrict buffer AberrationTable { Aberration aberrations_data[]; };
layout(std430, binding = 7) readonly restrict buffer PortalTable { Portal portals_data[]; };
layout(std430, binding = 8) readonly restrict buffer TlasNodeTable { TlasNode tlas_nodes_data[]; };
layout(std430, binding = 9) readonly restrict buffer TriangleBlockTable { TriangleBlock triangle_blocks_data[]; };
layout(std430, binding = 10) readonly restrict buffer SpaceNodeTable { SpaceNode space_nodes_data[]; };
layout(std430, binding = CAMERA_BINDING) readonly restrict buffer CameraTable { Camera camera_data[]; };

/* Table access: a record (an lvalue, so .field reads only that field). */
#define SETTINGS (settings_data[0])
#define TRIANGLE(i) (triangles_data[(i)])
#define TRIANGLE_UV(i) (triangle_uvs_data[(i)])
#define BVH_NODE(i) (bvh_nodes_data[(i)])
#define INSTANCE(i) (instances_data[(i)])
#define MATERIAL(i) (materials_data[(i)])
#define ABERRATION(i) (aberrations_data[(i)])
#define PORTAL(i) (portals_data[(i)])
#define TLAS_NODE(i) (tlas_nodes_data[(i)])
#define TRIANGLE_BLOCK(i) (triangle_blocks_data[(i)])
#define SPACE_NODE(i) (space_nodes_data[(i)])
#define CAMERA_ROW (camera_data[0])

#endif
