/* bvh_wide.h -- an instance's wide tree (BVH_WIDTH 4 or 8, 8 in OpenCL only): a node's children's
 * boxes tested at once with 4- or 8-vector operations, nearest first; leaves are blocks of 4
 * triangles (triangle.h's test_block). Binary and compact trees are in bvh_binary.h. */

#if BVH_WIDTH >= 4
/* Push child lane L of a wide node if the ray crosses its box within (t_min, best.t] (slab_hit),
 * keeping this node's pushes sorted with the nearest on top (an insertion step: at most width - 1
 * moves). A macro: the subset has no way to pass the stack arrays by reference. */
#define BVH_PUSH(L)                                                                                    \
    if (node.count.L >= 0 && tf.L >= max(tn.L, t_min) && tn.L <= best.t && sp < BVH_STACK_SIZE) {     \
        int j = sp;                                                                                    \
        while (j > base && stack_t[j - 1] < tn.L) {                                                    \
            stack_t[j] = stack_t[j - 1];                                                               \
            stack_node[j] = stack_node[j - 1];                                                         \
            stack_count[j] = stack_count[j - 1];                                                       \
            j -= 1;                                                                                    \
        }                                                                                              \
        stack_t[j] = tn.L;                                                                             \
        stack_node[j] = node.child.L;                                                                  \
        stack_count[j] = node.count.L;                                                                 \
        sp += 1;                                                                                       \
    }
/* Pop the next (child, count) still entered before the best hit into first/count; done if none. */
#define BVH_POP()                                                                                      \
    {                                                                                                  \
        bool found = false;                                                                            \
        while (sp > 0 && !found) {                                                                     \
            sp -= 1;                                                                                   \
            if (stack_t[sp] <= best.t) {                                                               \
                first = stack_node[sp];                                                                \
                count = stack_count[sp];                                                               \
                found = true;                                                                          \
            }                                                                                          \
        }                                                                                              \
        done = !found;                                                                                 \
    }

