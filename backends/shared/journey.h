/* journey.h -- a ray's journey: the primary ray, then event after event until it hits a mesh, leaves
 * the scene or runs out of events (docs/semantics.md); shadow rays take the same one. */

/* --- the journey (docs/semantics.md sections 3-13) ----------------------------------------------- */

/* A ray's state at its start (docs/semantics.md section 1): from o along unit d, no box yet, nothing left. */
FORCE_INLINE Ray start_ray(real3 o, real3 d)
{
    Ray ray;
    ray.o = o;
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

/* The primary ray through pixel (i, j), row 0 = top (docs/semantics.md, "Primary rays"), at the point
 * cam.subpixel.xy of the pixel (0.5 the centre): the camera-space vector normalised, then rotated (never a
 * difference of two world points). */
FORCE_INLINE Ray primary_ray(Camera cam, int i, int j)
{
    real tan_half = cam.lens.x;
    real aspect = cam.lens.y;
    real x = (REAL(2.0f) * (TO_REAL(i) + cam.subpixel.x) / TO_REAL(cam.size.x) - REAL(1.0f)) * aspect * tan_half;
    real y = (REAL(1.0f) - REAL(2.0f) * (TO_REAL(j) + cam.subpixel.y) / TO_REAL(cam.size.y)) * tan_half;
    real3 cam_dir = NORMALIZED(R3(x, y, -1.0f));
    real3 d = cam_dir.x * cam.right.xyz + cam_dir.y * cam.up.xyz + cam_dir.z * cam.back.xyz;
    return start_ray(cam.position.xyz, d);
}

/* How a journey ends (Journey.end): a mesh hit, the sky, out of events, or a shadow ray's reach covered. */
#define END_MESH 0
#define END_MISS 1
#define END_LIMIT 2
#define END_REACHED 3
/* SPLIT_PASS 1: a camera ray that needs the event loop, left for the second pass. */
#define END_DEFERRED 4

STRUCT_BEGIN(Journey)
    Ray ray;     /* the state before the final event */
    MeshHit hit; /* END_MESH: the hit on ray's leg */
    int end;
#if SPLIT_PASS == 1
    int deferred; /* END_DEFERRED: the first leg's event kind, pending at the second pass's start (-1: none) */
#endif
STRUCT_END(Journey)

#if HAS_SHADOWS
/* With shadows, journey() takes whether it is a shadow ray's occlusion test (true: any mesh hit that ends it
 * will do, its hit is not the nearest) or a camera ray's (false: the nearest hit, to shade). */
#define OCCLUSION_DECL , bool occlusion
#define OCCLUSION_ARG(x) , x
#else
#define OCCLUSION_DECL
#define OCCLUSION_ARG(x)
#endif

/* A ray's journey from its start, event after event (docs/semantics.md sections 3-13): the camera's rays
 * and the shadow rays take this one. clear: the start's clearance to every instance (the camera's, lens.z;
 * 0 for none); reach: the world path length at which the ray counts as arrived (REAL_MAX for none). */
FORCE_INLINE Journey journey(SCENE_DECL Camera cam, Ray ray, real clear, real reach OCCLUSION_DECL TILED_DECL)
{
    Journey trip;
    trip.end = END_MISS;
#if HAS_SPACE
    /* The radial mode's bounds from the camera's corner rays. */
    real3 sigma_lo = cam.sigma_min.xyz;
    real3 sigma_hi = cam.sigma_max.xyz;
#endif
    MeshHit hit;
    hit.t = REAL_MAX;
    hit.bary = R3S(0.0f);
    hit.instance = -1;
    hit.triangle = -1;
    int max_events = max(1, min(SETTINGS.counts.w, MAX_EVENTS));
#if INSTANCE_TILES
    /* The tile's list of instances, for the first leg's mesh search; count -1: too many listed, the tree's. */
    int tile_first = 0;
    int tile_count = -1;
    if (tiled) {
        int4 list = VIEW_TILE(tile).entry;
        tile_first = list.z;
        tile_count = list.w;
    }
#endif
#if HAS_SPACE
    /* Each leg's events, found once: here for the first leg, after each crossing for the next. */
    LegEvents ev = first_leg_events(SCENE_PASS ray, clear TILED_ARG(tiled, tile));
#endif
    /* Each pass of the event loop searches one leg for a mesh and either ends the ray or counts an event, so
     * MAX_EVENTS + 1 passes always suffice. A leg that ends on a portal or box face leaves that event to cross
     * (pending) at the start of the next pass: the crossings come first and the loop's test last, because
     * llvmpipe runs a loop's whole body masked while any lane is in it, and a body that ended the ray mid-way
     * would run the crossing code once more for nothing. */
    bool pending = false;
    int kind = EVENT_NONE;
    bool ended = false;
#if FIRST_LEG_APART
    /* A camera ray's first leg whose tile lists its instances is searched here, with the list alone, and the
     * event loop's searches walk the tree alone (but the portal legs' lists): llvmpipe runs both sides of a
     * branch masked, so a search that held both ran the list's copy of the instance code and the tree's at
     * every pass. The same pass as the loop's (no event yet: nothing pending, no walk, no limit reached). */
#if SPLIT_PASS == 2
    /* The first pass searched this ray's first leg (RESUME_KIND >= 0: it ended on that event, pending) or left
     * it to the loop (-1); either way this pass goes on as the one dispatch would. */
    if (RESUME_KIND >= 0) {
        kind = RESUME_KIND;
        pending = true;
    }
#else
    if (tiled && ev.search && tile_count >= 0 && meshes_reachable(SCENE_PASS ray.r)) {
#if HAS_SHADOWS
        real t_stop = TO_REAL(-F_INF);
#endif
        MeshHit mesh = tile_mesh(SCENE_PASS ray.o, ray.r, ev.t_min, ev.t_cut, tile_first, tile_count STOP_PASS);
        kind = leg_event_kind(ev, mesh, ray.o_len);
        if (kind == EVENT_MESH) {
            hit = mesh;
            trip.end = END_MESH;
        }
        pending = kind == EVENT_ABERRATION || kind == EVENT_PORTAL;
        ended = !pending;
    }
#endif
#define LOOP_LIST_LEG(n) (PORTAL_LEGS != 0 && (n) == 1)
#else
#define LOOP_LIST_LEG(n) TILE_LEG(n)
#endif
#if SPLIT_PASS == 1
    trip.deferred = pending ? kind : -1;
    if (!ended) {
        trip.end = END_DEFERRED;
    }
#else
    for (int pass = 0; pass <= MAX_EVENTS && !ended; ++pass) {
#if HAS_SPACE
#if SPACE_WALK
        /* The pending event, then the legs the host's clearances prove free of meshes, crossed without the mesh
         * search's code: a ray through a view-filling box takes its two events here and one pass, not three. */
        MeshHit none;
        none.t = REAL_MAX;
        none.bary = R3S(0.0f);
        none.instance = -1;
        none.triangle = -1;
        bool walk = pending;
        if (!pending) {
            kind = leg_event_kind(ev, none, ray.o_len);
            walk = !ev.search && ray.n < max_events && kind != EVENT_NONE;
        }
#if HAS_SHADOWS
        /* A shadow ray with a reach checks it at every event (below): no walk. */
        walk = walk && !(reach < REAL_MAX);
#endif
        if (walk) {
            do {
                PORTAL_LEG_LIST(kind, ev)
                ray = cross_event(SCENE_PASS ray, kind, ev, sigma_lo, sigma_hi);
                ev = leg_events(SCENE_PASS ray TILED_ARG(false, 0));
                kind = leg_event_kind(ev, none, ray.o_len);
                walk = !ev.search && ray.n < max_events && kind != EVENT_NONE;
            } while (walk);
        }
#else
        if (pending) {
            PORTAL_LEG_LIST(kind, ev)
            ray = cross_event(SCENE_PASS ray, kind, ev, sigma_lo, sigma_hi);
            ev = leg_events(SCENE_PASS ray TILED_ARG(false, 0));
        }
#endif
#endif
        if (ray.n >= max_events) {
            trip.end = END_LIMIT;
            break;
        }
#if HAS_SPACE
        real t_min = ev.t_min;
        real t_cut = ev.t_cut;
        bool search = ev.search;
#else
        real t_min = ray.t_from + T_MIN_RELATIVE * max(REAL(1.0f), ray.o_len + ray.t_from);
        real t_cut = REAL_MAX;
        bool search = true;
#endif
#if HAS_SHADOWS
        /* A shadow ray's mesh search ends at its reach: a mesh past it does not block it. */
        if (reach < REAL_MAX) {
            t_cut = min(t_cut, (reach - ray.L) / ray.r_len);
        }
        /* A shadow ray's search may stop at its first hit nearer than t_stop: that hit ends the journey unlit,
         * as the nearest one (no farther) would. t_stop lies short of the leg's nearest portal and box face by
         * twice the tie window (its rounding: float32's 1.2e-7 against 2e-5), so the hit comes first with no
         * portal tied to it (leg_event_kind), and short of the reach by a tie window of it, so L + t |r| stays
         * below the reach whatever the rounding. A hit between t_stop and t_cut searches on for the nearest.
         * A camera ray's -inf: no t is nearer, so its search's stop tests fold away. */
        real t_stop = TO_REAL(-F_INF);
        if (occlusion) {
            t_stop = t_cut;
#if HAS_SPACE
            real t_event = nearest_space_event(ev);
            if (t_event < REAL_MAX) {
                t_stop = min(t_stop, t_event - REAL(2.0f) * tie_window(ray.o_len, t_event));
            }
#endif
            if (reach < REAL_MAX) {
                t_stop = min(t_stop, (reach - ray.L - TIE_RELATIVE * max(REAL(1.0f), reach)) / ray.r_len);
            }
        }
#endif
        /* The mesh search stops where a mesh can no longer win. */
        MeshHit mesh;
        mesh.t = t_cut;
        mesh.bary = R3S(0.0f);
        mesh.instance = -1;
        mesh.triangle = -1;
        if (search) {
            /* A camera ray's first leg (no event crossed yet) takes the tile's instances, nearest first; with
             * PORTAL_LEGS the leg after its first portal takes that portal's list for the tile too. */
            mesh = nearest_mesh(SCENE_PASS ray.o, ray.r, t_min, t_cut STOP_PASS
                                    TILE_LIST_ARG(tile_first, tiled && LOOP_LIST_LEG(ray.n) ? tile_count : -1));
        }
#if HAS_SPACE
        kind = leg_event_kind(ev, mesh, ray.o_len);
#else
        kind = mesh.instance >= 0 ? EVENT_MESH : EVENT_NONE;
#endif
#if HAS_SHADOWS
        /* A shadow ray whose next event (or the sky) lies at or past its reach got there unblocked. */
        if (reach < REAL_MAX) {
            real t_event = kind == EVENT_MESH ? mesh.t : REAL_MAX;
#if HAS_PORTALS
            t_event = kind == EVENT_PORTAL ? ev.portal.t : t_event;
#endif
#if HAS_ABERRATIONS
            t_event = kind == EVENT_ABERRATION ? ev.face.t : t_event;
#endif
            if (kind == EVENT_NONE || ray.L + t_event * ray.r_len >= reach) {
                trip.end = END_REACHED;
                break;
            }
        }
#endif
        /* 2. Nothing: background. A mesh: shade, stop (after the journey). 3-4. A box face or portal: pending. */
        if (kind == EVENT_MESH) {
            hit = mesh;
            trip.end = END_MESH;
        }
        pending = kind == EVENT_ABERRATION || kind == EVENT_PORTAL;
        if (!pending) {
            break;
        }
    }
#endif
    trip.ray = ray;
    trip.hit = hit;
    return trip;
}

#if HAS_SHADOWS
/* Whether a point (camera-relative) is lit by a light towards (unit) and reach away along the journey
 * (docs/semantics.md, "Lights and shadows"): its shadow ray, started SHADOW_BIAS off the surface along n
 * in the transition from no box into the box there, ends in the sky or past its reach. */
FORCE_INLINE bool shadow_lit(SCENE_DECL Camera cam, real3 position, real3 n, real3 towards, real reach)
{
    Ray ray = start_ray(position + (SHADOW_BIAS * max(REAL(1.0f), length(position))) * n, towards);
#if HAS_ABERRATIONS
    ray = enter_box(SCENE_PASS ray, REAL(0.0f), box_after(SCENE_PASS ray.o, ray.r, ray.o_len, REAL(0.0f)),
                    cam.sigma_min.xyz, cam.sigma_max.xyz);
#endif
    int end = journey(SCENE_PASS cam, ray, REAL(0.0f), reach, true TILED_ARG(false, 0)).end;
    return end == END_MISS || end == END_REACHED;
}
#endif
