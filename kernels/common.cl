// common.cl: prepended to every kernel file by mlaa_stream.device.Context.program.
// Pixel access for the frame formats we accept, set by defines from mlaa_stream.formats.defines_for():
//   PIXEL_T   uchar | ushort | float | half-as-ushort is not used (half frames are widened to float on host)
//   CHANNELS  1, 3 or 4 (interleaved)
//   PIXEL_MAX 255.0f | 65535.0f | 1.0f
//   ORDER_BGR 1 when channels 0..2 are B,G,R (OpenCV frames)
//   LUT_SIZE  entries of each lookup table in `luts` (see colour tables below)
// and from the passes' options (mlaa_stream.mlaa.FilterOptions.pass_defines):
//   LINEAR_INPUT 1 when samples are linear light (EXR), 0 when sRGB-encoded
//   BLEND_LINEAR 1 to mix pixels in linear light (DECODE: sRGB samples are decoded to mix, encoded after)
#ifdef POCL_DEVICE_ADDRESS_BITS
// PoCL's clang 15 (Debian's PoCL 3.1) prints "use of logical '&&' with constant operand" to stderr where a define
// turns an operand into a constant (fallback.cl with FXAA everywhere): intended, so not said
#pragma clang diagnostic ignored "-Wconstant-logical-operand"
#endif
#ifndef PIXEL_T
#define PIXEL_T uchar
#endif
#ifndef CHANNELS
#define CHANNELS 3
#endif
#ifndef PIXEL_MAX
#define PIXEL_MAX 255.0f
#endif
#ifndef ORDER_BGR
#define ORDER_BGR 0
#endif
#ifndef LUT_SIZE
#define LUT_SIZE 4096
#endif
#ifndef LINEAR_INPUT
#define LINEAR_INPUT 0
#endif
#ifndef BLEND_LINEAR
#define BLEND_LINEAR 1
#endif
#define DECODE (BLEND_LINEAR && !LINEAR_INPUT)

#define IDX(x, y, w) ((y) * (w) + (x))

// Per-pixel passes run one work item per SEGMENT pixels of a row: enough work items for a GPU, and
// on a CPU a tight loop that skips flat stretches 8 pixels at a time. Global size (ceil(W/SEGMENT), H)
// (edges.cl: EDGE_ROWS rows per work item, (ceil(W/SEGMENT), ceil(H/EDGE_ROWS))).
#ifndef SEGMENT
#define SEGMENT 64
#endif
#define GROUP 8

// PoCL's CPU build calls vload8 / vstore8 / vload4 / vload2, rint, floor and sqrt out of line (a call, with
// the live vector registers saved around it); a load or store through a vector type of the element's
// alignment is one instruction on the same bytes, and clang's rint, floor and sqrt builtins are one
// instruction too (sqrt lane by lane: vectorised back into vsqrtps). All exact.
#ifdef POCL_DEVICE_ADDRESS_BITS
typedef uchar8 uchar8_a1 __attribute__((aligned(1)));
typedef ushort4 ushort4_a2 __attribute__((aligned(2)));
typedef uchar16 uchar16_a1 __attribute__((aligned(1)));
typedef float8 float8_a4 __attribute__((aligned(4)));
typedef int8 int8_a4 __attribute__((aligned(4)));
typedef short8 short8_a2 __attribute__((aligned(2)));
#define LOAD_UCHAR16(p) (*(__global const uchar16_a1 *)(p))
#define LOAD_FLOAT8(p) (*(__global const float8_a4 *)(p))
#define STORE_FLOAT8(v, p) (*(__global float8_a4 *)(p) = (v))
#define LOAD_FLOAT8_PRIVATE(p) (*(__private const float8_a4 *)(p))
#define STORE_FLOAT8_PRIVATE(v, p) (*(__private float8_a4 *)(p) = (v))
#define LOAD_INT8_PRIVATE(p) (*(__private const int8_a4 *)(p))
#define STORE_INT8_PRIVATE(v, p) (*(__private int8_a4 *)(p) = (v))
#define STORE_SHORT8_PRIVATE(v, p) (*(__private short8_a2 *)(p) = (v))
#define LOAD_UCHAR8(p) (*(__global const uchar8_a1 *)(p))
#define STORE_UCHAR8(v, p) (*(__global uchar8_a1 *)(p) = (v))
#define STORE_UCHAR8_PRIVATE(v, p) (*(__private uchar8_a1 *)(p) = (v))
#define LOAD_USHORT4(p) (*(__global const ushort4_a2 *)(p))
#define RINT(x) __builtin_rintf(x)
#define FLOOR(x) __builtin_floorf(x)
#define SQRT(x) __builtin_sqrtf(x)
#else
#define LOAD_UCHAR16(p) vload16(0, p)
#define LOAD_FLOAT8(p) vload8(0, p)
#define STORE_FLOAT8(v, p) vstore8(v, 0, p)
#define LOAD_FLOAT8_PRIVATE(p) vload8(0, p)
#define STORE_FLOAT8_PRIVATE(v, p) vstore8(v, 0, p)
#define LOAD_INT8_PRIVATE(p) vload8(0, p)
#define STORE_INT8_PRIVATE(v, p) vstore8(v, 0, p)
#define STORE_SHORT8_PRIVATE(v, p) vstore8(v, 0, p)
#define LOAD_UCHAR8(p) vload8(0, p)
#define STORE_UCHAR8(v, p) vstore8(v, 0, p)
#define STORE_UCHAR8_PRIVATE(v, p) vstore8(v, 0, p)
#define LOAD_USHORT4(p) vload4(0, p)
#define RINT(x) rint(x)
#define FLOOR(x) floor(x)
#define SQRT(x) sqrt(x)
#endif
// Element pair i of a float array (vload2(i, p)'s value), as two loads everywhere.
#define LOAD_FLOAT2(p, i) ((float2)((p)[2 * (i)], (p)[2 * (i) + 1]))

