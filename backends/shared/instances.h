/* instances.h -- the nearest mesh hit over every instance: the top-level tree over instances
 * (tlas_nodes), each instance's ray in object space, then its own tree (bvh_binary.h, bvh_wide.h). */

/* The ray (camera-relative world o, d) against one instance: into object space with
 * world_to_object, the direction left unnormalised so t stays the world t; then the
 * asset's BVH from its root, nearest child first, with a small stack. */
/* A point and a direction (camera-relative world) in instance inst's object space (world_to_object). */
FORCE_INLINE real3 object_point(Instance inst, real3 o)
{
    return R3(dot(inst.w2o0.xyz, o) + inst.w2o0.w, dot(inst.w2o1.xyz, o) + inst.w2o1.w,
              dot(inst.w2o2.xyz, o) + inst.w2o2.w);
}
FORCE_INLINE real3 object_vector(Instance inst, real3 d)
{
    return R3(dot(inst.w2o0.xyz, d), dot(inst.w2o1.xyz, d), dot(inst.w2o2.xyz, d));
}

FORCE_INLINE MeshHit trace_instance(SCENE_DECL MeshHit best, int row, real3 o, real3 d, real t_min STOP_DECL)
{
    Instance inst = INSTANCE(row);
    real3 oo = object_point(inst, o);
    real3 dd = object_vector(inst, d);
    bool cull = MATERIAL(inst.meta.y).flags.x != 0;
    ShearedRay sr = shear_ray(oo, dd);
    int root = inst.meta.x;
    return traverse_tree(SCENE_PASS best, sr, oo, dd, root, row, cull, t_min STOP_PASS);
}

#if USE_TLAS && TLAS_WIDTH >= 4
/* The wide top-level tree's lanes (engine/tlas_wide.py), as bvh_wide.h names an asset tree's: TlasW and
 * TLAS_INTW its real and int vectors, TLAS_RWS(s) every lane s, TLAS_LANES(M) M of each lane's name;
 * TLAS_LANE_HITS and TLAS_LANE_HIT(L) whether the ray enters lane L's box within (t_min, best.t]. */
#if TLAS_WIDTH == 8
#define TlasW real8
#define TLAS_INTW int8
#define TLAS_RWS(s) R8S(s)
#define TLAS_CONVERT_INTW(v) convert_int8(v)
#define TO_TLASW(v) TO_REAL8(v)
#define TLAS_LANES(M) M(s0) M(s1) M(s2) M(s3) M(s4) M(s5) M(s6) M(s7)
#else
#define TlasW real4
#define TLAS_INTW int4
#define TLAS_RWS(s) R4(s, s, s, s)
#define TLAS_CONVERT_INTW(v) convert_int4(v)
#define TO_TLASW(v) TO_REAL4(v)
#define TLAS_LANES(M) M(x) M(y) M(z) M(w)
#endif
#ifdef __OPENCL_VERSION__
#define TLAS_LANE_HITS                                                                                  \
    TLAS_INTW hit = TLAS_CONVERT_INTW(tf >= max(tn, TLAS_RWS(t_min))) &                                \
                    TLAS_CONVERT_INTW(tn <= TLAS_RWS(ENTRY_LIMIT(best.t))) & (node.count >= (TLAS_INTW)(0));
#define TLAS_LANE_HIT(L) (hit.L != 0)
#else
#define TLAS_LANE_HITS
#define TLAS_LANE_HIT(L) (node.count.L >= 0 && tf.L >= max(tn.L, t_min) && tn.L <= ENTRY_LIMIT(best.t))
#endif
#define TLAS_PUSH(L) WIDE_PUSH(L, TLAS_STACK_SIZE, TLAS_LANE_HIT(L))
#endif

#if INSTANCE_TILES
/* A camera ray's first leg names its tile's list of instances (first, count); count -1: the tree. */
#define TILE_LIST_DECL , int list_first, int list_count
#define TILE_LIST_ARG(first, count) , first, count
/* nearest_mesh over the count rows of the view tiles' table from first (engine/view_tiles.py): a camera ray's
 * first leg, whose tile's list holds every instance its rays can enter, nearest first with a lower bound of
 * its hits' t; each is culled by its exact bounds as in the tree's walk. Equal t across instances goes to the
 * lower row (test_triangle), so the list's order is unseen. A loop of its own, apart from the tree's walk:
 * on llvmpipe a list run inside the binary walk's loop, as its leaves, is slower than this second copy. */
FORCE_INLINE MeshHit tile_mesh(SCENE_DECL real3 o, real3 d, real t_min, real t_max, int first, int count STOP_DECL)
{
    MeshHit best;
    best.t = t_max;
    best.bary = R3S(0.0f);
    best.instance = -1;
    best.triangle = -1;
    real3 inv = safe_inverse(d);
    for (int k = first; k < first + count; ++k) {
        int4 e = VIEW_TILE(k).entry;
        /* Nearest first: an instance farther than the best hit holds no nearer one (nor a tie). */
        if (TO_REAL(AS_FLOAT(e.y)) > best.t) {
            break;
        }
        real2 h = slab(o, inv, INSTANCE(e.x).bounds_min.xyz, INSTANCE(e.x).bounds_max.xyz);
        if (slab_hit(h, t_min, best.t)) {
            best = trace_instance(SCENE_PASS best, e.x, o, d, t_min STOP_PASS);
        }
#if HAS_SHADOWS
        k = best.t < t_stop ? first + count : k;
#endif
    }
    return best;
}
#else
#define TILE_LIST_DECL
#define TILE_LIST_ARG(first, count)
#endif

