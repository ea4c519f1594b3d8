// reconstruct_rules.cl -- topological reconstruction of sub-pixel features (seed 000 §4), plus two rules
// beyond the paper (docs/reconstruct.md). Runs before edge detection. dst must hold a copy of src (the host
// enqueues it): the kernel writes reconstructed pixels only.
// The numpy reference is mlaa_stream.reconstruct.reconstruct_reference; this file mirrors it rule for rule.
//
// One kernel, one work item per SEGMENT pixels of STRIP rows (PoCL CPU runs branchy per-pixel kernels slowly,
// and CIELAB costs ~25 ns a pixel converted alone, several times less in lanes of eight), row by row, GROUP
// pixels at a time (docs/reconstruct.md, "Speed"):
//   1. RGB only (Lipschitz bound of ΔE in max-channel difference): a lane per pixel, the pixels where a rule
//      may fire (a gap among the ring neighbours at the bound, table bit 1; extended, a neighbour at twice
//      it); bit-identical windows settled at once; the frame's border groups run the rules a pixel at a time;
//   2. CIELAB a lane per pixel of rows y-1, y, y+1 of the groups holding such pixels (and the neighbour groups
//      their end lanes read), kept in a 3-row scratch per work item (each pixel converted once per strip);
//   3. the exact ring masks, eight ΔE at once per lane: only lanes whose X can make a rule fire run the
//      rules (reconstruct_at), from the same CIELAB numbers.
// Defines (mlaa_stream.reconstruct.Reconstructor):
//   CHEAP_BOUND      max-channel difference (normalised) below which ΔE76 cannot exceed the threshold
//   CHEAP_LEVELS     integer frames: the smallest difference in stored levels over CHEAP_BOUND * PIXEL_MAX
//   FAR_LEVELS       the same for 2 * CHEAP_BOUND (the extended rules' line contrast)
//   SAMPLE_BYTES     1, 2 or 4: bytes of a stored sample (uchar, ushort, float), for the identical-window
//                    tests and the 8-bit RGB loads
//   STRIP            rows per work item
//   EXTENDED         1: also the rules beyond the paper (line-relative X, two-pixel gaps)
//   LINEAR_INPUT     1 when samples are linear light: encoded to sRGB (table) before the Lab comparison
//   MAX_LINE_PIXELS  line-coloured pixels a 5x5 window around a gap may hold
//   MIN_AIM          cosine between a line piece's direction and the way to A
//   MAX_OFFSET       px between the lines through the two pieces
//   STOP_AFTER       0; 1 or 2 stop the work early, for reconstruct_bench --split's timing of the parts
// table[mask] (mask: bit k = ring neighbour k differs): bit 0 = gap (T8(A,X)=2, T8(A,X-bar)=1 or the
// straight-gap case, seed 000 eq. 4), bit 1 = some sub-mask is a gap, bits 8..15 = the ring pixels of
// the first 8-component of X.
#ifndef EXTENDED
#define EXTENDED 1
#endif
#ifndef CHEAP_BOUND
#define CHEAP_BOUND 0.0f
#endif
#ifndef CHEAP_LEVELS
#define CHEAP_LEVELS 0
#endif
#ifndef FAR_LEVELS
#define FAR_LEVELS 0
#endif
#ifndef MAX_LINE_PIXELS
#define MAX_LINE_PIXELS 8
#endif
#ifndef MIN_AIM
#define MIN_AIM 0.7f
#endif
#ifndef MAX_OFFSET
#define MAX_OFFSET 1.01f
#endif
#ifndef STRIP
#define STRIP 16
#endif
#ifndef STOP_AFTER
#define STOP_AFTER 0   // timing split only (reconstruct_bench --split): 1 = after the RGB gate, 2 = before the rules
#endif

// The ring N8*(A), clockwise from the top-left: bit k of a mask is (RX[k], RY[k]).
__constant int RX[8] = {-1, 0, 1, 1, 1, 0, -1, -1};
__constant int RY[8] = {-1, -1, -1, 0, 1, 1, 1, 0};

