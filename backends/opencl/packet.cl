/* packet.cl -- camera rays eight at a time (PACKET_PRIMARY; after pixel.h, before trace.cl).
 *
 * A work-item traces a 4x2 block of pixels, one ray per float8 lane: the block's view tile lists the
 * instances its rays can meet, and each listed instance's 8-wide tree is walked once for all eight rays, a
 * child entered while any ray enters it (the rays that do, as a lane mask, go down with it). PoCL runs a
 * work-item's code as scalar instructions on explicit vectors: one ray a work-item tests eight boxes per
 * node visit as a float8, a block tests each box against eight rays, and the neighbouring rays of a block
 * share nearly every node and leaf, so a node load and its bookkeeping serve eight rays.
 *
 * Each ray's numbers are the single ray's: its set-up is the scalar code per lane (primary_ray, the
 * instance transform, shear_ray, safe_inverse), and every slab and triangle test is the same operations
 * lane by lane (FP_CONTRACT is off, so a vector operation rounds as the scalar one). Only the order of
 * the visits differs, which the tie rule (keep_nearer: the least t, then instance row, then triangle)
 * leaves unseen, as it does between two single rays' walks: a ray tests a box or a triangle only where its
 * own slab test lets it, and the culling is the single walk's (ENTRY_LIMIT). So the frames are the ones
 * per pixel to the bit.
 *
 * The frames that qualify (the host's PACKET_PRIMARY, backends/opencl/packets.py): float, Euclidean,
 * without shadows, over 8-wide trees of 4-triangle blocks, with every mesh search a camera ray's first leg
 * with its tile's list (INSTANCE_TILES_ONLY) or a scene of one instance (USE_TLAS 0). */

#if PACKET_PRIMARY
#if REAL_IS_DOUBLE || BVH_WIDTH != 8 || HAS_SPACE || HAS_SHADOWS || EDGE_FALLBACK_FP64 || BRUTE_FORCE || \
    !(INSTANCE_TILES_ONLY ? VIEW_TILE_LOG2 >= 2 : !INSTANCE_TILES && !USE_TLAS)
#error "PACKET_PRIMARY: float Euclidean frames without shadows over 8-wide trees, instances from the tiles' lists or one"
#endif

/* The pixels of a work-item: PACKET_W x PACKET_H, lane k at (k % PACKET_W, k / PACKET_W); inside one view tile. */
#define PACKET_W 4
#define PACKET_H 2

/* Eight rays' nearest hits: MeshHit's fields, lane k = ray k. */
STRUCT_BEGIN(PacketHit)
    float8 t;
    float8 u;
    float8 v;
    float8 w;
    int8 instance;
    int8 triangle;
STRUCT_END(PacketHit)

/* Eight rays in an instance's object space: the origin, safe_inverse of the direction, and ShearedRay's
 * fields (p: the origin's components in the ray's kx, ky, kz order). */
STRUCT_BEGIN(PacketRay)
    float8 ox;
    float8 oy;
    float8 oz;
    float8 ix;
    float8 iy;
    float8 iz;
    float8 px;
    float8 py;
    float8 pz;
    float8 sx;
    float8 sy;
    float8 sz;
    int8 kx;
    int8 ky;
    int8 kz;
STRUCT_END(PacketRay)

/* A lane mask (-1 / 0 per lane) as bits, and back. */
#define PACKET_BITS ((int8)(1, 2, 4, 8, 16, 32, 64, 128))
inline int lane_bits(int8 mask)
{
    int8 b = mask & PACKET_BITS;
    return b.s0 | b.s1 | b.s2 | b.s3 | b.s4 | b.s5 | b.s6 | b.s7;
}
inline int8 lane_mask(int bits)
{
    return ((int8)(bits) & PACKET_BITS) != (int8)(0);
}

/* The least and the greatest lane of v among the lanes of mask (+inf / -inf for none). */
inline float lanes_min(float8 v, int8 mask)
{
    float8 m = select((float8)(F_INF), v, mask);
    float4 h = min(m.lo, m.hi);
    float2 q = min(h.lo, h.hi);
    return min(q.x, q.y);
}
inline float lanes_max(float8 v, int8 mask)
{
    float8 m = select((float8)(-F_INF), v, mask);
    float4 h = max(m.lo, m.hi);
    float2 q = max(h.lo, h.hi);
    return max(q.x, q.y);
}

/* Component K (0, 1, 2, per lane) of the point (x, y, z), as a float8. */
#define PACKET_PICK(K, X, Y, Z) select(select((float8)(X), (float8)(Y), (K) == (int8)(1)), (float8)(Z), (K) == (int8)(2))

/* Triangle lane L of block blk against the rays of pr in live: test_block's arithmetic and keep_nearer's rule,
 * ray by ray. */
