// temporal.cl -- temporal reprojection blending in one pass: warp the history (the previous output)
// into the current frame by a motion model, reject it where it cannot be trusted, and blend it with
// the spatially antialiased frame in linear light. Reference: mlaa_stream.temporal.temporal_reference.
//
// Per pixel x of the current frame (pixel centres at integer coordinates):
//   v_c = motion of x back to the previous frame: an affine map (static/global models) or a dense
//         flow field sampled bilinearly (stored at 1/FLOW_SCALE of the frame size, in its pixels)
//   q   = x + v_c, where x was in the previous frame; outside the frame -> no history
//   fb  = forward-backward consistency |v_c + g(q)| with g the forward (previous -> current) flow:
//         weight 1 below tol = FB_ABS + FB_REL |v_c|, falling to 0 at 2 tol (dense model only)
//   v_p = the velocity the history had at q (previous frame's motion model); velocity weight of
//         seed 002 ("Temporal Reprojection"), on velocity *vectors* and in pixel units:
//         w = W_MAX * max(0, 1 - K sqrt(|v_c - v_p|)) * fb
//   h   = history at q, Catmull-Rom in linear light, clipped toward the centre of the box
//         [max(min, mean - GAMMA sd), min(max, mean + GAMMA sd)] of the current 3x3 neighbourhood
//         (variance clipping, per channel, in linear light); t = how far outside the box h was, in
//         box half-widths: w *= clamp((REJECT - t) / (REJECT - 1), 0, 1) -- history that far off is
//         another surface (a disocclusion the flow missed), not aliasing to be averaged
//   out = c + w (h - c), encoded back by table; where w = 0 the current pixel is copied untouched.
//   FLAT rule (any mode, before everything above): where all 9 samples of the pixel's 3x3 neighbourhood
//   (edges replicated) are bit-identical in the frame's own type, the clip box is [c - EXT_FLOOR,
//   c + EXT_FLOOR] and the blend could move the pixel by a rounding level at most, so it is skipped:
//   out = c untouched, new history = c in linear light (as on a reset), w = 0, no history taps.
//   Checked in groups of GROUP pixels of a row (rows y-1, y, y+1 compared byte for byte), then per pixel.
// The new history (linear light, half floats RGBA) and the weight w (0..255) are written too.
//
// Modes (runtime ints): cur_mode 0 = reset (history := current, output untouched), 1 = affine,
// 2 = dense; prev_mode 0 = no previous motion (v_p := v_c), 1 = affine, 2 = dense.
// params: [0..5] current affine (x' = p0 x + p1 y + p2, y' = p3 x + p4 y + p5, current -> previous),
//         [6..11] previous frame's affine, [12] current flow scale, [13] previous flow scale,
//         [14] W_MAX, [15] K, [16] GAMMA, [17] FB_ABS, [18] FB_REL, [19] 1 = fb check on.
// Defines: LINEAR_INPUT 1 when samples are already linear light (no tables); REJECT (2.0).
#pragma OPENCL FP_CONTRACT OFF

#ifndef REJECT
#define REJECT 2.0f
#endif
// Half-width added to every clip box (linear light): a flat neighbourhood still admits history
// that differs by rounding only (about 1.5 8-bit levels near black, far less above).
#define EXT_FLOOR 0.0005f

inline float4 to_linear(__global const float *luts, float4 c)
{
#if LINEAR_INPUT
    return c;
#else
    return (float4)(lut_read(luts, c.x), lut_read(luts, c.y), lut_read(luts, c.z), c.w);
#endif
}

inline float4 from_linear(__global const float *luts, float4 c)
{
#if LINEAR_INPUT
    return c;
#else
    __global const float *enc = luts + 2 * (LUT_SIZE + 1);
    return (float4)(lut_read(enc, c.x), lut_read(enc, c.y), lut_read(enc, c.z), c.w);
#endif
}

