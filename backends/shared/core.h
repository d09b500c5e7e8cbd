/* core.h -- the tracer core shared by the GLSL and OpenCL backends (DESIGN.md sections 3-5, 9).
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
 *   helpers     ABS (float abs, scalar or vector), VIDX3(v, i) (component i of
 *               a real3), PRECISE (no fused multiply-add), FORCE_INLINE (before a
 *               function: always inline it; empty in GLSL), STRUCT_BEGIN/END
 *   scene       SCENE_DECL / SCENE_PASS (a first parameter carrying the tables,
 *               empty in GLSL), SETTINGS, TRIANGLE(i), TRIANGLE_UV(i),
 *               BVH_NODE(i) (a BvhNode, a BvhCompactNode with BVH_COMPACT, or a Bvh4Node /
 *               Bvh8Node by BVH_WIDTH), INSTANCE(i), MATERIAL(i), ABERRATION(i), PORTAL(i),
 *               TLAS_NODE(i), TRIANGLE_BLOCK(i) (records, from the bindings file)
 *
 * Compile-time defines (engine.packed.Features.defines() and the backend):
 *   HAS_PORTALS        linked portals exist: portal search and teleport (issue 6)
 *   HAS_ABERRATIONS    aberration boxes exist: box faces, active box, transitions (issue 5)
 *   HAS_METRIC HAS_RADIAL HAS_ADDITIVE  the box modes present: only their rules compile
 *   MAX_EVENTS         events a ray may take (the settings' max_events, which it bounds)
 *   REAL_IS_DOUBLE     trace in double precision
 *   EDGE_FALLBACK_FP64 float tracer: recompute an edge function that is exactly
 *                      0 in double (exact: a product of two floats fits a double)
 *   WORLD_FP64         float tracer: world-space checker coordinates in double
 *                      (the packed origin can be 1e5 away while cells are 0.05)
 *   BRUTE_FORCE        test every triangle of an instance (benchmarks only)
 *   BVH_STACK_SIZE     traversal stack; the host checks every tree fits
 *   BVH_WIDTH          2: binary nodes, one triangle at a time; 4: 4-wide nodes (child boxes SoA,
 *                      slabbed with 4-vector ops) whose leaves are blocks of 4 triangles tested at
 *                      once; 8 (OpenCL C only, real8): 8-wide nodes, the same blocks (layout.h;
 *                      the packer's bvh_width, from the table's dtype)
 *   BVH_COMPACT        1 with BVH_WIDTH 2: compact records, both children's boxes (16-bit grid) and
 *                      links in one 32-byte record (the packer's bvh_compact; GLSL on llvmpipe)
 *   USE_TLAS           find instances through the top-level tree (tlas_nodes), not a loop over all
 *   TLAS_STACK_SIZE    its traversal stack; the host sizes it to the tree's depth
 *   SKIP_CLEAR_SEARCH  1: skip the mesh searches the host's clearances prove empty (box rows' rot0.w,
 *                      the camera row's lens.z); FACE_NEXT_BOX 1: the box after a face of a box alone
 *                      (rot1.w) from the face, not the loop (engine/box_clearance.py); 0 for A/B only
 *
 * Entry point: Pixel trace_pixel(SCENE_DECL Camera cam, int i, int j).
 * Rules of the subset: no overloading, no `inout`/`out` (functions return
 * structs), no vector comparisons, no v[i] (VIDX3), literals with an `f`
 * suffix wrapped in REAL() where they meet reals, no float3-real mixing
 * without a cast (OpenCL C has no implicit vector conversions).
 */

#ifndef MAX_EVENTS
#define MAX_EVENTS 16
#endif
#ifndef HAS_PORTALS
#define HAS_PORTALS 0
#endif
#ifndef HAS_ABERRATIONS
#define HAS_ABERRATIONS 0
#endif
#ifndef REAL_IS_DOUBLE
#define REAL_IS_DOUBLE 0
#endif
#ifndef EDGE_FALLBACK_FP64
#define EDGE_FALLBACK_FP64 0
#endif
#ifndef WORLD_FP64
#define WORLD_FP64 0
#endif
#ifndef BRUTE_FORCE
#define BRUTE_FORCE 0
#endif
#ifndef BVH_STACK_SIZE
#define BVH_STACK_SIZE 64
#endif
#ifndef USE_TLAS
#define USE_TLAS 1
#endif
#ifndef TLAS_STACK_SIZE
#define TLAS_STACK_SIZE 32
#endif

#ifndef HAS_METRIC
#define HAS_METRIC 0
#endif
/* Shortcuts the host's box clearances prove exact (engine/box_clearance.py, docs/semantics.md section 14);
 * 0 turns one off (A/B benchmarks, and tests that the frames are bit-identical either way). Measured
 * (800x800, CPU time): -16 ms OpenCL, -29 ms GLSL per frame on ten-boxes-aberration, -6 ms GLSL on
 * ten-boxes-portals. */
#ifndef SKIP_CLEAR_SEARCH
#define SKIP_CLEAR_SEARCH 1
#endif
#ifndef FACE_NEXT_BOX
#define FACE_NEXT_BOX 1
#endif
#ifndef HAS_RADIAL
#define HAS_RADIAL 0
#endif
#ifndef HAS_ADDITIVE
#define HAS_ADDITIVE 0
#endif
/* Anything that bends or teleports rays: the journey has more than one leg. */
#define HAS_SPACE (HAS_ABERRATIONS || HAS_PORTALS)
/* Box modes that bend the perceived direction w (entry and exit rules). */
#define HAS_BENDING (HAS_RADIAL || HAS_ADDITIVE)

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
#else
#define T_MIN_RELATIVE REAL_C(1.0e-5)
#define TIE_RELATIVE REAL_C(2.0e-5)
#define NUDGE_RELATIVE REAL_C(5.0e-5)
#define BOX_WIDEN REAL_C(4.8e-7)
#endif
/* A vector shorter than this is not normalised: the previous direction is kept (no NaN ever). */
#define MIN_NORM REAL_C(1.0e-12)
/* Radial mode: an axis whose corner-ray range is narrower than this uses sigma_k = sign(v_k). */
#define COLLAPSED_RANGE REAL_C(1.0e-6)

/* Aberration modes and exit rules (engine.layout.ABERRATION_MODES / ABERRATION_EXITS). */
#define MODE_METRIC 0
#define MODE_RADIAL 1
#define MODE_ADDITIVE 2
#define EXIT_RESTORE 0
#define EXIT_REPEAT 1
#define EXIT_INVERT 2
/* Faces per box: face id = 6 * row + 2 * axis + (1 on the +1/2 side, 0 on the -1/2 side). */
#define BOX_FACES 6

