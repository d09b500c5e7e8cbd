/* trace.cl -- the OpenCL entry point (after defines, prelude_cl.h, layout.h, bindings_cl.h and the
 * tracer files, options.h to pixel.h).
 *
 * One work-item per pixel, row 0 = the image's top row. The scene tables come
 * in the order of engine.layout.TABLES, then the camera row and the view tiles, then one buffer
 * per AOV. An AOV the caller did not ask for is passed as a NULL buffer and
 * skipped by a uniform branch, so one program serves every AOV set with the
 * colour (a PoCL build costs seconds; a never-taken branch costs nothing), and
 * one without it every set that skips the shading (SHADE 0).
 */

__kernel void trace(__global const Settings* settings,
                    __global const Triangle* triangles,
                    __global const TriangleUv* triangle_uvs,
                    __global const BvhRow* bvh_nodes,
                    __global const Instance* instances,
                    __global const Material* materials,
                    __global const Aberration* aberrations,
                    __global const Portal* portals,
                    __global const TlasRow* tlas_nodes,
                    __global const TriangleBlock* triangle_blocks,
                    __global const SpaceNode* space_nodes,
                    __global const Light* lights,
                    __global const TriangleNormal* triangle_normals,
                    __global const Texel* texels,
                    __global const Camera* camera,
                    __global const ViewTile* view_tiles,
                    __global uchar4* color_out,
                    __global float* depth_out,
                    __global float* perceived_out,
                    __global int* instance_out,
                    __global uchar* events_out)
{
    int i = (int)get_global_id(0);
    int j = (int)get_global_id(1);
    Camera cam = camera[0];
    if (i >= cam.size.x || j >= cam.size.y) {
        return;
    }
    SceneTables sc;
    sc.settings = settings;
    sc.triangles = triangles;
    sc.triangle_uvs = triangle_uvs;
    sc.bvh_nodes = bvh_nodes;
    sc.instances = instances;
    sc.materials = materials;
    sc.aberrations = aberrations;
    sc.portals = portals;
    sc.tlas_nodes = tlas_nodes;
    sc.triangle_blocks = triangle_blocks;
    sc.space_nodes = space_nodes;
    sc.lights = lights;
    sc.triangle_normals = triangle_normals;
    sc.texels = texels;
    sc.view_tiles = view_tiles;
    Pixel px = trace_pixel(&sc, cam, i, j);
    int index = j * cam.size.x + i;
    if (color_out != 0) {
        color_out[index] = convert_uchar4(px.color); /* already integral 0..255 */
    }
    if (depth_out != 0) {
        depth_out[index] = px.depth;
    }
    if (perceived_out != 0) {
        perceived_out[index] = px.perceived;
    }
    if (instance_out != 0) {
        instance_out[index] = px.instance;
    }
    if (events_out != 0) {
        events_out[index] = (uchar)min(px.events, 255);
    }
}
