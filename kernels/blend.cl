// blend.cl -- blend each pixel with its four neighbours by the weights (seed 000 §3.5), in linear light.
// A pixel next to several lines takes out = c + sum_k w_k^2 (n_k - c) / sum_k w_k: one neighbour alone
// gives c + w (n - c); several never add up to more than the largest weight (no double blending,
// as SMAA's choice of one axis), and the rule is the same under flips and transposes.
// Defines: BLEND_LINEAR 1 decodes sRGB -> linear before mixing and encodes after (LINEAR_INPUT frames
// are mixed as they are). Alpha is copied from the source pixel. dst must already hold a copy of
// src (the host enqueues it): pixels next to no edge exit at once, and a weight slot is read only
// where the edge it belongs to exists (weights.cl writes no others).

inline float4 to_mix_space(__global const float *luts, float4 c)
{
#if DECODE
    return (float4)(lut_read(luts, c.x), lut_read(luts, c.y), lut_read(luts, c.z), c.w);
#else
    return c;
#endif
}

inline float4 from_mix_space(__global const float *luts, float4 c)
{
#if DECODE
    return (float4)(encode_mix(luts, c.x), encode_mix(luts, c.y), encode_mix(luts, c.z), c.w);
#else
    return c;
#endif
}

#define EDGE_BOTTOM 1
#define EDGE_RIGHT 2

// Grain and fine texture (film grain, sensor noise) are not jaggies: a pixel whose 3x3 window holds only
// pixels that differ from at least GRAIN_MIN of their 8 neighbours, by GRAIN_STEP / 255 of full scale or more
// in some colour channel, keeps its colour (beyond the seeds; mlaa_stream.mlaa.GRAIN_STEP, the numpy
// reference is reference.grain_mask). Neighbours and window are clamped at the frame's edge.
#ifndef GRAIN_GUARD
#define GRAIN_GUARD 1
#endif
#ifndef GRAIN_STEP
#define GRAIN_STEP 8
#endif
#ifndef GRAIN_MIN
#define GRAIN_MIN 5
#endif
#ifdef PIXEL_IS_FLOAT
typedef float grain_t;
#define GRAIN_LIMIT ((float)GRAIN_STEP / 255.0f)
#else
typedef int grain_t;
#define GRAIN_LIMIT ((GRAIN_STEP * (int)PIXEL_MAX + 254) / 255)   // whole levels, rounded up
#endif
#define GRAIN_CH (CHANNELS < 3 ? 1 : 3)

inline int grain_differs(__global const PIXEL_T *src, int i, int j)
{
    __global const PIXEL_T *a = src + (size_t)i * CHANNELS, *b = src + (size_t)j * CHANNELS;
    for (int c = 0; c < GRAIN_CH; ++c) {
        const grain_t u = a[c], v = b[c];
        if ((u > v ? u - v : v - u) >= GRAIN_LIMIT) return 1;
    }
    return 0;
}

inline int clampi(int v, int hi) { return v < 0 ? 0 : (v > hi ? hi : v); }

// At least GRAIN_MIN of the 8 neighbours of (x, y) differ (stops as soon as the count is settled).
// (always_inline here and below: PoCL's CPU build otherwise calls these per pixel; mixed frame 0.95x)
inline __attribute__((always_inline)) int busy_px(__global const PIXEL_T *src, int x, int y, int width, int height)
{
    const int i = IDX(x, y, width);
    int n = 0, left = 8;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            if (!dx && !dy) continue;
            n += grain_differs(src, i, IDX(clampi(x + dx, width - 1), clampi(y + dy, height - 1), width));
            --left;
            if (n >= GRAIN_MIN) return 1;
            if (n + left < GRAIN_MIN) return 0;
        }
    return 0;
}

inline int in_grain(__global const PIXEL_T *src, int x, int y, int width, int height)
{
    if (!busy_px(src, x, y, width, height)) return 0;   // the pixel itself first: most edges stop here
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
            if ((dx || dy) && !busy_px(src, clampi(x + dx, width - 1), clampi(y + dy, height - 1), width, height))
                return 0;
    return 1;
}