/* Event kinds (DESIGN.md section 5). */
#define EVENT_NONE 0
#define EVENT_MESH 1
#define EVENT_ABERRATION 2
#define EVENT_PORTAL 3

/* --- records of the journey ------------------------------------------------------ */

/* The state a ray carries (DESIGN.md section 5, docs/semantics.md section 1). Coordinates are
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

/* What a pixel gets: colour quantised to 0..255 (as floats), the AOVs of DESIGN.md section 5. */
STRUCT_BEGIN(Pixel)
    float4 color;
    float depth;
    float perceived;
    int instance;   /* entity id, -1 for none */
    int events;
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

/* Whether a slab interval is crossed within (t_min, t_max]; false on NaN. */
bool slab_hit(real2 h, real t_min, real t_max)
{
    return h.y >= max(h.x, t_min) && h.x <= t_max;
}

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

/* --- watertight ray-triangle test -------------------------------------------------- */

/* Permute so the largest |d| component is z; swap x/y when it is negative (keeps the winding). */
FORCE_INLINE ShearedRay shear_ray(real3 o, real3 d)
{
    ShearedRay sr;
    int kz = dominant_axis(d);
    int kx = kz == 2 ? 0 : kz + 1;
    int ky = kx == 2 ? 0 : kx + 1;
    real dz = VIDX3(d, kz);
    if (dz < REAL(0.0f)) {
        int swap = kx;
        kx = ky;
        ky = swap;
    }
    real sz = REAL(1.0f) / dz;
    sr.o = o;
    sr.s = R3(VIDX3(d, kx) * sz, VIDX3(d, ky) * sz, sz);
    sr.kx = kx;
    sr.ky = ky;
    sr.kz = kz;
    return sr;
}

/* (t, w0, w1, w2): distance in units of the (unnormalised) direction and barycentric
 * weights, or t = REAL_MAX for no hit. Front faces (v0, v1, v2 counter-clockwise seen
 * from the ray) have positive edge functions; with cull only those count. Each vertex is
 * sheared on its own and a shared edge's function is the same two products in swapped
 * order, so a ray through a shared edge or vertex never falls through. Edge-on and
 * degenerate triangles never hit; no NaN leaves. */
FORCE_INLINE real4 intersect_triangle(ShearedRay sr, real3 v0, real3 v1, real3 v2, bool cull)
{
    real4 miss = R4(REAL_MAX, 0.0f, 0.0f, 0.0f);
    real3 a = v0 - sr.o;
    real3 b = v1 - sr.o;
    real3 c = v2 - sr.o;
    real a_z = VIDX3(a, sr.kz);
    real b_z = VIDX3(b, sr.kz);
    real c_z = VIDX3(c, sr.kz);
    PRECISE real ax = VIDX3(a, sr.kx) - sr.s.x * a_z;
    PRECISE real ay = VIDX3(a, sr.ky) - sr.s.y * a_z;
    PRECISE real bx = VIDX3(b, sr.kx) - sr.s.x * b_z;
    PRECISE real by = VIDX3(b, sr.ky) - sr.s.y * b_z;
    PRECISE real cx = VIDX3(c, sr.kx) - sr.s.x * c_z;
    PRECISE real cy = VIDX3(c, sr.ky) - sr.s.y * c_z;
    PRECISE real u = cx * by - cy * bx;
    PRECISE real v = ax * cy - ay * cx;
    PRECISE real w = bx * ay - by * ax;
#if EDGE_FALLBACK_FP64 && !REAL_IS_DOUBLE
    /* A float edge function has the exact sign or is 0; recompute the zeros exactly. */
    if (u == 0.0f || v == 0.0f || w == 0.0f) {
        PRECISE double ud = TO_DOUBLE(cx) * TO_DOUBLE(by) - TO_DOUBLE(cy) * TO_DOUBLE(bx);
        PRECISE double vd = TO_DOUBLE(ax) * TO_DOUBLE(cy) - TO_DOUBLE(ay) * TO_DOUBLE(cx);
        PRECISE double wd = TO_DOUBLE(bx) * TO_DOUBLE(ay) - TO_DOUBLE(by) * TO_DOUBLE(ax);
        /* Keep the float value where it is not 0; else the exact sign at the smallest scale. */
        u = u != 0.0f ? u : (ud > 0.0 ? 1.0e-37f : (ud < 0.0 ? -1.0e-37f : 0.0f));
        v = v != 0.0f ? v : (vd > 0.0 ? 1.0e-37f : (vd < 0.0 ? -1.0e-37f : 0.0f));
        w = w != 0.0f ? w : (wd > 0.0 ? 1.0e-37f : (wd < 0.0 ? -1.0e-37f : 0.0f));
    }
#endif
    bool front = u >= REAL(0.0f) && v >= REAL(0.0f) && w >= REAL(0.0f);
    bool back = u <= REAL(0.0f) && v <= REAL(0.0f) && w <= REAL(0.0f);
    if (!(front || (back && !cull))) {
        return miss;
    }
    real det = u + v + w;
    if (det == REAL(0.0f)) {
        return miss;
    }
    real az = sr.s.z * a_z;
    real bz = sr.s.z * b_z;
    real cz = sr.s.z * c_z;
    real inv = REAL(1.0f) / det;
    real t = (u * az + v * bz + w * cz) * inv;
    if (!(ABS(t) < REAL_MAX && ABS(inv) < REAL_MAX)) {
        return miss;
    }
    return R4(t, u * inv, v * inv, w * inv);
}

/* Keep hit (t, w0, w1, w2) of triangle k of instance row if it beats best: the hit smallest in
 * (t, instance, triangle), so neither the tree's nor a block's visiting order shows in results. */
FORCE_INLINE MeshHit keep_nearer(MeshHit best, bool ok, real t, real u, real v, real w, int k, int row, real t_min)
{
    bool tie_wins = row < best.instance || (row == best.instance && k < best.triangle);
    if (ok && t > t_min && (t < best.t || (t == best.t && best.instance >= 0 && tie_wins))) {
        best.t = t;
        best.bary = R3(u, v, w);
        best.instance = row;
        best.triangle = k;
    }
    return best;
}

/* Test triangle k of instance row (keep_nearer's rule). */
FORCE_INLINE MeshHit test_triangle(SCENE_DECL MeshHit best, ShearedRay sr, int k, int row, bool cull, real t_min)
{
    Triangle tri = TRIANGLE(k);
    real4 h = intersect_triangle(sr, TO_REAL3(tri.v0.xyz), TO_REAL3(tri.v1.xyz), TO_REAL3(tri.v2.xyz), cull);
    return keep_nearer(best, true, h.x, h.y, h.z, h.w, k, row, t_min);
}