// A pixel of the current frame in linear light. Integer samples read the decode table `dec`
// (entry v = lut_read(luts, v / PIXEL_MAX), built on the host by the same arithmetic: one load instead
// of the interpolated table read, bit for bit the same value); float samples use the tables.
#if !LINEAR_INPUT && !defined(PIXEL_IS_FLOAT)
#define DECODE_TABLE 1
#else
#define DECODE_TABLE 0
#endif
inline float4 load_linear(__global const float *luts, __global const float *dec,
                          __global const PIXEL_T *img, int i)
{
#if DECODE_TABLE
#if CHANNELS == 1
    float v = dec[img[i]];
    return (float4)(v, v, v, 1.0f);
#else
    __global const PIXEL_T *p = img + (size_t)i * CHANNELS;
#if ORDER_BGR
    float4 c = (float4)(dec[p[2]], dec[p[1]], dec[p[0]], 1.0f);
#else
    float4 c = (float4)(dec[p[0]], dec[p[1]], dec[p[2]], 1.0f);
#endif
#if CHANNELS == 4
    c.w = (float)p[3] * (1.0f / PIXEL_MAX);
#endif
    return c;
#endif
#else
    return to_linear(luts, load_px(img, i));
#endif
}

// Bilinear sample of a (fh, fw, 2) flow field at full-frame position p, in full-frame pixels.
inline float2 sample_flow(__global const float *f, int fw, int fh, float s, float2 p)
{
    float fx = (p.x + 0.5f) / s - 0.5f, fy = (p.y + 0.5f) / s - 0.5f;
    fx = fx < 0.0f ? 0.0f : (fx > (float)(fw - 1) ? (float)(fw - 1) : fx);
    fy = fy < 0.0f ? 0.0f : (fy > (float)(fh - 1) ? (float)(fh - 1) : fy);
    int x0 = (int)fx, y0 = (int)fy;
    int x1 = x0 + 1 < fw ? x0 + 1 : x0, y1 = y0 + 1 < fh ? y0 + 1 : y0;
    float ax = fx - (float)x0, ay = fy - (float)y0;
    float2 a = vload2(y0 * fw + x0, f), b = vload2(y0 * fw + x1, f);
    float2 c = vload2(y1 * fw + x0, f), d = vload2(y1 * fw + x1, f);
    float2 top = a + (b - a) * ax, bot = c + (d - c) * ax;
    return (top + (bot - top) * ay) * s;
}

inline float2 affine_motion(__global const float *m, float2 p)
{
    return (float2)(m[0] * p.x + m[1] * p.y + m[2] - p.x, m[3] * p.x + m[4] * p.y + m[5] - p.y);
}

// Catmull-Rom weights of the four taps around a sample at fraction t (sharper than bilinear: a
// history resampled every frame does not blur away; overshoot is removed by the clip that follows).
inline float4 catmull_rom(float t)
{
    return (float4)(t * (-0.5f + t * (1.0f - 0.5f * t)), 1.0f + t * t * (-2.5f + 1.5f * t),
                    t * (0.5f + t * (2.0f - 1.5f * t)), t * t * (-0.5f + 0.5f * t));
}

// History (linear RGBA halves) at position q, Catmull-Rom over 4x4 taps clamped to the frame.
// (Written out without arrays or min/max built-ins: PoCL calls those out of line.)
#define CLAMPI(v, hi) ((v) < 0 ? 0 : ((v) > (hi) ? (hi) : (v)))
// Half -> float by bit manipulation, exact for finite halves (vload_half is a call on PoCL): normals
// by re-biasing the exponent (+112), subnormals as (1 + m 2^-10) 2^-14 - 2^-14; alpha is never used
// (the output keeps the current pixel's), so a texel's colour only.
inline float4 htex(__global const ushort *hb, int i)
{
    __global const ushort *p = hb + 4 * i;
    uint4 v = (uint4)(p[0], p[1], p[2], 0u);
    uint4 m = v & 0x7fffu;
    float4 nrm = as_float4((m << 13) + (112u << 23));
    float4 sub = as_float4((m << 13) + (113u << 23)) - 0x1p-14f;
    float4 f = m < (uint4)0x400u ? sub : nrm;
    return as_float4(as_uint4(f) | ((v & 0x8000u) << 16));
}
#define HROW(yy) (htex(hb, (yy) * w + x0) * wx.x + htex(hb, (yy) * w + x1) * wx.y + \
                  htex(hb, (yy) * w + x2) * wx.z + htex(hb, (yy) * w + x3) * wx.w)
