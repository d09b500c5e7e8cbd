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
layout(rgba32ui, binding = 12) readonly restrict uniform uimage2D lights_img;
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

/* Each record from its texels (layout.h's <struct>_from_texels, written from engine.layout). */
Settings fetch_settings_() { return Settings_from_texels(settings_img, 0); }
Triangle fetch_triangle_(int i) { return Triangle_from_texels(triangles_img, i * TRIANGLES_STRIDE); }
TriangleUv fetch_triangle_uv_(int i) { return TriangleUv_from_texels(triangle_uvs_img, i * TRIANGLE_UVS_STRIDE); }
#if BVH_WIDTH == 8
#error "BVH_WIDTH 8 is OpenCL only (GLSL has no 8-vectors)"
#endif
BvhRow fetch_bvh_node_(int i) { return BvhRow_from_texels(bvh_nodes_img, i * BVH_NODES_STRIDE); }
TriangleBlock fetch_triangle_block_(int i)
{
    return TriangleBlock_from_texels(triangle_blocks_img, i * TRIANGLE_BLOCKS_STRIDE);
}
Material fetch_material_(int i) { return Material_from_texels(materials_img, i * MATERIALS_STRIDE); }
Instance fetch_instance_(int i) { return Instance_from_texels(instances_img, i * INSTANCES_STRIDE); }
Aberration fetch_aberration_(int i) { return Aberration_from_texels(aberrations_img, i * ABERRATIONS_STRIDE); }
Portal fetch_portal_(int i) { return Portal_from_texels(portals_img, i * PORTALS_STRIDE); }
TlasRow fetch_tlas_node_(int i) { return TlasRow_from_texels(tlas_nodes_img, i * TLAS_NODES_STRIDE); }
SpaceNode fetch_space_node_(int i) { return SpaceNode_from_texels(space_nodes_img, i * SPACE_NODES_STRIDE); }
Light fetch_light_(int i) { return Light_from_texels(lights_img, i * LIGHTS_STRIDE); }
Camera fetch_camera_() { return Camera_from_texels(camera_img, 0); }

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
#define LIGHT(i) (fetch_light_(i))
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
layout(std430, binding = 8) readonly restrict buffer TlasNodeTable { TlasRow tlas_nodes_data[]; };
/* A compute shader may have 16 storage blocks (llvmpipe, and most GPUs): the tables a variant never reads are
 * left out, so the 12 tables, the camera and 4 AOV outputs fit where they are needed. */
#if BVH_WIDTH >= 4
layout(std430, binding = 9) readonly restrict buffer TriangleBlockTable { TriangleBlock triangle_blocks_data[]; };
#endif
#if PORTAL_TREE || BOX_TREE
layout(std430, binding = 10) readonly restrict buffer SpaceNodeTable { SpaceNode space_nodes_data[]; };
#endif
#if HAS_LIGHTS
layout(std430, binding = 11) readonly restrict buffer LightTable { Light lights_data[]; };
#endif
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
#define LIGHT(i) (lights_data[(i)])
#define CAMERA_ROW (camera_data[0])

#endif

/* The per-frame view tiles (engine/view_tiles.py), in an image under either store: with storage buffers the
 * 16 storage blocks are taken (see below); the backend asks for them only with images. */
#if VIEW_TILES || INSTANCE_TILES
layout(rgba32ui, binding = VIEW_TILES_IMAGE) readonly restrict uniform uimage2D view_tiles_img;
#if TABLES_IN_IMAGES
#define VIEW_TILE(i) (ViewTile_from_texels(view_tiles_img, (i)))
#else
#error "VIEW_TILES reads the tiles through layout.h's image readers (TABLES_IN_IMAGES)"
#endif
#endif

/* One box: its record is read once per invocation (main.comp, HELD_BOX_), not at every face search and
 * transition (ten-boxes-aberration: -4.5 % of a frame's CPU time; one portal pair held likewise gains nothing). */
#if BOX_COUNT == 1
Aberration aberration_0_;
#undef ABERRATION
#define ABERRATION(i) (aberration_0_)
#if TABLES_IN_IMAGES
#define HELD_BOX_ aberration_0_ = fetch_aberration_(0);
#else
#define HELD_BOX_ aberration_0_ = aberrations_data[0];
#endif
#else
#define HELD_BOX_
#endif

/* Vertex normals and texels live in RGBA32UI images under either store (image unit = table index + 1): with
 * storage buffers, the other tables, the camera and the AOVs already take the 16 storage blocks a compute
 * shader may have (GL_MAX_COMPUTE_SHADER_STORAGE_BLOCKS on Mesa and NVIDIA). */
#define SHADING_F4_(img, i) uintBitsToFloat(imageLoad(img, ivec2((i) & (TABLE_WIDTH - 1), (i) >> TABLE_WIDTH_LOG2)))
#if HAS_SMOOTH
layout(rgba32ui, binding = 13) readonly restrict uniform uimage2D triangle_normals_img;
TriangleNormal fetch_triangle_normal_(int i)
{
    int b = i * TRIANGLE_NORMALS_STRIDE;
    return TriangleNormal(SHADING_F4_(triangle_normals_img, b), SHADING_F4_(triangle_normals_img, b + 1),
                          SHADING_F4_(triangle_normals_img, b + 2));
}
#define TRIANGLE_NORMAL(i) (fetch_triangle_normal_(i))
#endif
#if HAS_TEXTURES
layout(rgba32ui, binding = 14) readonly restrict uniform uimage2D texels_img;
#define TEXEL(i) (Texel(SHADING_F4_(texels_img, (i) * TEXELS_STRIDE)))
#endif

#if SPLIT_PASS == 2
/* The second pass's ray: the kind of the event its first leg ended on in the first pass (journey.h), -1 for
 * none; main.comp sets it from the queue. */
int resume_kind_ = -1;
#define RESUME_KIND resume_kind_
#endif