#if BVH_WIDTH >= 4
/* The x, y or z float4 of a block's vertex (axis i, per ray, once per block: not per lane). */
#define BLOCK_AXIS(blk, V, i) TO_REAL4((i) == 0 ? blk.V##x : ((i) == 1 ? blk.V##y : blk.V##z))

/* intersect_triangle on the four triangles of triangle_blocks row b at once: the same per-triangle
 * arithmetic in 4-vectors (so the same watertight results, bit for bit), then test_triangle's rule
 * lane by lane. Padding lanes (index -1) never hit. */
FORCE_INLINE MeshHit test_block(SCENE_DECL MeshHit best, ShearedRay sr, int b, int row, bool cull, real t_min)
{
    TriangleBlock blk = TRIANGLE_BLOCK(b);
#if EDGE_FALLBACK_FP64 && !REAL_IS_DOUBLE
    /* Exact signs of zero edge functions are a per-lane branch: the scalar test keeps them exact. */
    int4 index = blk.index;
    for (int lane = 0; lane < 4; ++lane) {
        int k = lane == 0 ? index.x : (lane == 1 ? index.y : (lane == 2 ? index.z : index.w));
        if (k >= 0) {
            best = test_triangle(SCENE_PASS best, sr, k, row, cull, t_min);
        }
    }
    return best;
#else
    real ox = VIDX3(sr.o, sr.kx);
    real oy = VIDX3(sr.o, sr.ky);
    real oz = VIDX3(sr.o, sr.kz);
    real4 o_x = R4(ox, ox, ox, ox);
    real4 o_y = R4(oy, oy, oy, oy);
    real4 o_z = R4(oz, oz, oz, oz);
    real4 s_x = R4(sr.s.x, sr.s.x, sr.s.x, sr.s.x);
    real4 s_y = R4(sr.s.y, sr.s.y, sr.s.y, sr.s.y);
    real4 s_z = R4(sr.s.z, sr.s.z, sr.s.z, sr.s.z);
    real4 a_z = BLOCK_AXIS(blk, v0, sr.kz) - o_z;
    real4 b_z = BLOCK_AXIS(blk, v1, sr.kz) - o_z;
    real4 c_z = BLOCK_AXIS(blk, v2, sr.kz) - o_z;
    PRECISE real4 ax = (BLOCK_AXIS(blk, v0, sr.kx) - o_x) - s_x * a_z;
    PRECISE real4 ay = (BLOCK_AXIS(blk, v0, sr.ky) - o_y) - s_y * a_z;
    PRECISE real4 bx = (BLOCK_AXIS(blk, v1, sr.kx) - o_x) - s_x * b_z;
    PRECISE real4 by = (BLOCK_AXIS(blk, v1, sr.ky) - o_y) - s_y * b_z;
    PRECISE real4 cx = (BLOCK_AXIS(blk, v2, sr.kx) - o_x) - s_x * c_z;
    PRECISE real4 cy = (BLOCK_AXIS(blk, v2, sr.ky) - o_y) - s_y * c_z;
    PRECISE real4 u = cx * by - cy * bx;
    PRECISE real4 v = ax * cy - ay * cx;
    PRECISE real4 w = bx * ay - by * ax;
    real4 det = u + v + w;
    real4 inv = R4(1.0f, 1.0f, 1.0f, 1.0f) / det;
    real4 t = (u * (s_z * a_z) + v * (s_z * b_z) + w * (s_z * c_z)) * inv;
    real4 uu = u * inv;
    real4 vv = v * inv;
    real4 ww = w * inv;
    /* Per lane: front (or back without culling), det != 0, finite t and 1/det: intersect_triangle's tests. */
#define BLOCK_LANE_OK(L)                                                                              \
    (blk.index.L >= 0 &&                                                                              \
     ((u.L >= REAL(0.0f) && v.L >= REAL(0.0f) && w.L >= REAL(0.0f)) ||                                \
      (!cull && u.L <= REAL(0.0f) && v.L <= REAL(0.0f) && w.L <= REAL(0.0f))) &&                       \
     det.L != REAL(0.0f) && ABS(t.L) < REAL_MAX && ABS(inv.L) < REAL_MAX)
    best = keep_nearer(best, BLOCK_LANE_OK(x), t.x, uu.x, vv.x, ww.x, blk.index.x, row, t_min);
    best = keep_nearer(best, BLOCK_LANE_OK(y), t.y, uu.y, vv.y, ww.y, blk.index.y, row, t_min);
    best = keep_nearer(best, BLOCK_LANE_OK(z), t.z, uu.z, vv.z, ww.z, blk.index.z, row, t_min);
    best = keep_nearer(best, BLOCK_LANE_OK(w), t.w, uu.w, vv.w, ww.w, blk.index.w, row, t_min);
#undef BLOCK_LANE_OK
    return best;
#endif
}
#endif

/* --- per-instance BVH traversal ------------------------------------------------------ */

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
#endif

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

/* Entry and exit t of a compact record's child box (16-bit grid coordinates c.xyz, see layout.h):
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

/* The ray (camera-relative world o, d) against one instance: into object space with
 * world_to_object, the direction left unnormalised so t stays the world t; then the
 * asset's BVH from its root, nearest child first, with a small stack. */