#define PACKET_TRIANGLE(L)                                                                                   \
    if (blk.index.L >= 0) {                                                                                  \
        float8 a_z = PACKET_PICK(pr.kz, blk.v0x.L, blk.v0y.L, blk.v0z.L) - pr.pz;                             \
        float8 b_z = PACKET_PICK(pr.kz, blk.v1x.L, blk.v1y.L, blk.v1z.L) - pr.pz;                             \
        float8 c_z = PACKET_PICK(pr.kz, blk.v2x.L, blk.v2y.L, blk.v2z.L) - pr.pz;                             \
        float8 ax = (PACKET_PICK(pr.kx, blk.v0x.L, blk.v0y.L, blk.v0z.L) - pr.px) - pr.sx * a_z;              \
        float8 ay = (PACKET_PICK(pr.ky, blk.v0x.L, blk.v0y.L, blk.v0z.L) - pr.py) - pr.sy * a_z;              \
        float8 bx = (PACKET_PICK(pr.kx, blk.v1x.L, blk.v1y.L, blk.v1z.L) - pr.px) - pr.sx * b_z;              \
        float8 by = (PACKET_PICK(pr.ky, blk.v1x.L, blk.v1y.L, blk.v1z.L) - pr.py) - pr.sy * b_z;              \
        float8 cx = (PACKET_PICK(pr.kx, blk.v2x.L, blk.v2y.L, blk.v2z.L) - pr.px) - pr.sx * c_z;              \
        float8 cy = (PACKET_PICK(pr.ky, blk.v2x.L, blk.v2y.L, blk.v2z.L) - pr.py) - pr.sy * c_z;              \
        float8 u = cx * by - cy * bx;                                                                        \
        float8 v = ax * cy - ay * cx;                                                                        \
        float8 w = bx * ay - by * ax;                                                                        \
        float8 det = u + v + w;                                                                              \
        float8 inv = (float8)(1.0f) / det;                                                                   \
        float8 t = (u * (pr.sz * a_z) + v * (pr.sz * b_z) + w * (pr.sz * c_z)) * inv;                        \
        int8 front = (u >= (float8)(0.0f)) & (v >= (float8)(0.0f)) & (w >= (float8)(0.0f));                  \
        int8 back = (u <= (float8)(0.0f)) & (v <= (float8)(0.0f)) & (w <= (float8)(0.0f));                   \
        int8 ok = live & (front | (cull ? (int8)(0) : back)) & (det != (float8)(0.0f)) &                     \
                  (fabs(t) < (float8)(REAL_MAX)) & (fabs(inv) < (float8)(REAL_MAX));                          \
        int8 row8 = (int8)(row);                                                                             \
        int8 k8 = (int8)(blk.index.L);                                                                       \
        int8 tie_wins = (row8 < best.instance) | ((row8 == best.instance) & (k8 < best.triangle));           \
        int8 take = ok & (t > t_min) &                                                                       \
                    ((t < best.t) | ((t == best.t) & (best.instance >= (int8)(0)) & tie_wins));               \
        best.t = select(best.t, t, take);                                                                    \
        best.u = select(best.u, u * inv, take);                                                              \
        best.v = select(best.v, v * inv, take);                                                              \
        best.w = select(best.w, w * inv, take);                                                              \
        best.instance = select(best.instance, row8, take);                                                   \
        best.triangle = select(best.triangle, k8, take);                                                     \
    }

/* The four triangles of triangle_blocks row b against the rays of pr in live. */
FORCE_INLINE PacketHit packet_block(SCENE_DECL PacketHit best, PacketRay pr, int b, int row, bool cull, float8 t_min,
                                    int8 live)
{
    TriangleBlock blk = TRIANGLE_BLOCK(b);
    PACKET_TRIANGLE(x)
    PACKET_TRIANGLE(y)
    PACKET_TRIANGLE(z)
    PACKET_TRIANGLE(w)
    return best;
}

/* Child lane C of the wide node: WIDE_SLABS and BVH_LANE_HITS ray by ray, for the rays in active; pushed with
 * those that enter it (bits) and their least entry t, this visit's pushes kept nearest on top. */