// Sub-pixel features (beyond seed 000, the role of FXAA's sub-pixel pass and seed 000 §4's
// reconstruction for dots): a pixel bordered by edges on three or four sides is a dot, the end of a
// 1-px line or a 1-px bump -- a feature smaller than the pixel that the single sample either hit or
// missed (cables, fence wires, leaves and highlights far away, both dark and bright). The sample says
// nothing about how much of the pixel it covers: the expected colour lies between the sample and its
// surroundings. Such a pixel moves SUBPIXEL (four sides: a dot) or SUBPIXEL_END (three: a line's end or a
// bump, whose fourth side continues into more of it) of the way from its blended colour to the mean of its
// 3x3 window (itself included, clamped at the frame's edge), in linear light. 0 = off. Only a luma extremum
// on one background (SUBPIXEL_BG, below): speckle of photographs and textures is left alone. Measured
// (docs/spatial_tuning.md): rendered scenes +1.5..+9 points error removed, aliased text +4, wires -1.
#ifndef SUBPIXEL
#define SUBPIXEL 0.5f
#endif
#ifndef SUBPIXEL_ON
#define SUBPIXEL_ON 1
#endif
#ifndef SUBPIXEL_BG
#define SUBPIXEL_BG 2.0f
#endif
#ifndef SUBPIXEL_END
#define SUBPIXEL_END SUBPIXEL
#endif
#ifndef SUBPIXEL_SHARE
#define SUBPIXEL_SHARE 1.0f
#endif
inline float luma(float4 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }   // Rec. 709
// Edge sides of pixel (x, y): bit 0 top, 1 bottom, 2 left, 3 right.
inline int edge_sides(__global const uchar *edges, int x, int y, int width)
{
    const int i = IDX(x, y, width);
    const uchar e = edges[i];
    return (y > 0 && (edges[i - width] & EDGE_BOTTOM)) | ((e & EDGE_BOTTOM) << 1)
         | ((x > 0 && (edges[i - 1] & EDGE_RIGHT)) << 2) | ((e & EDGE_RIGHT) << 2);
}

inline int count_sides(int s) { return (s & 1) + ((s >> 1) & 1) + ((s >> 2) & 1) + ((s >> 3) & 1); }

// Seed 000 §3.5's blend of pixel i with the neighbours across its edges (`sides`), in mix space; *ws = the
// weights' sum (0: no line covers the pixel).
inline __attribute__((always_inline)) float4 line_blend(__global const PIXEL_T *src, __global const ushort *weights,
                                                       __global const float *luts, int i, int width, int sides,
                                                       float4 m, float *ws)
{
    ushort4 w16 = LOAD_USHORT4(weights + 4 * i);  // (top, bottom, left, right), valid where the edge exists
    float4 w = (float4)((sides & 1) ? w16.x : 0, (sides & 2) ? w16.y : 0,
                        (sides & 4) ? w16.z : 0, (sides & 8) ? w16.w : 0) * (1.0f / 65535.0f);
    *ws = w.x + w.y + w.z + w.w;
    if (*ws == 0.0f) return m;
    float4 acc = (float4)(0.0f);
    if (w.x > 0.0f) acc += w.x * w.x * (to_mix_space(luts, load_px(src, i - width)) - m);
    if (w.y > 0.0f) acc += w.y * w.y * (to_mix_space(luts, load_px(src, i + width)) - m);
    if (w.z > 0.0f) acc += w.z * w.z * (to_mix_space(luts, load_px(src, i - 1)) - m);
    if (w.w > 0.0f) acc += w.w * w.w * (to_mix_space(luts, load_px(src, i + 1)) - m);
    return m + acc / *ws;
}