FORCE_INLINE MeshHit trace_instance(SCENE_DECL MeshHit best, int row, real3 o, real3 d, real t_min)
{
    Instance inst = INSTANCE(row);
    real3 oo = R3(dot(inst.w2o0.xyz, o) + inst.w2o0.w, dot(inst.w2o1.xyz, o) + inst.w2o1.w,
                  dot(inst.w2o2.xyz, o) + inst.w2o2.w);
    real3 dd = R3(dot(inst.w2o0.xyz, d), dot(inst.w2o1.xyz, d), dot(inst.w2o2.xyz, d));
    bool cull = MATERIAL(inst.meta.y).flags.x != 0;
    ShearedRay sr = shear_ray(oo, dd);
    int root = inst.meta.x;
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
#elif BRUTE_FORCE && BVH_WIDTH == 8
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
#elif BRUTE_FORCE && BVH_COMPACT
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
#elif BVH_WIDTH == 8
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
        /* Skip entries entered beyond the best hit, then pop the next one, or done (-1 %). */
        while (sp > 0 && stack_t[sp - 1] > best.t) {
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
            BvhNode c0 = BVH_NODE(first);
            BvhNode c1 = BVH_NODE(first + 1);
            real2 h0 = slab(oo, inv, TO_REAL3(c0.lo.xyz), TO_REAL3(c0.hi.xyz));
            real2 h1 = slab(oo, inv, TO_REAL3(c1.lo.xyz), TO_REAL3(c1.hi.xyz));
            bool hit0 = slab_hit(h0, t_min, best.t);
            bool hit1 = slab_hit(h1, t_min, best.t);
            if (hit0 || hit1) {
                /* Visit the nearer child now, push the other (the host checks the depth fits). */
                bool second_first = hit1 && (!hit0 || h1.x < h0.x);
                if (hit0 && hit1 && sp < BVH_STACK_SIZE) {
                    stack_node[sp] = second_first ? first : first + 1;
                    stack_t[sp] = second_first ? h0.x : h1.x;
                    sp += 1;
                }
                node = second_first ? c1 : c0;
            } else {
                /* Pop the next node still entered before the best hit. */
                bool found = false;
                while (sp > 0 && !found) {
                    sp -= 1;
                    if (stack_t[sp] <= best.t) {
                        node = BVH_NODE(stack_node[sp]);
                        found = true;
                    }
                }
                done = !found;
            }
            first = AS_INT(node.lo.w);
            count = AS_INT(node.hi.w);
        }
        if (!done) {
            for (int k = first; k < first + count; ++k) {
                best = test_triangle(SCENE_PASS best, sr, k, row, cull, t_min);
            }
            bool found = false;
            while (sp > 0 && !found) {
                sp -= 1;
                if (stack_t[sp] <= best.t) {
                    node = BVH_NODE(stack_node[sp]);
                    found = true;
                }
            }
            done = !found;
            first = AS_INT(node.lo.w);
            count = AS_INT(node.hi.w);
        }
    }
    return best;
#endif
}

/* The nearest triangle hit with t_min < t <= t_max over every instance. USE_TLAS: the instances
 * a ray can reach come from the top-level tree (tlas_nodes, engine/tlas.py), nearest child first;
 * each leaf's instance is then culled by its exact world bounds (the leaf's are fattened, so a
 * small move changes only the instance row). Else: every instance's world bounds in turn. Equal t
 * across instances goes to the lower row either way (test_triangle), so the order is unseen. */
FORCE_INLINE MeshHit nearest_mesh(SCENE_DECL real3 o, real3 d, real t_min, real t_max)
{
    MeshHit best;
    best.t = t_max;
    best.bary = R3S(0.0f);
    best.instance = -1;
    best.triangle = -1;
    int count = SETTINGS.counts.x;
    if (!(dot(d, d) > REAL(0.0f)) || count == 0) {
        return best; /* a zero or NaN direction hits nothing */
    }
    real3 inv = safe_inverse(d);
#if USE_TLAS
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
            TlasNode c0 = TLAS_NODE(first);
            TlasNode c1 = TLAS_NODE(first + 1);
            real2 h0 = slab(o, inv, TO_REAL3(c0.lo.xyz), TO_REAL3(c0.hi.xyz));
            real2 h1 = slab(o, inv, TO_REAL3(c1.lo.xyz), TO_REAL3(c1.hi.xyz));
            bool hit0 = slab_hit(h0, t_min, best.t);
            bool hit1 = slab_hit(h1, t_min, best.t);
            if (hit0 || hit1) {
                /* The nearer child now, the other on the stack (the host sizes it to the tree's depth). */
                bool second_first = hit1 && (!hit0 || h1.x < h0.x);
                if (hit0 && hit1 && sp < TLAS_STACK_SIZE) {
                    stack_node[sp] = second_first ? first : first + 1;
                    stack_t[sp] = second_first ? h0.x : h1.x;
                    sp += 1;
                }
                node = second_first ? c1 : c0;
            } else {
                more = false;
                while (sp > 0 && !more) {
                    sp -= 1;
                    if (stack_t[sp] <= best.t) {
                        node = TLAS_NODE(stack_node[sp]);
                        more = true;
                    }
                }
            }
        }
        if (more) {
            /* A leaf: its instance, culled by the exact bounds on the instance row; then the next node
             * still entered before the best hit, or done. */
            int row = AS_INT(node.lo.w);
            real2 h = slab(o, inv, INSTANCE(row).bounds_min.xyz, INSTANCE(row).bounds_max.xyz);
            if (slab_hit(h, t_min, best.t)) {
                best = trace_instance(SCENE_PASS best, row, o, d, t_min);
            }
            more = false;
            while (sp > 0 && !more) {
                sp -= 1;
                if (stack_t[sp] <= best.t) {
                    node = TLAS_NODE(stack_node[sp]);
                    more = true;
                }
            }
        }
    }
#else
    for (int i = 0; i < count; ++i) {
        real2 h = slab(o, inv, INSTANCE(i).bounds_min.xyz, INSTANCE(i).bounds_max.xyz);
        if (slab_hit(h, t_min, best.t)) {
            best = trace_instance(SCENE_PASS best, i, o, d, t_min);
        }
    }
#endif
    return best;
}

/* --- shading (DESIGN.md section 4) ------------------------------------------------------ */

/* Checker parity of cell (floor(a/c) + floor(b/c)): true in odd (dark) cells. */
bool checker_odd(real a, real b, real c)
{
    real s = floor(a / c) + floor(b / c);
    return s - REAL(2.0f) * floor(s * REAL(0.5f)) == REAL(1.0f);
}

#if WORLD_FP64 && !REAL_IS_DOUBLE
bool checker_odd_fp64(double a, double b, double c)
{
    double s = floor(a / c) + floor(b / c);
    return s - 2.0 * floor(s * 0.5) == 1.0;
}
#endif

/* base * checker * (ambient + (1 - ambient) * max(0, n.l)), n the geometric normal
 * (object normal through the transpose of world_to_object's 3x3) turned to face the ray.
 * position is camera-relative; cam.origin turns it into world space for triplanar cells. */
