/* space.h -- what aberration boxes and portals share (docs/semantics.md): the journey's vector rules,
 * the tie rule, and the trees that find boxes and portals (space_nodes). The boxes' rules are in boxes.h,
 * the portals' in portals.h. */

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
 * SPACE_LEAVES_BEGIN's slab. */
real2 space_slab(real3 o, SpaceRay sr, SpaceNode n)
{
    real3 t0 = (TO_REAL3(n.lo.xyz) - o) * sr.inv;
    real3 t1 = (TO_REAL3(n.hi.xyz) - o) * sr.inv;
    real3 tn = min(t0, t1) - sr.pad;
    real3 tf = max(t0, t1) + sr.pad;
    return R2(max(max(tn.x, tn.y), tn.z), min(min(tf.x, tf.y), tf.z));
}

/* A node as the walk keeps it: an interior node's first child, or ~row for a leaf (rows are >= 0, an
 * interior node's first child > 0: the root is never a child), so a popped node needs no second load. */
#define SPACE_AT(n) (AS_INT(n.hi.w) == 0 ? AS_INT(n.lo.w) : ~AS_INT(n.lo.w))

#ifdef __OPENCL_VERSION__
/* The next stacked node entered no later than best.t into at; more tells whether there was one. */
#define SPACE_POP                                                                                    \
    more = false;                                                                                    \
    while (sp > 0 && !more) {                                                                        \
        sp -= 1;                                                                                     \
        if (stack_t[sp] <= best.t) {                                                                 \
            at = stack_at[sp];                                                                       \
            more = true;                                                                             \
        }                                                                                            \
    }
#endif

/* SPACE_LEAVES_BEGIN's walk after its set-up (at, more and the stack), and SPACE_LEAVES_END: descend to a
 * leaf (SPACE_DESCEND), stand at it, go on (SPACE_NEXT). */
#define SPACE_LEAVES_LOOP                                                                            \
    while (more) {                                                                                   \
        SPACE_DESCEND                                                                                \
        if (more) {                                                                                  \
            int leaf = ~at;
#define SPACE_LEAVES_END                                                                             \
        }                                                                                            \
        SPACE_NEXT                                                                                   \
    }

#if SPACE_WIDE
#ifndef __OPENCL_VERSION__
#error "SPACE_WIDE is OpenCL's (on llvmpipe the 4-wide walk is slower than the binary one)"
#endif
/* The leaves of a space tree that the ray (o, r) enters within (t_min, best.t], nearest first, through its
 * 4-wide form from wide_root (engine/space_wide.py; root, the binary tree's, is the host's):
 * SPACE_LEAVES_BEGIN(root, wide_root) declares the traversal and stands at each leaf with its row in
 * `leaf`, for the caller's test (which may lower best.t); SPACE_LEAVES_END pops to the next. A visit loads
 * a wide node's four rows, slabs its four children at once (space_slab's arithmetic lane by lane), pushes
 * those entered with the nearest on top, and pops the nearest; the stack holds a child's row or ~row for
 * a leaf (the host sizes it to 3 entries per wide level). */
#define SPACE_LEAVES_BEGIN(root, wide_root)                                                          \
    SpaceRay sr = space_ray(o, r);                                                                   \
    real4 ox = R4(o.x, o.x, o.x, o.x);                                                               \
    real4 oy = R4(o.y, o.y, o.y, o.y);                                                               \
    real4 oz = R4(o.z, o.z, o.z, o.z);                                                               \
    real4 ix = R4(sr.inv.x, sr.inv.x, sr.inv.x, sr.inv.x);                                           \
    real4 iy = R4(sr.inv.y, sr.inv.y, sr.inv.y, sr.inv.y);                                           \
    real4 iz = R4(sr.inv.z, sr.inv.z, sr.inv.z, sr.inv.z);                                           \
    real4 px = R4(sr.pad.x, sr.pad.x, sr.pad.x, sr.pad.x);                                           \
    real4 py = R4(sr.pad.y, sr.pad.y, sr.pad.y, sr.pad.y);                                           \
    real4 pz = R4(sr.pad.z, sr.pad.z, sr.pad.z, sr.pad.z);                                           \
    int stack_at[SPACE_STACK_SIZE];                                                                  \
    real stack_t[SPACE_STACK_SIZE];                                                                  \
    int sp = 0;                                                                                      \
    int at = wide_root;                                                                              \
    bool more = true;                                                                                \
    SPACE_LEAVES_LOOP

