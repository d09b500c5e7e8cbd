/* legs.h -- one leg of a ray's journey (journey.h): the portal and box-face events it meets, which one comes
 * first, and the crossing that starts the next leg; with the view tiles' lists for a camera ray's first legs. */

/* --- a leg's events (docs/semantics.md sections 3-13) --------------------------------------------- */

#if VIEW_TILES || INSTANCE_TILES
/* Whether a ray is a camera ray and the view tile it lies in (engine/view_tiles.py): its first leg's portals
 * (VIEW_TILES) and instances (INSTANCE_TILES) come from the tile's lists, not the trees; constant false for
 * the other legs and shadow rays. */
#define TILED_DECL , bool tiled, int tile
#define TILED_ARG(tiled, tile) , tiled, tile
#else
#define TILED_DECL
#define TILED_ARG(tiled, tile)
#endif

#if PORTAL_LEGS && HAS_PORTALS
/* The header row, in the view tiles' table, of the instance list for the leg after a camera ray's first leg
 * crossed portal row in tile (engine/portal_legs.py): the slot map's row for the portal (after the tiles'
 * headers) names its headers, one per tile of its rect; -1 where the portal has none or the tile lies outside
 * it (that leg walks the tree). */
FORCE_INLINE int portal_leg_head(SCENE_DECL Camera cam, int tile, int row)
{
    int tiles_x = (cam.size.x + (1 << VIEW_TILE_LOG2) - 1) >> VIEW_TILE_LOG2;
    int tiles_y = (cam.size.y + (1 << VIEW_TILE_LOG2) - 1) >> VIEW_TILE_LOG2;
    int4 slot = VIEW_TILE(tiles_x * tiles_y + row).entry;
    int tx = tile - (tile / tiles_x) * tiles_x;
    int ty = tile / tiles_x;
    int x0 = slot.y & 0xFFFF;
    int x1 = slot.y >> 16;
    int y0 = slot.z & 0xFFFF;
    int y1 = slot.z >> 16;
    bool inside = slot.x >= 0 && tx >= x0 && tx <= x1 && ty >= y0 && ty <= y1;
    return inside ? slot.x + (ty - y0) * (x1 - x0 + 1) + (tx - x0) : -1;
}

/* Before a camera ray's first crossing (kind, of the leg events ev): its next leg's list of instances. */
#define PORTAL_LEG_LIST(kind, ev)                                                                          \
    if (tiled && ray.n == 0) {                                                                             \
        int head = kind == EVENT_PORTAL ? portal_leg_head(SCENE_PASS cam, tile, ev.portal.row) : -1;       \
        int4 list = VIEW_TILE(max(head, 0)).entry;                                                         \
        tile_first = list.x;                                                                               \
        tile_count = head >= 0 ? list.y : -1;                                                              \
    }
/* Camera rays search their first two legs with lists: the second's is -1 where it has none. */
#define TILE_LEG(n) ((n) <= 1)
#else
#define PORTAL_LEG_LIST(kind, ev)
#define TILE_LEG(n) ((n) == 0)
#endif

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

#if HAS_SPACE
/* What one pass of the event loop finds on the ray's current leg before any mesh search: the nearest
 * portal and box face past t_min, where the mesh search stops (t_cut) and whether it can be skipped. */
STRUCT_BEGIN(LegEvents)
#if HAS_PORTALS
    Event portal;
#endif
#if HAS_ABERRATIONS
    Event face;
#endif
    real t_min;
    real t_cut;
    bool search;
STRUCT_END(LegEvents)

/* 1. The nearest linked portal quad and box face past the point the ray leaves (t_from along the leg) by
 * t_min, skipping the surface it leaves; the mesh search's limit and whether the host's clearances prove
 * it empty. Tiled: the portals from the view tile's list, which holds every row the tree would find, tested
 * alike. */
