/* core.h -- the tracer core shared by the GLSL and OpenCL backends (docs/design.md section 4):
 * its tolerances, records and small helpers. The core is this file and those after it, concatenated
 * in this order (backends.shared.TRACER_FILES), each using only what comes before it:
 *   options.h     the compile-time options and their defaults
 *   core.h        tolerances, the journey's records, slab tests
 *   triangle.h    the watertight triangle test (one, or a block of four) and the tie rule
 *   bvh_binary.h  an instance's binary tree (plain or compact records)
 *   bvh_wide.h    an instance's 4- or 8-wide tree
 *   instances.h   the nearest mesh hit: the tree over instances, then each instance's tree
 *   space.h       what boxes and portals share: vector rules, the tie rule, their trees (space_nodes)
 *   boxes.h       aberration boxes: faces, the box holding a point, transitions
 *   portals.h     portals: the nearest quad, teleports
 *   legs.h        one leg: its portal and box-face events, the first of them, the crossing to the next leg
 *   journey.h     primary rays and the event loop (camera and shadow rays alike)
 *   shade.h       the colour of a hit, its lights and their shadow rays
 *   pixel.h       trace_pixel, the kernels' entry point
 *
 * Written once in the common subset of GLSL 4.30 and OpenCL C 1.2, so the two
 * fast backends agree by construction. backends/reference/ is the float64
 * truth this code follows step by step (trace.py, traverse.py, intersect.py).
 *
 * What a language prelude provides (backends/glsl/prelude.glsl,
 * backends/shared/prelude_cl.h):
 *   types       real real2 real3 real4 (float, or double with REAL_IS_DOUBLE),
 *               float2..4 int2..4, double (only used under EDGE_FALLBACK_FP64 /
 *               WORLD_FP64)
 *   values      REAL(x) R2 R3 R4 R3S(splat) F3 F4, REAL_MAX (huge finite),
 *               REAL_TINY, F_INF (+inf as a float), REAL_C(x) (a literal written
 *               without suffix, as a real: exact in double, e.g. REAL_C(1.0e-9))
 *   casts       TO_REAL TO_REAL3 (from float3) TO_FLOAT TO_FLOAT3 TO_INT TO_DOUBLE,
 *               AS_INT / AS_FLOAT (bit reinterpretation)
 *   helpers     ABS (float abs, scalar or vector), NORMALIZED(v) (v / |v| for v neither zero
 *               nor near the range's ends), VIDX3(v, i) (component i of
 *               a real3), PRECISE (no fused multiply-add), FORCE_INLINE (before a
 *               function: always inline it; empty in GLSL), STRUCT_BEGIN/END
 *   scene       SCENE_DECL / SCENE_PASS (a first parameter carrying the tables,
 *               empty in GLSL), SETTINGS, TRIANGLE(i), TRIANGLE_UV(i),
 *               BVH_NODE(i) (a BvhNode, a BvhCompactNode with BVH_COMPACT, or a Bvh4Node /
 *               Bvh8Node by BVH_WIDTH), INSTANCE(i), MATERIAL(i), ABERRATION(i), PORTAL(i),
 *               TLAS_NODE(i), TRIANGLE_BLOCK(i), SPACE_NODE(i), LIGHT(i) (records, from the bindings file)
 *
 * Entry point (pixel.h): Pixel trace_pixel(PIXEL_SCENE_DECL Camera cam, int i, int j) (OpenCL: the
 * tables by address, bindings_cl.h).
 * Rules of the subset: no overloading, no `inout`/`out` (functions return
 * structs), no vector comparisons, no v[i] (VIDX3), literals with an `f`
 * suffix wrapped in REAL() where they meet reals, no float3-real mixing
 * without a cast (OpenCL C has no implicit vector conversions).
 */

/* Tolerances of docs/semantics.md section 2, relative to the size of the coordinates (at least 1):
 * hits at t <= T_MIN_RELATIVE * max(1, |p|) past the point p the ray leaves are ignored; candidates
 * within TIE_RELATIVE * max(1, |o| + t) of the nearest one are tied; the active box after an event is
 * looked up NUDGE_RELATIVE * max(1, |p|) past the event point. Double: the reference's values.
 * Float (camera-relative coordinates, |p| mostly below 30): the same relations (tie = 2 t_min,
 * nudge > t_min) at about 80 float epsilons for t_min ("float32 backends" in docs/semantics.md). */
#if REAL_IS_DOUBLE
#define T_MIN_RELATIVE REAL_C(1.0e-9)
#define TIE_RELATIVE REAL_C(2.0e-9)
#define NUDGE_RELATIVE REAL_C(1.0e-8)
/* A box's exit t is widened by this fraction of itself: rounding never loses a hit on a face. */
#define BOX_WIDEN REAL_C(4.0e-16)
/* A space tree's nodes grow by this fraction of max(1, |o|) around a ray from o (or a point o): far above
 * the rounding of the quad and box tests in their frames (space.h, space_slab). */
