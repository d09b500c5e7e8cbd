/* bvh_binary.h -- an instance's binary tree (BVH_WIDTH 2): plain 32-byte nodes, or with
 * BVH_COMPACT the compact records GLSL reads on llvmpipe (both children's boxes in one record).
 * Wide trees are in bvh_wide.h. */

#if BVH_WIDTH == 2
#if BVH_COMPACT
/* A compact tree's grid in one ray's frame: a grid coordinate q on axis i is at t = q * a_i + b_i,
 * with b_i widened by w_i (lo: toward the entry, hi: toward the exit) so that, whatever the
 * rounding, fused or not, flushed or not, each t contains the t that slab() gives for the decoded
 * box origin + q * scale, BOX_WIDEN included. With m_i = |inv_i| (|origin_i| + |o_i| + 65535
 * |scale_i| + 1e-31), both values are within 6u m_i of the exact one (u = 2^-24) and slab()'s
 * exit widening is at most 8.1u m_i + 5e-37, so w_i = 2^-19 m_i + 1e-32 (32u m_i) covers them
 * (the |inv| 1e-31 and 1e-32 terms cover flushed subnormals). An axis whose m_i is too large
 * for finite t (near-parallel rays in f64) does not cull. So the same nodes (and more by a
 * hair) are visited, and the same triangle wins: frames are bit-identical. */
STRUCT_BEGIN(CompactFrame)
    real3 a;
    real3 b_lo;
    real3 b_hi;
STRUCT_END(CompactFrame)

FORCE_INLINE real compact_widen_(real m, real inv)
{
    real w = m * REAL_C(1.9073486328125e-6) + REAL_C(1.0e-32);
    return inv < REAL(0.0f) ? -w : w;
}

FORCE_INLINE CompactFrame compact_frame(float3 origin, float3 scale, real3 o, real3 inv)
{
    real3 ro = TO_REAL3(origin);
    real3 rs = TO_REAL3(scale);
    real3 m = ABS(inv) * (ABS(ro) + ABS(o) + REAL(65535.0f) * ABS(rs) + R3S(REAL_C(1.0e-31)));
    real3 w = R3(compact_widen_(m.x, inv.x), compact_widen_(m.y, inv.y), compact_widen_(m.z, inv.z));
    real3 b = (ro - o) * inv;
    CompactFrame f;
    f.a = rs * inv;
    f.b_lo = b - w;
    f.b_hi = b + w;
    /* |t| <= 3 m_i stays finite below REAL_MAX / 8; else the axis takes every t (no NaN either). */
    real lim = REAL_MAX * REAL(0.125f);
    if (!(m.x < lim)) {
        f.a.x = REAL(0.0f);
        f.b_lo.x = -REAL_MAX;
        f.b_hi.x = REAL_MAX;
    }
    if (!(m.y < lim)) {
        f.a.y = REAL(0.0f);
        f.b_lo.y = -REAL_MAX;
        f.b_hi.y = REAL_MAX;
    }
    if (!(m.z < lim)) {
        f.a.z = REAL(0.0f);
        f.b_lo.z = -REAL_MAX;
        f.b_hi.z = REAL_MAX;
    }
    return f;
}

/* Entry and exit t of a compact record's child box (16-bit grid coordinates c.xyz, see engine/layout.py):
 * 6 multiply-adds in the ray's frame (compact_frame) instead of decoding the box and slab(): -1 % CPU
 * per frame on the tori (llvmpipe; the traversal's control flow, not its arithmetic, dominates). */
FORCE_INLINE real2 compact_slab(int4 c, CompactFrame f)
{
    real3 qlo = R3(TO_REAL(c.x & 0xffff), TO_REAL((c.x >> 16) & 0xffff), TO_REAL(c.y & 0xffff));
    real3 qhi = R3(TO_REAL((c.y >> 16) & 0xffff), TO_REAL(c.z & 0xffff), TO_REAL((c.z >> 16) & 0xffff));
    real3 t0 = qlo * f.a + f.b_lo;
    real3 t1 = qhi * f.a + f.b_hi;
    real3 tn = min(t0, t1);
    real3 tf = max(t0, t1);
    return R2(max(max(tn.x, tn.y), tn.z), min(min(tf.x, tf.y), tf.z));
}
#endif