#define PACKET_CHILD(C)                                                                                      \
    if (node.count.C >= 0) {                                                                                 \
        float8 tx0 = ((float8)(node.lo_x.C) - pr.ox) * pr.ix;                                                \
        float8 tx1 = ((float8)(node.hi_x.C) - pr.ox) * pr.ix;                                                \
        float8 ty0 = ((float8)(node.lo_y.C) - pr.oy) * pr.iy;                                                \
        float8 ty1 = ((float8)(node.hi_y.C) - pr.oy) * pr.iy;                                                \
        float8 tz0 = ((float8)(node.lo_z.C) - pr.oz) * pr.iz;                                                \
        float8 tz1 = ((float8)(node.hi_z.C) - pr.oz) * pr.iz;                                                \
        float8 tn = max(max(min(tx0, tx1), min(ty0, ty1)), min(tz0, tz1));                                   \
        float8 tf = min(min(max(tx0, tx1), max(ty0, ty1)), max(tz0, tz1));                                   \
        tf = tf + max(fabs(tf), tiny) * BOX_WIDEN;                                                           \
        int8 hit = active & (tf >= max(tn, t_min)) & (tn <= limit);                                          \
        int bits = lane_bits(hit);                                                                           \
        if (bits != 0 && sp < BVH_STACK_SIZE) {                                                              \
            float key = lanes_min(tn, hit);                                                                  \
            int j = sp;                                                                                      \
            while (j > base && stack_t[j - 1] <= key) {                                                      \
                stack_t[j] = stack_t[j - 1];                                                                 \
                stack_node[j] = stack_node[j - 1];                                                           \
                stack_count[j] = stack_count[j - 1];                                                         \
                stack_lanes[j] = stack_lanes[j - 1];                                                         \
                j -= 1;                                                                                      \
            }                                                                                                \
            stack_t[j] = key;                                                                                \
            stack_node[j] = node.child.C;                                                                    \
            stack_count[j] = node.count.C;                                                                   \
            stack_lanes[j] = bits;                                                                           \
            sp += 1;                                                                                         \
        }                                                                                                    \
    }

/* The next stacked child that one of its rays may still enter before that ray's best hit (ENTRY_LIMIT); done
 * if none. */
#define PACKET_POP                                                                                           \
    {                                                                                                        \
        bool found = false;                                                                                  \
        float8 limits = best.t * (REAL(1.0f) + BOX_WIDEN);                                                   \
        while (sp > 0 && !found) {                                                                           \
            sp -= 1;                                                                                         \
            if (stack_t[sp] <= lanes_max(limits, lane_mask(stack_lanes[sp]))) {                              \
                first = stack_node[sp];                                                                      \
                count = stack_count[sp];                                                                     \
                lanes = stack_lanes[sp];                                                                     \
                found = true;                                                                                \
            }                                                                                                \
        }                                                                                                    \
        done = !found;                                                                                       \
    }

/* The rays of pr in live against an instance's 8-wide tree from root (traverse_tree's walk, shared). */
FORCE_INLINE PacketHit packet_tree(SCENE_DECL PacketHit best, PacketRay pr, int root, int row, bool cull,
                                   float8 t_min, int8 live)
{
    float8 tiny = (float8)(REAL_TINY);
    int stack_node[BVH_STACK_SIZE];
    int stack_count[BVH_STACK_SIZE];
    int stack_lanes[BVH_STACK_SIZE];
    float stack_t[BVH_STACK_SIZE];
    int sp = 0;
    int first = root;
    int count = 0;
    int lanes = lane_bits(live);
    bool done = false;
    while (!done) {
        while (count == 0 && !done) {
            Bvh8Node node = BVH_NODE(first);
            int8 active = lane_mask(lanes);
            float8 limit = best.t * (REAL(1.0f) + BOX_WIDEN);
            int base = sp;
            PACKET_CHILD(s0)
            PACKET_CHILD(s1)
            PACKET_CHILD(s2)
            PACKET_CHILD(s3)
            PACKET_CHILD(s4)
            PACKET_CHILD(s5)
            PACKET_CHILD(s6)
            PACKET_CHILD(s7)
            PACKET_POP
        }
        if (!done) {
            /* A leaf: its (count + 3) / 4 blocks of 4 triangles, for the rays that entered it. */
            int8 active = lane_mask(lanes);
            for (int b = first; b < first + (count + 3) / 4; ++b) {
                best = packet_block(SCENE_PASS best, pr, b, row, cull, t_min, active);
            }
            PACKET_POP
        }
    }
    return best;
}

/* The rays (o, d per lane, world) in live against instance row: trace_instance's set-up ray by ray, then its
 * tree for all of them. */