/* The four children's entry and exit t (tn, tf) of wide node at (rows: lo.x lo.y | lo.z hi.x | hi.y hi.z |
 * child: kids.lo). */
#define SPACE_WIDE_SLABS                                                                             \
    SpaceNode w0 = SPACE_NODE(at);                                                                   \
    SpaceNode w1 = SPACE_NODE(at + 1);                                                               \
    SpaceNode w2 = SPACE_NODE(at + 2);                                                               \
    SpaceNode kids = SPACE_NODE(at + 3);                                                             \
    real4 tx0 = (TO_REAL4(w0.lo) - ox) * ix;                                                         \
    real4 tx1 = (TO_REAL4(w1.hi) - ox) * ix;                                                         \
    real4 ty0 = (TO_REAL4(w0.hi) - oy) * iy;                                                         \
    real4 ty1 = (TO_REAL4(w2.lo) - oy) * iy;                                                         \
    real4 tz0 = (TO_REAL4(w1.lo) - oz) * iz;                                                         \
    real4 tz1 = (TO_REAL4(w2.hi) - oz) * iz;                                                         \
    real4 tn = max(max(min(tx0, tx1) - px, min(ty0, ty1) - py), min(tz0, tz1) - pz);                 \
    real4 tf = min(min(max(tx0, tx1) + px, max(ty0, ty1) + py), max(tz0, tz1) + pz);

/* The four lanes tested as vectors, then a lane's branch is one compare; those entered pushed with the
 * nearest on top (an insertion step), and the nearest popped. */
#define SPACE_DESCEND                                                                                \
    while (at > 0 && more) {                                                                         \
        SPACE_WIDE_SLABS                                                                             \
        int4 hit = convert_int4(tf >= max(tn, R4(t_min, t_min, t_min, t_min))) &                     \
                   convert_int4(tn <= R4(best.t, best.t, best.t, best.t)) &                          \
                   (as_int4(kids.lo) != (int4)(0));                                                  \
        int base = sp;                                                                               \
        SPACE_WIDE_PUSH(x)                                                                           \
        SPACE_WIDE_PUSH(y)                                                                           \
        SPACE_WIDE_PUSH(z)                                                                           \
        SPACE_WIDE_PUSH(w)                                                                           \
        SPACE_POP                                                                                    \
    }
#define SPACE_WIDE_PUSH(L)                                                                           \
    if (hit.L != 0 && sp < SPACE_STACK_SIZE) {                                                       \
        int j = sp;                                                                                  \
        while (j > base && stack_t[j - 1] < tn.L) {                                                  \
            stack_t[j] = stack_t[j - 1];                                                             \
            stack_at[j] = stack_at[j - 1];                                                           \
            j -= 1;                                                                                  \
        }                                                                                            \
        stack_t[j] = tn.L;                                                                           \
        stack_at[j] = AS_INT(kids.lo.L);                                                             \
        sp += 1;                                                                                     \
    }
#define SPACE_NEXT                                                                                   \
    if (more) {                                                                                      \
        SPACE_POP                                                                                    \
    }

#else
/* The leaves of a space tree from root that the ray (o, r) enters within (t_min, best.t], nearest first:
 * SPACE_LEAVES_BEGIN(root, wide_root) declares the traversal (wide_root unused) and stands at each leaf
 * with its row in `leaf`, for the caller's test (which may lower best.t); SPACE_LEAVES_END pops to the
 * next. While-while, as the tree over instances (instances.h): the leaf test runs outside the descent loop. A visit (SPACE_VISIT) loads both
 * children, slabs them (space_slab), goes on to the nearer one entered and stacks the other with its
 * entry t (the host sizes the stack to the tree's depth); the stack holds SPACE_AT, so a pop loads
 * nothing. */