inline float4 sample_history(__global const half *hist, int w, int h, float2 q)
{
    float fx = q.x < 0.0f ? 0.0f : (q.x > (float)(w - 1) ? (float)(w - 1) : q.x);
    float fy = q.y < 0.0f ? 0.0f : (q.y > (float)(h - 1) ? (float)(h - 1) : q.y);
    int xi = (int)fx, yi = (int)fy;
    __global const ushort *hb = (__global const ushort *)hist;
    // on a texel (a static shot, a whole-pixel shift) the weights are (0, 1, 0, 0): the texel exactly
    if (fx == (float)xi && fy == (float)yi) return htex(hb, yi * w + xi);
    float4 wx = catmull_rom(fx - (float)xi), wy = catmull_rom(fy - (float)yi);
    int x0 = CLAMPI(xi - 1, w - 1), x1 = xi, x2 = CLAMPI(xi + 1, w - 1), x3 = CLAMPI(xi + 2, w - 1);
    int y0 = CLAMPI(yi - 1, h - 1), y2 = CLAMPI(yi + 1, h - 1), y3 = CLAMPI(yi + 2, h - 1);
    float4 acc = HROW(y0) * wy.x;
    acc += HROW(yi) * wy.y;
    acc += HROW(y2) * wy.z;
    acc += HROW(y3) * wy.w;
    return acc;
}

// Flatness, byte for byte in the frame's own type (plain loops: faster than vload8 on PoCL).
#define PXB (CHANNELS * (int)sizeof(PIXEL_T))
inline int bytes_equal(__global const uchar *a, __global const uchar *b, int n)
{
    uchar d = 0;
    for (int k = 0; k < n; ++k) d |= a[k] ^ b[k];
    return d == 0;
}

// Pixels [gx, gx + GROUP) all flat: row y constant over [gx - 1, gx + GROUP], rows y-1 and y+1 equal
// to it there. Needs 1 <= gx and gx + GROUP < width.
inline int group_flat(__global const uchar *ra, __global const uchar *rm, __global const uchar *rb, int gx)
{
    __global const uchar *m = rm + (gx - 1) * PXB;
    return bytes_equal(m, m + PXB, (GROUP + 1) * PXB) &&
           bytes_equal(ra + (gx - 1) * PXB, m, (GROUP + 2) * PXB) &&
           bytes_equal(rb + (gx - 1) * PXB, m, (GROUP + 2) * PXB);
}

// The near-flat rule: FLAT_LEVELS (stored units, host: temporal.flat_levels) is how far a sample of
// the 3x3 neighbourhood may be from the centre's and still count as flat (codec noise, dithering).
#ifndef FLAT_NEAR
#define FLAT_NEAR 0
#define FLAT_LEVELS 0
#endif
#ifdef PIXEL_IS_FLOAT
typedef float sample_t;
#else
typedef int sample_t;
#endif
inline int samples_near(__global const PIXEL_T *a, __global const PIXEL_T *b)
{
    int ok = 1;
    for (int k = 0; k < CHANNELS; ++k) {
        const sample_t d = (sample_t)a[k] - (sample_t)b[k];
        ok &= (d <= (sample_t)FLAT_LEVELS) & (d >= -(sample_t)FLAT_LEVELS);
    }
    return ok;
}

// Pixels [gx, gx + GROUP) all near-flat, sufficiently: the 3 x (GROUP + 2) window's range per channel
// is at most FLAT_LEVELS (so every pixel's 8 neighbours are within it). Needs 1 <= gx, gx + GROUP < width.
inline int group_near_flat(__global const PIXEL_T *ra, __global const PIXEL_T *rm, __global const PIXEL_T *rb,
                           int gx)
{
    int ok = 1;
    for (int k = 0; k < CHANNELS; ++k) {
        sample_t lo = (sample_t)rm[(gx - 1) * CHANNELS + k], hi = lo;
        for (int i = gx - 1; i <= gx + GROUP; ++i) {
            const sample_t a = (sample_t)ra[i * CHANNELS + k], m = (sample_t)rm[i * CHANNELS + k];
            const sample_t b = (sample_t)rb[i * CHANNELS + k];
            lo = a < lo ? a : lo; hi = a > hi ? a : hi;
            lo = m < lo ? m : lo; hi = m > hi ? m : hi;
            lo = b < lo ? b : lo; hi = b > hi ? b : hi;
        }
        ok &= hi - lo <= (sample_t)FLAT_LEVELS;
    }
    return ok;
}

