/* main.comp -- the GLSL compute entry point (after prelude, layout.h, bindings.glsl and the shared
 * tracer files, options.h to pixel.h).
 *
 * One invocation per pixel. The colour goes to an rgba8 image (the
 * editor draws it without a read-back; texel row 0 is the image's top row);
 * the other AOVs go to storage buffers, each compiled in only when requested.
 */

layout(local_size_x = WORKGROUP_X, local_size_y = WORKGROUP_Y, local_size_z = 1) in;

layout(rgba8, binding = 0) writeonly restrict uniform image2D color_image;
#if WRITE_DEPTH
layout(std430, binding = DEPTH_BINDING) writeonly restrict buffer DepthOut { float depth_out[]; };
#endif
#if WRITE_PERCEIVED
layout(std430, binding = PERCEIVED_BINDING) writeonly restrict buffer PerceivedOut { float perceived_out[]; };
#endif
#if WRITE_INSTANCE
layout(std430, binding = INSTANCE_BINDING) writeonly restrict buffer InstanceOut { int instance_out[]; };
#endif
#if WRITE_EVENTS
layout(std430, binding = EVENTS_BINDING) writeonly restrict buffer EventsOut { uint events_out[]; };
#endif

#if SPLIT_PASS
/* The rays the first pass leaves to the second: a count, then one entry per ray, its pixel's index times 8
 * plus its first leg's event kind + 1 (0: none). */
layout(std430, binding = QUEUE_BINDING) restrict buffer Deferred { uint deferred_count; uint deferred_pad[3]; int deferred[]; };
#endif

/* The pixel's AOVs, those the variant writes. */
void write_pixel(ivec2 p, int index, Pixel px)
{
#if SHADE
    /* Exact: the unorm8 conversion of q / 255 rounds back to the integer q. A frame of other AOVs without
     * the colour (SHADE 0) leaves the image as it was. */
    imageStore(color_image, p, px.color * (1.0 / 255.0));
#endif
#if WRITE_DEPTH
    depth_out[index] = px.depth;
#endif
#if WRITE_PERCEIVED
    perceived_out[index] = px.perceived;
#endif
#if WRITE_INSTANCE
    instance_out[index] = px.instance;
#endif
#if WRITE_EVENTS
    events_out[index] = uint(min(px.events, 255));
#endif
}

void main()
{
    Camera cam = CAMERA_ROW;
    HELD_BOX_
#if SPLIT_PASS == 2
    /* One invocation per queued ray, in the first pass's order (its work-groups' invocations, 8 at a time,
     * queue neighbouring pixels; gathering each group's into consecutive entries behind barriers cost more:
     * 1.04-1.07x the time of this). */
    uint k = gl_WorkGroupID.x * uint(WORKGROUP_X * WORKGROUP_Y) + gl_LocalInvocationIndex;
    if (k >= deferred_count) {
        return;
    }
    int entry = deferred[k];
    int index = entry >> 3;
    resume_kind_ = (entry & 7) - 1;
    ivec2 p = ivec2(index % cam.size.x, index / cam.size.x);
    write_pixel(p, index, trace_pixel(cam, p.x, p.y));
#else
#if LANE_BLOCK_X == WORKGROUP_X && LANE_BLOCK_Y == 1
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
#else
    /* Each run of LANE_BLOCK_X * LANE_BLOCK_Y consecutive invocations (one 8-lane SIMD vector on
     * llvmpipe) takes a LANE_BLOCK_X x LANE_BLOCK_Y block of pixels instead of a row: rays of a
     * squarer block diverge less in traversal (4x2: about 3 % faster on mesh-10k / mesh-200k).
     * A bijection on the work-group's tile, so every pixel is still traced exactly once. */
    const uint block_size = uint(LANE_BLOCK_X * LANE_BLOCK_Y);
    const uint blocks_per_row = uint(WORKGROUP_X / LANE_BLOCK_X);
    uint lane = gl_LocalInvocationIndex % block_size;
    uint block = gl_LocalInvocationIndex / block_size;
    uvec2 local = uvec2((block % blocks_per_row) * uint(LANE_BLOCK_X) + lane % uint(LANE_BLOCK_X),
                        (block / blocks_per_row) * uint(LANE_BLOCK_Y) + lane / uint(LANE_BLOCK_X));
    ivec2 p = ivec2(gl_WorkGroupID.xy * uvec2(WORKGROUP_X, WORKGROUP_Y) + local);
#endif
    if (p.x >= cam.size.x || p.y >= cam.size.y) {
        return;
    }
    int index = p.y * cam.size.x + p.x;
    Pixel px = trace_pixel(cam, p.x, p.y);
#if SPLIT_PASS == 1
    if (px.deferred != -2) {
        deferred[atomicAdd(deferred_count, 1u)] = index * 8 + px.deferred + 1;
        return;
    }
#endif
    write_pixel(p, index, px);
#endif
}