/* The ray in object space (oo, dd; sr its sheared form) against the instance's tree from root. */
FORCE_INLINE MeshHit traverse_tree(SCENE_DECL MeshHit best, ShearedRay sr, real3 oo, real3 dd, int root, int row,
                                   bool cull, real t_min)
{
#if BRUTE_FORCE && BVH_WIDTH == 4
    /* As below, through the wide tree (slot 0 is never empty, the last used slot is the rightmost)
     * and the leaves' blocks, whose index lanes name the triangles' rows. */
    Bvh4Node left = BVH_NODE(root);
    while (left.count.x == 0) {
        left = BVH_NODE(left.child.x);
    }
    int end = 0;
    int begin = TRIANGLE_BLOCK(left.child.x).index.x;
    Bvh4Node right = BVH_NODE(root);
    bool inner = true;
    while (inner) {
        int c = right.count.w >= 0 ? right.child.w
                                   : (right.count.z >= 0 ? right.child.z : (right.count.y >= 0 ? right.child.y : right.child.x));
        int n = right.count.w >= 0 ? right.count.w
                                   : (right.count.z >= 0 ? right.count.z : (right.count.y >= 0 ? right.count.y : right.count.x));
        inner = n == 0;
        if (inner) {
            right = BVH_NODE(c);
        } else {
            end = TRIANGLE_BLOCK(c).index.x + n; /* the leaf's blocks hold its n consecutive rows */
        }
    }
    for (int k = begin; k < end; ++k) {
        best = test_triangle(SCENE_PASS best, sr, k, row, cull, t_min);
    }
    return best;
#elif BRUTE_FORCE
    /* As with width 4: used slots are a prefix, so the rightmost is the last with count >= 0. */
    Bvh8Node left = BVH_NODE(root);
    while (left.count.s0 == 0) {
        left = BVH_NODE(left.child.s0);
    }
    int end = 0;
    int begin = TRIANGLE_BLOCK(left.child.s0).index.x;
    Bvh8Node right = BVH_NODE(root);
    bool inner = true;
    while (inner) {
        int c = right.child.s0;
        int n = right.count.s0;
#define BVH8_LAST(L)            \
    if (right.count.L >= 0) {   \
        c = right.child.L;      \
        n = right.count.L;      \
    }
        BVH8_LAST(s1) BVH8_LAST(s2) BVH8_LAST(s3) BVH8_LAST(s4) BVH8_LAST(s5) BVH8_LAST(s6) BVH8_LAST(s7)
#undef BVH8_LAST
        inner = n == 0;
        if (inner) {
            right = BVH_NODE(c);
        } else {
            end = TRIANGLE_BLOCK(c).index.x + n;
        }
    }
    for (int k = begin; k < end; ++k) {
        best = test_triangle(SCENE_PASS best, sr, k, row, cull, t_min);
    }
    return best;
#elif BVH_WIDTH == 4
    /* The wide tree: one visit slabs the four children at once with 4-vector min/max (the slab()
     * arithmetic lane by lane), pushes the children hit nearest-on-top and pops the nearest, so
     * children are visited near to far. Stack entries are (child, count, entry t) as in the node. */
    real3 inv = safe_inverse(dd);
    real4 ox = R4(oo.x, oo.x, oo.x, oo.x);
    real4 oy = R4(oo.y, oo.y, oo.y, oo.y);
    real4 oz = R4(oo.z, oo.z, oo.z, oo.z);
    real4 ix = R4(inv.x, inv.x, inv.x, inv.x);
    real4 iy = R4(inv.y, inv.y, inv.y, inv.y);
    real4 iz = R4(inv.z, inv.z, inv.z, inv.z);
    real4 tiny = R4(REAL_TINY, REAL_TINY, REAL_TINY, REAL_TINY);
    int stack_node[BVH_STACK_SIZE];
    int stack_count[BVH_STACK_SIZE];
    real stack_t[BVH_STACK_SIZE];
    int sp = 0;
    int first = root;
    int count = 0;
    bool done = false;
    while (!done) {
        while (count == 0 && !done) {
            Bvh4Node node = BVH_NODE(first);
            real4 tx0 = (TO_REAL4(node.lo_x) - ox) * ix;
            real4 tx1 = (TO_REAL4(node.hi_x) - ox) * ix;
            real4 ty0 = (TO_REAL4(node.lo_y) - oy) * iy;
            real4 ty1 = (TO_REAL4(node.hi_y) - oy) * iy;
            real4 tz0 = (TO_REAL4(node.lo_z) - oz) * iz;
            real4 tz1 = (TO_REAL4(node.hi_z) - oz) * iz;
            real4 tn = max(max(min(tx0, tx1), min(ty0, ty1)), min(tz0, tz1));
            real4 tf = min(min(max(tx0, tx1), max(ty0, ty1)), max(tz0, tz1));
            tf = tf + max(ABS(tf), tiny) * BOX_WIDEN;
            int base = sp;
            BVH_PUSH(x)
            BVH_PUSH(y)
            BVH_PUSH(z)
            BVH_PUSH(w)
            BVH_POP()
        }
        if (!done) {
            /* A leaf: its (count + 3) / 4 blocks of 4 triangles. */
            for (int b = first; b < first + (count + 3) / 4; ++b) {
                best = test_block(SCENE_PASS best, sr, b, row, cull, t_min);
            }
            BVH_POP()
        }
    }
    return best;
#else
    /* Width 4's traversal with 8-vectors (OpenCL only): eight child boxes per visit, one AVX2
     * register per bound component on a CPU. */
    real3 inv = safe_inverse(dd);
    real8 ox = R8S(oo.x);
    real8 oy = R8S(oo.y);
    real8 oz = R8S(oo.z);
    real8 ix = R8S(inv.x);
    real8 iy = R8S(inv.y);
    real8 iz = R8S(inv.z);
    real8 tiny = R8S(REAL_TINY);
    int stack_node[BVH_STACK_SIZE];
    int stack_count[BVH_STACK_SIZE];
    real stack_t[BVH_STACK_SIZE];
    int sp = 0;
    int first = root;
    int count = 0;
    bool done = false;
    while (!done) {
        while (count == 0 && !done) {
            Bvh8Node node = BVH_NODE(first);
            real8 tx0 = (TO_REAL8(node.lo_x) - ox) * ix;
            real8 tx1 = (TO_REAL8(node.hi_x) - ox) * ix;
            real8 ty0 = (TO_REAL8(node.lo_y) - oy) * iy;
            real8 ty1 = (TO_REAL8(node.hi_y) - oy) * iy;
            real8 tz0 = (TO_REAL8(node.lo_z) - oz) * iz;
            real8 tz1 = (TO_REAL8(node.hi_z) - oz) * iz;
            real8 tn = max(max(min(tx0, tx1), min(ty0, ty1)), min(tz0, tz1));
            real8 tf = min(min(max(tx0, tx1), max(ty0, ty1)), max(tz0, tz1));
            tf = tf + max(ABS(tf), tiny) * BOX_WIDEN;
            int base = sp;
            /* The slab_hit test of all eight lanes as vectors, then a lane's branch is one compare: -2 %
             * CPU time per frame on the torus meshes against BVH_PUSH's scalar tests (PoCL 3.1). No
             * any(hit) before the lanes: PoCL reduces it with shuffles and branches, -2 % on the tori
             * without it. */
            int8 hit = convert_int8(tf >= max(tn, R8S(t_min))) & convert_int8(tn <= R8S(best.t)) &
                       (node.count >= (int8)(0));
/* BVH_PUSH with the lane's hit already known. */
#define BVH8_PUSH_HIT(L)                                               \
    if (hit.L != 0 && sp < BVH_STACK_SIZE) {                         \
        int j = sp;                                                    \
        while (j > base && stack_t[j - 1] < tn.L) {                    \
            stack_t[j] = stack_t[j - 1];                               \
            stack_node[j] = stack_node[j - 1];                         \
            stack_count[j] = stack_count[j - 1];                       \
            j -= 1;                                                    \
        }                                                              \
        stack_t[j] = tn.L;                                             \
        stack_node[j] = node.child.L;                                  \
        stack_count[j] = node.count.L;                                 \
        sp += 1;                                                       \
    }
            BVH8_PUSH_HIT(s0)
            BVH8_PUSH_HIT(s1)
            BVH8_PUSH_HIT(s2)
            BVH8_PUSH_HIT(s3)
            BVH8_PUSH_HIT(s4)
            BVH8_PUSH_HIT(s5)
            BVH8_PUSH_HIT(s6)
            BVH8_PUSH_HIT(s7)
#undef BVH8_PUSH_HIT
            BVH_POP()
        }
        if (!done) {
            for (int b = first; b < first + (count + 3) / 4; ++b) {
                best = test_block(SCENE_PASS best, sr, b, row, cull, t_min);
            }
            BVH_POP()
        }
    }
    return best;
#endif
}
#endif
