/* pixel.h -- the kernels' entry point: a pixel's primary ray, its journey (journey.h) and the colour of
 * what it ends on (shade.h). */

/* A pixel before its camera ray's journey: the sky, no hit. */
FORCE_INLINE Pixel pixel_start(SCENE_DECL Camera cam)
{
    Pixel px;
    px.color = quantize_rgba(SETTINGS.background.xyz);
    px.depth = F_INF;
    px.perceived = F_INF;
    px.instance = -1;
    px.events = 0;
    return px;
}

/* The pixel px (pixel_start's) at the end of its camera ray's journey. */
FORCE_INLINE Pixel pixel_end(SCENE_DECL Camera cam, Pixel px, Journey end)
{
#if SPLIT_PASS == 1
    px.deferred = end.end == END_DEFERRED ? end.deferred : -2;
#endif
    Ray ray = end.ray;
    MeshHit hit = end.hit;
    if (end.end == END_LIMIT) {
        px.color = quantize_rgba(SETTINGS.event_limit_color.xyz);
    }
    /* A mesh: shade it here, once, not in the loop, where SIMD lanes (llvmpipe) would run the shading
     * code masked on every pass. */
    if (hit.instance >= 0) {
        real len_r = ray.r_len;
#if SHADE
        real3 position = ray.o + hit.t * ray.r;
        px.color = quantize_rgba(shade(SCENE_PASS cam, hit, ray.r, position));
#endif
        px.depth = TO_FLOAT(ray.L + hit.t * len_r);
        px.perceived = TO_FLOAT(ray.Lambda + (hit.t - ray.t_piece) * len_r * ray.f);
        px.instance = INSTANCE(hit.instance).meta.z;
    }
    px.events = ray.n;
    return px;
}

#if VIEW_TILES || INSTANCE_TILES
/* The view tile (engine/view_tiles.py, row-major tiles of 2^VIEW_TILE_LOG2 pixels) holding pixel (i, j). */
FORCE_INLINE int view_tile_of(Camera cam, int i, int j)
{
    int tiles_x = (cam.size.x + (1 << VIEW_TILE_LOG2) - 1) >> VIEW_TILE_LOG2;
    return (j >> VIEW_TILE_LOG2) * tiles_x + (i >> VIEW_TILE_LOG2);
}
#endif

Pixel trace_pixel(PIXEL_SCENE_DECL Camera cam, int i, int j)
{
    PIXEL_SCENE_OPEN
    Ray ray = primary_ray(cam, i, j);
    Pixel px = pixel_start(SCENE_PASS cam);
#if HAS_ABERRATIONS
    /* The radial mode's bounds from the camera's corner rays; the transition into the camera's box. */
    real3 sigma_lo = cam.sigma_min.xyz;
    real3 sigma_hi = cam.sigma_max.xyz;
    /* The camera's box, the same for every ray unless the camera is near a face (the host's camera_box):
     * no box needs no transition at all, and the per-ray look-up runs only where rays may disagree. */
#if CAMERA_BOX_ENTRY
    int camera_box = cam.size.z;
    if (camera_box != -1) {
        int next = camera_box >= 0 ? camera_box : box_after(SCENE_PASS ray.o, ray.r, ray.o_len, REAL(0.0f));
        ray = enter_box(SCENE_PASS ray, REAL(0.0f), next, sigma_lo, sigma_hi);
    }
#endif
#endif
#if VIEW_TILES || INSTANCE_TILES
    /* The view tile of the pixel (engine/view_tiles.py): its lists serve the first leg. */
    int tile = view_tile_of(cam, i, j);
#endif
    Journey end = journey(SCENE_PASS cam, ray, cam.lens.z, REAL_MAX OCCLUSION_ARG(false) TILED_ARG(true, tile));
    return pixel_end(SCENE_PASS cam, px, end);
}
