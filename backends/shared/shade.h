/* shade.h -- the colour of a mesh hit (docs/semantics.md, "Meshes and shading"). */

/* --- shading ------------------------------------------------------------------------- */

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

#if HAS_SHADOWS
/* journey.h: whether the shadow ray from position towards a light reaches it (declared here, shade needs it). */
FORCE_INLINE bool shadow_lit(SCENE_DECL Camera cam, real3 position, real3 n, real3 towards, real reach);
#endif

#if HAS_LIGHTS
/* The lights' sum (docs/semantics.md, "Lights and shadows"): colour * max(0, n.l) * falloff, a point light's
 * falloff 1/d^2 (times (clamp(1 - (d/range)^4, 0, 1))^2 with a range), shadowing lights' terms only where
 * their shadow rays get there; a light behind the surface sends none. */
FORCE_INLINE float3 light_sum(SCENE_DECL Camera cam, real3 n, real3 position)
{
    float3 total = F3(0.0f, 0.0f, 0.0f);
    int count = min(SETTINGS.lights.x, MAX_LIGHTS);
    for (int k = 0; k < count; ++k) {
        Light light = LIGHT(k);
        real3 towards = light.vector.xyz;
        float falloff = 1.0f;
        real reach = REAL_MAX;
        if (light.meta.x == LIGHT_POINT) {
            real3 d = light.vector.xyz - position;
            real distance = length(d);
            if (!(distance > REAL(0.0f))) {
                continue;
            }
            towards = d / distance;
            float dist = TO_FLOAT(distance);
            falloff = 1.0f / (dist * dist);
            if (light.color.w > 0.0f) {
                float q = dist / light.color.w;
                float window = clamp(1.0f - q * q * q * q, 0.0f, 1.0f);
                falloff *= window * window;
            }
            reach = distance;
        }
        float weight = max(0.0f, TO_FLOAT(dot(n, towards))) * falloff;
        if (!(weight > 0.0f)) {
            continue;
        }
#if HAS_SHADOWS
        if (light.meta.y != 0 && !shadow_lit(SCENE_PASS cam, position, n, towards, reach)) {
            continue;
        }
#endif
        total += light.color.xyz * weight;
    }
    return total;
}
#endif

/* base * checker * (ambient + (1 - ambient) * max(0, n.l)), n the geometric normal
 * (object normal through the transpose of world_to_object's 3x3) turned to face the ray.
 * position is camera-relative; cam.origin turns it into world space for triplanar cells. */
FORCE_INLINE float3 shade(SCENE_DECL Camera cam, MeshHit hit, real3 r, real3 position)
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
#if HAS_LIGHTS
    /* With Light entities: their sum (light_sum) in place of the implicit sun's max(0, n.l). */
    float3 lambert = light_sum(SCENE_PASS cam, n, position);
#else
    float lambert = max(0.0f, TO_FLOAT(dot(n, TO_REAL3(SETTINGS.light_dir.xyz))));
#endif
    Material mat = MATERIAL(inst.meta.y);
    float cell = mat.color.w;
    float factor = 1.0f;
    if (cell > 0.0f) {
        bool odd = false;
        if ((inst.meta.w & INSTANCE_FLAG_HAS_UVS) != 0) {
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
#if HAS_LIGHTS
    return mat.color.xyz * (factor * (F3(ambient, ambient, ambient) + (1.0f - ambient) * lambert));
#else
    return mat.color.xyz * (factor * (ambient + (1.0f - ambient) * lambert));
#endif
}