// One pixel flat: its 8 neighbours (xl, xr, ya, yb clamped) equal the centre (within FLAT_LEVELS).
inline int pixel_flat(__global const uchar *ra, __global const uchar *rm, __global const uchar *rb,
                      int xl, int x, int xr)
{
#if FLAT_NEAR
    __global const PIXEL_T *a = (__global const PIXEL_T *)ra, *m = (__global const PIXEL_T *)rm;
    __global const PIXEL_T *b = (__global const PIXEL_T *)rb, *c = m + x * CHANNELS;
    return samples_near(m + xl * CHANNELS, c) && samples_near(m + xr * CHANNELS, c) &&
           samples_near(a + xl * CHANNELS, c) && samples_near(a + x * CHANNELS, c) &&
           samples_near(a + xr * CHANNELS, c) && samples_near(b + xl * CHANNELS, c) &&
           samples_near(b + x * CHANNELS, c) && samples_near(b + xr * CHANNELS, c);
#else
    __global const uchar *c = rm + x * PXB;
    return bytes_equal(rm + xl * PXB, c, PXB) && bytes_equal(rm + xr * PXB, c, PXB) &&
           bytes_equal(ra + xl * PXB, c, PXB) && bytes_equal(ra + x * PXB, c, PXB) &&
           bytes_equal(ra + xr * PXB, c, PXB) && bytes_equal(rb + xl * PXB, c, PXB) &&
           bytes_equal(rb + x * PXB, c, PXB) && bytes_equal(rb + xr * PXB, c, PXB);
#endif
}

// The flat rule's output for pixels [xa, xb) that all hold the value at xa: the current pixel untouched,
// history = `bits` (that value in linear light as 4 halves), weight 0. Fixed-length loops when whole.
inline void pass_flat(__global const PIXEL_T *cur, __global half *hist_out, __global PIXEL_T *dst,
                      __global uchar *conf, ulong bits, int row, int xa, int xb)
{
    __global ulong *ho = (__global ulong *)hist_out + row + xa;
    __global uchar *cf = conf + row + xa;
    __global const uchar *src = (__global const uchar *)cur + (size_t)(row + xa) * PXB;
    __global uchar *out = (__global uchar *)dst + (size_t)(row + xa) * PXB;
    if (xb - xa == GROUP) {
        for (int k = 0; k < GROUP; ++k) { ho[k] = bits; cf[k] = 0; }
        for (int k = 0; k < GROUP * PXB; ++k) out[k] = src[k];
    } else {
        for (int k = 0; k < xb - xa; ++k) { ho[k] = bits; cf[k] = 0; }
        for (int k = 0; k < (xb - xa) * PXB; ++k) out[k] = src[k];
    }
}

// Pixels [xa, xb) without history: each untouched, its own value in linear light as the new history,
// weight 0 (what the per-pixel path below gives them, without its 3x3 statistics).
inline void pass_own(__global const float *luts, __global const float *dec, __global const PIXEL_T *cur,
                     __global half *hist_out, __global PIXEL_T *dst, __global uchar *conf, int row, int xa, int xb)
{
    for (int x = xa; x < xb; ++x) {
        vstore_half4_rte(load_linear(luts, dec, cur, row + x), row + x, hist_out);
        conf[row + x] = 0;
    }
    __global const uchar *s8 = (__global const uchar *)cur + (size_t)(row + xa) * PXB;
    __global uchar *d8 = (__global uchar *)dst + (size_t)(row + xa) * PXB;
    for (int k = 0; k < (xb - xa) * PXB; ++k) d8[k] = s8[k];
}