FORCE_INLINE float3 shade(SCENE_DECL Camera cam, MeshHit hit, real3 r, real3 position)
{
    Instance inst = INSTANCE(hit.instance);
    Triangle tri = TRIANGLE(hit.triangle);
    real3 v0 = TO_REAL3(tri.v0.xyz);
    real3 n_obj = cross(TO_REAL3(tri.v1.xyz) - v0, TO_REAL3(tri.v2.xyz) - v0);
    real3 n = n_obj.x * inst.w2o0.xyz + n_obj.y * inst.w2o1.xyz + n_obj.z * inst.w2o2.xyz;
    real len = length(n);
    n = (len > REAL(0.0f) && len < REAL_MAX) ? n / len : R3S(0.0f);
    if (dot(n, r) > REAL(0.0f)) {
        n = -n;
    }
    float ambient = SETTINGS.shading.x;
    float lambert = max(0.0f, TO_FLOAT(dot(n, TO_REAL3(SETTINGS.light_dir.xyz))));
    Material mat = MATERIAL(inst.meta.y);
    float cell = mat.color.w;
    float factor = 1.0f;
    if (cell > 0.0f) {
        bool odd = false;
        if ((inst.meta.w & 1) != 0) {
            TriangleUv t = TRIANGLE_UV(hit.triangle);
            real u = hit.bary.x * TO_REAL(t.uv01.x) + hit.bary.y * TO_REAL(t.uv01.z) + hit.bary.z * TO_REAL(t.uv2.x);
            real v = hit.bary.x * TO_REAL(t.uv01.y) + hit.bary.y * TO_REAL(t.uv01.w) + hit.bary.z * TO_REAL(t.uv2.y);
            odd = checker_odd(u, v, TO_REAL(cell));
        } else {
            /* Triplanar: the two world axes other than the normal's dominant one. */
            int axis = dominant_axis(n);
            int ia = axis == 2 ? 0 : axis + 1;
            int ib = ia == 2 ? 0 : ia + 1;
#if WORLD_FP64 && !REAL_IS_DOUBLE
            double a = TO_DOUBLE(VIDX3(cam.origin.xyz, ia)) + TO_DOUBLE(VIDX3(position, ia));
            double b = TO_DOUBLE(VIDX3(cam.origin.xyz, ib)) + TO_DOUBLE(VIDX3(position, ib));
            odd = checker_odd_fp64(a, b, TO_DOUBLE(cell));
#else
            real a = VIDX3(cam.origin.xyz, ia) + VIDX3(position, ia);
            real b = VIDX3(cam.origin.xyz, ib) + VIDX3(position, ib);
            odd = checker_odd(a, b, TO_REAL(cell));
#endif
        }
        factor = odd ? 0.5f : 1.0f;
    }
    return mat.color.xyz * (factor * (ambient + (1.0f - ambient) * lambert));
}

/* --- vectors of the journey (docs/semantics.md rule 11) ------------------------------------- */

#if HAS_SPACE
/* The affine map with rows m0, m1, m2 (3x4) applied to a point. */
real3 affine_point(real4 m0, real4 m1, real4 m2, real3 p)
{
    return R3(dot(m0.xyz, p) + m0.w, dot(m1.xyz, p) + m1.w, dot(m2.xyz, p) + m2.w);
}

/* The linear part of the map with rows m0, m1, m2 applied to a vector. */
real3 linear_vector(real4 m0, real4 m1, real4 m2, real3 v)
{
    return R3(dot(m0.xyz, v), dot(m1.xyz, v), dot(m2.xyz, v));
}

/* v scaled to unit length; previous where |v| < MIN_NORM or |v| is not finite (directions.normalize_or_keep). */
real3 normalize_or_keep(real3 v, real3 previous)
{
    real len = length(v);
    return (len >= MIN_NORM && len < REAL_MAX) ? v / len : previous;
}

bool same_direction(real3 a, real3 b)
{
    return a.x == b.x && a.y == b.y && a.z == b.z;
}

/* Candidates within this of the nearest (at t from o, o_len = |o|) are tied: |o| + t bounds the event point's size. */
real tie_window(real o_len, real t)
{
    return TIE_RELATIVE * max(REAL(1.0f), o_len + t);
}
#endif

/* --- aberrations (DESIGN.md section 6, docs/semantics.md rules 3-9; reference/aberrations.py) --- */

#if HAS_ABERRATIONS
/* Entry and exit of a ray through the unit box, built axis by axis (aberrations.slab_faces). */
STRUCT_BEGIN(BoxSpan)
    real t_near;
    real t_far;
    int near_face;
    int far_face;
STRUCT_END(BoxSpan)

/* Axis k of the slab test: a, v the local origin and direction components. An axis with v = 0 is
 * inside its slab for every t when |a| <= 1/2 (closed box) and nowhere otherwise; equal entries
 * keep the lower axis (strict comparisons). */
BoxSpan box_axis(BoxSpan span, real a, real v, int k)
{
    if (v != REAL(0.0f)) {
        bool up = v > REAL(0.0f);
        /* One division per axis, not two (section 14: a face's t may differ by an ulp from the reference's). */
        real inv = REAL(1.0f) / v;
        real t_minus = (REAL(-0.5f) - a) * inv;
        real t_plus = (REAL(0.5f) - a) * inv;
        real tn = up ? t_minus : t_plus;
        real tf = up ? t_plus : t_minus;
        if (tn > span.t_near) {
            span.t_near = tn;
            span.near_face = up ? 2 * k : 2 * k + 1;
        }
        if (tf < span.t_far) {
            span.t_far = tf;
            span.far_face = up ? 2 * k + 1 : 2 * k;
        }
    } else if (!(ABS(a) <= REAL(0.5f))) {
        span.t_near = REAL_MAX;
        span.t_far = -REAL_MAX;
    }
    return span;
}

/* The nearest box face crossed with t_min < t (aberrations.nearest_box_faces): kind EVENT_ABERRATION,
 * row = face id, t = REAL_MAX for none. The face being left (skip) never counts; ties go to the
 * lower row, then the entry face. */
FORCE_INLINE Event nearest_box_face(SCENE_DECL real3 o, real3 r, real t_min, int skip)
{
    Event best;
    best.t = REAL_MAX;
    best.kind = EVENT_NONE;
    best.row = -1;
    best.far = -REAL_MAX;
    best.gap = REAL(0.0f);
    best.clear = REAL(0.0f);
    int count = SETTINGS.counts.y;
    for (int b = 0; b < count; ++b) {
        Aberration box = ABERRATION(b);
        real3 a = affine_point(box.w2l0, box.w2l1, box.w2l2, o);
        real3 v = linear_vector(box.w2l0, box.w2l1, box.w2l2, r);
        BoxSpan span;
        span.t_near = -REAL_MAX;
        span.t_far = REAL_MAX;
        span.near_face = -1;
        span.far_face = -1;
        span = box_axis(span, a.x, v.x, 0);
        span = box_axis(span, a.y, v.y, 1);
        span = box_axis(span, a.z, v.z, 2);
        if (span.t_near <= span.t_far) {
            int id = BOX_FACES * b + span.near_face;
            if (span.near_face >= 0 && span.t_near > t_min && span.t_near < best.t && id != skip) {
                best.t = span.t_near;
                best.kind = EVENT_ABERRATION;
                best.row = id;
                best.far = span.t_far;
                best.gap = box.rot1.w;
            }
            id = BOX_FACES * b + span.far_face;
            if (span.far_face >= 0 && span.t_far > t_min && id != skip) {
                if (span.t_far < best.t) {
                    best.t = span.t_far;
                    best.kind = EVENT_ABERRATION;
                    best.row = id;
                    best.far = -REAL_MAX;
                    best.gap = box.rot1.w;
                }
#if SKIP_CLEAR_SEARCH
                /* The segment from t_min to this exit lies in the box: its clearance bounds the reach. */
                if (span.t_near <= t_min) {
                    best.clear = max(best.clear, box.rot0.w);
                }
#endif
            }
        }
    }
    return best;
}