#if SUBPIXEL_ON
// The sub-pixel move of pixel (x, y) with edge sides `sides` (3 or 4) and blended colour b: *delta, returns 1
// where the pixel is a feature as described above (0: no move).
RARELY_CALLED int subpixel_move(__global const PIXEL_T *src, __global const float *luts,
                                                       int x, int y, int width, int height, int sides, float4 m,
                                                       float4 b, float4 *delta)
{
    const int i = IDX(x, y, width);
    // only a local extremum: lighter (or darker) than every neighbour across its edges, as a thin
    // feature is -- a coverage mix of already antialiased content sits between its neighbours
    const float yc = luma(m);
    int lo = 0, hi = 0;
    float ymin = 1e30f, ymax = -1e30f;
#define ACROSS_LUMA(has, k) if (has) { const float yn = luma(to_mix_space(luts, load_px(src, k))); lo |= yn < yc; hi |= yn > yc; \
                                       ymin = yn < ymin ? yn : ymin; ymax = yn > ymax ? yn : ymax; }
    ACROSS_LUMA(sides & 1, i - width)
    ACROSS_LUMA(sides & 2, i + width)
    ACROSS_LUMA(sides & 4, i - 1)
    ACROSS_LUMA(sides & 8, i + 1)
#undef ACROSS_LUMA
    // ... on one background: the neighbours across its edges spread by at most SUBPIXEL_BG times the
    // feature's own contrast to the nearest of them (texture and photographs' speckle have no such background)
    const float contrast = hi ? ymin - yc : yc - ymax;
    if (ymax - ymin > SUBPIXEL_BG * contrast) lo = hi = 1;
    if (lo && hi) return 0;
    float4 box = (float4)(0.0f);
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
            box += to_mix_space(luts, load_px(src, IDX(clampi(x + dx, width - 1), clampi(y + dy, height - 1), width)));
    *delta = (count_sides(sides) == 4 ? SUBPIXEL : SUBPIXEL_END) * (box * (1.0f / 9.0f) - b);
    return 1;
}

// What the feature at (x, y) -- if it is one -- gives to each neighbour across its edges: SUBPIXEL_SHARE of
// its move, negated and split among those neighbours (the ink a dot loses goes to its surroundings, so a
// thin feature keeps its weight; measured in docs/spatial_tuning.md). 0 where (x, y) is no moved feature.
RARELY_CALLED float4 feature_share(__global const PIXEL_T *src, __global const ushort *weights, __global const float *luts,
                            __global const uchar *edges, int x, int y, int width, int height)
{
    const int sides = edge_sides(edges, x, y, width), n = count_sides(sides);
    if (n < 3) return (float4)(0.0f);
#if GRAIN_GUARD
    if (in_grain(src, x, y, width, height)) return (float4)(0.0f);
#endif
    const int i = IDX(x, y, width);
    const float4 m = to_mix_space(luts, load_px(src, i));
    float ws;
    const float4 b = line_blend(src, weights, luts, i, width, sides, m, &ws);
    float4 delta;
    if (!subpixel_move(src, luts, x, y, width, height, sides, m, b, &delta)) return (float4)(0.0f);
    return delta * (-SUBPIXEL_SHARE / (float)n);
}
#endif

inline __attribute__((always_inline)) void blend_pixel(__global const PIXEL_T *src, __global const uchar *edges,
                        __global const ushort *weights, __global const float *luts,
                        __global const uchar *moved_features, __global const float4 *shares,
                        __global PIXEL_T *dst, int x, int y, int width, int height)
{
    const int i = IDX(x, y, width);
    const int sides = edge_sides(edges, x, y, width);
    if (sides == 0) return;
    const ushort4 w16 = LOAD_USHORT4(weights + 4 * i);
    const int weighted = ((sides & 1) && w16.x) || ((sides & 2) && w16.y) || ((sides & 4) && w16.z) || ((sides & 8) && w16.w);
#if SUBPIXEL_ON
    const int n = count_sides(sides);
    // neighbours across this pixel's edges that may be features (3+ sides)
    // neighbours across this pixel's edges that are moved features (feature_shares, the pass before)
    const int near = ((sides & 1) && moved_features[i - width]) | (((sides & 2) && moved_features[i + width]) << 1)
                   | (((sides & 4) && moved_features[i - 1]) << 2) | (((sides & 8) && moved_features[i + 1]) << 3);
    if (!weighted && n < 3 && !near) return;
#else
    if (!weighted) return;
#endif
    float4 c = load_px(src, i);
    float4 m = to_mix_space(luts, c);
    float ws;
    float4 b = line_blend(src, weights, luts, i, width, sides, m, &ws);
    int moved = ws > 0.0f;
#if SUBPIXEL_ON
    // neighbours across this pixel's edges that are moved features give it a share of their move
    float4 share = (float4)(0.0f);
    if (near & 1) share += shares[i - width];
    if (near & 2) share += shares[i + width];
    if (near & 4) share += shares[i - 1];
    if (near & 8) share += shares[i + 1];
    const int shared = share.x != 0.0f || share.y != 0.0f || share.z != 0.0f;
    if (!moved && n < 3 && !shared) return;
#endif
#if GRAIN_GUARD
    if (in_grain(src, x, y, width, height)) return;
#endif
#if SUBPIXEL_ON
    if (n >= 3) {
        float4 delta;
        if (subpixel_move(src, luts, x, y, width, height, sides, m, b, &delta)) {
            b += delta;
            moved = 1;
        }
    }
    if (shared) {
        b += share;
        moved = 1;
    }
    if (!moved) return;
#endif
    float4 out = from_mix_space(luts, b);
    out.w = c.w;
    store_px(dst, i, out);
}