// Whether the gate is 0 on all of gate[i .. i + n).
inline int gate_closed(__global const uchar *gate, int i, int n)
{
    uchar g = 0;
    for (int k = 0; k < n; ++k) g |= gate[i + k];
    return g == 0;
}

// Vertical Catmull-Rom of texel column cx over rows r0..r3 (clamped): one column of the 4x4 taps.
#define VCOL(cx) (htex(hb, r0 * width + CLAMPI(cx, width - 1)) * wy.x + \
                  htex(hb, r1 * width + CLAMPI(cx, width - 1)) * wy.y + \
                  htex(hb, r2 * width + CLAMPI(cx, width - 1)) * wy.z + \
                  htex(hb, r3 * width + CLAMPI(cx, width - 1)) * wy.w)

#define MIN4(a, b) ((float4)((a).x < (b).x ? (a).x : (b).x, (a).y < (b).y ? (a).y : (b).y, \
                             (a).z < (b).z ? (a).z : (b).z, (a).w < (b).w ? (a).w : (b).w))
#define MAX4(a, b) ((float4)((a).x > (b).x ? (a).x : (b).x, (a).y > (b).y ? (a).y : (b).y, \
                             (a).z > (b).z ? (a).z : (b).z, (a).w > (b).w ? (a).w : (b).w))

// Statistics of column cx over rows ya, y, yb (in the kernel's scope): sum (a + m) + b, sum of
// squares in the same order, min, max; m = the sample of row y. The 3x3 sums are the column sums
// added left to right (temporal_reference adds in the same order).
#define COLUMN_STATS(cx, sum, sq, lo, hi, m) do { \
        float4 a_ = load_linear(luts, dec, cur, IDX(cx, ya, width)); \
        m = load_linear(luts, dec, cur, IDX(cx, y, width)); \
        float4 b_ = load_linear(luts, dec, cur, IDX(cx, yb, width)); \
        sum = a_ + m + b_; sq = a_ * a_ + m * m + b_ * b_; \
        lo = MIN4(MIN4(a_, m), b_); hi = MAX4(MAX4(a_, m), b_); \
    } while (0)