FORCE_INLINE LegEvents leg_events(SCENE_DECL Ray ray TILED_DECL)
{
    LegEvents ev;
    ev.t_min = ray.t_from + T_MIN_RELATIVE * max(REAL(1.0f), ray.o_len + ray.t_from);
    ev.t_cut = REAL_MAX;
    ev.search = true;
#if HAS_PORTALS
    int skip_portal = ray.leaving_kind == EVENT_PORTAL ? ray.leaving : -1;
#if PORTAL_LEGS_FREE
    /* The host proved that no leg after a camera ray's first one meets a portal (engine/portal_legs.py) and the
     * frame has no other rays: the later legs' portal search is compiled out. */
    if (!tiled) {
        ev.portal = no_event();
    } else
#endif
#if VIEW_TILES && PORTAL_TREE
    if (tiled) {
        ViewTile list = VIEW_TILE(tile);
        ev.portal = tile_portal(SCENE_PASS ray.o, ray.r, ev.t_min, skip_portal, list.entry.x, list.entry.y);
    } else
#endif
    {
        ev.portal = portal_from(SCENE_PASS ray.o, ray.r, ray.o_len, ray.r_len, ray.t_from, ev.t_min, skip_portal);
    }
    ev.t_cut = ev.portal.t;
#endif
#if HAS_ABERRATIONS
    ev.face = box_face_from(SCENE_PASS ray.aberration, ray.o, ray.r, ray.o_len, ray.r_len, ray.t_from, ev.t_min,
                            ray.leaving_kind == EVENT_ABERRATION ? ray.leaving : -1);
    if (ev.face.t < REAL_MAX) {
        real tie = tie_window(ray.o_len, ev.face.t);
        ev.t_cut = min(ev.t_cut, ev.face.t + tie);
        /* Inside a box whose clearance to every instance exceeds the search's reach past its exit (the
         * tie window, twice over for rounding), no mesh can be hit: no search (section 14). */
        ev.search = !(ev.face.clear > REAL(2.0f) * tie * ray.r_len);
    }
#endif
    return ev;
}

/* leg_events for the first leg (no event yet), which starts where clear says (the camera's clearance to
 * every instance, lens.z from the host; 0 for none): a search that ends (with the tie window for rounding)
 * nearer than that finds nothing. Only here, so the crossings' code does not carry the test. */
FORCE_INLINE LegEvents first_leg_events(SCENE_DECL Ray ray, real clear TILED_DECL)
{
    LegEvents ev = leg_events(SCENE_PASS ray TILED_ARG(tiled, tile));
#if SKIP_CLEAR_SEARCH && CAMERA_CLEAR_SEARCH
    if ((ev.t_cut + REAL(2.0f) * tie_window(ray.o_len, ev.t_cut)) * ray.r_len < clear) {
        ev.search = false;
    }
#endif
    return ev;
}

/* The t of a leg's nearest portal or box face; REAL_MAX for none. */
FORCE_INLINE real nearest_space_event(LegEvents ev)
{
    real nearest = REAL_MAX;
#if HAS_PORTALS
    nearest = min(nearest, ev.portal.t);
#endif
#if HAS_ABERRATIONS
    nearest = min(nearest, ev.face.t);
#endif
    return nearest;
}

/* The event of a leg: candidates within the tie window of the nearest are tied: portal, then mesh, then box
 * face; EVENT_NONE for none. */
FORCE_INLINE int leg_event_kind(LegEvents ev, MeshHit mesh, real o_len)
{
    int kind = mesh.instance >= 0 ? EVENT_MESH : EVENT_NONE;
    real nearest = min(mesh.instance >= 0 ? mesh.t : REAL_MAX, nearest_space_event(ev));
    if (nearest < REAL_MAX) {
        real limit = nearest + tie_window(o_len, nearest);
#if HAS_ABERRATIONS
        if (ev.face.t <= limit) {
            kind = EVENT_ABERRATION;
        }
#endif
        if (mesh.instance >= 0 && mesh.t <= limit) {
            kind = EVENT_MESH;
        }
#if HAS_PORTALS
        if (ev.portal.t <= limit) {
            kind = EVENT_PORTAL;
        }
#endif
    }
    return kind;
}

/* Across a portal or box face event (kind): the event counted, the ray on its next leg. */
FORCE_INLINE Ray cross_event(SCENE_DECL Ray ray, int kind, LegEvents ev, real3 sigma_lo, real3 sigma_hi)
{
    ray.n += 1;
#if HAS_PORTALS
    /* 4. A portal: teleport through X, then the active box at the arrival. */
    if (kind == EVENT_PORTAL) {
        ray = teleport(SCENE_PASS ray, ev.portal.row, ev.portal.t);
#if HAS_ABERRATIONS
        ray = enter_box(SCENE_PASS ray, REAL(0.0f), box_after(SCENE_PASS ray.o, ray.r, ray.o_len, REAL(0.0f)), sigma_lo,
                        sigma_hi);
#endif
    }
#endif
#if HAS_ABERRATIONS
    /* 3. A box face: the ray stays on the face, leaving it; the active box just past it. */
    if (kind == EVENT_ABERRATION) {
        ray = enter_box(SCENE_PASS ray, ev.face.t,
                        box_after_face(SCENE_PASS ray.o, ray.r, ray.o_len, ray.r_len, ev.face), sigma_lo, sigma_hi);
        ray.leaving_kind = EVENT_ABERRATION;
        ray.leaving = ev.face.row;
    }
#endif
    return ray;
}
#endif