// ---- the cheap test, in stored values: integer levels for 8/16-bit frames, normalised floats otherwise.
// Max-channel differences of integer samples are exact: d >= CHEAP_LEVELS is d > CHEAP_BOUND * PIXEL_MAX,
// which every pair with ΔE over the threshold meets (ΔE <= Lipschitz * max-channel difference).
#ifdef PIXEL_IS_FLOAT
typedef float4 rawpx;
typedef float rawdiff;
#define NEAR_LIMIT CHEAP_BOUND
#define FAR_LIMIT (2.0f * CHEAP_BOUND)
inline rawpx raw_px(__global const PIXEL_T *src, int i) { return load_px(src, i); }
#else
typedef int4 rawpx;
typedef int rawdiff;
#define NEAR_LIMIT CHEAP_LEVELS
#define FAR_LIMIT FAR_LEVELS
inline rawpx raw_px(__global const PIXEL_T *src, int i)
{
#if CHANNELS == 1
    int v = src[i];
    return (int4)(v, v, v, 0);
#else
    __global const PIXEL_T *p = src + (size_t)i * CHANNELS;   // channel order does not matter here
    return (int4)(p[0], p[1], p[2], 0);
#endif
}
#endif

// PoCL calls fabs/fmax/min/max out of line: plain expressions in the hot path.
inline rawdiff max_diff(rawpx a, rawpx b)
{
    rawpx d = a - b;
    rawdiff x = d.x < 0 ? -d.x : d.x, y = d.y < 0 ? -d.y : d.y, z = d.z < 0 ? -d.z : d.z;
    rawdiff m = x > y ? x : y;
    return m > z ? m : z;
}

// ---- CIELAB, the same numbers as common.cl's rgb_to_lab (after the LINEAR_INPUT encoding). Integer
// frames read the per-level sRGB->linear values from `lin` (filled once by common.cl's linear_levels with
// the same lut_read), which halves the cost of a conversion.
inline float3 lab_of(__global const float *luts, float4 c)
{
#if LINEAR_INPUT
    __global const float *enc = luts + 2 * (LUT_SIZE + 1);
    c = (float4)(lut_read(enc, encode_arg(c.x)), lut_read(enc, encode_arg(c.y)), lut_read(enc, encode_arg(c.z)), c.w);
#endif
    return rgb_to_lab(luts, c);
}

inline float3 lab_px(__global const PIXEL_T *src, __global const float *luts, __global const float *lin, int i)
{
#ifdef PIXEL_IS_FLOAT
    return lab_of(luts, load_px(src, i));
#else
    return lab_of_levels(src, luts, lin, i);
#endif
}

inline float d2(float3 a, float3 b)
{
    float3 d = a - b;
    return d.x * d.x + d.y * d.y + d.z * d.z;
}

inline int inside(int x, int y, int w, int h) { return x >= 0 && y >= 0 && x < w && y < h; }

// All colours of the shape within the threshold of their mean (seed 000 §4.2: "sharing the same color");
// returns the mean Lab in *mean.
inline int one_colour(const float3 *n, uint mask, float t2, float3 *mean)
{
    float3 m = (float3)(0.0f);
    int cnt = 0;
    for (int k = 0; k < 8; ++k)
        if (mask >> k & 1u) { m += n[k]; ++cnt; }
    m /= (float)cnt;
    *mean = m;
    for (int k = 0; k < 8; ++k)
        if ((mask >> k & 1u) && d2(n[k], m) > t2) return 0;
    return 1;
}

