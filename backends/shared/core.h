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
 *               REAL_TINY, F_INF (+inf as a float)
 *   casts       TO_REAL TO_REAL3 (from float3) TO_FLOAT TO_FLOAT3 TO_INT TO_DOUBLE,
 *               AS_INT / AS_FLOAT (bit reinterpretation)
 *   helpers     ABS (float abs, scalar or vector), VIDX3(v, i) (component i of
 *               a real3), PRECISE (no fused multiply-add), STRUCT_BEGIN/END
 *   scene       SCENE_DECL / SCENE_PASS (a first parameter carrying the tables,
 *               empty in GLSL), SETTINGS, TRIANGLE(i), TRIANGLE_UV(i),
 *               BVH_NODE(i), INSTANCE(i), MATERIAL(i), ABERRATION(i), PORTAL(i)
 *               (records, from the bindings file)
 *
 * Compile-time defines (engine.packing.Features.defines() and the backend):
 *   HAS_PORTALS HAS_ABERRATIONS HAS_METRIC HAS_RADIAL HAS_ADDITIVE MAX_EVENTS
 *   REAL_IS_DOUBLE     trace in double precision
 *   EDGE_FALLBACK_FP64 float tracer: recompute an edge function that is exactly
 *                      0 in double (exact: a product of two floats fits a double)
 *   WORLD_FP64         float tracer: world-space checker coordinates in double
 *                      (the packed origin can be 1e5 away while cells are 0.05)
 *   BRUTE_FORCE        test every triangle of an instance (benchmarks only)
 *   BVH_STACK_SIZE     traversal stack; the host checks every tree fits
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

#if REAL_IS_DOUBLE
/* Hits at t <= T_MIN_RELATIVE * max(1, |o|) are ignored (the reference's value). */
#define T_MIN_RELATIVE 1.0e-9f
/* A box's exit t is widened by this fraction of itself: rounding never loses a hit on a face. */
#define BOX_WIDEN 4.0e-16f
#else
#define T_MIN_RELATIVE 1.0e-6f
#define BOX_WIDEN 4.8e-7f
#endif

/* Event kinds (DESIGN.md section 5). */
#define EVENT_NONE 0
#define EVENT_MESH 1
#define EVENT_ABERRATION 2
#define EVENT_PORTAL 3

/* --- records of the journey ------------------------------------------------------ */

/* The state a ray carries (DESIGN.md section 5). Coordinates are camera-relative. */
STRUCT_BEGIN(Ray)
    real3 o;          /* origin */
    real3 r;          /* world direction */
    real3 w;          /* perceived direction (unit) */
    real3 d0;         /* primary direction, carried through portals (the "restore" exit rule) */
    real L;           /* path length: world units travelled */
    real Lambda;      /* perceived length */
    int aberration;   /* active aberration row, -1 for none */
    int n;            /* event count */
    int leaving_kind; /* the surface the ray is leaving (EVENT_ABERRATION / EVENT_PORTAL), -1 none */
    int leaving;      /* ... and its row */
STRUCT_END(Ray)

/* The nearest mesh hit: t along r, barycentric weights of v0, v1, v2, instance row and triangle (-1: none). */
STRUCT_BEGIN(MeshHit)
    real t;
    real3 bary;
    int instance;
    int triangle;
STRUCT_END(MeshHit)

/* The next event of a ray: its kind, distance t along r and the row of what was hit. */
STRUCT_BEGIN(Event)
    real t;
    int kind;
    int row;
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