#define SPACE_PAD REAL_C(1.0e-12)
/* A shadow ray starts this fraction of max(1, |p|) off the surface along its normal (the reference's). */
#define SHADOW_BIAS REAL_C(1.0e-7)
#else
#define T_MIN_RELATIVE REAL_C(1.0e-5)
#define TIE_RELATIVE REAL_C(2.0e-5)
#define NUDGE_RELATIVE REAL_C(5.0e-5)
#define BOX_WIDEN REAL_C(4.8e-7)
#define SPACE_PAD REAL_C(1.0e-5)
/* Ten t_min: past the hit point's rounding (a few ulps of |p| over the cosine) down to grazing light. */
#define SHADOW_BIAS REAL_C(1.0e-4)
#endif
/* A vector shorter than this is not normalised: the previous direction is kept (no NaN ever). */
#define MIN_NORM REAL_C(1.0e-12)
/* Radial mode: an axis whose corner-ray range is narrower than this uses sigma_k = sign(v_k). */
#define COLLAPSED_RANGE REAL_C(1.0e-6)

/* Faces per box: face id = 6 * row + 2 * axis + (1 on the +1/2 side, 0 on the -1/2 side). */
#define BOX_FACES 6

/* Event kinds (docs/semantics.md section 3). */
#define EVENT_NONE 0
#define EVENT_MESH 1
#define EVENT_ABERRATION 2
#define EVENT_PORTAL 3

/* --- records of the journey ------------------------------------------------------ */

/* The state a ray carries (docs/semantics.md section 1). Coordinates are
 * camera-relative. A leg is a straight piece of the journey: o and r change only when the direction
 * does (a bend, a portal), so a box face that leaves r as it is (D = 0, a ray along a metric box's
 * axis) splits nothing: later hits on the leg are found from the same o and come out bit-identical
 * to a scene without that box. Events on a leg are at t_from along it. */
STRUCT_BEGIN(Ray)
    real3 o;          /* origin of the leg */
    real3 r;          /* world direction */
    real o_len;       /* |o| and |r|, computed once per leg (t_min, tie windows, nudges, lengths) */
    real r_len;
    real3 w;          /* perceived direction (unit) */
    real3 d0;         /* primary direction, carried through portals (the "restore" exit rule) */
    real L;           /* path length at o: world units travelled */
    real Lambda;      /* perceived length at o + t_piece r */
    real t_from;      /* t along the leg of the last event on it (0: none, the ray leaves o) */
    real t_piece;     /* t along the leg where the perceived rate f last changed */
    real f;           /* perceived length per world length since t_piece (docs/semantics.md rule 4) */
    int aberration;   /* active aberration row, -1 for none */
    int n;            /* event count */
    int leaving_kind; /* the surface the ray is leaving (EVENT_ABERRATION / EVENT_PORTAL), -1 none */
    int leaving;      /* ... and its id: box face id (BOX_FACES * row + face) or portal row */
STRUCT_END(Ray)

/* The nearest mesh hit: t along r, barycentric weights of v0, v1, v2, instance row and triangle (-1: none). */
STRUCT_BEGIN(MeshHit)
    real t;
    real3 bary;
    int instance;
    int triangle;
STRUCT_END(MeshHit)

/* The next event of a ray: its kind, distance t along r and the row of what was hit. A box face also
 * gives its box's exit t when the face is the entry (-REAL_MAX for an exit face) and the box's gap to
 * every other box, and the largest clearance to every instance of a box the segment from t_min lies in
 * (0 for none): docs/semantics.md section 14, engine/box_clearance.py. */
STRUCT_BEGIN(Event)
    real t;
    int kind;
    int row;
    real far;
    real gap;
    real clear;
STRUCT_END(Event)

/* Per-ray set-up of the watertight triangle test (Woop, Benthin & Wald 2013). */
STRUCT_BEGIN(ShearedRay)
    real3 o;  /* object-space origin */
    real3 s;  /* shear (Sx, Sy, Sz) */
    int kx;
    int ky;
    int kz;
STRUCT_END(ShearedRay)

/* What a pixel gets: colour quantised to 0..255 (as floats), the AOVs (docs/semantics.md, "What a frame holds"). */
STRUCT_BEGIN(Pixel)
    float4 color;
    float depth;
    float perceived;
    int instance;   /* entity id, -1 for none */
    int events;
#if SPLIT_PASS == 1
    int deferred; /* -2: finished; else left for the second pass, its first leg's event kind (-1 for none) */
#endif
STRUCT_END(Pixel)

/* --- small helpers ----------------------------------------------------------------- */

