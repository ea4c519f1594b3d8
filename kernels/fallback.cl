// fallback.cl -- FXAA 3.11 (fxaa.cl, built into the same program) for the pixels the MLAA passes left,
// where the frame shows 1-spp aliasing: the pass after blending (and bridging) in the default chain.
//
// Why (beyond the seeds; SMAA and CMAA2 pair a line search with a local fallback in the same way): on
// rendered frames a third of the input's error sits on edge pixels that no line of the MLAA search
// covers -- short texture edges, foliage, outlines of lit surfaces -- and FXAA's local gradient blend
// removes about 40 % of it there, while MLAA removes more than FXAA where it blends (docs/spatial_tuning.md,
// FALLBACK_*). FXAA alone would blur text and photographs, so a pixel takes FALLBACK_WEIGHT of FXAA's
// colour (linear light) only where
//   - the MLAA passes left it unchanged,
//   - its tile of FALLBACK_TILE^2 pixels and the eight around it hold at least FALLBACK_MIN_CHANGED pixels
//     that the MLAA passes changed (evidence of 1-spp aliasing nearby: antialiased content, photographs
//     and flat regions have few), and
//   - its 3x3 window holds at least FALLBACK_COLOURS distinct colours (equal: every channel within
//     FALLBACK_SAME of full scale): flat-colour art -- text, UI boxes, vector drawings -- has fewer.
// Numpy reference: mlaa_stream.spatial.fallback.fallback_reference.

#ifndef FALLBACK_TILE
#define FALLBACK_TILE 8
#endif
#ifndef FALLBACK_MIN_CHANGED
#define FALLBACK_MIN_CHANGED 24
#endif
#ifndef FALLBACK_COLOURS
#define FALLBACK_COLOURS 4
#endif
#ifndef FALLBACK_SAME
#define FALLBACK_SAME (2.5f / 255.0f)
#endif
#ifndef FALLBACK_WEIGHT
#define FALLBACK_WEIGHT 0.8f
#endif

// Any stored channel (alpha included) of pixel i differs between a and b.
inline int px_differs(__global const PIXEL_T *a, __global const PIXEL_T *b, int i)
{
    for (int c = 0; c < CHANNELS; ++c)
        if (a[(size_t)i * CHANNELS + c] != b[(size_t)i * CHANNELS + c]) return 1;
    return 0;
}

// counts[tile] = pixels of the tile that the MLAA passes changed (dst != src); one work item per tile.
__kernel void count_changed(__global const PIXEL_T *src, __global const PIXEL_T *dst, __global uchar *counts,
                            const int w, const int h, const int tiles_x)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    const int x0 = tx * FALLBACK_TILE, y0 = ty * FALLBACK_TILE;
    if (x0 >= w || y0 >= h) return;
    const int x1 = min(x0 + FALLBACK_TILE, w), y1 = min(y0 + FALLBACK_TILE, h);
    int n = 0;
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x)
            n += px_differs(src, dst, IDX(x, y, w));
    counts[ty * tiles_x + tx] = (uchar)n;
}

// Distinct colours in the 3x3 window of (x, y), clamped at the frame's edge, counted in row order: a pixel
// counts when no earlier pixel of the window equals it.
inline int window_colours(__global const PIXEL_T *src, int x, int y, int w, int h)
{
    float4 px[9];
    for (int k = 0; k < 9; ++k)
        px[k] = load_px(src, IDX(clamp(x + k % 3 - 1, 0, w - 1), clamp(y + k / 3 - 1, 0, h - 1), w));
    int distinct = 0;
    for (int a = 0; a < 9; ++a) {
        int twin = 0;
        for (int o = 0; o < a && !twin; ++o) {
            const float4 d = fabs(px[a] - px[o]);
            twin = d.x <= FALLBACK_SAME && d.y <= FALLBACK_SAME && d.z <= FALLBACK_SAME;
        }
        distinct += !twin;
    }
    return distinct;
}

// One work item per tile: nothing to do unless the 3x3 tiles around it hold FALLBACK_MIN_CHANGED changed
// pixels; then each unchanged pixel of a busy window moves FALLBACK_WEIGHT of the way to FXAA's colour.
__kernel void fxaa_fallback(__global const PIXEL_T *src, __global const float *luts,
                            __global const uchar *counts, __global PIXEL_T *dst,
                            const int w, const int h, const int tiles_x, const int tiles_y)
{
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tiles_x || ty >= tiles_y) return;
    int changed = 0;
    for (int j = max(ty - 1, 0); j <= min(ty + 1, tiles_y - 1); ++j)
        for (int k = max(tx - 1, 0); k <= min(tx + 1, tiles_x - 1); ++k)
            changed += counts[j * tiles_x + k];
    if (changed < FALLBACK_MIN_CHANGED) return;
    const int x0 = tx * FALLBACK_TILE, y0 = ty * FALLBACK_TILE;
    const int x1 = min(x0 + FALLBACK_TILE, w), y1 = min(y0 + FALLBACK_TILE, h);
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x) {
            const int i = IDX(x, y, w);
            if (px_differs(src, dst, i) || window_colours(src, x, y, w, h) < FALLBACK_COLOURS) continue;
            float3 f;
            if (!fxaa_pixel(src, luts, x, y, w, h, &f)) continue;
            float4 c = load_px(src, i);
            float3 m = blend_rgb(src, luts, x, y, w, h);
            c.xyz = fxaa_encode(luts, m + FALLBACK_WEIGHT * (f - m));
            store_px(dst, i, c);
        }
}
