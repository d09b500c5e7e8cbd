/* portals.h -- portal quads: the nearest one a ray passes, and the teleport (after space.h). */

/* --- portals (docs/semantics.md rules 3 and 10; reference/portals.py) ----------------------- */

#if HAS_PORTALS
/* Portal p as a candidate after best (portals.nearest_portal_hits): a linked quad, not skip, that the ray
 * passes through with t_min < t. */
FORCE_INLINE Event portal_quad(SCENE_DECL Event best, int p, real3 o, real3 r, real t_min, int skip)
{
    Portal portal = PORTAL(p);
    if (portal.meta.x >= 0 && p != skip) {
        real3 a = affine_point(portal.w2l0, portal.w2l1, portal.w2l2, o);
        real3 v = linear_vector(portal.w2l0, portal.w2l1, portal.w2l2, r);
        if (v.z != REAL(0.0f)) {
            real t = -a.z / v.z;
            real x = a.x + t * v.x;
            real y = a.y + t * v.y;
            if (t > t_min && earlier(t, p, best.t, best.row) && ABS(x) <= REAL(1.0f) && ABS(y) <= REAL(1.0f)) {
                best.t = t;
                best.kind = EVENT_PORTAL;
                best.row = p;
            }
        }
    }
    return best;
}

#if PORTAL_TREE
/* The quads after best that the ray passes with t_quad < t, of the leaves it enters within (t_min, best.t],
 * t_min >= t_quad where no other quad can be passed nearer (portal_from). */
FORCE_INLINE Event tree_portals(SCENE_DECL Event best, real3 o, real3 r, real t_min, real t_quad, int skip)
{
    SPACE_LEAVES_BEGIN(SETTINGS.space_roots.x, SETTINGS.space_roots.z)
    best = portal_quad(SCENE_PASS best, leaf, o, r, t_quad, skip);
    SPACE_LEAVES_END
    return best;
}
#endif

/* The nearest linked portal quad the ray passes through with t_min < t (portals.nearest_portal_hits):
 * kind EVENT_PORTAL, t = REAL_MAX for none. The closed quad |x|, |y| <= 1 at z = 0, two-sided; a ray
 * parallel to its plane never hits; the portal being left (skip) and unlinked ones never count; ties
 * go to the lower row. PORTAL_TREE: the quads whose leaves the ray enters, from the tree; else all. */
FORCE_INLINE Event nearest_portal(SCENE_DECL real3 o, real3 r, real t_min, int skip)
{
    Event best = no_event();
#if PORTAL_TREE
    best = tree_portals(SCENE_PASS best, o, r, t_min, t_min, skip);
#else
    int count = PORTAL_ROWS;
    for (int p = 0; p < count; ++p) {
        best = portal_quad(SCENE_PASS best, p, o, r, t_min, skip);
    }
#endif
    return best;
}

/* nearest_portal for a leg that starts (at t_from) on the quad of portal `left` (-1: none), the one it skips.
 * LEFT_PORTAL_GAP: every other quad lies at least left's gap away (meta.z, from the host: a lower bound of
 * the distance), so none is passed before t_from + gap / |r|, less twice the nudge for the rounding of the
 * start point: the tree's walk starts there, and after a ray comes out of a portal it no longer descends to
 * the leaves around the quad it left. */
FORCE_INLINE Event portal_from(SCENE_DECL real3 o, real3 r, real o_len, real r_len, real t_from, real t_min, int left)
{
#if LEFT_PORTAL_GAP && PORTAL_TREE
    real reach = t_min;
    if (left >= 0) {
        real nudge = NUDGE_RELATIVE * max(REAL(1.0f), o_len + t_from);
        reach = max(t_min, t_from + TO_REAL(AS_FLOAT(PORTAL(left).meta.z)) / r_len - REAL(2.0f) * nudge);
    }
    return tree_portals(SCENE_PASS no_event(), o, r, reach, t_min, left);
#else
    return nearest_portal(SCENE_PASS o, r, t_min, left);
#endif
}

#if VIEW_TILES && PORTAL_TREE
/* nearest_portal from the count rows of the view tiles' table from first (engine/view_tiles.py): a camera
 * ray's first leg, whose tile's list holds every portal its rays can meet. */
FORCE_INLINE Event tile_portal(SCENE_DECL real3 o, real3 r, real t_min, int skip, int first, int count)
{
    Event best = no_event();
    for (int k = first; k < first + count; ++k) {
        int4 e = VIEW_TILE(k).entry;
        /* Nearest first: a leaf farther than the best hit holds no nearer one (nor a tie). */
        if (TO_REAL(AS_FLOAT(e.y)) > best.t) {
            break;
        }
        best = portal_quad(SCENE_PASS best, e.x, o, r, t_min, skip);
    }
    return best;
}
#endif

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