/* 1/d with (near-)zero components replaced by a tiny value of the same sign: no inf * 0 = NaN in slabs. */
real3 safe_inverse(real3 d)
{
    real x = ABS(d.x) < REAL_TINY ? (d.x < REAL(0.0f) ? -REAL_TINY : REAL_TINY) : d.x;
    real y = ABS(d.y) < REAL_TINY ? (d.y < REAL(0.0f) ? -REAL_TINY : REAL_TINY) : d.y;
    real z = ABS(d.z) < REAL_TINY ? (d.z < REAL(0.0f) ? -REAL_TINY : REAL_TINY) : d.z;
    return R3(REAL(1.0f) / x, REAL(1.0f) / y, REAL(1.0f) / z);
}

/* Entry and exit t of a ray against a box; the exit is widened a few ulps (conservative). The
 * widening is at least BOX_WIDEN * REAL_TINY: an exit a hair from 0 (a ray starting on a bound,
 * common where a mesh is split at a coordinate plane through the camera) would otherwise make a
 * subnormal product, which costs a CPU a microcode assist per lane without flush-to-zero. */
real2 slab(real3 o, real3 inv, real3 lo, real3 hi)
{
    real3 t0 = (lo - o) * inv;
    real3 t1 = (hi - o) * inv;
    real3 tn = min(t0, t1);
    real3 tf = max(t0, t1);
    real t_enter = max(max(tn.x, tn.y), tn.z);
    real t_exit = min(min(tf.x, tf.y), tf.z);
    return R2(t_enter, t_exit + max(ABS(t_exit), REAL_TINY) * BOX_WIDEN);
}

/* The latest entry t of a box still entered with the best hit at t (> 0): t widened as slab() widens exits.
 * A triangle on a box face gets its t from other arithmetic than the face's entry, at times an ulp below it;
 * a box entered a hair after a best hit at that t would be culled, and a lower instance row's equal hit
 * with it, so the walk's order would decide the tie. One multiply per visit, not one per lane. */
#define ENTRY_LIMIT(t) ((t) * (REAL(1.0f) + BOX_WIDEN))

/* Whether a slab interval is crossed within (t_min, t_max] (its entry up to ENTRY_LIMIT); false on NaN. */
bool slab_hit(real2 h, real t_min, real t_max)
{
    return h.y >= max(h.x, t_min) && h.x <= ENTRY_LIMIT(t_max);
}

/* The steps of a binary tree's "while-while" traversal (an asset's plain tree, the tree over
 * instances), over the caller's stacks stack_node / stack_t and its node, sp and best (macros: the
 * subset cannot pass arrays by reference). BINARY_POP: the next stacked node entered no later than
 * best.t into node (a NODE, read with FETCH); found tells whether there was one. BINARY_STEP: from the
 * interior node whose children are first and first + 1, to the nearer child the ray enters within
 * (t_min, best.t], the other stacked (up to STACK entries: the host sizes stacks to the tree's
 * depth); neither entered: BINARY_POP. SLAB(o, inv, child): a child's entry and exit t for the ray o, inv
 * in the tree's space (NODE_SLAB: the node's box; space.h pads its trees' boxes). */
#define NODE_SLAB(o, inv, c) slab(o, inv, TO_REAL3(c.lo.xyz), TO_REAL3(c.hi.xyz))
#define BINARY_POP(FETCH, found)                                                                     \
    found = false;                                                                                   \
    while (sp > 0 && !found) {                                                                       \
        sp -= 1;                                                                                     \
        if (stack_t[sp] <= ENTRY_LIMIT(best.t)) {                                                    \
            node = FETCH(stack_node[sp]);                                                            \
            found = true;                                                                            \
        }                                                                                            \
    }
#define BINARY_STEP(NODE, FETCH, STACK, SLAB, o, inv, first, found)                                  \
    {                                                                                                \
        NODE c0 = FETCH(first);                                                                      \
        NODE c1 = FETCH(first + 1);                                                                  \
        real2 h0 = SLAB(o, inv, c0);                                                                 \
        real2 h1 = SLAB(o, inv, c1);                                                                 \
        bool hit0 = slab_hit(h0, t_min, best.t);                                                     \
        bool hit1 = slab_hit(h1, t_min, best.t);                                                     \
        if (hit0 || hit1) {                                                                          \
            bool second_first = hit1 && (!hit0 || h1.x < h0.x);                                      \
            if (hit0 && hit1 && sp < STACK) {                                                        \
                stack_node[sp] = second_first ? first : first + 1;                                   \
                stack_t[sp] = second_first ? h0.x : h1.x;                                            \
                sp += 1;                                                                             \
            }                                                                                        \
            node = second_first ? c1 : c0;                                                           \
            found = true;                                                                            \
        } else {                                                                                     \
            BINARY_POP(FETCH, found)                                                                 \
        }                                                                                            \
    }