#define SPACE_LEAVES_BEGIN(root, wide_root)                                                          \
    SpaceRay sr = space_ray(o, r);                                                                   \
    int stack_at[SPACE_STACK_SIZE];                                                                  \
    real stack_t[SPACE_STACK_SIZE];                                                                  \
    int sp = 0;                                                                                      \
    SpaceNode top = SPACE_NODE(root);                                                                \
    int at = SPACE_AT(top);                                                                          \
    bool more = slab_hit(space_slab(o, sr, top), t_min, best.t);                                     \
    SPACE_LEAVES_LOOP

/* One visit of interior node at's children: their slabs h0, h1, whether the ray enters each, which
 * comes first. */
#define SPACE_VISIT                                                                                  \
    SpaceNode c0 = SPACE_NODE(at);                                                                   \
    SpaceNode c1 = SPACE_NODE(at + 1);                                                               \
    real2 h0 = space_slab(o, sr, c0);                                                                \
    real2 h1 = space_slab(o, sr, c1);                                                                \
    bool hit0 = slab_hit(h0, t_min, best.t);                                                         \
    bool hit1 = slab_hit(h1, t_min, best.t);                                                         \
    bool second_first = hit1 && (!hit0 || h1.x < h0.x);

#ifdef __OPENCL_VERSION__
/* PoCL: the descent pushes only when both children are entered and pops after a miss; SPACE_NEXT pops
 * after a leaf (against the llvmpipe shape below: 2-5 % less CPU time per frame). */
#define SPACE_DESCEND                                                                                \
    while (at >= 0 && more) {                                                                        \
        SPACE_VISIT                                                                                  \
        if (hit0 || hit1) {                                                                          \
            if (hit0 && hit1 && sp < SPACE_STACK_SIZE) {                                             \
                stack_at[sp] = second_first ? SPACE_AT(c0) : SPACE_AT(c1);                           \
                stack_t[sp] = second_first ? h0.x : h1.x;                                            \
                sp += 1;                                                                             \
            }                                                                                        \
            at = second_first ? SPACE_AT(c1) : SPACE_AT(c0);                                         \
        } else {                                                                                     \
            SPACE_POP                                                                                \
        }                                                                                            \
    }
#define SPACE_NEXT                                                                                   \
    if (more) {                                                                                      \
        SPACE_POP                                                                                    \
    }
#else
/* llvmpipe runs all of a loop's body on every lane until the last one leaves, so the descent is shaped as
 * the compact mesh tree's (bvh_binary.h): it neither pops nor branches to push (the farther child is
 * written above the top and kept only if both were entered; the clamp keeps it in bounds regardless), a
 * miss leaves it, and one pop serves misses and leaves (against the PoCL shape: 2-7 % less CPU time per
 * frame with 256-1,024 portals or boxes in view, 2-3 % in the hotel). */
#define SPACE_DESCEND                                                                                \
    bool miss = false;                                                                               \
    while (at >= 0 && !miss) {                                                                       \
        SPACE_VISIT                                                                                  \
        int slot = min(sp, SPACE_STACK_SIZE - 1);                                                    \
        stack_at[slot] = second_first ? SPACE_AT(c0) : SPACE_AT(c1);                                 \
        stack_t[slot] = second_first ? h0.x : h1.x;                                                  \
        sp += (hit0 && hit1 && sp < SPACE_STACK_SIZE) ? 1 : 0;                                       \
        at = second_first ? SPACE_AT(c1) : SPACE_AT(c0);                                             \
        miss = !(hit0 || hit1);                                                                      \
    }                                                                                                \
    more = !miss;
#define SPACE_NEXT                                                                                   \
    while (sp > 0 && stack_t[sp - 1] > best.t) {                                                     \
        sp -= 1;                                                                                     \
    }                                                                                                \
    more = sp > 0;                                                                                   \
    if (more) {                                                                                      \
        sp -= 1;                                                                                     \
        at = stack_at[sp];                                                                           \
    }
#endif

#endif /* SPACE_WIDE */

#endif