// The 5x5 checks the paper's 3x3 rule lacks: every pixel is line-coloured (within the threshold of c)
// or background (within it of A; `relaxed`: nearer to A than to c and within 2 thresholds of A), at most
// MAX_LINE_PIXELS are line-coloured, each piece of the shape continues outward and aims at A, and the
// lines through the two pieces are at most MAX_OFFSET apart (one line, not two parallel strokes).
inline int thin_gap(__global const PIXEL_T *src, __global const float *luts, __global const float *lin, int x, int y,
                    int w, int h, float3 a, float3 c, uint mask, uint comp1, float t2, int relaxed)
{
    int line = 0;
    float ox[2] = {0.0f, 0.0f}, oy[2] = {0.0f, 0.0f};
    int on[2] = {0, 0};
    for (int dy = -2; dy <= 2; ++dy) {
        for (int dx = -2; dx <= 2; ++dx) {
            if ((dx == 0 && dy == 0) || !inside(x + dx, y + dy, w, h)) continue;
            float3 q = lab_px(src, luts, lin, IDX(x + dx, y + dy, w));
            float dc = d2(q, c), da = d2(q, a);
            if (dc <= t2) {
                ++line;
                if (abs(dx) == 2 || abs(dy) == 2) {
                    for (int p = 0; p < 2; ++p) {
                        uint comp = p == 0 ? comp1 : (mask & ~comp1);
                        int touches = 0;
                        for (int k = 0; k < 8; ++k)
                            if ((comp >> k & 1u) && abs(dx - RX[k]) <= 1 && abs(dy - RY[k]) <= 1) touches = 1;
                        if (touches) { ox[p] += (float)dx; oy[p] += (float)dy; ++on[p]; }
                    }
                }
            } else if (relaxed ? (da >= dc || da > 4.0f * t2) : (da > t2)) {
                return 0;
            }
        }
    }
    if (line > MAX_LINE_PIXELS || on[0] == 0 || on[1] == 0) return 0;
    float px[2], py[2], ux[2], uy[2];
    for (int p = 0; p < 2; ++p) {
        uint comp = p == 0 ? comp1 : (mask & ~comp1);
        float sx = 0.0f, sy = 0.0f;
        int cnt = 0;
        for (int k = 0; k < 8; ++k)
            if (comp >> k & 1u) { sx += (float)RX[k]; sy += (float)RY[k]; ++cnt; }
        px[p] = sx / (float)cnt;
        py[p] = sy / (float)cnt;
        float vx = px[p] - ox[p] / (float)on[p], vy = py[p] - oy[p] / (float)on[p];
        float vn = sqrt(vx * vx + vy * vy);
        if (vn == 0.0f || -(px[p] * vx + py[p] * vy) < MIN_AIM * sqrt(px[p] * px[p] + py[p] * py[p]) * vn)
            return 0;
        ux[p] = vx / vn;
        uy[p] = vy / vn;
    }
    float dx = ux[0] - ux[1], dy = uy[0] - uy[1];
    float un = sqrt(dx * dx + dy * dy);
    return un > 0.0f && fabs((px[1] - px[0]) * dy - (py[1] - py[0]) * dx) <= MAX_OFFSET * un;
}

// Mean colour of the ring pixels in `mask` (stored values, normalised), alpha from A.
inline void store_mean(__global const PIXEL_T *src, __global PIXEL_T *dst, int x, int y, int w, uint mask)
{
    float4 s = (float4)(0.0f);
    int cnt = 0;
    for (int k = 0; k < 8; ++k)
        if (mask >> k & 1u) { s += load_px(src, IDX(x + RX[k], y + RY[k], w)); ++cnt; }
    float4 m = s / (float)cnt;
    m.w = load_px(src, IDX(x, y, w)).w;
    store_px(dst, IDX(x, y, w), m);
}