/* Entry and exit t of a ray against a box; the exit is widened a few ulps (conservative). */
real2 slab(real3 o, real3 inv, real3 lo, real3 hi)
{
    real3 t0 = (lo - o) * inv;
    real3 t1 = (hi - o) * inv;
    real3 tn = min(t0, t1);
    real3 tf = max(t0, t1);
    real t_enter = max(max(tn.x, tn.y), tn.z);
    real t_exit = min(min(tf.x, tf.y), tf.z);
    return R2(t_enter, t_exit + ABS(t_exit) * REAL(BOX_WIDEN));
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
ShearedRay shear_ray(real3 o, real3 d)
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
real4 intersect_triangle(ShearedRay sr, real3 v0, real3 v1, real3 v2, bool cull)
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

/* Test triangle k of instance row; keep the hit smallest in (t, instance, triangle). */
MeshHit test_triangle(SCENE_DECL MeshHit best, ShearedRay sr, int k, int row, bool cull, real t_min)
{
    Triangle tri = TRIANGLE(k);
    real4 h = intersect_triangle(sr, TO_REAL3(tri.v0.xyz), TO_REAL3(tri.v1.xyz), TO_REAL3(tri.v2.xyz), cull);
    if (h.x > t_min && (h.x < best.t || (h.x == best.t && row == best.instance && k < best.triangle))) {
        best.t = h.x;
        best.bary = R3(h.y, h.z, h.w);
        best.instance = row;
        best.triangle = k;
    }
    return best;
}

/* --- per-instance BVH traversal ------------------------------------------------------ */

/* The ray (camera-relative world o, d) against one instance: into object space with
 * world_to_object, the direction left unnormalised so t stays the world t; then the
 * asset's BVH from its root, nearest child first, with a small stack. */
MeshHit trace_instance(SCENE_DECL MeshHit best, int row, real3 o, real3 d, real t_min)
{
    Instance inst = INSTANCE(row);
    real3 oo = R3(dot(inst.w2o0.xyz, o) + inst.w2o0.w, dot(inst.w2o1.xyz, o) + inst.w2o1.w,
                  dot(inst.w2o2.xyz, o) + inst.w2o2.w);
    real3 dd = R3(dot(inst.w2o0.xyz, d), dot(inst.w2o1.xyz, d), dot(inst.w2o2.xyz, d));
    bool cull = MATERIAL(inst.meta.y).flags.x != 0;
    ShearedRay sr = shear_ray(oo, dd);
    int root = inst.meta.x;
#if BRUTE_FORCE
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

/* The nearest triangle hit with t_min < t <= t_max over every instance, culled by world bounds. */
MeshHit nearest_mesh(SCENE_DECL real3 o, real3 d, real t_min, real t_max)
{
    MeshHit best;
    best.t = t_max;
    best.bary = R3S(0.0f);
    best.instance = -1;
    best.triangle = -1;
    if (!(dot(d, d) > REAL(0.0f))) {
        return best; /* a zero or NaN direction hits nothing */
    }
    real3 inv = safe_inverse(d);
    int count = SETTINGS.counts.x;
    for (int i = 0; i < count; ++i) {
        real2 h = slab(o, inv, INSTANCE(i).bounds_min.xyz, INSTANCE(i).bounds_max.xyz);
        if (slab_hit(h, t_min, best.t)) {
            best = trace_instance(SCENE_PASS best, i, o, d, t_min);
        }
    }
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
float3 shade(SCENE_DECL Camera cam, MeshHit hit, real3 r, real3 position)
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

/* --- the journey (DESIGN.md section 5) -------------------------------------------------- */

/* The primary ray through pixel (i, j), row 0 = top (DESIGN.md section 3): the camera-space
 * vector normalised, then rotated (never a difference of two world points). */
Ray primary_ray(Camera cam, int i, int j)
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
    ray.w = d;
    ray.d0 = d;
    ray.L = REAL(0.0f);
    ray.Lambda = REAL(0.0f);
    ray.aberration = -1;
    ray.n = 0;
    ray.leaving_kind = -1;
    ray.leaving = -1;
#if HAS_RADIAL || HAS_ADDITIVE
    /* STUB (issue 5): a camera inside a radial/additive box pre-deforms primary rays. */
#endif
    return ray;
}

/* Perceived length per world length along the ray's current direction: 1 outside every box. */
real perceived_per_world(SCENE_DECL Ray ray)
{
#if HAS_ABERRATIONS
    /* STUB (issue 5): 1 / |s (.) R^T w| inside a metric box. */
#endif
    return REAL(1.0f);
}

Pixel trace_pixel(SCENE_DECL Camera cam, int i, int j)
{
    Ray ray = primary_ray(cam, i, j);
    Pixel px;
    px.color = quantize_rgba(SETTINGS.background.xyz);
    px.depth = F_INF;
    px.perceived = F_INF;
    px.instance = -1;
    px.events = 0;
    int max_events = min(SETTINGS.counts.w, MAX_EVENTS);
    /* Each pass either ends the ray or counts an event, so MAX_EVENTS + 1 passes always suffice. */
    for (int pass = 0; pass <= MAX_EVENTS; ++pass) {
        if (ray.n >= max_events) {
            px.color = quantize_rgba(SETTINGS.event_limit_color.xyz);
            break;
        }
        real t_min = REAL(T_MIN_RELATIVE) * max(REAL(1.0f), length(ray.o));
        /* 1. The nearest of: a mesh triangle, an aberration box face, a portal quad. */
        MeshHit mesh = nearest_mesh(SCENE_PASS ray.o, ray.r, t_min, REAL_MAX);
        Event ev;
        ev.kind = mesh.instance >= 0 ? EVENT_MESH : EVENT_NONE;
        ev.t = mesh.t;
        ev.row = mesh.instance;
#if HAS_ABERRATIONS
        /* STUB (issue 5): the nearest aberration box face with t < ev.t, skipping
         * (ray.leaving_kind, ray.leaving), replaces ev (kind EVENT_ABERRATION). */
#error "aberrations are not traced by the shared core yet (issue 5)"
#endif
#if HAS_PORTALS
        /* STUB (issue 6): the nearest linked portal quad with t < ev.t, skipping
         * (ray.leaving_kind, ray.leaving), replaces ev (kind EVENT_PORTAL). */
#error "portals are not traced by the shared core yet (issue 6)"
#endif
        /* 2. Nothing: background. A mesh: shade, stop. */
        if (ev.kind == EVENT_NONE) {
            break;
        }
        if (ev.kind == EVENT_MESH) {
            real travelled = mesh.t * length(ray.r);
            real3 position = ray.o + mesh.t * ray.r;
            px.color = quantize_rgba(shade(SCENE_PASS cam, mesh, ray.r, position));
            px.depth = TO_FLOAT(ray.L + travelled);
            px.perceived = TO_FLOAT(ray.Lambda + travelled * perceived_per_world(SCENE_PASS ray));
            px.instance = INSTANCE(mesh.instance).meta.z;
            break;
        }
#if HAS_ABERRATIONS
        /* STUB (issue 5), 3. An aberration face: move to the hit, recompute the active box just
         * past it, update r by its model, n += 1. */
#endif
#if HAS_PORTALS
        /* STUB (issue 6), 4. A portal: teleport through X, n += 1. */
#endif
    }
    px.events = ray.n;
    return px;
}