/* The active box at a point: the last row whose closed unit box contains it, -1 for none
 * (aberrations.containing_box; rows are sorted by priority, then entity). */
int containing_box(SCENE_DECL real3 p)
{
    int found = -1;
    int count = SETTINGS.counts.y;
    for (int b = 0; b < count; ++b) {
        Aberration box = ABERRATION(b);
        real3 q = affine_point(box.w2l0, box.w2l1, box.w2l2, p);
        if (ABS(q.x) <= REAL(0.5f) && ABS(q.y) <= REAL(0.5f) && ABS(q.z) <= REAL(0.5f)) {
            found = b;
        }
    }
    return found;
}

/* The active box just past the point o + t r (NUDGE_RELATIVE of its size further along r). */
int box_after(SCENE_DECL real3 o, real3 r, real o_len, real t)
{
    real nudge = NUDGE_RELATIVE * max(REAL(1.0f), o_len + t);
    return containing_box(SCENE_PASS o + (t + nudge) * r);
}

/* box_after for a box face event (face): a box farther than the nudge from every other box (its gap,
 * from the host) is the only one that can hold the looked-up point, and the point is in it exactly when
 * the face is its entry and the nudge stays short of its exit. Else the loop over the boxes. */
int box_after_face(SCENE_DECL real3 o, real3 r, real o_len, real r_len, Event face)
{
    real nudge = NUDGE_RELATIVE * max(REAL(1.0f), o_len + face.t);
#if FACE_NEXT_BOX
    if (face.gap > REAL(2.0f) * nudge * r_len) {
        return face.t + nudge <= face.far ? face.row / BOX_FACES : -1;
    }
#endif
    return containing_box(SCENE_PASS o + (face.t + nudge) * r);
}

bool zero_deformation(Aberration box)
{
    return box.deformation.x == REAL(0.0f) && box.deformation.y == REAL(0.0f) && box.deformation.z == REAL(0.0f);
}

/* The perceived and world directions after a transition, and the new perceived rate. */
STRUCT_BEGIN(Turn)
    real3 w;
    real3 r;
    real f;
STRUCT_END(Turn)

#if HAS_METRIC
/* s (.) (R^T w) in box axes, s = 1 + D (aberrations._metric_local); rot rows are R's rows. */
real3 metric_local(Aberration box, real3 w)
{
    real3 axes = w.x * box.rot0.xyz + w.y * box.rot1.xyz + w.z * box.rot2.xyz;
    return (R3S(1.0f) + box.deformation.xyz) * axes;
}

/* r = normalize(R scaled) (aberrations.world_direction), scaled = metric_local(box, w) of length norm,
 * f = perceived_rate(norm); previous if degenerate. R is a rotation, so |R scaled| = |scaled|: r is
 * R scaled times f, one norm and one division for both (docs/semantics.md section 14). (The caller
 * skips a box with D = 0: it leaves the unit w as it is.) */
real3 metric_direction(Aberration box, real3 scaled, real norm, real f, real3 previous)
{
    real3 world = R3(dot(box.rot0.xyz, scaled), dot(box.rot1.xyz, scaled), dot(box.rot2.xyz, scaled));
    return (norm >= MIN_NORM && norm < REAL_MAX) ? world * f : previous;
}
#endif

/* Perceived length per world length in a metric box (aberrations.perceived_per_world): 1 / |scaled|
 * from norm = |scaled|, scaled = metric_local(box, w) (0 where the norm overflows); 1 elsewhere and
 * in a box with D = 0. */
real perceived_rate(real norm)
{
    return norm > REAL(0.0f) ? REAL(1.0f) / norm : REAL(1.0f);
}

#if HAS_BENDING
#if HAS_RADIAL
/* One axis of sigma: 2 smoothstep(lo, hi, v) - 1, or sign(v) where the range collapsed. */
real sigma_axis(real v, real lo, real hi)
{
    real span = hi - lo;
    if (span < COLLAPSED_RANGE) {
        return v > REAL(0.0f) ? REAL(1.0f) : (v < REAL(0.0f) ? REAL(-1.0f) : REAL(0.0f));
    }
    real u = clamp((v - lo) / span, REAL(0.0f), REAL(1.0f));
    return REAL(2.0f) * (u * u * (REAL(3.0f) - REAL(2.0f) * u)) - REAL(1.0f);
}
#endif

/* The entry rule of a radial/additive box with scale * D (scale = 1 or -1) applied to w (aberrations.bend): radial
 * normalize(w + D (.) sigma(w)), additive normalize(w + D); w kept where the sum degenerates, and
 * where nothing is added (w is unit already). lo, hi: the camera's sigma bounds. */
real3 bend(Aberration box, real3 w, real scale, real3 lo, real3 hi)
{
    real3 offset = scale * box.deformation.xyz;
#if HAS_RADIAL
    if (box.meta.x == MODE_RADIAL) {
        offset = offset * R3(sigma_axis(w.x, lo.x, hi.x), sigma_axis(w.y, lo.y, hi.y), sigma_axis(w.z, lo.z, hi.z));
    }
#endif
    if (offset.x == REAL(0.0f) && offset.y == REAL(0.0f) && offset.z == REAL(0.0f)) {
        return w;
    }
    return normalize_or_keep(w + offset, w);
}
#endif

/* The transition from box old to box next (aberrations.transition; -1 for none), lo/hi the sigma
 * bounds: 1. leaving a bending box, its exit rule sets w (restore: d0, repeat: its entry rule
 * again, invert: with -D); 2. entering a bending box, its entry rule bends w; 3. r follows from w
 * by the new box (metric) or is w. */