FORCE_INLINE PacketHit packet_instance(SCENE_DECL PacketHit best, int row, float3 o, const float *dx,
                                       const float *dy, const float *dz, float8 t_min, int8 live)
{
    Instance inst = INSTANCE(row);
    float lanes[12][8];
    int axes[3][8];
    for (int k = 0; k < 8; ++k) {
        real3 d = R3(dx[k], dy[k], dz[k]);
        real3 oo = object_point(inst, o);
        real3 dd = object_vector(inst, d);
        ShearedRay sr = shear_ray(oo, dd);
        real3 inv = safe_inverse(dd);
        lanes[0][k] = oo.x;
        lanes[1][k] = oo.y;
        lanes[2][k] = oo.z;
        lanes[3][k] = inv.x;
        lanes[4][k] = inv.y;
        lanes[5][k] = inv.z;
        lanes[6][k] = VIDX3(sr.o, sr.kx);
        lanes[7][k] = VIDX3(sr.o, sr.ky);
        lanes[8][k] = VIDX3(sr.o, sr.kz);
        lanes[9][k] = sr.s.x;
        lanes[10][k] = sr.s.y;
        lanes[11][k] = sr.s.z;
        axes[0][k] = sr.kx;
        axes[1][k] = sr.ky;
        axes[2][k] = sr.kz;
    }
    PacketRay pr;
    pr.ox = vload8(0, lanes[0]);
    pr.oy = vload8(0, lanes[1]);
    pr.oz = vload8(0, lanes[2]);
    pr.ix = vload8(0, lanes[3]);
    pr.iy = vload8(0, lanes[4]);
    pr.iz = vload8(0, lanes[5]);
    pr.px = vload8(0, lanes[6]);
    pr.py = vload8(0, lanes[7]);
    pr.pz = vload8(0, lanes[8]);
    pr.sx = vload8(0, lanes[9]);
    pr.sy = vload8(0, lanes[10]);
    pr.sz = vload8(0, lanes[11]);
    pr.kx = vload8(0, axes[0]);
    pr.ky = vload8(0, axes[1]);
    pr.kz = vload8(0, axes[2]);
    bool cull = MATERIAL(inst.meta.y).flags.x != 0;
    return packet_tree(SCENE_PASS best, pr, inst.meta.x, row, cull, t_min, live);
}

/* The nearest hits of the block's rays (o, d per lane) in live: nearest_mesh ray by ray. INSTANCE_TILES_ONLY: over
 * the count instances listed from first in the view tiles' table (tile_mesh: a listed instance's lower bound
 * of t stops a ray, and the list once it passes every ray's best hit); else over the count instances from
 * first (a scene of one instance, USE_TLAS 0). */
FORCE_INLINE PacketHit packet_mesh(SCENE_DECL float3 o, const float *dx, const float *dy, const float *dz,
                                   float8 t_min, int8 live, int first, int count)
{
    PacketHit best;
    best.t = (float8)(REAL_MAX);
    best.u = (float8)(0.0f);
    best.v = (float8)(0.0f);
    best.w = (float8)(0.0f);
    best.instance = (int8)(-1);
    best.triangle = (int8)(-1);
    float inverse[3][8];
    for (int k = 0; k < 8; ++k) {
        real3 inv = safe_inverse(R3(dx[k], dy[k], dz[k]));
        inverse[0][k] = inv.x;
        inverse[1][k] = inv.y;
        inverse[2][k] = inv.z;
    }
    float8 ix = vload8(0, inverse[0]);
    float8 iy = vload8(0, inverse[1]);
    float8 iz = vload8(0, inverse[2]);
    for (int k = first; k < first + count; ++k) {
#if INSTANCE_TILES_ONLY
        int4 e = VIEW_TILE(k).entry;
        int row = e.x;
        int8 going = live & ((float8)(AS_FLOAT(e.y)) <= best.t);
        if (lane_bits(going) == 0) {
            break;
        }
#else
        int row = k;
        int8 going = live;
#endif
        /* slab() and slab_hit() ray by ray. */
        float4 lo = INSTANCE(row).bounds_min;
        float4 hi = INSTANCE(row).bounds_max;
        float8 tx0 = ((float8)(lo.x) - (float8)(o.x)) * ix;
        float8 ty0 = ((float8)(lo.y) - (float8)(o.y)) * iy;
        float8 tz0 = ((float8)(lo.z) - (float8)(o.z)) * iz;
        float8 tx1 = ((float8)(hi.x) - (float8)(o.x)) * ix;
        float8 ty1 = ((float8)(hi.y) - (float8)(o.y)) * iy;
        float8 tz1 = ((float8)(hi.z) - (float8)(o.z)) * iz;
        float8 enter = max(max(min(tx0, tx1), min(ty0, ty1)), min(tz0, tz1));
        float8 exit = min(min(max(tx0, tx1), max(ty0, ty1)), max(tz0, tz1));
        exit = exit + max(fabs(exit), (float8)(REAL_TINY)) * BOX_WIDEN;
        int8 hit = going & (exit >= max(enter, t_min)) & (enter <= best.t * (REAL(1.0f) + BOX_WIDEN));
        if (lane_bits(hit) != 0) {
            best = packet_instance(SCENE_PASS best, row, o, dx, dy, dz, t_min, hit);
        }
    }
    return best;
}
#endif
