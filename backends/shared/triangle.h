/* triangle.h -- the watertight ray-triangle test (Woop, Benthin & Wald 2013), one triangle or a
 * block of four at once, and the tie rule that keeps the nearest hit. */

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
