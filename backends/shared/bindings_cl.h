/* bindings_cl.h -- how the OpenCL kernel reaches the packed tables (after layout.h).
 *
 * The GLSL twin is backends/glsl/bindings.glsl (global storage buffers). Here
 * the tables are __global pointers gathered in a private struct that every
 * core function takes as its first parameter through SCENE_DECL / SCENE_PASS
 * (both empty in GLSL). A kernel builds it once and hands trace_pixel its address (PIXEL_SCENE_DECL):
 *
 *     SceneTables sc;
 *     sc.settings = settings; sc.triangles = triangles; ...
 *     Pixel px = trace_pixel(&sc, camera[0], i, j);
 */

typedef struct SceneTables {
    __global const Settings* settings;
    __global const Triangle* triangles;
    __global const TriangleUv* triangle_uvs;
    __global const BvhRow* bvh_nodes;
    __global const Instance* instances;
    __global const Material* materials;
    __global const Aberration* aberrations;
    __global const Portal* portals;
    __global const TlasRow* tlas_nodes;
    __global const TriangleBlock* triangle_blocks;
    __global const SpaceNode* space_nodes;
    __global const Light* lights;
    __global const TriangleNormal* triangle_normals;
    __global const Texel* texels;
    __global const ViewTile* view_tiles; /* per frame, beside the camera row */
} SceneTables;

#define SCENE_DECL SceneTables sc,
#define SCENE_PASS sc,
/* trace_pixel takes the tables by address and copies them in (PIXEL_SCENE_OPEN): PoCL keeps the kernel's
 * struct per work-item in stack memory written 8 bytes at a time, and a by-value call reloaded it 32 bytes
 * at a time, each load stalled on the stores it could not forward from (2-4 % of a Euclidean frame). */
#define PIXEL_SCENE_DECL const SceneTables* tables,
#define PIXEL_SCENE_OPEN SceneTables sc = *tables;

/* Table access: a record (an lvalue, so .field reads only that field). */
#define SETTINGS (sc.settings[0])
#define TRIANGLE(i) (sc.triangles[(i)])
#define TRIANGLE_UV(i) (sc.triangle_uvs[(i)])
#define BVH_NODE(i) (sc.bvh_nodes[(i)])
#define INSTANCE(i) (sc.instances[(i)])
#define MATERIAL(i) (sc.materials[(i)])
#define ABERRATION(i) (sc.aberrations[(i)])
#define PORTAL(i) (sc.portals[(i)])
#define TLAS_NODE(i) (sc.tlas_nodes[(i)])
#define TRIANGLE_BLOCK(i) (sc.triangle_blocks[(i)])
#define SPACE_NODE(i) (sc.space_nodes[(i)])
#define LIGHT(i) (sc.lights[(i)])
#define TRIANGLE_NORMAL(i) (sc.triangle_normals[(i)])
#define TEXEL(i) (sc.texels[(i)])
#define VIEW_TILE(i) (sc.view_tiles[(i)])