// A rarely taken helper called from several places of a hot kernel: out of line on PoCL, where inlining it
// everywhere bloats the kernel (blend.cl's feature helpers: blend pass 8.6 -> 6.8 ms on the 1080p mixed frame);
// plain inline elsewhere.
#ifdef POCL_DEVICE_ADDRESS_BITS
#define RARELY_CALLED __attribute__((noinline))
#else
#define RARELY_CALLED inline
#endif

// Eight edge bytes at once (byte alignment is enough).
inline ulong edge_group(__global const uchar *e) { return as_ulong(LOAD_UCHAR8(e)); }

// A pixel as normalised RGBA (grayscale repeated in r, g, b; alpha 1 when absent).
inline float4 load_px(__global const PIXEL_T *img, int i)
{
#if CHANNELS == 1
    float v = (float)img[i] * (1.0f / PIXEL_MAX);
    return (float4)(v, v, v, 1.0f);
#else
    __global const PIXEL_T *p = img + (size_t)i * CHANNELS;
#if ORDER_BGR
    float4 c = (float4)((float)p[2], (float)p[1], (float)p[0], 0.0f);
#else
    float4 c = (float4)((float)p[0], (float)p[1], (float)p[2], 0.0f);
#endif
    c *= (1.0f / PIXEL_MAX);
#if CHANNELS == 4
    c.w = (float)p[3] * (1.0f / PIXEL_MAX);
#else
    c.w = 1.0f;
#endif
    return c;
#endif
}

// PoCL calls built-ins such as clamp/min/rint as out-of-line functions (rint in software), so the
// hot helpers here use plain expressions.
inline PIXEL_T to_pixel(float v)
{
#ifdef PIXEL_IS_FLOAT
    return v;
#else
    float t = v * PIXEL_MAX + 0.5f;
    t = t < 0.0f ? 0.0f : (t > PIXEL_MAX ? PIXEL_MAX : t);
    return (PIXEL_T)t;   // truncation of t + 0.5: round half up
#endif
}

// Are pixels i and j bit-identical in colour? A cheap test that lets passes skip flat areas.
inline int same_px(__global const PIXEL_T *img, int i, int j)
{
#if CHANNELS == 1
    return img[i] == img[j];
#else
    __global const PIXEL_T *a = img + (size_t)i * CHANNELS, *b = img + (size_t)j * CHANNELS;
    return a[0] == b[0] && a[1] == b[1] && a[2] == b[2];
#endif
}