// ---- step 1: where a rule may fire, from RGB alone.
// Quiet group: none of the GROUP pixels has a ring neighbour at the cheap bound or beyond in any channel, so
// no ring neighbour can be in X. Tested on the raw sample stream (channel order does not
// matter: a pixel's samples are compared with the same samples of its neighbours); flat and smooth areas
// cost just this. Interior groups only (the caller checks). Alpha samples take part (a stricter test).
// Plain byte/sample loops: PoCL runs them 2-3x faster than vload8 words here (docs/reconstruct.md).
inline int same_bytes(__global const uchar *a, __global const uchar *b, int n)
{
    int same = 1;
    for (int o = 0; o < n; ++o) same &= a[o] == b[o];
    return same;
}

// Bit-identical 3x(GROUP+2) window (rendered flat areas): rows above and below equal this row over
// x-1..x+GROUP, and this row equal to itself shifted by a pixel.
inline int identical_window(__global const PIXEL_T *src, int i, int width)
{
    const int px = CHANNELS * SAMPLE_BYTES, row = width * px;
    __global const uchar *p = (__global const uchar *)src + (size_t)(i - 1) * px;
    return same_bytes(p, p - row, (GROUP + 2) * px) && same_bytes(p, p + row, (GROUP + 2) * px) &&
           same_bytes(p, p + px, (GROUP + 1) * px);
}

#ifdef PIXEL_IS_FLOAT
// Float frames: every sample against the same sample of its 8 neighbours (smooth areas).
inline int smooth_group(__global const PIXEL_T *src, int i, int width)
{
    __global const PIXEL_T *q = src + (size_t)i * CHANNELS;
    const int rs = width * CHANNELS;
    for (int k = 0; k < 8; ++k) {   // a neighbour at a time: busy groups leave early
        const int off = RY[k] * rs + RX[k] * CHANNELS;
        int hit = 0;
        for (int t = 0; t < GROUP * CHANNELS; ++t) {
            rawdiff u = q[t], v = q[t + off];
            hit |= (u > v ? u - v : v - u) >= NEAR_LIMIT;
        }
        if (hit) return 0;
    }
    return 1;
}
#endif

// Ring bits whose neighbour lies inside the frame.
inline uint valid_ring(int x, int y, int width, int height)
{
    uint v = 0xffu;
    if (x == 0) v &= ~0xc1u;            // NW, SW, W
    if (x == width - 1) v &= ~0x1cu;    // NE, E, SE
    if (y == 0) v &= ~0x07u;            // NW, N, NE
    if (y == height - 1) v &= ~0x70u;   // SE, S, SW
    return v;
}

#ifndef PIXEL_IS_FLOAT
// ---- integer frames: a whole group at once, a lane per pixel (OpenCL vectors: SIMD on a CPU, plain
// registers on a GPU). A row vector holds one sample of the pixels g-1 .. g+GROUP of a row (10 lanes); a
// neighbour column of the group is that row shifted by 0 (x-1), 1 (x) or 2 (x+1) lanes. ushort lanes hold
// 8- and 16-bit samples, and |a - b| as the larger minus the smaller never overflows. Macros, not
// functions, for the wide vectors (PoCL passes them to calls through memory).
#define CH (CHANNELS < 3 ? 1 : 3)   // samples compared (gray: one; RGBA: alpha left out, as in raw_px)
#define RGB8 (CHANNELS == 3 && SAMPLE_BYTES == 1)
#define ROW_SAMPLE(p, c) ((ushort16)((p)[c], (p)[(c) + CHANNELS], (p)[(c) + 2 * CHANNELS],               \
    (p)[(c) + 3 * CHANNELS], (p)[(c) + 4 * CHANNELS], (p)[(c) + 5 * CHANNELS], (p)[(c) + 6 * CHANNELS],   \
    (p)[(c) + 7 * CHANNELS], (p)[(c) + 8 * CHANNELS], (p)[(c) + 9 * CHANNELS], 0, 0, 0, 0, 0, 0))