/* Whether a mesh search along d can find anything: a zero or NaN direction hits nothing, nor does a scene of
 * no instances. */
FORCE_INLINE bool meshes_reachable(SCENE_DECL real3 d)
{
    return dot(d, d) > REAL(0.0f) && SETTINGS.counts.x != 0;
}

/* The nearest triangle hit with t_min < t <= t_max over every instance, or with shadows the first one
 * found nearer than t_stop (core.h, SEARCH_STOP). USE_TLAS: the instances
 * a ray can reach come from the top-level tree (tlas_nodes, engine/tlas.py; TLAS_WIDTH 4 or 8: its
 * wide nodes, engine/tlas_wide.py), nearest child first; each leaf's instance is then culled by its exact world bounds (the leaf's are fattened, so a
 * small move changes only the instance row). Else: every instance's world bounds in turn. Equal t
 * across instances goes to the lower row either way (test_triangle), so the order is unseen. */
FORCE_INLINE MeshHit nearest_mesh(SCENE_DECL real3 o, real3 d, real t_min, real t_max STOP_DECL TILE_LIST_DECL)
{
    MeshHit best;
    best.t = t_max;
    best.bary = R3S(0.0f);
    best.instance = -1;
    best.triangle = -1;
    if (!meshes_reachable(SCENE_PASS d)) {
        return best;
    }
    real3 inv = safe_inverse(d);
#if INSTANCE_TILES_ONLY
    /* Every search of the frame is a camera ray's first leg, with its list (the host's INSTANCE_TILES_ONLY). */
    best = tile_mesh(SCENE_PASS o, d, t_min, t_max, list_first, list_count STOP_PASS);
#else
#if INSTANCE_TILES
    if (list_count >= 0) {
        return tile_mesh(SCENE_PASS o, d, t_min, t_max, list_first, list_count STOP_PASS);
    }
#endif
#if USE_TLAS && TLAS_WIDTH >= 4
    /* As an asset's wide tree (bvh_wide.h): a visit slabs every lane at once, pushes those entered
     * nearest-on-top and pops the nearest; a popped lane of kind (its count) 1 is instance row first. */
    WIDE_RAY(TlasW, TLAS_RWS, o, inv)
    int stack_node[TLAS_STACK_SIZE];
    int stack_count[TLAS_STACK_SIZE];
    real stack_t[TLAS_STACK_SIZE];
    int sp = 0;
    int first = 0;
    int kind = 0;
    bool done = false;
    while (!done) {
        while (kind == 0 && !done) {
            TlasRow node = TLAS_NODE(first);
            WIDE_SLABS(TlasW, TO_TLASW)
            int base = sp;
            TLAS_LANE_HITS
            TLAS_LANES(TLAS_PUSH)
            WIDE_POP(first, kind)
        }
        if (!done) {
            /* A leaf: its instance, culled by the exact bounds on the instance row (a moved one's lane is fat);
             * then the next lane still entered before the best hit, or done (also once the search stops). */
            real2 h = slab(o, inv, INSTANCE(first).bounds_min.xyz, INSTANCE(first).bounds_max.xyz);
            if (slab_hit(h, t_min, best.t)) {
                best = trace_instance(SCENE_PASS best, first, o, d, t_min STOP_PASS);
            }
            SEARCH_STOP()
            WIDE_POP(first, kind)
        }
    }
#elif USE_TLAS
    int stack_node[TLAS_STACK_SIZE];
    real stack_t[TLAS_STACK_SIZE];
    int sp = 0;
    TlasNode node = TLAS_NODE(0);
    bool more = slab_hit(slab(o, inv, TO_REAL3(node.lo.xyz), TO_REAL3(node.hi.xyz)), t_min, best.t);
    /* While-while, as trace_instance: descend to a leaf, then trace its instance outside the descent
     * loop, so SIMD lanes (llvmpipe) run the large instance code once per leaf, not per node. */
    while (more) {
        while (AS_INT(node.hi.w) == 0 && more) {
            int first = AS_INT(node.lo.w);
            BINARY_STEP(TlasNode, TLAS_NODE, TLAS_STACK_SIZE, NODE_SLAB, o, inv, first, more)
        }
        if (more) {
            /* A leaf: its instance, culled by the exact bounds on the instance row; then the next node
             * still entered before the best hit, or done (also once the search stops). */
            int row = AS_INT(node.lo.w);
            real2 h = slab(o, inv, INSTANCE(row).bounds_min.xyz, INSTANCE(row).bounds_max.xyz);
            if (slab_hit(h, t_min, best.t)) {
                best = trace_instance(SCENE_PASS best, row, o, d, t_min STOP_PASS);
            }
            SEARCH_STOP()
            BINARY_POP(TLAS_NODE, more)
        }
    }
#else
    int count = SETTINGS.counts.x;
    for (int i = 0; i < count; ++i) {
        real2 h = slab(o, inv, INSTANCE(i).bounds_min.xyz, INSTANCE(i).bounds_max.xyz);
        if (slab_hit(h, t_min, best.t)) {
            best = trace_instance(SCENE_PASS best, i, o, d, t_min STOP_PASS);
        }
#if HAS_SHADOWS
        i = best.t < t_stop ? count : i;
#endif
    }
#endif
#endif
    return best;
}