FORCE_INLINE Turn transition(SCENE_DECL int old, int next, real3 w, real3 r, real3 d0, real3 lo, real3 hi)
{
#if HAS_BENDING
    if (old != next) {
        if (old >= 0) {
            Aberration box = ABERRATION(old);
            if (box.meta.x != MODE_METRIC) {
                int rule = box.meta.y;
                w = rule == EXIT_RESTORE ? d0 : bend(box, w, rule == EXIT_INVERT ? REAL(-1.0f) : REAL(1.0f), lo, hi);
            }
        }
        if (next >= 0) {
            Aberration box = ABERRATION(next);
            if (box.meta.x != MODE_METRIC) {
                w = bend(box, w, REAL(1.0f), lo, hi);
            }
        }
    }
#endif
    Turn turn;
    turn.w = w;
    turn.r = w;
    turn.f = REAL(1.0f);
#if HAS_METRIC
    if (next >= 0) {
        /* s (.) R^T w once, for both the direction and the rate. */
        Aberration box = ABERRATION(next);
        if (box.meta.x == MODE_METRIC && !zero_deformation(box)) {
            real3 scaled = metric_local(box, w);
            real norm = length(scaled);
            turn.f = perceived_rate(norm);
            turn.r = metric_direction(box, scaled, norm, turn.f, r);
        }
    }
#endif
    return turn;
}
#endif

/* --- portals (DESIGN.md section 7, docs/semantics.md rules 3 and 10; reference/portals.py) -------- */

#if HAS_PORTALS
/* The nearest linked portal quad the ray passes through with t_min < t (portals.nearest_portal_hits):
 * kind EVENT_PORTAL, t = REAL_MAX for none. The closed quad |x|, |y| <= 1 at z = 0, two-sided; a ray
 * parallel to its plane never hits; the portal being left (skip) and unlinked ones never count; ties
 * go to the lower row. */
FORCE_INLINE Event nearest_portal(SCENE_DECL real3 o, real3 r, real t_min, int skip)
{
    Event best;
    best.t = REAL_MAX;
    best.kind = EVENT_NONE;
    best.row = -1;
    best.far = -REAL_MAX;
    best.gap = REAL(0.0f);
    best.clear = REAL(0.0f);
    int count = SETTINGS.counts.z;
    for (int p = 0; p < count; ++p) {
        Portal portal = PORTAL(p);
        if (portal.meta.x >= 0 && p != skip) {
            real3 a = affine_point(portal.w2l0, portal.w2l1, portal.w2l2, o);
            real3 v = linear_vector(portal.w2l0, portal.w2l1, portal.w2l2, r);
            if (v.z != REAL(0.0f)) {
                real t = -a.z / v.z;
                real x = a.x + t * v.x;
                real y = a.y + t * v.y;
                if (t > t_min && t < best.t && ABS(x) <= REAL(1.0f) && ABS(y) <= REAL(1.0f)) {
                    best.t = t;
                    best.kind = EVENT_PORTAL;
                    best.row = p;
                }
            }
        }
    }
    return best;
}

/* Through portal row at t along the leg (portals.teleport): the segment's length is added, then the
 * hit point goes through X and r, w, d0 through its linear part (renormalised, kept if degenerate);
 * a new leg starts on the target quad, which the ray is then leaving. The active box is the caller's. */
FORCE_INLINE Ray teleport(SCENE_DECL Ray ray, int row, real t)
{
    ray.L = ray.L + t * ray.r_len;
    ray.Lambda = ray.Lambda + (t - ray.t_piece) * ray.r_len * ray.f;
    Portal portal = PORTAL(row);
    ray.o = affine_point(portal.transfer0, portal.transfer1, portal.transfer2, ray.o + t * ray.r);
    ray.r = normalize_or_keep(linear_vector(portal.transfer0, portal.transfer1, portal.transfer2, ray.r), ray.r);
    ray.w = normalize_or_keep(linear_vector(portal.transfer0, portal.transfer1, portal.transfer2, ray.w), ray.w);
    ray.d0 = normalize_or_keep(linear_vector(portal.transfer0, portal.transfer1, portal.transfer2, ray.d0), ray.d0);
    ray.o_len = length(ray.o);
    ray.r_len = length(ray.r);
    ray.t_from = REAL(0.0f);
    ray.t_piece = REAL(0.0f);
    ray.leaving_kind = EVENT_PORTAL;
    ray.leaving = portal.meta.x;
    return ray;
}
#endif

/* --- the journey (DESIGN.md section 5, docs/semantics.md sections 3-13) -------------------------- */

/* The primary ray through pixel (i, j), row 0 = top (DESIGN.md section 3): the camera-space
 * vector normalised, then rotated (never a difference of two world points). */
FORCE_INLINE Ray primary_ray(Camera cam, int i, int j)
{
    real tan_half = cam.lens.x;
    real aspect = cam.lens.y;
    real x = (REAL(2.0f) * (TO_REAL(i) + REAL(0.5f)) / TO_REAL(cam.size.x) - REAL(1.0f)) * aspect * tan_half;
    real y = (REAL(1.0f) - REAL(2.0f) * (TO_REAL(j) + REAL(0.5f)) / TO_REAL(cam.size.y)) * tan_half;
    real3 cam_dir = normalize(R3(x, y, -1.0f));
    real3 d = cam_dir.x * cam.right.xyz + cam_dir.y * cam.up.xyz + cam_dir.z * cam.back.xyz;
    Ray ray;
    ray.o = cam.position.xyz;
    ray.r = d;
    ray.o_len = length(ray.o);
    ray.r_len = length(d);
    ray.w = d;
    ray.d0 = d;
    ray.L = REAL(0.0f);
    ray.Lambda = REAL(0.0f);
    ray.t_from = REAL(0.0f);
    ray.t_piece = REAL(0.0f);
    ray.f = REAL(1.0f);
    ray.aberration = -1;
    ray.n = 0;
    ray.leaving_kind = -1;
    ray.leaving = -1;
    return ray;
}

#if HAS_ABERRATIONS
/* After an event that left the ray at t along its leg (a box face) or at a new leg's start (a portal,
 * t = 0): the transition into the active box next just past that point (rule 7; box_after), and a
 * new leg where the direction changed. Lambda is closed off where the perceived rate changes. */
FORCE_INLINE Ray enter_box(SCENE_DECL Ray ray, real t, int next, real3 lo, real3 hi)
{
    Turn turn = transition(SCENE_PASS ray.aberration, next, ray.w, ray.r, ray.d0, lo, hi);
    real len_r = ray.r_len;
    if (same_direction(turn.r, ray.r)) {
        if (turn.f != ray.f) {
            ray.Lambda = ray.Lambda + (t - ray.t_piece) * len_r * ray.f;
            ray.t_piece = t;
        }
        ray.t_from = t;
    } else {
        ray.L = ray.L + t * len_r;
        ray.Lambda = ray.Lambda + (t - ray.t_piece) * len_r * ray.f;
        ray.o = ray.o + t * ray.r;
        ray.r = turn.r;
        ray.o_len = length(ray.o);
        ray.r_len = length(ray.r);
        ray.t_from = REAL(0.0f);
        ray.t_piece = REAL(0.0f);
    }
    ray.w = turn.w;
    ray.f = turn.f;
    ray.aberration = next;
    return ray;
}
#endif

