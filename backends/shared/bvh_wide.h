/* bvh_wide.h -- an instance's wide tree (BVH_WIDTH 4 or 8, 8 in OpenCL only): a node's children's
 * boxes tested at once with 4- or 8-vector operations, nearest first; leaves are blocks of 4
 * triangles (triangle.h's test_block). Binary and compact trees are in bvh_binary.h. */

#if BVH_WIDTH >= 4
/* One traversal for both widths; what differs is named here:
 *   WideNode, realw, intw     the node record, its real and int vector types
 *   RWS(s), CONVERT_INTW(v)   a realw with every lane s, a comparison's lanes as intw
 *   TO_REALW(v)               a node's float vector as realw
 *   BVH_LANE0, BVH_LANES_1(M) the first lane's name, M applied to each other lane's
 *   BVH_LANE_HITS             what the node's lane tests share, computed once per visit
 *   BVH_LANE_HIT(L)           whether the ray enters lane L's box within (t_min, best.t] (slab_hit)
 * OpenCL C tests all lanes as vectors, then a lane's branch is one compare: against per-lane scalar
 * tests, -2 % CPU time per frame on the torus meshes at width 8, -1.5 % at width 4 with doubles,
 * -1 % with floats (PoCL 3.1). No any(hit) before the lanes: PoCL reduces it with shuffles and
 * branches, -2 % on the tori without it. GLSL keeps per-lane tests (its vector compares give bvecs,
 * not masks; width 4 is not its default tree, so not measured there). */
#if BVH_WIDTH == 8
#define WideNode Bvh8Node
#define realw real8
#define intw int8
#define RWS(s) R8S(s)
#define CONVERT_INTW(v) convert_int8(v)
#define TO_REALW(v) TO_REAL8(v)
#define BVH_LANE0 s0
#define BVH_LANES_1(M) M(s1) M(s2) M(s3) M(s4) M(s5) M(s6) M(s7)
#else
#define WideNode Bvh4Node
#define realw real4
#define intw int4
#define RWS(s) R4(s, s, s, s)
#define CONVERT_INTW(v) convert_int4(v)
#define TO_REALW(v) TO_REAL4(v)
#define BVH_LANE0 x
#define BVH_LANES_1(M) M(y) M(z) M(w)
#endif
#ifdef __OPENCL_VERSION__
#define BVH_LANE_HITS                                                                                   \
    intw hit = CONVERT_INTW(tf >= max(tn, RWS(t_min))) & CONVERT_INTW(tn <= RWS(ENTRY_LIMIT(best.t))) &\
               (node.count >= (intw)(0));
#define BVH_LANE_HIT(L) (hit.L != 0)
#else
#define BVH_LANE_HITS
#define BVH_LANE_HIT(L) (node.count.L >= 0 && tf.L >= max(tn.L, t_min) && tn.L <= ENTRY_LIMIT(best.t))
#endif
#define BVH_LANES(M) M(BVH_LANE0) BVH_LANES_1(M)

/* Push child lane L of a wide node if the ray enters its box; pop the next (core.h's wide steps). */
#define BVH_PUSH(L) WIDE_PUSH(L, BVH_STACK_SIZE, BVH_LANE_HIT(L))
#define BVH_POP() WIDE_POP(first, count)
/* BRUTE_FORCE: the rightmost used slot of node `right` into (c, n) (used slots are a prefix). */
#define BVH_LAST(L)             \
    if (right.count.L >= 0) {   \
        c = right.child.L;      \
        n = right.count.L;      \
    }

/* The ray in object space (oo, dd; sr its sheared form) against the instance's tree from root. */
FORCE_INLINE MeshHit traverse_tree(SCENE_DECL MeshHit best, ShearedRay sr, real3 oo, real3 dd, int root, int row,
                                   bool cull, real t_min STOP_DECL)
{
#if BRUTE_FORCE
    /* Every triangle between the leftmost and the rightmost leaf's, through the wide tree (slot 0
     * is never empty) and the leaves' blocks, whose index lanes name the triangles' rows. */
    WideNode left = BVH_NODE(root);
    while (left.count.BVH_LANE0 == 0) {
        left = BVH_NODE(left.child.BVH_LANE0);
    }
    int end = 0;
    int begin = TRIANGLE_BLOCK(left.child.BVH_LANE0).index.x;
    WideNode right = BVH_NODE(root);
    bool inner = true;
    while (inner) {
        int c = right.child.BVH_LANE0;
        int n = right.count.BVH_LANE0;
        BVH_LANES_1(BVH_LAST)
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
#else
    /* One visit slabs all children at once with vector min/max (the slab() arithmetic lane by
     * lane), pushes the children hit nearest-on-top and pops the nearest, so children are visited
     * near to far. Stack entries are (child, count, entry t) as in the node. */
    real3 inv = safe_inverse(dd);
    WIDE_RAY(realw, RWS, oo, inv)
    int stack_node[BVH_STACK_SIZE];
    int stack_count[BVH_STACK_SIZE];
    real stack_t[BVH_STACK_SIZE];
    int sp = 0;
    int first = root;
    int count = 0;
    bool done = false;
    while (!done) {
        while (count == 0 && !done) {
            WideNode node = BVH_NODE(first);
            WIDE_SLABS(realw, TO_REALW)
            int base = sp;
            BVH_LANE_HITS
            BVH_LANES(BVH_PUSH)
            BVH_POP()
        }
        if (!done) {
            /* A leaf: its (count + 3) / 4 blocks of 4 triangles. */
            for (int b = first; b < first + (count + 3) / 4; ++b) {
                best = test_block(SCENE_PASS best, sr, b, row, cull, t_min);
            }
            SEARCH_STOP()
            BVH_POP()
        }
    }
    return best;
#endif
}
#endif
