/* trace.cl -- the OpenCL entry point (after defines, prelude_cl.h, layout.h, bindings_cl.h and the
 * tracer files, options.h to pixel.h).
 *
 * One work-item per pixel (with PACKET_PRIMARY, per 4x2 block: packet.cl), row 0 = the image's top row. The scene tables come
 * in the order of engine.layout.TABLES, then the camera row, the view tiles and the tile order, then one buffer
 * per AOV. An AOV the caller did not ask for is passed as a NULL buffer and
 * skipped by a uniform branch, so one program serves every AOV set with the
 * colour (a PoCL build costs seconds; a never-taken branch costs nothing), and
 * one without it every set that skips the shading (SHADE 0).
 */

/* A pixel's AOVs into the buffers the frame asked for (a NULL buffer: not asked). */
inline void write_pixel(Pixel px, int index, __global uchar4* color_out, __global float* depth_out,
                        __global float* perceived_out, __global int* instance_out, __global uchar* events_out)
{
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
                    __global const int* tile_order,
                    __global uchar4* color_out,
                    __global float* depth_out,
                    __global float* perceived_out,
                    __global int* instance_out,
                    __global uchar* events_out)
{
    Camera cam = camera[0];
#if TILE_ORDER
    /* The work-item's tile from the frame's list, its pixel (or block) within it from the first id. */
    int tile = tile_order[get_global_id(1)];
    if (tile < 0) {
        return; /* the list's padding to whole work-groups */
    }
    int tiles_x = (cam.size.x + (1 << VIEW_TILE_LOG2) - 1) >> VIEW_TILE_LOG2;
    int item = (int)get_global_id(0);
#if PACKET_PRIMARY
    int blocks_x = (1 << VIEW_TILE_LOG2) / PACKET_W;
    int i = (tile % tiles_x) * blocks_x + item % blocks_x;
    int j = (tile / tiles_x) * ((1 << VIEW_TILE_LOG2) / PACKET_H) + item / blocks_x;
#else
    int i = ((tile % tiles_x) << VIEW_TILE_LOG2) + (item & ((1 << VIEW_TILE_LOG2) - 1));
    int j = ((tile / tiles_x) << VIEW_TILE_LOG2) + (item >> VIEW_TILE_LOG2);
#endif
#else
    int i = (int)get_global_id(0);
    int j = (int)get_global_id(1);
#endif
#if PACKET_PRIMARY
    if (i * PACKET_W >= cam.size.x || j * PACKET_H >= cam.size.y) {
        return;
    }
#else
    if (i >= cam.size.x || j >= cam.size.y) {
        return;
    }
#endif
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
#if PACKET_PRIMARY
    /* A 4x2 block of pixels (packet.cl), all in one view tile. */
    int i0 = i * PACKET_W;
    int j0 = j * PACKET_H;
#if INSTANCE_TILES_ONLY
    int4 list = view_tiles[view_tile_of(cam, i0, j0)].entry;
    int first = list.z;
    int count = list.w;
#else
    int first = 0;
    int count = settings[0].counts.x;
#endif
    float dx[8], dy[8], dz[8], t_min[8];
    int live[8];
    float3 o = cam.position.xyz;
    for (int k = 0; k < 8; ++k) {
        /* The rays as journey() starts them; a lane off the image or whose search cannot find anything
         * (meshes_reachable) takes no part. */
        Ray ray = primary_ray(cam, min(i0 + k % PACKET_W, cam.size.x - 1), min(j0 + k / PACKET_W, cam.size.y - 1));
        dx[k] = ray.r.x;
        dy[k] = ray.r.y;
        dz[k] = ray.r.z;
        t_min[k] = ray.t_from + T_MIN_RELATIVE * max(REAL(1.0f), ray.o_len + ray.t_from);
        live[k] = (i0 + k % PACKET_W < cam.size.x && j0 + k / PACKET_W < cam.size.y &&
                   meshes_reachable(sc, ray.r)) ? -1 : 0;
    }
    PacketHit hits = packet_mesh(sc, o, dx, dy, dz, vload8(0, t_min), vload8(0, live), first, count);
    float ht[8], hu[8], hv[8], hw[8];
    int hi[8], htri[8];
    vstore8(hits.t, 0, ht);
    vstore8(hits.u, 0, hu);
    vstore8(hits.v, 0, hv);
    vstore8(hits.w, 0, hw);
    vstore8(hits.instance, 0, hi);
    vstore8(hits.triangle, 0, htri);
    Pixel sky = pixel_start(sc, cam); /* the same for every pixel */
    for (int k = 0; k < 8; ++k) {
        int pi = i0 + k % PACKET_W;
        int pj = j0 + k / PACKET_W;
        if (pi < cam.size.x && pj < cam.size.y) {
            /* What journey() returns for the lane's ray: its primary ray and the nearest hit (none: the sky). */
            Journey end;
            end.ray = start_ray(o, R3(dx[k], dy[k], dz[k])); /* primary_ray's, as journey() starts it */
            end.hit.t = ht[k];
            end.hit.bary = R3(hu[k], hv[k], hw[k]);
            end.hit.instance = hi[k];
            end.hit.triangle = htri[k];
            end.end = hi[k] >= 0 ? END_MESH : END_MISS;
            Pixel px = pixel_end(sc, cam, sky, end);
            write_pixel(px, pj * cam.size.x + pi, color_out, depth_out, perceived_out, instance_out, events_out);
        }
    }
#else
    Pixel px = trace_pixel(&sc, cam, i, j);
    write_pixel(px, j * cam.size.x + i, color_out, depth_out, perceived_out, instance_out, events_out);
#endif
}