#define ABS_DIFF(u, v) ((u) > (v) ? (u) - (v) : (v) - (u))
#define RING_BITS(d0, d1, d2, d3, d4, d5, d6, d7, lim)                                                    \
    (((d0 >= (ushort)(lim)) & (short8)1) | ((d1 >= (ushort)(lim)) & (short8)2) |                         \
     ((d2 >= (ushort)(lim)) & (short8)4) | ((d3 >= (ushort)(lim)) & (short8)8) |                         \
     ((d4 >= (ushort)(lim)) & (short8)16) | ((d5 >= (ushort)(lim)) & (short8)32) |                       \
     ((d6 >= (ushort)(lim)) & (short8)64) | ((d7 >= (ushort)(lim)) & (short8)128))

// Ring masks of the GROUP pixels from i on (an interior group): bit k where neighbour k's max-channel
// difference reaches NEAR_LIMIT (*maybe) or FAR_LIMIT (*far) -- ring_masks() a lane per pixel
// (formats other than 8-bit RGB, which gate_rgb8 handles).
inline void group_masks(__global const PIXEL_T *src, int i, int width, short8 *maybe, short8 *far)
{
    __global const PIXEL_T *p = src + (size_t)(i - 1) * CHANNELS;
    const size_t rs = (size_t)width * CHANNELS;
#if CH == 3
    ushort16 c0 = ROW_SAMPLE(p, 0), c1 = ROW_SAMPLE(p, 1), c2 = ROW_SAMPLE(p, 2);
#define LOAD_ROW(q) { c0 = ROW_SAMPLE(q, 0); c1 = ROW_SAMPLE(q, 1); c2 = ROW_SAMPLE(q, 2); }
    const ushort8 a0 = c0.s12345678, a1 = c1.s12345678, a2 = c2.s12345678;
#define DIFF(sw, out) {                                                                    \
        ushort8 u = ABS_DIFF(c0.sw, a0), v = ABS_DIFF(c1.sw, a1), w = ABS_DIFF(c2.sw, a2);    \
        u = u > v ? u : v;                                                                 \
        out = u > w ? u : w; }
#else
    ushort16 c0 = ROW_SAMPLE(p, 0);
    const ushort8 a0 = c0.s12345678;
#define DIFF(sw, out) { out = ABS_DIFF(c0.sw, a0); }
#define LOAD_ROW(q) { c0 = ROW_SAMPLE(q, 0); }
#endif
    ushort8 d0, d1, d2, d3, d4, d5, d6, d7;
    DIFF(s01234567, d7)   // W
    DIFF(s23456789, d3)   // E
    LOAD_ROW(p - rs)
    DIFF(s01234567, d0)   // NW
    DIFF(s12345678, d1)   // N
    DIFF(s23456789, d2)   // NE
    LOAD_ROW(p + rs)
    DIFF(s01234567, d6)   // SW
    DIFF(s12345678, d5)   // S
    DIFF(s23456789, d4)   // SE
#undef DIFF
#undef LOAD_ROW
    *maybe = RING_BITS(d0, d1, d2, d3, d4, d5, d6, d7, NEAR_LIMIT);
    *far = RING_BITS(d0, d1, d2, d3, d4, d5, d6, d7, FAR_LIMIT);
}
#endif

#if RGB8
// 8-bit RGB: the pixels of the interior group from i on (bit t: pixel i + t) where a rule may fire by the RGB
// bounds alone, candidate()'s first tests a lane per pixel on uchar planes: two ring neighbours at ring
// distance >= 3 (what table bit 1 means: such a pair is a gap, and every gap holds one) reach NEAR_LIMIT in some
// sample, or (extended rules) one reaches FAR_LIMIT.
#define PLANES(q, c0, c1, c2) {                                                                          \
        const uchar16 l_ = LOAD_UCHAR16(q), h_ = LOAD_UCHAR16((q) + 14);                               \
        c0 = (uchar16)(l_.s0, l_.s3, l_.s6, l_.s9, l_.sc, l_.sf, h_.s4, h_.s7, h_.sa, h_.sd, 0, 0, 0, 0, 0, 0); \
        c1 = (uchar16)(l_.s1, l_.s4, l_.s7, l_.sa, l_.sd, h_.s2, h_.s5, h_.s8, h_.sb, h_.se, 0, 0, 0, 0, 0, 0); \
        c2 = (uchar16)(l_.s2, l_.s5, l_.s8, l_.sb, l_.se, h_.s3, h_.s6, h_.s9, h_.sc, h_.sf, 0, 0, 0, 0, 0, 0); }