/* A wide visit's slabs (an asset's wide tree, the tree over instances): WIDE_RAY broadcasts the ray's
 * origin o and inverse direction inv into vectors (W: the lanes' real vector, RWS(s) one with every lane s);
 * WIDE_SLABS gives every lane's entry tn and exit tf for the boxes of node (TO_W: a node field as W), the
 * arithmetic of slab() lane by lane, exit widening included. */
#define WIDE_RAY(W, RWS, o, inv)                                                                       \
    W ox = RWS(o.x);                                                                                   \
    W oy = RWS(o.y);                                                                                   \
    W oz = RWS(o.z);                                                                                   \
    W ix = RWS(inv.x);                                                                                 \
    W iy = RWS(inv.y);                                                                                 \
    W iz = RWS(inv.z);                                                                                 \
    W tiny = RWS(REAL_TINY);
#define WIDE_SLABS(W, TO_W)                                                                            \
    W tx0 = (TO_W(node.lo_x) - ox) * ix;                                                               \
    W tx1 = (TO_W(node.hi_x) - ox) * ix;                                                               \
    W ty0 = (TO_W(node.lo_y) - oy) * iy;                                                               \
    W ty1 = (TO_W(node.hi_y) - oy) * iy;                                                               \
    W tz0 = (TO_W(node.lo_z) - oz) * iz;                                                               \
    W tz1 = (TO_W(node.hi_z) - oz) * iz;                                                               \
    W tn = max(max(min(tx0, tx1), min(ty0, ty1)), min(tz0, tz1));                                      \
    W tf = min(min(max(tx0, tx1), max(ty0, ty1)), max(tz0, tz1));                                      \
    tf = tf + max(ABS(tf), tiny) * BOX_WIDEN;
/* The steps of a wide tree's walk (an asset's in bvh_wide.h, the tree over instances in instances.h) over
 * the caller's stacks stack_node / stack_count / stack_t, its sp, best, node (the wide record visited),
 * tn (its lanes' entry t) and base (sp before this visit's pushes). WIDE_PUSH: lane L if HIT (the ray
 * enters its box), keeping this visit's pushes sorted with the nearest on top and equal entries in lane
 * order (as a binary step takes child 0 first: a hit that ties one in a later lane, whose entry t rounds a
 * hair above it, is then never culled), an insertion step of at most width - 1 moves, up to STACK entries. WIDE_POP: the next (child, count) still entered before the best
 * hit into first, count; done if none. */
#define WIDE_PUSH(L, STACK, HIT)                                                                       \
    if ((HIT) && sp < STACK) {                                                                         \
        int j = sp;                                                                                    \
        while (j > base && stack_t[j - 1] <= tn.L) {                                                   \
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
#define WIDE_POP(first, count)                                                                         \
    {                                                                                                  \
        bool found = false;                                                                            \
        while (sp > 0 && !found) {                                                                     \
            sp -= 1;                                                                                   \
            if (stack_t[sp] <= ENTRY_LIMIT(best.t)) {                                                  \
                first = stack_node[sp];                                                                \
                count = stack_count[sp];                                                               \
                found = true;                                                                          \
            }                                                                                          \
        }                                                                                              \
        done = !found;                                                                                 \
    }
/* With shadows, the mesh search (nearest_mesh, trace_instance, traverse_tree) takes a t_stop after its
 * t limits (STOP_DECL, STOP_PASS) and ends as soon as its best hit is nearer than that: after a leaf or an
 * instance, SEARCH_STOP empties the caller's stack when it is. A shadow ray's occlusion test stops at the
 * first hit that decides it (journey.h); camera rays pass -inf, never nearer: the nearest hit. */
#if HAS_SHADOWS
#define STOP_DECL , real t_stop
#define STOP_PASS , t_stop
#define SEARCH_STOP() sp = best.t < t_stop ? 0 : sp;
#else
#define STOP_DECL
#define STOP_PASS
#define SEARCH_STOP()
#endif

/* The axis of the largest |v| component; ties go to the first (NumPy's argmax). */
int dominant_axis(real3 v)
{
    real3 a = ABS(v);
    return (a.x >= a.y && a.x >= a.z) ? 0 : ((a.y >= a.z) ? 1 : 2);
}

/* round(clip(c, 0, 1) * 255) with halves rounded up, as the reference's to_uint8; NaN gives 0. */
float4 quantize_rgba(float3 c)
{
    float r = c.x > 0.0f ? min(c.x, 1.0f) : 0.0f;
    float g = c.y > 0.0f ? min(c.y, 1.0f) : 0.0f;
    float b = c.z > 0.0f ? min(c.z, 1.0f) : 0.0f;
    return F4(floor(r * 255.0f + 0.5f), floor(g * 255.0f + 0.5f), floor(b * 255.0f + 0.5f), 255.0f);
}