// Before blend_neighbours: moved_features[i] = 1 where pixel i is a feature that moves (feature_share != 0),
// shares[i] = what each neighbour across its edges takes (written only there); 0 elsewhere. Computed once per
// feature instead of once per neighbour. One work item per SEGMENT pixels of a row.
__kernel void feature_shares(__global const PIXEL_T *src, __global const uchar *edges,
                             __global const ushort *weights, __global const float *luts,
                             __global uchar *moved_features, __global float4 *shares,
                             const int width, const int height)
{
    const int x0 = get_global_id(0) * SEGMENT, y = get_global_id(1);
    if (x0 >= width || y >= height) return;
    const int x1 = min(x0 + SEGMENT, width);
    const ulong bottom_bits = 0x0101010101010101UL;
    for (int x = x0; x < x1;) {
        const int i = IDX(x, y, width);
        if (x + GROUP <= x1) {   // 8 pixels bordering no edge: no feature among them
            ulong own = edge_group(edges + i);
            ulong above = y > 0 ? edge_group(edges + i - width) & bottom_bits : 0;
            int from_left = x > 0 && (edges[i - 1] & EDGE_RIGHT);
            if ((own | above) == 0 && !from_left) {
                STORE_UCHAR8((uchar8)(0), moved_features + i);
                x += GROUP;
                continue;
            }
        }
        int moved = 0;
#if SUBPIXEL_ON
        if (count_sides(edge_sides(edges, x, y, width)) >= 3) {
            const float4 sh = feature_share(src, weights, luts, edges, x, y, width, height);
            moved = sh.x != 0.0f || sh.y != 0.0f || sh.z != 0.0f;
            if (moved) shares[i] = sh;
        }
#endif
        moved_features[i] = (uchar)moved;
        ++x;
    }
}

__kernel void blend_neighbours(__global const PIXEL_T *src, __global const uchar *edges,
                               __global const ushort *weights, __global const float *luts,
                               __global const uchar *moved_features, __global const float4 *shares,
                               __global PIXEL_T *dst, const int width, const int height)
{
    const int x0 = get_global_id(0) * SEGMENT, y = get_global_id(1);
    if (x0 >= width || y >= height) return;
    const int x1 = min(x0 + SEGMENT, width);
    const ulong bottom_bits = 0x0101010101010101UL;   // EDGE_BOTTOM in each of 8 bytes
    for (int x = x0; x < x1;) {
        const int i = IDX(x, y, width);
        if (x + GROUP <= x1) {   // 8 pixels with no edge of their own, none from above or the left
            ulong own = edge_group(edges + i);
            ulong above = y > 0 ? edge_group(edges + i - width) & bottom_bits : 0;
            int from_left = x > 0 && (edges[i - 1] & EDGE_RIGHT);
            if ((own | above) == 0 && !from_left) { x += GROUP; continue; }
        }
        blend_pixel(src, edges, weights, luts, moved_features, shares, dst, x, y, width, height);
        ++x;
    }
}