inline uint gate_rgb8(__global const uchar *src, int i, int width)
{
#if NEAR_LIMIT > 255
    return 0u;
#else
    __global const uchar *q = src + (size_t)(i - 1) * 3;
    const int rs = width * 3;
    uchar16 c0, c1, c2;
    PLANES(q, c0, c1, c2)
    const uchar8 a0 = c0.s12345678, a1 = c1.s12345678, a2 = c2.s12345678;
#define PDIFF(sw, out) {                                                                                 \
        const uchar8 u_ = ABS_DIFF(c0.sw, a0), v_ = ABS_DIFF(c1.sw, a1), w_ = ABS_DIFF(c2.sw, a2);     \
        const uchar8 m_ = u_ > v_ ? u_ : v_;                                                           \
        out = m_ > w_ ? m_ : w_; }
    uchar8 d0, d1, d2, d3, d4, d5, d6, d7;
    PDIFF(s01234567, d7) PDIFF(s23456789, d3)
    PLANES(q - rs, c0, c1, c2)
    PDIFF(s01234567, d0) PDIFF(s12345678, d1) PDIFF(s23456789, d2)
    PLANES(q + rs, c0, c1, c2)
    PDIFF(s01234567, d6) PDIFF(s12345678, d5) PDIFF(s23456789, d4)
#undef PDIFF
    const uchar lim = (uchar)NEAR_LIMIT;
    const char8 h0 = d0 >= lim, h1 = d1 >= lim, h2 = d2 >= lim, h3 = d3 >= lim, h4 = d4 >= lim, h5 = d5 >= lim,
                h6 = d6 >= lim, h7 = d7 >= lim;
    // pairs at ring distance 4 (opposite) and 3 (knight's move)
    char8 p = (h0 & h4) | (h1 & h5) | (h2 & h6) | (h3 & h7) | (h0 & h3) | (h1 & h4) | (h2 & h5) | (h3 & h6) |
              (h4 & h7) | (h5 & h0) | (h6 & h1) | (h7 & h2);
#if EXTENDED && FAR_LIMIT <= 255
    uchar8 mx = d0 > d1 ? d0 : d1;
    mx = mx > d2 ? mx : d2; mx = mx > d3 ? mx : d3; mx = mx > d4 ? mx : d4;
    mx = mx > d5 ? mx : d5; mx = mx > d6 ? mx : d6; mx = mx > d7 ? mx : d7;
    p |= mx >= (uchar)FAR_LIMIT;
#endif
    ulong v = as_ulong(p) & 0x8040201008040201ul;   // byte t: bit t where lane t may fire
    v |= v >> 32;
    v |= v >> 16;
    v |= v >> 8;
    return (uint)(v & 0xfful);
#endif
}
#endif

// Necessary conditions of the two-pixel rule along ring direction k, in RGB: q1 q2 (ahead) and q3 q4 (behind
// B) all more than 2 thresholds from A in ΔE (each is within one threshold of the line's mean, which is more
// than 3 from A), so at least 2 * CHEAP_BOUND from A in some channel; all inside the frame.
inline int two_gap_possible(__global const PIXEL_T *src, rawpx a, int x, int y, int k, int width, int height)
{
    const int dx = RX[k], dy = RY[k];
    if (!inside(x + 2 * dx, y + 2 * dy, width, height) || !inside(x - 3 * dx, y - 3 * dy, width, height))
        return 0;
    return max_diff(raw_px(src, IDX(x + 2 * dx, y + 2 * dy, width)), a) >= FAR_LIMIT &&
           max_diff(raw_px(src, IDX(x - 2 * dx, y - 2 * dy, width)), a) >= FAR_LIMIT &&
           max_diff(raw_px(src, IDX(x - 3 * dx, y - 3 * dy, width)), a) >= FAR_LIMIT;
}