__kernel void temporal_blend(__global const PIXEL_T *cur, __global const half *hist,
                             __global half *hist_out, __global PIXEL_T *dst, __global uchar *conf,
                             __global const float *flow_b, __global const float *flow_f,
                             __global const float *flow_prev, __global const float *params,
                             __global const float *luts, __global const float *dec,
                             const int width, const int height,
                             const int fw, const int fh, const int pfw, const int pfh,
                             const int cur_mode, const int prev_mode,
                             __global const uchar *gate, const int gated)
{
    const int x0 = get_global_id(0) * SEGMENT, y = get_global_id(1);
    if (x0 >= width || y >= height) return;
    const int x1 = min(x0 + SEGMENT, width);
    const int ya = y > 0 ? y - 1 : 0, yb = y + 1 < height ? y + 1 : height - 1;
    const float w_max = params[14], k = params[15], gamma = params[16];
    const float fb_abs = params[17], fb_rel = params[18];
    const int fb_on = params[19] > 0.5f;

    __global const uchar *ra = (__global const uchar *)cur + (size_t)ya * width * PXB;
    __global const uchar *rm = (__global const uchar *)cur + (size_t)y * width * PXB;
    __global const uchar *rb = (__global const uchar *)cur + (size_t)yb * width * PXB;
    const int row = y * width;

    ulong bits = 0;     // the flat run's history value; consecutive flat groups share their value
    int run = 0;
    // A pure translation (static / global models) samples every pixel of this row at the same
    // fraction and rows: the vertically filtered texel columns are shared by neighbouring pixels,
    // so a sliding window of 4 columns needs 4 new taps per pixel instead of 16.
    const int translation = cur_mode == 1 && params[0] == 1.0f && params[1] == 0.0f &&
                            params[3] == 0.0f && params[4] == 1.0f;
    __global const ushort *hb = (__global const ushort *)hist;
    float4 wy = (float4)(0.0f), k0 = (float4)(0.0f), k1 = k0, k2 = k0, k3 = k0;
    int r0 = 0, r1 = 0, r2 = 0, r3 = 0, cached = -3, texel_row = 0;   // k0..k3 = columns cached-1 .. cached+2
    if (translation) {
        float fy = (float)y + affine_motion(params, (float2)(0.0f, (float)y)).y;
        fy = fy < 0.0f ? 0.0f : (fy > (float)(height - 1) ? (float)(height - 1) : fy);
        r1 = (int)fy;
        wy = catmull_rom(fy - (float)r1);
        r0 = CLAMPI(r1 - 1, height - 1); r2 = CLAMPI(r1 + 1, height - 1); r3 = CLAMPI(r1 + 2, height - 1);
        texel_row = fy == (float)r1;
    }
    for (int gx = x0; gx < x1; gx += GROUP) {
        const int gend = gx + GROUP < x1 ? gx + GROUP : x1;
        if (gx >= 1 && gx + GROUP < width && group_flat(ra, rm, rb, gx)) {   // the flat rule, 8 at once
            if (!run) vstore_half4_rte(load_linear(luts, dec, cur, row + gx), 0, (half *)&bits);
            run = 1;
            pass_flat(cur, hist_out, dst, conf, bits, row, gx, gend);
            continue;
        }
        run = 0;
        // a reset, or a group the gate closes (where="render": most of a frame): no history in the group
        if (cur_mode == 0 || (gated && gate_closed(gate, row + gx, gend - gx))) {
            pass_own(luts, dec, cur, hist_out, dst, conf, row, gx, gend);
            continue;
        }
#if FLAT_NEAR
        if (gx >= 1 && gx + GROUP < width &&
            group_near_flat((__global const PIXEL_T *)ra, (__global const PIXEL_T *)rm,
                            (__global const PIXEL_T *)rb, gx)) {
            pass_own(luts, dec, cur, hist_out, dst, conf, row, gx, gend);   // near-flat: no history either
            continue;
        }
#endif
        // Sliding 3x3 window in linear light, kept as per-column statistics of rows y-1, y, y+1:
        // sum, sum of squares, min, max of columns L (x-1), C (x), R (x+1); Cm = the pixel itself.
        int xl = gx > 0 ? gx - 1 : 0;
        float4 sL, qL, nL, xL, sC, qC, nC, xC, Cm;
        COLUMN_STATS(xl, sL, qL, nL, xL, Cm);
        COLUMN_STATS(gx, sC, qC, nC, xC, Cm);

        for (int x = gx; x < gend; ++x) {
            const int xr = x + 1 < width ? x + 1 : width - 1;
            float4 sR, qR, nR, xR, Rm;
            COLUMN_STATS(xr, sR, qR, nR, xR, Rm);
            const int i = IDX(x, y, width);
            float4 c = Cm;   // current pixel, linear (alpha as stored)
            float wgt = 0.0f;
            float4 out = c;
            // the gate (gated: history only where gate[i] != 0), then the flat rule
            if (cur_mode != 0 && (!gated || gate[i]) && !pixel_flat(ra, rm, rb, x > 0 ? x - 1 : 0, x, xr)) {
                float2 p = (float2)((float)x, (float)y);
                float2 vc = cur_mode == 2 ? sample_flow(flow_b, fw, fh, params[12], p)
                                          : affine_motion(params, p);
                float2 q = p + vc;
                int inside = q.x >= -0.5f && q.x <= (float)width - 0.5f &&
                             q.y >= -0.5f && q.y <= (float)height - 0.5f;
                if (inside) {
                    float fbw = 1.0f;
                    if (cur_mode == 2 && fb_on) {
                        float2 g = sample_flow(flow_f, fw, fh, params[12], q);
                        float2 eg = vc + g;
                        float e = sqrt(eg.x * eg.x + eg.y * eg.y);
                        float tol = fb_abs + fb_rel * sqrt(vc.x * vc.x + vc.y * vc.y);
                        fbw = 2.0f - e / tol;
                        fbw = fbw < 0.0f ? 0.0f : (fbw > 1.0f ? 1.0f : fbw);
                    }
                    float2 vp = prev_mode == 2 ? sample_flow(flow_prev, pfw, pfh, params[13], q)
                              : (prev_mode == 1 ? affine_motion(params + 6, q) : vc);
                    // seed 002: w = 0.5 max(0, 1 - K sqrt(|v_c - v_p|)), vectors, pixel units
                    float2 dv = vc - vp;
                    float vw = 1.0f - k * sqrt(sqrt(dv.x * dv.x + dv.y * dv.y));
                    wgt = w_max * (vw > 0.0f ? vw : 0.0f) * fbw;
                }
                if (wgt > 0.0f) {
                    float4 h;
                    if (translation) {
                        float fx = q.x < 0.0f ? 0.0f : (q.x > (float)(width - 1) ? (float)(width - 1) : q.x);
                        int xi = (int)fx;
                        if (texel_row && fx == (float)xi) {
                            // on a texel (static shot, whole-pixel shift): weights (0, 1, 0, 0), the texel
                            h = htex(hb, r1 * width + xi);
                        } else {
                            if (xi == cached + 1) {
                                k0 = k1; k1 = k2; k2 = k3; k3 = VCOL(xi + 2);
                            } else if (xi != cached) {
                                k0 = VCOL(xi - 1); k1 = VCOL(xi); k2 = VCOL(xi + 1); k3 = VCOL(xi + 2);
                            }
                            cached = xi;
                            float4 wx = catmull_rom(fx - (float)xi);
                            h = k0 * wx.x + k1 * wx.y + k2 * wx.z + k3 * wx.w;
                        }
                    } else {
                        h = sample_history(hist, width, height, q);
                    }
                    // 3x3 statistics of the current frame (variance clipping, Salvi 2016)
                    float4 s = sL + sC + sR, s2 = qL + qC + qR;
                    float4 mn = MIN4(MIN4(nL, nC), nR), mx = MAX4(MAX4(xL, xC), xR);
                    float4 mu = s * (1.0f / 9.0f);
                    float4 var = s2 * (1.0f / 9.0f) - mu * mu;
                    float4 sd = sqrt(MAX4(var, (float4)(0.0f)));
                    float4 lo_v = mu - gamma * sd, hi_v = mu + gamma * sd;
                    float4 lo = MAX4(mn, lo_v), hi = MIN4(mx, hi_v);
                    float4 ctr = (lo + hi) * 0.5f, ext = (hi - lo) * 0.5f + EXT_FLOOR;
                    float4 d = h - ctr;
                    float tx = (d.x < 0.0f ? -d.x : d.x) / ext.x, ty = (d.y < 0.0f ? -d.y : d.y) / ext.y;
                    float tz = (d.z < 0.0f ? -d.z : d.z) / ext.z;
                    float t = tx > ty ? (tx > tz ? tx : tz) : (ty > tz ? ty : tz);
                    if (t > 1.0f) h = ctr + d / t;
                    // history far outside the box is another surface (a disocclusion the flow missed):
                    // its weight falls from full at the box (t = 1) to none at t = REJECT
                    float keep = (REJECT - t) * (1.0f / (REJECT - 1.0f));
                    wgt *= keep < 0.0f ? 0.0f : (keep > 1.0f ? 1.0f : keep);
                    out = c + (h - c) * wgt;
                    out.w = c.w;
                }
            }
            vstore_half4_rte(out, i, hist_out);
            conf[i] = (uchar)(wgt * 255.0f + 0.5f);
            if (wgt > 0.0f) {
                store_px(dst, i, from_linear(luts, out));
            } else {   // no history here: the spatial output, bit for bit
    #if CHANNELS == 1
                dst[i] = cur[i];
    #else
                for (int ch = 0; ch < CHANNELS; ++ch)
                    dst[(size_t)i * CHANNELS + ch] = cur[(size_t)i * CHANNELS + ch];
    #endif
            }
            sL = sC; qL = qC; nL = nC; xL = xC;
            sC = sR; qC = qR; nC = nR; xC = xR; Cm = Rm;
        }
    }
}