/* The ray in object space (oo, dd; sr its sheared form) against the instance's tree from root. */
FORCE_INLINE MeshHit traverse_tree(SCENE_DECL MeshHit best, ShearedRay sr, real3 oo, real3 dd, int root, int row,
                                   bool cull, real t_min STOP_DECL)
{
#if BRUTE_FORCE && BVH_COMPACT
    /* As below, through the links: leftmost leaf's first to rightmost leaf's end. */
    int link = BVH_NODE(root).child0.w;
    while ((link & BVH_LINK_MASK) == 0) {
        link = BVH_NODE(link >> BVH_LINK_SHIFT).child0.w;
    }
    int begin = link >> BVH_LINK_SHIFT;
    link = BVH_NODE(root).child0.w;
    while ((link & BVH_LINK_MASK) == 0) {
        link = BVH_NODE(link >> BVH_LINK_SHIFT).child1.w;
    }
    int end = (link >> BVH_LINK_SHIFT) + (link & BVH_LINK_MASK);
    for (int k = begin; k < end; ++k) {
        best = test_triangle(SCENE_PASS best, sr, k, row, cull, t_min);
    }
    return best;
#elif BRUTE_FORCE
    /* Every triangle (benchmarks: what the BVH saves). The asset's triangles are contiguous:
     * from its leftmost leaf's first to its rightmost leaf's end. */
    BvhNode left = BVH_NODE(root);
    while (AS_INT(left.hi.w) == 0) {
        left = BVH_NODE(AS_INT(left.lo.w));
    }
    BvhNode right = BVH_NODE(root);
    while (AS_INT(right.hi.w) == 0) {
        right = BVH_NODE(AS_INT(right.lo.w) + 1);
    }
    int end = AS_INT(right.lo.w) + AS_INT(right.hi.w);
    for (int k = AS_INT(left.lo.w); k < end; ++k) {
        best = test_triangle(SCENE_PASS best, sr, k, row, cull, t_min);
    }
    return best;
#elif BVH_COMPACT
    /* The binary tree's traversal (below) over compact records: one record holds both children's
     * boxes and links, so a visit loads 2 texels (not 2 nodes of 2) and a pop none; the stack holds
     * links. The boxes are conservative, so the same triangles can win: the hit is the same. */
    real3 inv = safe_inverse(dd);
    BvhCompactNode header = BVH_NODE(root);
    float3 origin = F3(AS_FLOAT(header.child0.x), AS_FLOAT(header.child0.y), AS_FLOAT(header.child0.z));
    float3 scale = F3(AS_FLOAT(header.child1.x), AS_FLOAT(header.child1.y), AS_FLOAT(header.child1.z));
    float3 top = origin + TO_FLOAT(BVH_GRID_MAX) * scale;
    if (!slab_hit(slab(oo, inv, TO_REAL3(origin), TO_REAL3(top)), t_min, best.t)) {
        return best;
    }
    CompactFrame frame = compact_frame(origin, scale, oo, inv);
    int stack_link[BVH_STACK_SIZE];
    real stack_t[BVH_STACK_SIZE];
    int sp = 0;
    bool done = false;
    int link = header.child0.w;
    int first = link >> BVH_LINK_SHIFT;
    int count = link & BVH_LINK_MASK;
    /* Shaped for llvmpipe, where every lane runs every instruction of a loop body until the last lane
     * leaves: the cost is the body's size, not its trip count (unrolling the descent twice: +12 %).
     * So the descent neither pops nor branches to push; a miss leaves it, and one pop loop serves
     * misses and leaves. Against a pop loop in the descent and one after the leaf: -8 % CPU per
     * frame on mesh-10k and mesh-200k, -2 % on ten-boxes. One pop per round (the entry-t check on
     * the popped node) was +7 %, if-if +37 %, postponing a leaf to test two per round +20 %. */
    while (!done) {
        bool miss = false;
        while (count == 0 && !miss) {
            BvhCompactNode node = BVH_NODE(first);
            real2 h0 = compact_slab(node.child0, frame);
            real2 h1 = compact_slab(node.child1, frame);
            bool hit0 = slab_hit(h0, t_min, best.t);
            bool hit1 = slab_hit(h1, t_min, best.t);
            bool second_first = hit1 && (!hit0 || h1.x < h0.x);
            /* The farther child is written above the top always and kept only if both were hit (-2 %); the
             * host sizes the stack to the tree's depth, so the slot is free (the clamp: in bounds regardless). */
            int slot = min(sp, BVH_STACK_SIZE - 1);
            stack_link[slot] = second_first ? node.child0.w : node.child1.w;
            stack_t[slot] = second_first ? h0.x : h1.x;
            sp += (hit0 && hit1 && sp < BVH_STACK_SIZE) ? 1 : 0;
            link = second_first ? node.child1.w : node.child0.w;
            miss = !(hit0 || hit1);
            first = link >> BVH_LINK_SHIFT;
            count = link & BVH_LINK_MASK;
        }
        /* A leaf (none after a miss): a bound, not a branch around the loop (-2 %). */
        int end = miss ? first : first + count;
        for (int k = first; k < end; ++k) {
            best = test_triangle(SCENE_PASS best, sr, k, row, cull, t_min);
        }
        /* Skip entries entered beyond the best hit, then pop the next one, or done (-1 %; also once the
         * search stops). */
        SEARCH_STOP()
        while (sp > 0 && stack_t[sp - 1] > ENTRY_LIMIT(best.t)) {
            sp -= 1;
        }
        done = sp == 0;
        if (!done) {
            sp -= 1;
            link = stack_link[sp];
        }
        first = link >> BVH_LINK_SHIFT;
        count = link & BVH_LINK_MASK;
    }
    return best;
#else
    real3 inv = safe_inverse(dd);
    int stack_node[BVH_STACK_SIZE];
    real stack_t[BVH_STACK_SIZE];
    int sp = 0;
    BvhNode node = BVH_NODE(root);
    if (!slab_hit(slab(oo, inv, TO_REAL3(node.lo.xyz), TO_REAL3(node.hi.xyz)), t_min, best.t)) {
        return best;
    }
    /* "While-while" traversal (Aila & Laine 2009): descend interior nodes until this ray stands
     * at a leaf, then test the leaf; SIMD lanes (llvmpipe, GPU warps) then test leaves together.
     * On llvmpipe it beats "if-if" by 15-20 % on meshes. */
    bool done = false;
    int first = AS_INT(node.lo.w);
    int count = AS_INT(node.hi.w);
    while (!done) {
        while (count == 0 && !done) {
            bool found;
            BINARY_STEP(BvhNode, BVH_NODE, BVH_STACK_SIZE, NODE_SLAB, oo, inv, first, found)
            done = !found;
            first = AS_INT(node.lo.w);
            count = AS_INT(node.hi.w);
        }
        if (!done) {
            for (int k = first; k < first + count; ++k) {
                best = test_triangle(SCENE_PASS best, sr, k, row, cull, t_min);
            }
            SEARCH_STOP()
            bool found;
            BINARY_POP(BVH_NODE, found)
            done = !found;
            first = AS_INT(node.lo.w);
            count = AS_INT(node.hi.w);
        }
    }
    return best;
#endif
}
#endif
