/* prelude_cl.h -- the OpenCL C 1.2 spelling of the shared tracer core's types and helpers.
 *
 * Twin of backends/glsl/prelude.glsl: same names, same meaning. Include it
 * first, then layout.h, bindings_cl.h, the tracer files (options.h ... pixel.h) and the kernel:
 *
 *     defines (REAL_IS_DOUBLE, HAS_*, MAX_EVENTS, ...) + prelude_cl.h + layout.h
 *     + bindings_cl.h + options.h + core.h + ... + pixel.h + the kernel that calls trace_pixel()
 *
 * Defines read here: REAL_IS_DOUBLE (trace in double; needs cl_khr_fp64),
 * EDGE_FALLBACK_FP64 and WORLD_FP64 (double helpers in a float tracer; set
 * them only when the device has cl_khr_fp64).
 */

#if REAL_IS_DOUBLE || EDGE_FALLBACK_FP64 || WORLD_FP64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#endif
/* No contraction into fused multiply-adds: the watertight edge functions need
 * a*b - c*d computed as two rounded products (GLSL says `precise`). */
#pragma OPENCL FP_CONTRACT OFF
/* floor as the compiler's own exact floor (one rounding instruction on a CPU with SSE4.1): PoCL 3.1 maps
 * floor to a library routine of compares and branches instead. Same value for every input, NaN and
 * signed zeros included. Elsewhere (another driver's compiler) the device's floor stays. */
#if defined(__has_builtin)
#if __has_builtin(__builtin_elementwise_floor)
#undef floor
#define floor(x) __builtin_elementwise_floor(x)
#endif
#endif

/* --- scalar and vector types ------------------------------------------------------ */
#if REAL_IS_DOUBLE
typedef double real;
typedef double2 real2;
typedef double3 real3;
typedef double4 real4;
#define REAL_MAX 1.0e300
#define REAL_TINY 1.0e-300
/* A real literal written without a suffix: REAL_C(1.0e-9) is the double nearest 1e-9. */
#define REAL_C(x) x
#define TO_REAL3(v) convert_double3(v)
#define TO_REAL4(v) convert_double4(v)
#define TO_REAL8(v) convert_double8(v)
typedef double8 real8;
#else
typedef float real;
typedef float2 real2;
typedef float3 real3;
typedef float4 real4;
#define REAL_MAX 3.0e38f
#define REAL_TINY 1.0e-30f
#define REAL_C(x) x##f
#define TO_REAL3(v) convert_float3(v)
#define TO_REAL4(v) (v)
#define TO_REAL8(v) (v)
typedef float8 real8;
#endif

/* --- constructors and conversions ------------------------------------------------- */
#define REAL(x) ((real)(x))
#define R2(a, b) ((real2)((real)(a), (real)(b)))
#define R3(a, b, c) ((real3)((real)(a), (real)(b), (real)(c)))
#define R4(a, b, c, d) ((real4)((real)(a), (real)(b), (real)(c), (real)(d)))
#define R3S(s) ((real3)((real)(s)))
/* OpenCL only (8-wide BVH nodes): a real8 with every lane s. */
#define R8S(s) ((real8)((real)(s)))
#define F3(a, b, c) ((float3)((float)(a), (float)(b), (float)(c)))
#define F4(a, b, c, d) ((float4)((float)(a), (float)(b), (float)(c), (float)(d)))
#define TO_REAL(x) ((real)(x))
#define TO_FLOAT(x) ((float)(x))
#define TO_FLOAT3(v) convert_float3(v)
#define TO_INT(x) ((int)(x))
#define TO_DOUBLE(x) ((double)(x))
#define AS_INT(x) as_int(x)
#define AS_FLOAT(x) as_float(x)

/* --- helpers ------------------------------------------------------------------------ */
#define ABS(x) fabs(x)
/* v / |v| for a v that is neither zero nor near the range's ends (the primary ray's camera-space vector). In
 * float, PoCL's normalize without its tests for zero, tiny and huge vectors: v * (1 / sqrt(v . v)), the bits
 * of its usual path, and the frame 0.81-0.99x the time (README.md); in double the library's (no gain). */
#if REAL_IS_DOUBLE
#define NORMALIZED(v) normalize(v)
#else
#define NORMALIZED(v) ((v) * (REAL(1.0f) / sqrt(dot((v), (v)))))
#endif
/* Component i (0, 1, 2) of a real3, i not a constant (OpenCL C has no v[i]). */
inline real vidx3_(real3 v, int i) { return i == 0 ? v.x : (i == 1 ? v.y : v.z); }
#define VIDX3(v, i) vidx3_(v, i)
#define PRECISE
/* Inline this function (the core's large ones, called in loops): PoCL otherwise keeps some calls, and
 * the structs they take and return (Ray: 100 bytes) go through the stack, with store-forwarding
 * stalls. Measured on PoCL 3.1: -25 % frame time with aberrations, -10 % on plain scenes. A benchmark
 * may define it empty (extra_defines) to compare. */
#ifndef FORCE_INLINE
#define FORCE_INLINE __attribute__((always_inline))
#endif
#define F_INF INFINITY

/* A struct usable by its bare name, as in GLSL. */
#define STRUCT_BEGIN(name) typedef struct name name; struct name {
#define STRUCT_END(name) };
