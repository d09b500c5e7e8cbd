/* journey.h -- a pixel's journey: the primary ray, then event after event until it hits a mesh,
 * leaves the scene or runs out of events (docs/semantics.md). The kernels' entry point. */

/* --- the journey (docs/semantics.md sections 3-13) ----------------------------------------------- */

/* The primary ray through pixel (i, j), row 0 = top (docs/semantics.md, "Primary rays"), at the point
 * cam.subpixel.xy of the pixel (0.5 the centre): the camera-space vector normalised, then rotated (never a
 * difference of two world points). */
FORCE_INLINE Ray primary_ray(Camera cam, int i, int j)
{
    real tan_half = cam.lens.x;
    real aspect = cam.lens.y;
    real x = (REAL(2.0f) * (TO_REAL(i) + cam.subpixel.x) / TO_REAL(cam.size.x) - REAL(1.0f)) * aspect * tan_half;
    real y = (REAL(1.0f) - REAL(2.0f) * (TO_REAL(j) + cam.subpixel.y) / TO_REAL(cam.size.y)) * tan_half;
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
#if SKIP_CLEAR_SEARCH && CAMERA_CLEAR_SEARCH && HAS_SPACE
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