// A rule may fire at the pixel with ring bits `maybe` (its neighbours at or over the cheap bound) and `far`
// (at or over twice it): the paper's rule and the line-relative rule need a gap among the sub-masks of X,
// so of `maybe` (table bit 1); the two-pixel rule needs two_gap_possible along a far direction.
inline int candidate(__global const PIXEL_T *src, __global const uint *table, rawpx a, uint maybe, uint far,
                     int x, int y, int width, int height)
{
    int cand = (table[maybe] & 2u) != 0;
#if EXTENDED
    for (int k = 0; far >> k && !cand; ++k)
        if (far >> k & 1u) cand = two_gap_possible(src, a, x, y, k, width, height);
#endif
    return cand;
}
// The rules at pixel (x, y) with CIELAB a; `maybe` holds every ring neighbour over the threshold (X) and
// ring[k] its CIELAB for k in `maybe`; writes dst[i] when a rule fires.
inline void reconstruct_at(__global const PIXEL_T *src, __global PIXEL_T *dst, __global const float *luts,
                           __global const float *lin, __global const uint *table, const int x, const int y,
                           const int width, const int height, const float t2, const uint maybe, const float3 a,
                           const float3 *ring)
{
    const int i = IDX(x, y, width);
    // X from the Lab of the ring pixels in `maybe`: the others are within the threshold of A, so their da
    // stays 0 here and their Lab is read only if the two-pixel rule needs it (as B).
    float3 n[8];
    float da[8];
    int valid[8];
    uint X = 0;
    for (int k = 0; k < 8; ++k) {
        valid[k] = inside(x + RX[k], y + RY[k], width, height);
        n[k] = a;
        da[k] = 0.0f;
        if (maybe >> k & 1u) {
            n[k] = ring[k];
            da[k] = d2(n[k], a);
            if (da[k] > t2) X |= 1u << k;
        }
    }
    if (X == 0) return;

    // seed 000 §4.2-4.3: T8(A, X) = 2 and T8(A, X-bar) = 1 (table), X of one colour; plus the 5x5 checks
    float3 c;
    uint e = table[X];
    if ((e & 1u) && one_colour(n, X, t2, &c) && thin_gap(src, luts, lin, x, y, width, height, a, c, X, e >> 8, t2, 0)) {
        store_mean(src, dst, x, y, width, X);
        return;
    }
#if EXTENDED
    // beyond the paper (1): X relative to a line colour n[k] -- the neighbours nearer to it than to A.
    // Its shape xk lies within the threshold of a mean more than 3 thresholds from A, so inside
    // far = {k : ΔE(n_k, A) > 2 thresholds}, which must hold a gap (table bit 1) and k.
    uint far = 0;
    for (int k = 0; k < 8; ++k) far |= (uint)(da[k] > 3.99f * t2) << k;   // 2t, less rounding slack
    if (!(table[far] & 2u)) far = 0;
    if (far) {   // every xk is X when X lies within 0.49 thresholds of its mean: |n_j - n_k| < t < |n_j - A|
        float3 mx = (float3)(0.0f);
        int cnt = 0, tight = 1;
        for (int j = 0; j < 8; ++j)
            if (X >> j & 1u) { mx += n[j]; ++cnt; }
        mx /= (float)cnt;
        for (int j = 0; j < 8; ++j)
            if (X >> j & 1u) tight &= d2(n[j], mx) < 0.24f * t2;
        if (tight) far = 0;
    }
    for (int k = 0; far >> k; ++k) {
        if (!(far >> k & 1u)) continue;
        uint xk = 0;
        for (int j = 0; j < 8; ++j)
            if ((X >> j & 1u) && d2(n[j], n[k]) < da[j]) xk |= 1u << j;
        uint ek = table[xk];
        if (xk != X && (ek & 1u) && one_colour(n, xk, t2, &c) && d2(c, a) > 9.0f * t2 &&
            thin_gap(src, luts, lin, x, y, width, height, a, c, xk, ek >> 8, t2, 1)) {
            store_mean(src, dst, x, y, width, xk);
            return;
        }
    }
    // beyond the paper (2): a gap of two pixels, A and B, in a straight line q2 q1 A B q3 q4.
    // Every ring pixel but q1 and B is within the threshold of A or B, and B of A: within 2 thresholds of
    // A (1% slack for rounding). So at most one ring pixel lies beyond that, and it is q1.
    uint beyond = 0;
    for (int k = 0; k < 8; ++k) beyond |= (uint)(da[k] > 4.04f * t2) << k;
    const uint line = beyond & (beyond - 1u) ? 0u : (beyond ? beyond : X);
    rawpx ca = raw_px(src, i);
    for (int k = 0; line >> k; ++k) {
        if (!(line >> k & 1u)) continue;
        // necessary conditions from the ring alone first (implied by the full test below): B = the
        // opposite neighbour is A's colour, q1 is more than 2 thresholds away, q2..q4 may be (RGB), the rest
        // of the ring is background (within the threshold of A or B)
        const int kb = (k + 4) & 7;
        if (!valid[kb] || da[kb] > t2 || da[k] <= 4.0f * t2) continue;
        if (!two_gap_possible(src, ca, x, y, k, width, height)) continue;
        const int dx = RX[k], dy = RY[k];
        const int bx = x - dx, by = y - dy;
        float3 b = (maybe >> kb & 1u) ? n[kb] : lab_px(src, luts, lin, IDX(bx, by, width));
        int plain = 1;
        for (int j = 0; j < 8; ++j)
            if (j != k && j != kb && valid[j] && da[j] > t2 && d2(n[j], b) > t2) plain = 0;
        if (!plain) continue;
        int qx[4] = {x + dx, x + 2 * dx, x - 2 * dx, x - 3 * dx};
        int qy[4] = {y + dy, y + 2 * dy, y - 2 * dy, y - 3 * dy};
        int ok = 1;
        float3 l[4];
        float3 m = (float3)(0.0f);
        for (int q = 0; q < 4; ++q) { l[q] = lab_px(src, luts, lin, IDX(qx[q], qy[q], width)); m += l[q]; }
        m /= 4.0f;
        for (int q = 0; q < 4; ++q) ok = ok && d2(l[q], m) <= t2;
        if (!ok) continue;
        if (!(d2(a, b) <= t2 && d2(a, m) > 9.0f * t2 && d2(b, m) > 9.0f * t2)) continue;
        // thin, on a plain background: every other pixel around A or B is background, none line-coloured
        for (int s = 0; s < 2 && ok; ++s) {
            int cx = s == 0 ? x : bx, cy = s == 0 ? y : by;
            for (int j = 0; j < 8 && ok; ++j) {
                int px = cx + RX[j], py = cy + RY[j];
                if (!inside(px, py, width, height) || (px == x && py == y) || (px == bx && py == by) ||
                    (px == qx[0] && py == qy[0]) || (px == qx[2] && py == qy[2]))
                    continue;
                float3 q = lab_px(src, luts, lin, IDX(px, py, width));
                ok = d2(q, m) > t2 && fmin(d2(q, a), d2(q, b)) <= t2;
            }
        }
        if (!ok) continue;
        float4 sum = (float4)(0.0f);
        for (int q = 0; q < 4; ++q) sum += load_px(src, IDX(qx[q], qy[q], width));
        sum *= 0.25f;
        sum.w = load_px(src, i).w;
        store_px(dst, i, sum);
        return;
    }
#endif
}