Pixel trace_pixel(SCENE_DECL Camera cam, int i, int j)
{
    Ray ray = primary_ray(cam, i, j);
    Pixel px;
    px.color = quantize_rgba(SETTINGS.background.xyz);
    px.depth = F_INF;
    px.perceived = F_INF;
    px.instance = -1;
    px.events = 0;
#if HAS_ABERRATIONS
    /* The radial mode's bounds from the camera's corner rays; the transition into the camera's box. */
    real3 sigma_lo = cam.sigma_min.xyz;
    real3 sigma_hi = cam.sigma_max.xyz;
    /* The camera's box, the same for every ray unless the camera is near a face (the host's camera_box):
     * no box needs no transition at all, and the per-ray look-up runs only where rays may disagree. */
    int camera_box = cam.size.z;
    if (camera_box != -1) {
        int next = camera_box >= 0 ? camera_box : box_after(SCENE_PASS ray.o, ray.r, ray.o_len, REAL(0.0f));
        ray = enter_box(SCENE_PASS ray, REAL(0.0f), next, sigma_lo, sigma_hi);
    }
#endif
    MeshHit hit;
    hit.t = REAL_MAX;
    hit.bary = R3S(0.0f);
    hit.instance = -1;
    hit.triangle = -1;
    int max_events = max(1, min(SETTINGS.counts.w, MAX_EVENTS));
    /* Each pass either ends the ray or counts an event, so MAX_EVENTS + 1 passes always suffice. */
    for (int pass = 0; pass <= MAX_EVENTS; ++pass) {
        if (ray.n >= max_events) {
            px.color = quantize_rgba(SETTINGS.event_limit_color.xyz);
            break;
        }
        /* 1. The nearest of: a linked portal quad, a box face, a mesh triangle, past the point the ray
         * leaves (t_from along the leg) by t_min, skipping the surface it leaves. */
        real t_min = ray.t_from + T_MIN_RELATIVE * max(REAL(1.0f), ray.o_len + ray.t_from);
        real t_cut = REAL_MAX;
#if HAS_PORTALS
        Event portal = nearest_portal(SCENE_PASS ray.o, ray.r, t_min, ray.leaving_kind == EVENT_PORTAL ? ray.leaving : -1);
        t_cut = portal.t;
#endif
#if HAS_ABERRATIONS
        Event face = nearest_box_face(SCENE_PASS ray.o, ray.r, t_min, ray.leaving_kind == EVENT_ABERRATION ? ray.leaving : -1);
        bool search = true;
        if (face.t < REAL_MAX) {
            real tie = tie_window(ray.o_len, face.t);
            t_cut = min(t_cut, face.t + tie);
            /* Inside a box whose clearance to every instance exceeds the search's reach past its exit (the
             * tie window, twice over for rounding), no mesh can be hit: no search (section 14). */
            search = !(face.clear > REAL(2.0f) * tie * ray.r_len);
        }
#else
        bool search = true;
#endif
#if SKIP_CLEAR_SEARCH && HAS_SPACE
        /* The first leg starts at the camera: a search that ends (with the tie window for rounding) nearer
         * than the camera's clearance to every instance (lens.z, from the host) finds nothing. */
        if (pass == 0 && (t_cut + REAL(2.0f) * tie_window(ray.o_len, t_cut)) * ray.r_len < cam.lens.z) {
            search = false;
        }
#endif
        /* The mesh search stops where a mesh can no longer win. */
        MeshHit mesh;
        mesh.t = t_cut;
        mesh.bary = R3S(0.0f);
        mesh.instance = -1;
        mesh.triangle = -1;
        if (search) {
            mesh = nearest_mesh(SCENE_PASS ray.o, ray.r, t_min, t_cut);
        }
        int kind = mesh.instance >= 0 ? EVENT_MESH : EVENT_NONE;
#if HAS_SPACE
        /* Candidates within the tie window of the nearest are tied: portal, then mesh, then box face. */
        real nearest = mesh.instance >= 0 ? mesh.t : REAL_MAX;
#if HAS_PORTALS
        nearest = min(nearest, portal.t);
#endif
#if HAS_ABERRATIONS
        nearest = min(nearest, face.t);
#endif
        if (nearest < REAL_MAX) {
            real limit = nearest + tie_window(ray.o_len, nearest);
#if HAS_ABERRATIONS
            if (face.t <= limit) {
                kind = EVENT_ABERRATION;
            }
#endif
            if (mesh.instance >= 0 && mesh.t <= limit) {
                kind = EVENT_MESH;
            }
#if HAS_PORTALS
            if (portal.t <= limit) {
                kind = EVENT_PORTAL;
            }
#endif
        }
#endif
        /* 2. Nothing: background. A mesh: shade, stop. */
        if (kind == EVENT_NONE) {
            break;
        }
        if (kind == EVENT_MESH) {
            hit = mesh; /* shaded after the loop */
            break;
        }
        ray.n += 1;
#if HAS_PORTALS
        /* 4. A portal: teleport through X, then the active box at the arrival. */
        if (kind == EVENT_PORTAL) {
            ray = teleport(SCENE_PASS ray, portal.row, portal.t);
#if HAS_ABERRATIONS
            ray = enter_box(SCENE_PASS ray, REAL(0.0f), box_after(SCENE_PASS ray.o, ray.r, ray.o_len, REAL(0.0f)), sigma_lo,
                            sigma_hi);
#endif
        }
#endif
#if HAS_ABERRATIONS
        /* 3. A box face: the ray stays on the face, leaving it; the active box just past it. */
        if (kind == EVENT_ABERRATION) {
            ray = enter_box(SCENE_PASS ray, face.t, box_after_face(SCENE_PASS ray.o, ray.r, ray.o_len, ray.r_len, face),
                            sigma_lo, sigma_hi);
            ray.leaving_kind = EVENT_ABERRATION;
            ray.leaving = face.row;
        }
#endif
    }
    /* A mesh: shade it here, once, not in the loop, where SIMD lanes (llvmpipe) would run the shading
     * code masked on every pass. */
    if (hit.instance >= 0) {
        real len_r = ray.r_len;
        real3 position = ray.o + hit.t * ray.r;
        px.color = quantize_rgba(shade(SCENE_PASS cam, hit, ray.r, position));
        px.depth = TO_FLOAT(ray.L + hit.t * len_r);
        px.perceived = TO_FLOAT(ray.Lambda + (hit.t - ray.t_piece) * len_r * ray.f);
        px.instance = INSTANCE(hit.instance).meta.z;
    }
    px.events = ray.n;
    return px;
}
