/* space.h -- what bends and teleports rays: aberration boxes and portals (DESIGN.md sections 6-7). */

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

/* What a search returns when nothing is crossed (t = REAL_MAX). */
Event no_event()
{
    Event none;
    none.t = REAL_MAX;
    none.kind = EVENT_NONE;
    none.row = -1;
    none.far = -REAL_MAX;
    none.gap = REAL(0.0f);
    none.clear = REAL(0.0f);
    return none;
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

/* Whether a candidate at t with key (a portal row, or a box row) comes before the best so far at best_t with
 * best_key: the nearer, ties to the lower key. Searching rows in ascending order, the tie never decides (the
 * loops), so a tree that finds them in any order gives the loops' answer. */
bool earlier(real t, int key, real best_t, int best_key)
{
    return t < best_t || (t == best_t && key < best_key);
}
#endif

/* --- the trees over portals and boxes (space_nodes, engine/packing_space.py) ----------------------- */

#if PORTAL_TREE || BOX_TREE
/* A ray's set-up for a space tree: 1/r (safe_inverse) and its padding in t per axis, SPACE_PAD * max(1, |o|)
 * world units over each |r_k|. */
STRUCT_BEGIN(SpaceRay)
    real3 inv;
    real3 pad;
STRUCT_END(SpaceRay)

SpaceRay space_ray(real3 o, real3 r)
{
    SpaceRay sr;
    sr.inv = safe_inverse(r);
    sr.pad = (SPACE_PAD * max(REAL(1.0f), length(o))) * ABS(sr.inv);
    return sr;
}

/* Entry and exit t of a ray against a space tree's node grown by the ray's padding. The host grew the
 * leaves by SPACE_SLACK of their own coordinates' size; the two cover the rounding of the quad and box
 * tests in their local frames, so a ray those tests accept is always inside (docs/semantics.md section 14).
 * A SLAB for BINARY_STEP (core.h). */
real2 space_slab(real3 o, SpaceRay sr, SpaceNode n)
{
    real3 t0 = (TO_REAL3(n.lo.xyz) - o) * sr.inv;
    real3 t1 = (TO_REAL3(n.hi.xyz) - o) * sr.inv;
    real3 tn = min(t0, t1) - sr.pad;
    real3 tf = max(t0, t1) + sr.pad;
    return R2(max(max(tn.x, tn.y), tn.z), min(min(tf.x, tf.y), tf.z));
}

/* The leaves of a space tree from root that the ray (o, r) enters within (t_min, best.t], nearest first:
 * SPACE_LEAVES_BEGIN(root) declares the traversal and stands at each leaf with its row in `leaf`, for the
 * caller's test (which may lower best.t); SPACE_LEAVES_END pops to the next. While-while, as the tree over
 * instances (instances.h): the leaf test runs outside the descent loop. */
#define SPACE_LEAVES_BEGIN(root)                                                                     \
    SpaceRay sr = space_ray(o, r);                                                                   \
    int stack_node[SPACE_STACK_SIZE];                                                                \
    real stack_t[SPACE_STACK_SIZE];                                                                  \
    int sp = 0;                                                                                      \
    SpaceNode node = SPACE_NODE(root);                                                               \
    bool more = slab_hit(space_slab(o, sr, node), t_min, best.t);                                    \
    while (more) {                                                                                   \
        while (AS_INT(node.hi.w) == 0 && more) {                                                     \
            int first = AS_INT(node.lo.w);                                                           \
            BINARY_STEP(SpaceNode, SPACE_NODE, SPACE_STACK_SIZE, space_slab, o, sr, first, more)      \
        }                                                                                            \
        if (more) {                                                                                  \
            int leaf = AS_INT(node.lo.w);
#define SPACE_LEAVES_END                                                                             \
            BINARY_POP(SPACE_NODE, more)                                                             \
        }                                                                                            \
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

/* Box b's faces as candidates after best (aberrations.nearest_box_faces): its entry face, then its exit face,
 * each crossed with t_min < t and not skip; and the box's clearance where the segment from t_min lies in it. */
FORCE_INLINE Event box_faces(SCENE_DECL Event best, int b, real3 o, real3 r, real t_min, int skip)
{
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
        if (span.near_face >= 0 && span.t_near > t_min && earlier(span.t_near, b, best.t, best.row / BOX_FACES) &&
            id != skip) {
            best.t = span.t_near;
            best.kind = EVENT_ABERRATION;
            best.row = id;
            best.far = span.t_far;
            best.gap = box.rot1.w;
        }
        id = BOX_FACES * b + span.far_face;
        if (span.far_face >= 0 && span.t_far > t_min && id != skip) {
            if (earlier(span.t_far, b, best.t, best.row / BOX_FACES)) {
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
    return best;
}

/* The nearest box face crossed with t_min < t (aberrations.nearest_box_faces): kind EVENT_ABERRATION,
 * row = face id, t = REAL_MAX for none. The face being left (skip) never counts; ties go to the
 * lower row, then the entry face. BOX_TREE: the boxes the ray enters, from the tree; else every box. */
FORCE_INLINE Event nearest_box_face(SCENE_DECL real3 o, real3 r, real t_min, int skip)
{
    Event best = no_event();
#if BOX_TREE
    SPACE_LEAVES_BEGIN(SETTINGS.space_roots.y)
    best = box_faces(SCENE_PASS best, leaf, o, r, t_min, skip);
    SPACE_LEAVES_END
#else
    int count = SETTINGS.counts.y;
    for (int b = 0; b < count; ++b) {
        best = box_faces(SCENE_PASS best, b, o, r, t_min, skip);
    }
#endif
    return best;
}

/* Whether box b's closed unit box holds p. */
bool box_holds(SCENE_DECL int b, real3 p)
{
    Aberration box = ABERRATION(b);
    real3 q = affine_point(box.w2l0, box.w2l1, box.w2l2, p);
    return ABS(q.x) <= REAL(0.5f) && ABS(q.y) <= REAL(0.5f) && ABS(q.z) <= REAL(0.5f);
}

/* The active box at a point: the last row whose closed unit box contains it, -1 for none
 * (aberrations.containing_box; rows are sorted by priority, then entity). BOX_TREE: the boxes
 * whose leaves (grown by SPACE_PAD of |p|) hold p, from the tree; else every box. */
int containing_box(SCENE_DECL real3 p)
{
    int found = -1;
#if BOX_TREE
    real3 pad = R3S(SPACE_PAD * max(REAL(1.0f), length(p)));
    int stack_node[SPACE_STACK_SIZE];
    int sp = 0;
    int next = SETTINGS.space_roots.y;
    bool more = true;
    while (more) {
        SpaceNode node = SPACE_NODE(next);
        real3 lo = TO_REAL3(node.lo.xyz) - pad;
        real3 hi = TO_REAL3(node.hi.xyz) + pad;
        bool inside = p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z;
        int first = AS_INT(node.lo.w);
        if (inside && AS_INT(node.hi.w) == 0) {
            /* Both children may hold p: the second waits on the stack (the host sizes it to the depth). */
            if (sp < SPACE_STACK_SIZE) {
                stack_node[sp] = first + 1;
                sp += 1;
            }
            next = first;
        } else {
            if (inside && first > found && box_holds(SCENE_PASS first, p)) {
                found = first;
            }
            more = sp > 0;
            if (more) {
                sp -= 1;
                next = stack_node[sp];
            }
        }
    }
#else
    int count = SETTINGS.counts.y;
    for (int b = 0; b < count; ++b) {
        if (box_holds(SCENE_PASS b, p)) {
            found = b;
        }
    }
#endif
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

/* The nearest linked portal quad the ray passes through with t_min < t (portals.nearest_portal_hits):
 * kind EVENT_PORTAL, t = REAL_MAX for none. The closed quad |x|, |y| <= 1 at z = 0, two-sided; a ray
 * parallel to its plane never hits; the portal being left (skip) and unlinked ones never count; ties
 * go to the lower row. PORTAL_TREE: the quads whose leaves the ray enters, from the tree; else all. */
FORCE_INLINE Event nearest_portal(SCENE_DECL real3 o, real3 r, real t_min, int skip)
{
    Event best = no_event();
#if PORTAL_TREE
    SPACE_LEAVES_BEGIN(SETTINGS.space_roots.x)
    best = portal_quad(SCENE_PASS best, leaf, o, r, t_min, skip);
    SPACE_LEAVES_END
#else
    int count = SETTINGS.counts.z;
    for (int p = 0; p < count; ++p) {
        best = portal_quad(SCENE_PASS best, p, o, r, t_min, skip);
    }
#endif
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
