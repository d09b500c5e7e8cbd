/* boxes.h -- aberration boxes: their faces, the box holding a point, transitions (after space.h). */

/* --- aberrations (docs/semantics.md rules 3-9; reference/aberrations.py) ----------------- */

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

#if BOX_TREE
/* The tree's part of nearest_box_face after best: the faces crossed with t_face < t of the boxes whose leaves the
 * ray enters within (t_min, best.t], t_min >= t_face where no other box can have a face nearer (box_face_from). */
FORCE_INLINE Event tree_box_faces(SCENE_DECL Event best, real3 o, real3 r, real t_min, real t_face, int skip)
{
    SPACE_LEAVES_BEGIN(SETTINGS.space_roots.y, SETTINGS.space_roots.w)
    best = box_faces(SCENE_PASS best, leaf, o, r, t_face, skip);
    SPACE_LEAVES_END
    return best;
}
#endif

/* The nearest box face crossed with t_min < t (aberrations.nearest_box_faces): kind EVENT_ABERRATION,
 * row = face id, t = REAL_MAX for none. The face being left (skip) never counts; ties go to the
 * lower row, then the entry face. BOX_TREE: the boxes the ray enters, from the tree; else every box. */
FORCE_INLINE Event nearest_box_face(SCENE_DECL real3 o, real3 r, real t_min, int skip)
{
    Event best = no_event();
#if BOX_TREE
    best = tree_box_faces(SCENE_PASS best, o, r, t_min, t_min, skip);
#else
    int count = BOX_ROWS;
    for (int b = 0; b < count; ++b) {
        best = box_faces(SCENE_PASS best, b, o, r, t_min, skip);
    }
#endif
    return best;
}

/* Whether the box of a face event (face) lies farther than twice the nudge at the face from every other box
 * (its gap, from the host): no other box then holds a point within the nudge of the face, nor has a face
 * within the rounding of it. FACE_NEXT_ONLY: the host proved it for every face of the frame. */
bool box_alone(Event face, real o_len, real r_len)
{
#if FACE_NEXT_ONLY
    return true;
#else
    return face.gap > REAL(2.0f) * NUDGE_RELATIVE * max(REAL(1.0f), o_len + face.t) * r_len;
#endif
}

/* nearest_box_face on a leg inside box b (the ray's active box, -1 for none): a box alone at its exit is the
 * only one with a face on the segment to that exit or within the rounding of it, so its own faces are the
 * search's answer, the one the tree's walk finds. Else that search. Beside the tree only: against the loop
 * over a few boxes, llvmpipe pays for both (one box filling the view: 1.05x the time). */
FORCE_INLINE Event box_face_from(SCENE_DECL int b, real3 o, real3 r, real o_len, real r_len, real t_from, real t_min,
                                 int skip)
{
#if OWN_BOX_FACES && BOX_TREE
    Event own = no_event();
    if (b >= 0) {
        own = box_faces(SCENE_PASS own, b, o, r, t_min, skip);
        if (own.t < REAL_MAX && box_alone(own, o_len, r_len)) {
            return own;
        }
    }
#endif
#if LEFT_BOX_GAP && BOX_TREE
    /* A leg that leaves a face of box `left` starts on it (at t_from), and every other box lies at least left's
     * gap away (from the host, a lower bound of the distance): none has a face before t_from + gap / |r|, less
     * twice the nudge for the rounding of the start point. So left's own faces, then the tree's walk from there:
     * after a ray leaves a box, the walk no longer descends to the leaves around the one it left. */
    Event best = no_event();
    real reach = t_min;
    if (skip >= 0) {
        int left = skip / BOX_FACES;
#if OWN_BOX_FACES
        /* Leaving a face of the box it is in (not alone), the ray has that box's faces already. */
        best = left == b ? own : box_faces(SCENE_PASS best, left, o, r, t_min, skip);
#else
        best = box_faces(SCENE_PASS best, left, o, r, t_min, skip);
#endif
        real nudge = NUDGE_RELATIVE * max(REAL(1.0f), o_len + t_from);
        reach = max(t_min, t_from + ABERRATION(left).rot1.w / r_len - REAL(2.0f) * nudge);
    }
    return tree_box_faces(SCENE_PASS best, o, r, reach, t_min, skip);
#else
    return nearest_box_face(SCENE_PASS o, r, t_min, skip);
#endif
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
    int count = BOX_ROWS;
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
#if FACE_NEXT_BOX && FACE_NEXT_ONLY
    /* The host proved the gap test true for every face event of the frame: the loop is dead code. */
    return face.t + nudge <= face.far ? face.row / BOX_FACES : -1;
#else
#if FACE_NEXT_BOX
    if (box_alone(face, o_len, r_len)) {
        return face.t + nudge <= face.far ? face.row / BOX_FACES : -1;
    }
#endif
    return containing_box(SCENE_PASS o + (face.t + nudge) * r);
#endif
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