// Store RGB (alpha is copied by the caller's choice: `alpha` argument).
inline void store_px(__global PIXEL_T *img, int i, float4 c)
{
#if CHANNELS == 1
    img[i] = to_pixel(c.x);
#else
    __global PIXEL_T *p = img + (size_t)i * CHANNELS;
#if ORDER_BGR
    p[0] = to_pixel(c.z); p[1] = to_pixel(c.y); p[2] = to_pixel(c.x);
#else
    p[0] = to_pixel(c.x); p[1] = to_pixel(c.y); p[2] = to_pixel(c.z);
#endif
#if CHANNELS == 4
    p[3] = to_pixel(c.w);
#endif
#endif
}

// Tables (built on host by mlaa_stream.colour.device_luts): luts[0..LUT_SIZE] sRGB -> linear,
// luts[LUT_SIZE+1 .. 2*LUT_SIZE+1] the CIELAB f(t) (cube root with the linear toe), then
// luts[2*(LUT_SIZE+1) ..] linear -> sRGB; all over [0,1],
// LUT_SIZE+1 samples each, read with linear interpolation. PoCL's cbrt/pow are slow (see DESIGN.md).
inline float lut_read(__global const float *lut, float x)
{
    float t = x * (float)LUT_SIZE;
    // Written so that NaN (false in every comparison) reads entry 0 instead of an index out of range.
    t = t > 0.0f ? (t < (float)LUT_SIZE ? t : (float)LUT_SIZE) : 0.0f;
    int i = (int)t;
    i = i > LUT_SIZE - 1 ? LUT_SIZE - 1 : i;
    float f = t - (float)i, a = lut[i];
    return a + f * (lut[i + 1] - a);
}

inline float srgb_to_linear(__global const float *luts, float v) { return lut_read(luts, v); }

// A linear sample's argument to the encode table (luts' third table). ENCODE_WARP 1 (HDR video's transfers,
// device/transfer.py): the table holds the transfer's signal of (u^4 x its peak) over u in [0, 1], so light v
// (relative to reference white) reads it at u = (v ENCODE_SCALE)^(1/4), ENCODE_SCALE = reference white / peak: the
// fourth root spreads the curve's steep dark end over the table's entries.
#ifndef ENCODE_WARP
#define ENCODE_WARP 0
#endif
#ifndef ENCODE_SCALE
#define ENCODE_SCALE 1.0f
#endif
inline float encode_arg(float v)
{
#if ENCODE_WARP
    v *= ENCODE_SCALE;
    return v > 0.0f ? SQRT(SQRT(v)) : 0.0f;   // NaN reads entry 0, as lut_read does
#else
    return v;
#endif
}

// Mix space (linear light) -> stored scale [0, 1]: the encode table (sRGB, or an HDR transfer's).
inline float encode_mix(__global const float *luts, float v)
{
    return lut_read(luts + 2 * (LUT_SIZE + 1), encode_arg(v));
}

// CIELAB (D65) of a colour already decoded to linear light (r, g, b from the sRGB->linear table).
inline float3 lab_from_linear(__global const float *luts, float r, float g, float b)
{
    __global const float *f = luts + LUT_SIZE + 1;
    float X = (0.4124564f * r + 0.3575761f * g + 0.1804375f * b) * (1.0f / 0.95047f);
    float Y = 0.2126729f * r + 0.7151522f * g + 0.0721750f * b;
    float Z = (0.0193339f * r + 0.1191920f * g + 0.9503041f * b) * (1.0f / 1.08883f);
    float fx = lut_read(f, X), fy = lut_read(f, Y), fz = lut_read(f, Z);
    return (float3)(116.0f * fy - 16.0f, 500.0f * (fx - fy), 200.0f * (fy - fz));
}

// CIELAB (D65) of an sRGB colour; values above 1 (float frames) are clamped for the comparison only.
inline float3 rgb_to_lab(__global const float *luts, float4 c)
{
    return lab_from_linear(luts, lut_read(luts, c.x), lut_read(luts, c.y), lut_read(luts, c.z));
}

#ifndef PIXEL_IS_FLOAT
// CIELAB of pixel i of an integer frame, each stored level decoded by one load from `lin` (linear_levels
// below: the same numbers as rgb_to_lab's table reads).
inline float3 lab_of_levels(__global const PIXEL_T *src, __global const float *luts, __global const float *lin, int i)
{
#if CHANNELS < 3
    const float v = lin[src[i]];
    return lab_from_linear(luts, v, v, v);
#else
    __global const PIXEL_T *p = src + (size_t)i * CHANNELS;
#if ORDER_BGR
    return lab_from_linear(luts, lin[p[2]], lin[p[1]], lin[p[0]]);
#else
    return lab_from_linear(luts, lin[p[0]], lin[p[1]], lin[p[2]]);
#endif
#endif
}
#endif

