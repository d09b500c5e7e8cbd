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

#if HAS_LIGHTS
/* The lights' sum (docs/semantics.md, "Lights and shadows"): colour * max(0, n.l) * falloff, a point light's
 * falloff 1/d^2 (times (clamp(1 - (d/range)^4, 0, 1))^2 with a range), shadowing lights' terms only where
 * their shadow rays get there; a light behind the surface sends none. n_s (the shading normal) weighs,
 * the shadow ray starts off the surface along the geometric n. */
FORCE_INLINE float3 light_sum(SCENE_DECL Camera cam, real3 n_s, real3 n, real3 position)
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
        float weight = max(0.0f, TO_FLOAT(dot(n_s, towards))) * falloff;
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

#if HAS_TEXTURES
/* Bilinear between texel centres, repeat wrap (reference: backends/reference/shading.py texture_colors).
 * tex = (first texel, width, height, _); image row 0 is the top (v = 1). */
float3 sample_texture(SCENE_DECL int4 tex, real u, real v)
{
    real s = (u - floor(u)) * TO_REAL(tex.y) - REAL(0.5f);
    real t = (REAL(1.0f) - (v - floor(v))) * TO_REAL(tex.z) - REAL(0.5f);
    real fx = floor(s);
    real fy = floor(t);
    float ax = TO_FLOAT(s - fx);
    float ay = TO_FLOAT(t - fy);
    int x0 = TO_INT(fx);
    int y0 = TO_INT(fy);
    x0 = x0 < 0 ? x0 + tex.y : (x0 >= tex.y ? x0 - tex.y : x0);
    y0 = y0 < 0 ? y0 + tex.z : (y0 >= tex.z ? y0 - tex.z : y0);
    int x1 = x0 + 1 >= tex.y ? 0 : x0 + 1;
    int y1 = y0 + 1 >= tex.z ? 0 : y0 + 1;
    float3 c00 = TEXEL(tex.x + y0 * tex.y + x0).rgba.xyz;
    float3 c10 = TEXEL(tex.x + y0 * tex.y + x1).rgba.xyz;
    float3 c01 = TEXEL(tex.x + y1 * tex.y + x0).rgba.xyz;
    float3 c11 = TEXEL(tex.x + y1 * tex.y + x1).rgba.xyz;
    float3 top = (1.0f - ax) * c00 + ax * c10;
    float3 bottom = (1.0f - ax) * c01 + ax * c11;
    return (1.0f - ay) * top + ay * bottom;
}
#endif

/* base * texture * checker * (ambient + (1 - ambient) * max(0, n_s.l)), n the geometric normal
 * (object normal through the transpose of world_to_object's 3x3) turned to face the ray, n_s the
 * shading normal: a smooth instance's corner normals interpolated at the hit (turned with n), else n.
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
    bool flipped = dot(n, r) > REAL(0.0f);
    if (flipped) {
        n = -n;
    }
    Material mat = MATERIAL(inst.meta.y);
    real3 n_s = n;
#if HAS_SMOOTH
    if ((inst.meta.w & INSTANCE_FLAG_SMOOTH) != 0) {
        TriangleNormal tn = TRIANGLE_NORMAL(hit.triangle + mat.texture.w);
        real3 s_obj = hit.bary.x * TO_REAL3(tn.n0.xyz) + hit.bary.y * TO_REAL3(tn.n1.xyz)
                      + hit.bary.z * TO_REAL3(tn.n2.xyz);
        real3 s = s_obj.x * inst.w2o0.xyz + s_obj.y * inst.w2o1.xyz + s_obj.z * inst.w2o2.xyz;
        real s_len = length(s);
        if (s_len > REAL(0.0f) && s_len < REAL_MAX) {
            n_s = flipped ? -s / s_len : s / s_len;
        }
    }
#endif
    float ambient = SETTINGS.shading.x;
#if HAS_LIGHTS
    /* With Light entities: their sum (light_sum) in place of the implicit sun's max(0, n_s.l). */
    float3 lambert = light_sum(SCENE_PASS cam, n_s, n, position);
#else
    float lambert = max(0.0f, TO_FLOAT(dot(n_s, TO_REAL3(SETTINGS.light_dir.xyz))));
#endif
    float3 base = mat.color.xyz;
#if HAS_TEXTURES
    if (mat.texture.y > 0 && (inst.meta.w & INSTANCE_FLAG_HAS_UVS) != 0) {
        TriangleUv tuv = TRIANGLE_UV(hit.triangle);
        real tu = hit.bary.x * TO_REAL(tuv.uv01.x) + hit.bary.y * TO_REAL(tuv.uv01.z) + hit.bary.z * TO_REAL(tuv.uv2.x);
        real tv = hit.bary.x * TO_REAL(tuv.uv01.y) + hit.bary.y * TO_REAL(tuv.uv01.w) + hit.bary.z * TO_REAL(tuv.uv2.y);
        base *= sample_texture(SCENE_PASS mat.texture, tu, tv);
    }
#endif
    float factor = 1.0f;
#if HAS_CHECKER
    /* Compiled out where no material has a checker: llvmpipe runs the branch at every hit, masked, with
     * every lane off (its triplanar cells in double cost mesh-10k 10 % of a frame). */
    float cell = mat.color.w;
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
#endif
#if HAS_LIGHTS
    return base * (factor * (F3(ambient, ambient, ambient) + (1.0f - ambient) * lambert));
#else
    return base * (factor * (ambient + (1.0f - ambient) * lambert));
#endif
}
