/* prelude.glsl -- the GLSL 4.30 spelling of the shared tracer core's types and helpers.
 *
 * The tracer core (backends/shared/options.h to pixel.h) is written in the common subset of GLSL
 * and OpenCL C; everything that is spelt differently goes through the macros
 * below. backends/shared/prelude_cl.h is the OpenCL C twin of this file: keep
 * the two in step (same names, same meaning).
 */

/* --- scalar and vector types ------------------------------------------------------ */
#if REAL_IS_DOUBLE
#define real double
#define real2 dvec2
#define real3 dvec3
#define real4 dvec4
#define REAL_MAX 1.0e300lf
#define REAL_TINY 1.0e-300lf
/* A real literal written without a suffix: REAL_C(1.0e-9) is the double nearest 1e-9. */
#define REAL_C(x) x##lf
#else
#define real float
#define real2 vec2
#define real3 vec3
#define real4 vec4
#define REAL_MAX 3.0e38
#define REAL_TINY 1.0e-30
#define REAL_C(x) x##f
#endif
#define float2 vec2
#define float3 vec3
#define float4 vec4
#define int2 ivec2
#define int3 ivec3
#define int4 ivec4

/* --- constructors and conversions ------------------------------------------------- */
#define REAL(x) real(x)
#define R2(a, b) real2(a, b)
#define R3(a, b, c) real3(a, b, c)
#define R4(a, b, c, d) real4(a, b, c, d)
#define R3S(s) real3(s)
#define F3(a, b, c) vec3(a, b, c)
#define F4(a, b, c, d) vec4(a, b, c, d)
#define TO_REAL(x) real(x)
#define TO_REAL3(v) real3(v)
#define TO_REAL4(v) real4(v)
#define TO_FLOAT(x) float(x)
#define TO_FLOAT3(v) vec3(v)
#define TO_INT(x) int(x)
#define TO_DOUBLE(x) double(x)
#define AS_INT(x) floatBitsToInt(x)
#define AS_FLOAT(x) intBitsToFloat(x)

/* --- helpers ------------------------------------------------------------------------ */
#define ABS(x) abs(x)
/* v / |v| for a v that is neither zero nor near the range's ends (backends/shared/prelude_cl.h). */
#define NORMALIZED(v) normalize(v)
/* Component i (0, 1, 2) of a real3, i not a constant. */
#define VIDX3(v, i) ((v)[i])
/* No fused multiply-add in the expressions feeding this variable (watertight edge functions). */
#define PRECISE precise
/* OpenCL C: always_inline; GLSL compilers inline every call already. */
#define FORCE_INLINE
#define F_INF uintBitsToFloat(0x7F800000u)

/* A struct usable by its bare name (OpenCL needs a typedef for that). */
#define STRUCT_BEGIN(name) struct name {
#define STRUCT_END(name) };

/* The scene tables are global storage buffers (bindings.glsl): no parameter to pass. */
#define SCENE_DECL
#define SCENE_PASS
#define PIXEL_SCENE_DECL
#define PIXEL_SCENE_OPEN