// Eight floats t[v.s0] .. t[v.s7]: a table read per lane.
#define GATHER8(t, v) ((float8)((t)[(v).s0], (t)[(v).s1], (t)[(v).s2], (t)[(v).s3], \
                                (t)[(v).s4], (t)[(v).s5], (t)[(v).s6], (t)[(v).s7]))

#ifndef PIXEL_IS_FLOAT
// CIELAB of 8 pixels from their stored levels (R, G, B int8 lanes): lab_of_levels' arithmetic lane by
// lane (per-level linear values from `lin`, the matrix and f(t) table read as lut_read does), the same
// numbers; used by edges.cl and reconstruct.cl, which have `luts` and `lin` in scope. Macros: PoCL
// passes wide vectors to calls through memory.
#define LUT8(lut, x, out) {                                                                              \
        float8 t_ = (x) * (float)LUT_SIZE;                                                             \
        t_ = t_ < 0.0f ? 0.0f : (t_ > (float)LUT_SIZE ? (float)LUT_SIZE : t_);                         \
        int8 i_ = convert_int8(t_);                                                                    \
        i_ = i_ > LUT_SIZE - 1 ? LUT_SIZE - 1 : i_;                                                    \
        const float8 f_ = t_ - convert_float8(i_), a_ = GATHER8(lut, i_);                              \
        out = a_ + f_ * (GATHER8(lut, i_ + 1) - a_); }
#define LAB8(R, G, B, L, A, Z) {                                                                         \
        const float8 lr_ = GATHER8(lin, R), lg_ = GATHER8(lin, G), lb_ = GATHER8(lin, B);              \
        const float8 X_ = (0.4124564f * lr_ + 0.3575761f * lg_ + 0.1804375f * lb_) * (1.0f / 0.95047f); \
        const float8 Y_ = 0.2126729f * lr_ + 0.7151522f * lg_ + 0.0721750f * lb_;                       \
        const float8 Z_ = (0.0193339f * lr_ + 0.1191920f * lg_ + 0.9503041f * lb_) * (1.0f / 1.08883f); \
        __global const float *fl_ = luts + LUT_SIZE + 1;                                               \
        float8 fx_, fy_, fz_;                                                                          \
        LUT8(fl_, X_, fx_) LUT8(fl_, Y_, fy_) LUT8(fl_, Z_, fz_)                                       \
        L = 116.0f * fy_ - 16.0f; A = 500.0f * (fx_ - fy_); Z = 200.0f * (fy_ - fz_); }
#endif

// A stored sample as an 8-bit level (device/formats.py levels8): the overlay and noise tests count in these, exact on
// every sample type.
inline int level8(PIXEL_T v)
{
#ifdef PIXEL_IS_FLOAT
    const float f = fmin(fmax((float)v, 0.0f), 1.0f) * 255.0f;
    return (int)(f + 0.5f);  // truncation of a non-negative value: floor
#else
    return PIXEL_MAX > 255.0f ? ((int)v * 255 + 32767) / 65535 : (int)v;
#endif
}

// Pixel i's colour as 8-bit levels in R, G, B order, into c[0 .. 2].
inline void levels8(__global const PIXEL_T *src, int i, int *c)
{
#if CHANNELS == 1
    c[0] = c[1] = c[2] = level8(src[i]);
#else
    __global const PIXEL_T *p = src + (size_t)i * CHANNELS;
    c[0] = level8(p[ORDER_BGR ? 2 : 0]);
    c[1] = level8(p[1]);
    c[2] = level8(p[ORDER_BGR ? 0 : 2]);
#endif
}

// lin[v] = the linear value rgb_to_lab reads from the table for the stored level v (load_px's
// scaling; LINEAR_INPUT frames are encoded first, as the passes do): integer frames decode a
// sample with one load, the same number. Filled once per frame format (mlaa_stream.device).
__kernel void linear_levels(__global const float *luts, __global float *lin)
{
    const int v = get_global_id(0);
    float c = (float)v * (1.0f / PIXEL_MAX);
#if LINEAR_INPUT
    c = lut_read(luts + 2 * (LUT_SIZE + 1), encode_arg(c));
#endif
    lin[v] = lut_read(luts, c);
}
