// fallback.cl -- FXAA 3.11 (fxaa.cl, built into the same program) for the edge pixels of 1-spp content: the
// pass after blending (and bridging) in the default chain. It reads the edge buffer of the MLAA passes
// (edges.cl): outside render regions (below), a pixel that borders no edge is neither counted nor changed.
//
// Why (beyond the seeds; SMAA and CMAA2 pair a line search with a local fallback in the same way): on
// rendered frames a third of the input's error sits on edge pixels that no line of the MLAA search
// covers -- short texture edges, foliage, outlines of lit surfaces -- and FXAA's local gradient blend
// removes about 40 % of it there; where the MLAA passes blend, half of FXAA's colour on top of theirs removes
// more than either alone (dense patterns: fences, foliage; docs/spatial_tuning.md, FALLBACK_*). FXAA alone
// would blur text and photographs, so only eligible pixels change. A pixel is eligible where it borders an
// edge of the MLAA passes, FXAA's contrast test passes, and its region (its tile of FALLBACK_TILE^2 pixels
// and the eight around it) shows 1-spp aliasing:
//   - either 1-spp content with shading or texture ("busy"): at least FALLBACK_RICH_MIN pixels that the
//     MLAA passes changed and whose 3x3 window holds FALLBACK_COLOURS bit-identical colours or more, and at least
//     1 / FALLBACK_RICH_DIV of the region's edge-bordering pixels are such (photographs, antialiased text
//     and wires have a few such pixels among many edges);
//   - or, for pixels the MLAA passes left, at least FALLBACK_MIN_CHANGED changed edge-bordering pixels (any
//     colours) and the pixel's own 3x3 window holds at least FALLBACK_COLOURS distinct colours (equal: every
//     channel within FALLBACK_SAME of full scale): flat-colour art -- text, UI boxes, vector drawings -- has fewer.
// An eligible pixel that the MLAA passes left takes FALLBACK_WEIGHT of FXAA's colour (linear light); one they
// changed moves FALLBACK_MIX of the way from their colour to FXAA's.
// Except: a pixel on a straight edge run of FALLBACK_KEEP_RUN pixels or more (hdist / vdist of distances.cl) keeps
// the MLAA passes' colour -- their verdict on a straight edge: FXAA's sub-pixel blend would smear pixel-aligned
// rules and stems wherever noise or compression makes their windows busy. In render regions the run must be
// REGION_KEEP_RUN pixels or more: a render's straight runs of 16-31 px are mostly edges at sub-pixel offsets.
// Render regions: a tile whose wide neighbourhood (RENDER_RADIUS tiles each way) looks like a 1-spp 3D render is
// treated as busy, and every pixel of it then takes the footprint table (below). The neighbourhood test: at least
// RENDER_MIN busy pixels (count_changed's k = 2) in tiles with a luma range of RENDER_RANGE or more, busy pixels at
// least 1 / RENDER_DIV of its edge-bordering pixels, and its busy tiles not two-toned -- on average at most
// RENDER_NEAR_PCT % of a busy tile's pixels lie within a tenth of the tile's luma range from its darkest or
// lightest (text and UI, even through JPEG ringing, are two-toned: 92-96 %; renders 67-78 %).
// The frame as a whole: where at least RENDER_FRAME_PCT % of the tiles that hold edge-bordering pixels are render
// regions, the frame is a render, and every tile whose neighbourhood holds a busy pixel is a region -- thin features
// on flat backgrounds (cables against the sky, fences, at 1080p most silhouettes) are two-toned in a render too, a
// video codec's smoothing fails the busy counts, and a render's share of regions falls with the frame's size; text
// and UI frames, compressed or not, hold under 20 % (a 1080p mixed frame through JPEG q75: 38 %), and flat-colour
// art has no busy pixel (docs/spatial_tuning.md, RENDER_FRAME_PCT).
// A frame that is already supersampled (rendered with several samples per pixel, or downscaled) is no 1-spp render:
// across its strong luma steps (SUPERSAMPLED_STEP or more between neighbours) coverage blends make ramps -- the next
// step on one side goes the same way by at least half as much -- where a 1-spp frame has single-pixel steps. Where
// at least SUPERSAMPLED_PCT % of the strong steps in the tiles that hold edge-bordering pixels (a quarter of them
// sampled: even tile rows and columns) are ramps (1-spp renders, also through H.264: 0-9 %; 2x2 and 3x3 supersampled
// renders: 21-47 %), or where at least SUPERSAMPLED_CLEAN_PCT % of its clean transitions (below) are ramps
// (photo-textured renders with 3x3 samples per pixel whose strong steps are mostly hard), no pixel outside render
// regions takes FXAA: the MLAA passes' own already-antialiased test judges its edges (docs/spatial_tuning.md,
// "SUPERSAMPLED_PCT", "SUPERSAMPLED_CLEAN_PCT"). Either verdict holds only while under SUPERSAMPLED_HARD_PCT % of the
// strong steps are hard stair ends (clean transitions that are no ramps): 1-spp geometry, where photographic
// textures make the ramps (docs/spatial_tuning.md, "SUPERSAMPLED_HARD_PCT").
// In such a frame render regions are judged locally: a tile stays a region where, over its neighbourhood's sampled
// tiles, under RENDER_RAMP_PCT % of the clean transitions (a strong step at a stair's end, or two steps the same
// way, between two plateaus) are ramps. Magnified photographic textures make ramps too, enough to take a whole
// 1-spp render for a supersampled one, while its geometric edges stay hard steps; a supersampled frame's edges are
// ramps everywhere (docs/spatial_tuning.md, "RENDER_RAMP_PCT").
// The footprint table (mlaa_stream/spatial/footprint.py says what and why): a 1-spp frame holds point samples, its
// truth the average over each pixel's square footprint; each pixel of a render region becomes a linear filter of
// its 5x5 window and the chain's colour, one filter per local structure class, clamped to its 3x3 window's range.
// RENDER_REGIONS 0 makes no tile a render region (Filter(fallback="edges"): screen captures).
// FALLBACK_MIN_CHANGED 0 drops the region and colour tests and makes every tile a render region
// (Filter(fallback="everywhere"): frames known to be 1-spp renders). Numpy reference:
// mlaa_stream.spatial.fallback.fallback_reference.

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
#ifndef FALLBACK_MIX
#define FALLBACK_MIX 0.5f
#endif
#ifndef FALLBACK_RICH_MIN
#define FALLBACK_RICH_MIN 12
#endif
#ifndef FALLBACK_RICH_DIV
#define FALLBACK_RICH_DIV 20
#endif
#ifndef FALLBACK_KEEP_RUN
#define FALLBACK_KEEP_RUN 16
#endif
#ifndef REGION_KEEP_RUN
#define REGION_KEEP_RUN 32
#endif
#ifndef RENDER_RADIUS
#define RENDER_RADIUS 7
#endif
#ifndef RENDER_MIN
#define RENDER_MIN 48
#endif
#ifndef RENDER_DIV
#define RENDER_DIV 10
#endif
#ifndef RENDER_NEAR_PCT
#define RENDER_NEAR_PCT 88
#endif
#ifndef RENDER_RANGE
#define RENDER_RANGE (24.0f / 255.0f)
#endif
#ifndef RENDER_DIV_1SPP
#define RENDER_DIV_1SPP 20
#endif
#ifndef RENDER_FRAME_PCT
#define RENDER_FRAME_PCT 45
#endif
#ifndef SUPERSAMPLED_STEP
#define SUPERSAMPLED_STEP 0.2f
#endif
#ifndef SUPERSAMPLED_PCT
#define SUPERSAMPLED_PCT 14
#endif
#ifndef SUPERSAMPLED_MIN
#define SUPERSAMPLED_MIN 64
#endif
#ifndef SUPERSAMPLED_CLEAN_PCT
#define SUPERSAMPLED_CLEAN_PCT 75
#endif
#ifndef SUPERSAMPLED_HARD_PCT
#define SUPERSAMPLED_HARD_PCT 12
#endif
#ifndef RENDER_RAMP_PCT
#define RENDER_RAMP_PCT 50
#endif
#ifndef RAMP_FLANK
#define RAMP_FLANK 0.2f
#endif
#ifndef RENDER_REGIONS
#define RENDER_REGIONS 1
#endif
#ifndef FOOTPRINT_TABLE
#define FOOTPRINT_TABLE 1
#endif
#ifndef FOOTPRINT_BUCKETS
#define FOOTPRINT_BUCKETS 144
#endif
#ifndef FOOTPRINT_WEIGHTS
#define FOOTPRINT_WEIGHTS 26
#endif
#ifndef REFINE_TABLE
#define REFINE_TABLE 0
#endif
#define COUNTS 16         // bytes per tile in `counts` (9 used; 16 keeps each tile's first 8 aligned)
#define NOT_MEASURED 255  // counts[3] of a tile with no busy pixel or a luma range under RENDER_RANGE

// Any stored channel (alpha included) of pixel i differs between a and b.
inline int px_differs(__global const PIXEL_T *a, __global const PIXEL_T *b, int i)
{
    __global const PIXEL_T *p = a + (size_t)i * CHANNELS, *q = b + (size_t)i * CHANNELS;
    int d = 0;
    for (int c = 0; c < CHANNELS; ++c) d |= p[c] != q[c];
    return d;
}

#define EDGE_BOTTOM 1
#define EDGE_RIGHT 2

// Pixel (x, y) borders an edge of the MLAA passes (its own bottom or right, the bottom of the pixel above,
// the right of the pixel to the left): only such pixels can be blended, and only such pixels are left to FXAA.
inline int borders_edge(__global const uchar *edges, int x, int y, int w)
{
    const int i = IDX(x, y, w);
    return edges[i] != 0 || (y > 0 && (edges[i - w] & EDGE_BOTTOM)) || (x > 0 && (edges[i - 1] & EDGE_RIGHT));
}

// Eight pixels from (x, y) border no edge (the test of blend.cl's group skip); x + 8 <= w.
inline int group_is_quiet(__global const uchar *edges, int x, int y, int w)
{
    const int i = IDX(x, y, w);
    const ulong above = y > 0 ? edge_group(edges + i - w) & 0x0101010101010101UL : 0;
    return (edge_group(edges + i) | above) == 0 && !(x > 0 && (edges[i - 1] & EDGE_RIGHT));
}

// Two stored pixels are one colour: every colour channel within FALLBACK_SAME of full scale (integer
// frames compare whole levels: FALLBACK_SAME_LEVELS = the largest difference within it).
#ifdef PIXEL_IS_FLOAT
typedef float sample_t;
#define SAME_LIMIT FALLBACK_SAME
#else
typedef int sample_t;
#define SAME_LIMIT FALLBACK_SAME_LEVELS
#endif
#define COLOUR_CH (CHANNELS < 3 ? 1 : 3)

// At least FALLBACK_COLOURS bit-identical colours in the 3x3 window of (x, y), clamped at the frame's edge: the
// region statistic's test (smooth shading and texture differ by a level or two between neighbours; noise-free
// flat-colour art has two or three colours per window).
RARELY_CALLED int window_has_exact_colours(__global const PIXEL_T *src, int x, int y, int w, int h)
{
    int idx[9];
    for (int k = 0; k < 9; ++k)
        idx[k] = IDX(clamp_to(x + k % 3 - 1, w - 1), clamp_to(y + k / 3 - 1, h - 1), w);
    int exact = 0;
    for (int a = 0; a < 9 && exact < FALLBACK_COLOURS; ++a) {
        int twin = 0;
        for (int o = 0; o < a && !twin; ++o) twin = same_px(src, idx[a], idx[o]);
        exact += !twin;
    }
    return exact >= FALLBACK_COLOURS;
}

// At least FALLBACK_COLOURS distinct colours in the 3x3 window of (x, y), clamped at the frame's edge,
// counted in row order (a pixel counts when no earlier pixel of the window equals it); stops once settled.
RARELY_CALLED int window_has_colours(__global const PIXEL_T *src, int x, int y, int w, int h)
{
    // bit-identical colours first: merging within FALLBACK_SAME can only lower the count, so a window of
    // fewer exact colours (flat-colour art, most of the pixels that get here) is settled at once
    if (!window_has_exact_colours(src, x, y, w, h)) return 0;
    int idx[9];
    for (int k = 0; k < 9; ++k)
        idx[k] = IDX(clamp_to(x + k % 3 - 1, w - 1), clamp_to(y + k / 3 - 1, h - 1), w);
    sample_t px[9][COLOUR_CH];
    for (int k = 0; k < 9; ++k)
        for (int c = 0; c < COLOUR_CH; ++c) px[k][c] = src[(size_t)idx[k] * CHANNELS + c];
    int distinct = 0;
    for (int a = 0; a < 9; ++a) {
        int twin = 0;
        for (int o = 0; o < a && !twin; ++o) {
            int same = 1;
            for (int c = 0; c < COLOUR_CH; ++c) {
                const sample_t d = px[a][c] > px[o][c] ? px[a][c] - px[o][c] : px[o][c] - px[a][c];
                same &= d <= SAME_LIMIT;
            }
            twin = same;
        }
        distinct += !twin;
        if (distinct >= FALLBACK_COLOURS) return 1;
        if (distinct + 8 - a < FALLBACK_COLOURS) return 0;
    }
    return 0;
}

// The 3x3 window of (x, y), clamped at the frame's edge, holds at most two bit-identical colours: the edges of
// flat-colour art, most windows the colour counts see, settled by comparing packed keys (then it cannot hold
// FALLBACK_COLOURS >= 3 colours).
RARELY_CALLED int window_two_colours(__global const PIXEL_T *src, int x, int y, int w, int h)
{
    const int x0 = x > 0 ? x - 1 : 0, x2 = x < w - 1 ? x + 1 : w - 1;
    const int r0 = (y > 0 ? y - 1 : 0) * w, r1 = y * w, r2 = (y < h - 1 ? y + 1 : h - 1) * w;
    const int idx[9] = {r0 + x0, r0 + x, r0 + x2, r1 + x0, r1 + x, r1 + x2, r2 + x0, r2 + x, r2 + x2};
#ifdef PIXEL_IS_FLOAT
    int second = -1;
    for (int k = 0; k < 9; ++k) {
        if (same_px(src, idx[k], idx[4])) continue;
        if (second < 0) second = idx[k];
        else if (!same_px(src, idx[k], second)) return 0;
    }
    return 1;
#else
    ulong key[9];
    for (int k = 0; k < 9; ++k) {
        __global const PIXEL_T *p = src + (size_t)idx[k] * CHANNELS;
#if CHANNELS == 1
        key[k] = p[0];
#else
        key[k] = (ulong)p[0] | (ulong)p[1] << 16 | (ulong)p[2] << 32;
#endif
    }
    const ulong a = key[4];
    ulong b = a;
    for (int k = 0; k < 9; ++k) b = b == a ? key[k] : b;
    int two = 1;
    for (int k = 0; k < 9; ++k) two &= (key[k] == a) | (key[k] == b);
    return two;
#endif
}

// The 3x3 window is busy: at least FALLBACK_COLOURS colours (window_has_colours; _EXACT: bit-identical ones,
// window_has_exact_colours), the quick test first.
#if FALLBACK_COLOURS >= 3
#define WINDOW_BUSY(src, x, y, w, h) (!window_two_colours(src, x, y, w, h) && window_has_colours(src, x, y, w, h))
#define WINDOW_BUSY_EXACT(src, x, y, w, h) \
    (!window_two_colours(src, x, y, w, h) && window_has_exact_colours(src, x, y, w, h))
#else
#define WINDOW_BUSY(src, x, y, w, h) window_has_colours(src, x, y, w, h)
#define WINDOW_BUSY_EXACT(src, x, y, w, h) window_has_exact_colours(src, x, y, w, h)
#endif

// The longest straight edge run (distances.cl: left + right + 1, up + down + 1) among the edges that pixel (x, y)
// borders is at least `min_run` pixels (0: no test).
inline int on_long_run(__global const uchar *edges, __global const ushort2 *hdist, __global const ushort2 *vdist,
                       int x, int y, int w, int min_run)
{
    if (min_run <= 0) return 0;
    const int i = IDX(x, y, w);
    int run = 0;
    if (edges[i] & EDGE_BOTTOM) run = max(run, hdist[i].x + hdist[i].y + 1);
    if (y > 0 && (edges[i - w] & EDGE_BOTTOM)) run = max(run, hdist[i - w].x + hdist[i - w].y + 1);
    if (edges[i] & EDGE_RIGHT) run = max(run, vdist[i].x + vdist[i].y + 1);
    if (x > 0 && (edges[i - 1] & EDGE_RIGHT)) run = max(run, vdist[i - 1].x + vdist[i - 1].y + 1);
    return run >= min_run;
}
#define ON_LONG_RUN(edges, hdist, vdist, x, y, w) on_long_run(edges, hdist, vdist, x, y, w, FALLBACK_KEEP_RUN)
#define ON_REGION_RUN(edges, hdist, vdist, x, y, w) on_long_run(edges, hdist, vdist, x, y, w, REGION_KEEP_RUN)

// How many of the tile's pixels (x0..x1, y0..y1) lie within a tenth of its luma range (px_luma) from its darkest or
// lightest: the two-tone test of render regions; NOT_MEASURED where the range is under RENDER_RANGE.
RARELY_CALLED int tile_near_extremes(__global const PIXEL_T *src, int x0, int x1, int y0, int y1, int w, int h)
{
    float lo = px_luma(src, x0, y0, w, h), hi = lo;
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x) {
            const float l = px_luma(src, x, y, w, h);
            lo = fmin(lo, l);
            hi = fmax(hi, l);
        }
    const float range = hi - lo;
    if (!(range >= RENDER_RANGE)) return NOT_MEASURED;
    int near = 0;
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x) {
            const float l = px_luma(src, x, y, w, h);
            near += (l - lo) * 10.0f <= range || (hi - l) * 10.0f <= range;
        }
    return near;
}

// px_luma clipped to display white: tile_ramps' luma (HDR frames' highlights above 1 count as flat, so bright
// shading gradients and dark-noise steps scaled up with the exposure make no ramps; docs/spatial_tuning.md).
inline float ramp_luma(__global const PIXEL_T *src, int x, int y, int w, int h)
{
    return fmin(px_luma(src, x, y, w, h), 1.0f);
}

// The tile's strong luma steps (ramp_luma, SUPERSAMPLED_STEP or more from a pixel to its right or lower neighbour
// inside the frame) and of those the ramps (the step before or after it goes the same way by at least half as
// much); and its clean transitions and of those the ramps: with d(k) the step from k to k + 1 along the direction
// (pixel 0 the tile's, pixel 2 inside the frame, clamped reads), a hard stair end -- |d0| >= SUPERSAMPLED_STEP with
// |d(-1)|, |d1| <= RAMP_FLANK |d0|, and on one side across the direction the step does not go on the same way by at
// least half as much (where a 1-spp edge's staircase shifts; pixel-aligned edges and the runs between stairs do not
// count) -- or a ramp: d0 and d1 the same way, T = d0 + d1 with |T| >= SUPERSAMPLED_STEP, both over RAMP_FLANK |T|
// and |d(-1)|, |d2| <= RAMP_FLANK |T| (one pixel between two plateaus). As (strong, ramps, clean, clean ramps).
RARELY_CALLED int4 tile_ramps(__global const PIXEL_T *src, int x0, int x1, int y0, int y1, int w, int h)
{
    int4 n = (int4)(0, 0, 0, 0);
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x) {
            const float a = ramp_luma(src, x, y, w, h);
            for (int k = 0; k < 2; ++k) {
                const int dx = k == 0, dy = k == 1;
                if (x + dx >= w || y + dy >= h) continue;
                const float b = ramp_luma(src, x + dx, y + dy, w, h), c = b - a;
                if (!(fabs(c) > RAMP_FLANK * SUPERSAMPLED_STEP)) continue;  // no strong step, no clean ramp
                const float before = a - ramp_luma(src, x - dx, y - dy, w, h);
                const float l2 = ramp_luma(src, x + 2 * dx, y + 2 * dy, w, h), after = l2 - b;
                if (fabs(c) >= SUPERSAMPLED_STEP) {
                    const float mid = 0.5f * c;
                    n.x += 1;
                    n.y += c > 0.0f ? (before >= mid || after >= mid) : (before <= mid || after <= mid);
                }
                if (x + 2 * dx >= w || y + 2 * dy >= h) continue;
                const float t = c + after, at = fabs(t), ac = fabs(c), aa = fabs(after);
                const float d2 = ramp_luma(src, x + 3 * dx, y + 3 * dy, w, h) - l2;
                int hard = ac >= SUPERSAMPLED_STEP && fabs(before) <= RAMP_FLANK * ac && aa <= RAMP_FLANK * ac;
                if (hard) {  // ... at a stair's end: beside it (one pixel across the direction) it does not go on
                    int ends = 0;
                    for (int sd = -1; sd <= 1; sd += 2) {
                        const float cs = ramp_luma(src, x + dx + sd * dy, y + dy + sd * dx, w, h)
                                         - ramp_luma(src, x + sd * dy, y + sd * dx, w, h);
                        ends |= !(cs * c > 0.0f && fabs(cs) >= 0.5f * ac);
                    }
                    hard = ends;
                }
                const int ramp = at >= SUPERSAMPLED_STEP && c * t > 0.0f && after * t > 0.0f &&
                                 fmin(ac, aa) > RAMP_FLANK * at && fabs(before) <= RAMP_FLANK * at &&
                                 fabs(d2) <= RAMP_FLANK * at;
                n.z += hard | ramp;
                n.w += ramp;
            }
        }
    return n;
}

// Nine counts per tile (tx, ty), at counts[COUNTS * (ty * tiles_x + tx) + k]: k = 0 its pixels that border an
// edge and that the MLAA passes changed (dst != src), k = 1 its pixels that border an edge, k = 2 the changed ones
// whose 3x3 window holds FALLBACK_COLOURS bit-identical colours ("busy"), k = 3 tile_near_extremes where k = 2 is
// not 0 and there are render regions (else NOT_MEASURED), k = 4 .. 7 tile_ramps where k = 1 is not 0, tx and ty
// are even and there are render regions (else 0; at most 128 each), k = 8 the busy ones whose 3x3 window of luma
// lies within the frame's grain (noise.cl pixel_quiet; 0 where its level is 0: grain_verdict says whether they
// count). One work item per SEGMENT pixels (a multiple of FALLBACK_TILE) of a band of FALLBACK_TILE rows.
__kernel void count_changed(__global const PIXEL_T *src, __global const PIXEL_T *dst,
                            __global const uchar *edges, __global const int *noise, __global uchar *counts,
                            const int w, const int h, const int tiles_x)
{
    const int x0 = get_global_id(0) * SEGMENT, ty = get_global_id(1), y0 = ty * FALLBACK_TILE;
    if (x0 >= w || y0 >= h) return;
    const int level = noise[0];
    const int x1 = min(x0 + SEGMENT, w), y1 = min(y0 + FALLBACK_TILE, h);
    for (int t0 = x0; t0 < x1; t0 += FALLBACK_TILE) {
        const int t1 = min(t0 + FALLBACK_TILE, x1);
        int changed = 0, bordering = 0, busy = 0, grainy = 0;
        for (int y = y0; y < y1; ++y)
            if (!(t1 - t0 == 8 && group_is_quiet(edges, t0, y, w)))
                for (int x = t0; x < t1; ++x) {
                    if (!borders_edge(edges, x, y, w)) continue;
                    ++bordering;
                    if (!px_differs(src, dst, IDX(x, y, w))) continue;
                    ++changed;
                    if (WINDOW_BUSY_EXACT(src, x, y, w, h)) {
                        ++busy;
                        grainy += pixel_quiet(src, x, y, w, h, level);
                    }
                }
        __global uchar *c = counts + COUNTS * (ty * tiles_x + t0 / FALLBACK_TILE);
        c[0] = (uchar)changed;
        c[1] = (uchar)bordering;
        c[2] = (uchar)busy;
        c[3] = (uchar)(RENDER_REGIONS && busy ? tile_near_extremes(src, t0, t1, y0, y1, w, h) : NOT_MEASURED);
        const int sampled = ((t0 / FALLBACK_TILE) & 1) == 0 && (ty & 1) == 0;  // a quarter of the tiles suffices
        const int4 ramps = RENDER_REGIONS && bordering && sampled ? tile_ramps(src, t0, t1, y0, y1, w, h)
                                                                  : (int4)(0, 0, 0, 0);
        c[4] = (uchar)ramps.x;
        c[5] = (uchar)ramps.y;
        c[6] = (uchar)ramps.z;
        c[7] = (uchar)ramps.w;
        c[8] = (uchar)grainy;
    }
}

// noise[1] = 1 where busy pixels within the grain (count_changed's k = 8) are no evidence of a render: the frame has
// grain (noise[0], its level, over 0) and no 1-spp geometry -- hard stair ends (clean transitions that are no ramps)
// under SUPERSAMPLED_HARD_PCT % of its strong steps, tile_ramps' counts summed. A photograph with colour noise: the
// MLAA passes blend some of the noise (dark colour noise passes the CIELAB threshold) in windows of many exact
// colours, which made most of it render regions; a grainy render keeps its stair ends and its busy pixels
// (docs/spatial_tuning.md, "Busy pixels within the grain"). One work item.
__kernel void grain_verdict(__global const uchar *counts, __global int *noise, const int tiles)
{
    if (get_global_id(0) != 0) return;
    if (noise[0] <= 0) {
        noise[1] = 0;
        return;
    }
    int strong = 0, clean = 0, clean_ramps = 0;
    for (int t = 0; t < tiles; ++t) {
        __global const uchar *c = counts + COUNTS * t;
        strong += c[4];
        clean += c[6];
        clean_ramps += c[7];
    }
    noise[1] = !(strong > 0 && (clean - clean_ramps) * 100 >= SUPERSAMPLED_HARD_PCT * strong);
}

// A tile's busy pixels (count_changed's k = 2), less those within the grain where they do not count (grain_verdict).
inline int tile_busy(__global const uchar *c, int grain_free)
{
    return c[2] - (grain_free ? c[8] : 0);
}

// A tile's six terms of the render-region sums: busy pixels, edge-bordering pixels, busy pixels of a measured
// tile, those weighted by its near count, clean transitions and clean ramps (two lanes unused).
inline int8 region_terms(__global const uchar *counts, int tile, int grain_free)
{
    __global const uchar *c = counts + COUNTS * tile;
    const int busy = tile_busy(c, grain_free), measured = c[3] != NOT_MEASURED;
    return (int8)(busy, c[1], measured ? busy : 0, measured ? busy * c[3] : 0, c[6], c[7], 0, 0);
}

// rows[tile] = region_terms summed over the tiles tx - RENDER_RADIUS .. tx + RENDER_RADIUS of its row, clamped to
// the frame (the first of the two separable passes of render regions). One work item per tile row, a running sum.
__kernel void render_rows(__global const uchar *counts, __global const int *noise, __global int8 *rows,
                          const int tiles_x, const int tiles_y)
{
    const int ty = get_global_id(0);
    if (ty >= tiles_y) return;
    const int grain_free = noise[1];
    const int row = ty * tiles_x;
    int8 sum = (int8)(0);
    for (int k = 0; k < RENDER_RADIUS && k < tiles_x; ++k) sum += region_terms(counts, row + k, grain_free);
    for (int tx = 0; tx < tiles_x; ++tx) {
        if (tx + RENDER_RADIUS < tiles_x) sum += region_terms(counts, row + tx + RENDER_RADIUS, grain_free);
        rows[row + tx] = sum;
        if (tx >= RENDER_RADIUS) sum -= region_terms(counts, row + tx - RENDER_RADIUS, grain_free);
    }
}

// render[tile] = the neighbourhood tests of the tiles within RENDER_RADIUS (rows' sums over the column), bit 0: it
// looks like a 1-spp render -- RENDER_MIN busy pixels in measured tiles (low-contrast tiles cannot show whether they
// are two-toned), busy pixels a share of the edge pixels, and not two-toned; bit 1: it holds a busy pixel (the second
// separable pass); bit 2: under RENDER_RAMP_PCT % of its clean transitions are ramps (or it has none); bit 3: bit 0
// with busy pixels only 1 / RENDER_DIV_1SPP of the edge pixels (render_frame takes it in 1-spp frames).
// shares[tx] = the column's tiles with edge-bordering pixels, of those its tiles with bit 0, and their strong steps,
// ramps, clean transitions and clean ramps (render_frame's evidence), and its tiles with bit 3. One work item per
// tile column, a running sum.
__kernel void render_tiles(__global const int8 *rows, __global const uchar *counts, __global uchar *render,
                           __global int8 *shares, const int tiles_x, const int tiles_y)
{
    const int tx = get_global_id(0);
    if (tx >= tiles_x) return;
    int8 sum = (int8)(0);
    int8 share = (int8)(0);
    for (int k = 0; k < RENDER_RADIUS && k < tiles_y; ++k) sum += rows[k * tiles_x + tx];
    for (int ty = 0; ty < tiles_y; ++ty) {
        if (ty + RENDER_RADIUS < tiles_y) sum += rows[(ty + RENDER_RADIUS) * tiles_x + tx];
        const int tile = ty * tiles_x + tx;
        const int measured = sum.s2 >= RENDER_MIN &&
                             sum.s3 * 100 <= RENDER_NEAR_PCT * (FALLBACK_TILE * FALLBACK_TILE) * sum.s2;
        const int rendered = measured && sum.s0 * RENDER_DIV >= sum.s1;
        const int relaxed = measured && sum.s0 * RENDER_DIV_1SPP >= sum.s1;
        const int hard = sum.s5 * 100 < RENDER_RAMP_PCT * (sum.s4 > 1 ? sum.s4 : 1);
        render[tile] = (uchar)((relaxed << 3) | (hard << 2) | ((sum.s0 > 0) << 1) | rendered);
        __global const uchar *c = counts + COUNTS * tile;
        if (c[1]) share += (int8)(1, rendered, c[4], c[5], c[6], c[7], relaxed, 0);
        if (ty >= RENDER_RADIUS) sum -= rows[(ty - RENDER_RADIUS) * tiles_x + tx];
    }
    shares[tx] = share;
}

// render[tile] = 1 where the tile is a render region: bit 0 of render_tiles, or bit 1 in a frame where at least
// RENDER_FRAME_PCT % of the tiles with edge-bordering pixels have bit 0 (a render: every tile near a busy pixel).
// In a frame whose hard stair ends (clean transitions that are no ramps) are SUPERSAMPLED_HARD_PCT % or more of its
// strong steps -- 1-spp geometry -- bit 3 stands for bit 0: a video codec's blur makes the MLAA passes skip many of
// a compressed render's edges as already antialiased, and fewer of its pixels count as busy.
// In a supersampled frame (SUPERSAMPLED_MIN strong steps or more, SUPERSAMPLED_PCT % of them ramps, or as many clean
// transitions, SUPERSAMPLED_CLEAN_PCT % of them ramps; hard stair ends, clean transitions that are no ramps, under
// SUPERSAMPLED_HARD_PCT % of the strong steps) only tiles with bit 2 as well (the neighbourhood's clean
// transitions mostly hard steps), and the tiles' counts k = 0..2 are cleared: fxaa_fallback then finds no tile
// busy and none with evidence outside render regions.
// A frame of a shot held as a render (hold[parity] > 0: a frame of the same shot within RENDER_HOLD_FRAMES was
// judged one by its own share; `cut`: none before this frame counts) is one too: a video codec's P- and B-frames
// fall under RENDER_FRAME_PCT where the keyframe before them passes (spatial/shots.py). So is one that looks
// supersampled, if it is one of at most HELD_SUPERSAMPLED_RUN such frames in a row (hold[2 + parity] before it): a
// codec's blur makes its B-frames look so; a shot that turns supersampled for longer is judged supersampled.
// Work item 0 writes the hold and the run for the next frame into hold[1 - parity] and hold[3 - parity].
// One work item per tile column; each sums the columns' shares (tiles_x of them: cheaper than another pass).
__kernel void render_frame(__global uchar *render, __global uchar *counts, __global const int8 *shares,
                           __global int *hold, const int parity, const int cut, const int tiles_x, const int tiles_y)
{
    const int tx = get_global_id(0);
    if (tx >= tiles_x) return;
    int8 total = (int8)(0);
    for (int k = 0; k < tiles_x; ++k) total += shares[k];
    const int looks_supersampled =
        ((total.s2 >= SUPERSAMPLED_MIN && total.s3 * 100 >= SUPERSAMPLED_PCT * total.s2) ||
         (total.s4 >= SUPERSAMPLED_MIN && total.s5 * 100 >= SUPERSAMPLED_CLEAN_PCT * total.s4)) &&
        (total.s4 - total.s5) * 100 < SUPERSAMPLED_HARD_PCT * total.s2;
    const int one_spp = total.s2 > 0 && (total.s4 - total.s5) * 100 >= SUPERSAMPLED_HARD_PCT * total.s2;
    const int regions = one_spp ? total.s6 : total.s1;
    const int own = total.s0 > 0 && regions * 100 >= RENDER_FRAME_PCT * total.s0;
    const int held = !cut && hold[parity] > 0;
    // frames in a row that look supersampled, this one included: a codec's B-frames between its reference frames
    const int run = looks_supersampled ? (cut ? 1 : hold[2 + parity] + 1) : 0;
    const int supersampled = looks_supersampled && !(held && run <= HELD_SUPERSAMPLED_RUN);
    if (tx == 0) {
        hold[1 - parity] = own ? RENDER_HOLD_FRAMES : (held ? hold[parity] - 1 : 0);
        hold[3 - parity] = run;
    }
    const uchar bit = total.s0 > 0 && (own || (held && !supersampled)) ? 2 : (one_spp ? 8 : 1);
    for (int ty = 0; ty < tiles_y; ++ty) {
        const int tile = ty * tiles_x + tx;
        render[tile] = (uchar)((render[tile] & bit) != 0 && (!supersampled || (render[tile] & 4) != 0));
        if (supersampled) {
            __global uchar *c = counts + COUNTS * tile;
            c[0] = c[1] = c[2] = c[8] = 0;
        }
    }
}

// Pixel (x, y) of dst becomes `start`'s colour moved `share` of the way to FXAA's (linear light), where FXAA
// changes the pixel: start = src with FALLBACK_WEIGHT for pixels the MLAA passes left, start = dst with
// FALLBACK_MIX for pixels they blended (out of line: FXAA's search is long and few pixels get here).
RARELY_CALLED void towards_fxaa(__global const PIXEL_T *src, __global const float *luts, __global PIXEL_T *dst,
                                __global const PIXEL_T *start, float share, int x, int y, int w, int h)
{
    float3 f;
    if (!fxaa_pixel(src, luts, x, y, w, h, &f)) return;
    const int i = IDX(x, y, w);
    float4 c = load_px(start, i);
    float3 m = blend_rgb(start, luts, x, y, w, h);
    c.xyz = fxaa_encode(luts, m + share * (f - m));
    store_px(dst, i, c);
}

// A pixel's colour channels in mix space (linear light when DECODE; integer frames decoded with one load per
// channel from `lin`, common.cl linear_levels), in storage order.
inline float3 mix_channels(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                           int i)
{
#if CHANNELS == 1
    const PIXEL_T a = src[i], b = a, c = a;
#else
    __global const PIXEL_T *p = src + (size_t)i * CHANNELS;
    const PIXEL_T a = p[0], b = p[1], c = p[2];
#endif
#if DECODE && !defined(PIXEL_IS_FLOAT)
    return (float3)(lin[a], lin[b], lin[c]);
#else
    const float3 v = (float3)((float)a, (float)b, (float)c) * (1.0f / PIXEL_MAX);
#if DECODE
    return (float3)(srgb_to_linear(luts, v.x), srgb_to_linear(luts, v.y), srgb_to_linear(luts, v.z));
#else
    return v;
#endif
#endif
}

#if FOOTPRINT_TABLE
#define FP_R 2                    // footprint.py TABLE_RADIUS: the 5x5 window
#define FP_N (2 * FP_R + 1)
#define FP_L (FP_N + 2)           // luma is read over 7x7: central differences at every tap of the 5x5
#if ORDER_BGR
#define FP_LUMA(c) ((c).z * 0.2126f + (c).y * 0.7152f + (c).x * 0.0722f)
#else
#define FP_LUMA(c) ((c).x * 0.2126f + (c).y * 0.7152f + (c).z * 0.0722f)
#endif
#define FP_STRENGTHS 3
#define FP_COHERENCES 3

// How many of the two levels t a band statistic reaches, per lane (footprint.py footprint_buckets: no square roots).
// Strength: l1 = (tr + sqrt(det2)) / 2 >= t^2 scale2 (footprint.py footprint_buckets: scale2 s^2 or s).
inline int8 fp_strength(float8 tr, float8 det2, float8 scale2)
{
    int8 n = 0;
    const float t[2] = {STRENGTH_LO, STRENGTH_HI};  // footprint.py STRENGTH_LEVELS
    for (int k = 0; k < 2; ++k) {
        const float8 need = 2.0f * t[k] * t[k] * scale2 - tr;
        n -= (need <= 0.0f) | (det2 >= need * need);  // a vector comparison is -1 where true
    }
    return n;
}

inline int8 fp_coherence(float8 tr, float8 det2)
{
    int8 n = 0;
    const float t[2] = {0.3f, 0.6f};  // COHERENCE_LEVELS: sqrt(det2) >= tr 2t / (1 + t^2)
    for (int k = 0; k < 2; ++k) {
        const float8 q = tr * (2.0f * t[k] / (1.0f + t[k] * t[k]));
        n -= det2 >= q * q;
    }
    return n;
}

#define FP_LC (FALLBACK_TILE + 2 * FP_R + 2)  // luma rows / columns: y0 - 3 .. y0 + FALLBACK_TILE + 2 (x alike)
#define FP_CC (FALLBACK_TILE + 2 * FP_R)      // colour and gradient rows / columns: y0 - 2 .. y0 + FALLBACK_TILE + 1
#if FALLBACK_TILE != 8
#error "footprint_tile runs a tile row as 8 lanes: FALLBACK_TILE 8"
#endif
// The tile's windows: colours (planar) over rows y0 - 2 .. y0 + FALLBACK_TILE + 1 (columns alike), their linear
// luma and the gradient products gx^2, gy^2, gx gy of it (central differences) there, luma read over one pixel more
// each way.
inline void fp_read_window(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                           int x0, int y0, int w, int h, float wr[FP_CC][FP_CC], float wg[FP_CC][FP_CC],
                           float wb[FP_CC][FP_CC], float wy[FP_CC][FP_CC], float pxx[FP_CC][FP_CC],
                           float pyy[FP_CC][FP_CC], float pxy[FP_CC][FP_CC])
{
    float luma[FP_LC][FP_LC];
    for (int j = 0; j < FP_LC; ++j) {
        const int row = clamp_to(y0 + j - FP_R - 1, h - 1) * w;
        for (int k = 0; k < FP_LC; ++k) {
            const float3 c = mix_channels(src, luts, lin, row + clamp_to(x0 + k - FP_R - 1, w - 1));
            luma[j][k] = FP_LUMA(c);
            if (j >= 1 && j <= FP_CC && k >= 1 && k <= FP_CC) {
                wr[j - 1][k - 1] = c.x;
                wg[j - 1][k - 1] = c.y;
                wb[j - 1][k - 1] = c.z;
                wy[j - 1][k - 1] = luma[j][k];
            }
        }
    }
    for (int j = 1; j <= FP_CC; ++j)
        for (int k = 1; k <= FP_CC; ++k) {
            const float gx = (luma[j][k + 1] - luma[j][k - 1]) * 0.5f;
            const float gy = (luma[j + 1][k] - luma[j - 1][k]) * 0.5f;
            pxx[j - 1][k - 1] = gx * gx;
            pyy[j - 1][k - 1] = gy * gy;
            pxy[j - 1][k - 1] = gx * gy;
        }
}

// The bucket per lane (footprint.py footprint_buckets) from the window's sums of the gradient products and of its
// luma (sy); `changed` -1 where the pixel's colour differs from the input's; `weber_squared` as the reference's.
inline int8 fp_bucket(float8 sxx, float8 syy, float8 sxy, float8 sy, int8 changed, int weber_squared)
{
    sxx *= 1.0f / (FP_N * FP_N);
    syy *= 1.0f / (FP_N * FP_N);
    sxy *= 1.0f / (FP_N * FP_N);
    const float8 scale = (sy * (1.0f / (FP_N * FP_N)) + STRENGTH_FLOOR) * STRENGTH_UNIT;
    const float8 scale2 = weber_squared ? scale * scale : scale;
    const float8 u = sxx - syy, v = 2.0f * sxy, tr = sxx + syy, det2 = u * u + v * v;
    const float8 au = fabs(u), av = fabs(v);
    // octant of the doubled angle: the gradient's orientation in eight bins of pi / 8
    // (select(a, b, c): b where c, else a)
    const int8 lower = select(select((int8)5, (int8)4, av < au), select((int8)7, (int8)6, av > au), u >= 0.0f);
    const int8 upper = select(select((int8)3, (int8)2, av > au), select((int8)1, (int8)0, av < au), u > 0.0f);
    const int8 octant = select(lower, upper, v >= 0.0f);
    const int8 strength = fp_strength(tr, det2, scale2);
    return ((octant * FP_STRENGTHS + strength) * FP_COHERENCES + fp_coherence(tr, det2)) * 2 - changed;
}

// q += sum over the 5x5 window of row r's lanes (rows r .. r + 4) of (window - m) * the table's weight of the tap,
// per channel, in the reference's order.
inline void fp_window_sum(float wr[FP_CC][FP_CC], float wg[FP_CC][FP_CC], float wb[FP_CC][FP_CC], int r,
                          __global const float *table, int8 base, float8 mr, float8 mg, float8 mb, float8 *qr,
                          float8 *qg, float8 *qb)
{
    for (int j = 0; j < FP_N; ++j)
        for (int k = 0; k < FP_N; ++k) {
            const float8 wt = GATHER8(table + j * FP_N + k, base);
            *qr += (LOAD_FLOAT8_PRIVATE(&wr[r + j][k]) - mr) * wt;
            *qg += (LOAD_FLOAT8_PRIVATE(&wg[r + j][k]) - mg) * wt;
            *qb += (LOAD_FLOAT8_PRIVATE(&wb[r + j][k]) - mb) * wt;
        }
}

// No overshoot: q clamped, per lane, to the range of the window's 3x3 around row r's pixels and the colour c, into
// the out arrays.
inline void fp_clamp_row(float wr[FP_CC][FP_CC], float wg[FP_CC][FP_CC], float wb[FP_CC][FP_CC], int r, float8 cr,
                         float8 cg, float8 cb, float8 qr, float8 qg, float8 qb, float *outr, float *outg,
                         float *outb)
{
    float8 lr = cr, lg = cg, lb = cb, hr = cr, hg = cg, hb = cb;
    for (int j = r + FP_R - 1; j <= r + FP_R + 1; ++j)
        for (int k = FP_R - 1; k <= FP_R + 1; ++k) {
            const float8 tr_ = LOAD_FLOAT8_PRIVATE(&wr[j][k]), tg = LOAD_FLOAT8_PRIVATE(&wg[j][k]),
                         tb = LOAD_FLOAT8_PRIVATE(&wb[j][k]);
            lr = fmin(lr, tr_);
            lg = fmin(lg, tg);
            lb = fmin(lb, tb);
            hr = fmax(hr, tr_);
            hg = fmax(hg, tg);
            hb = fmax(hb, tb);
        }
    STORE_FLOAT8_PRIVATE(fmin(fmax(qr, lr), hr), outr);
    STORE_FLOAT8_PRIVATE(fmin(fmax(qg, lg), hg), outg);
    STORE_FLOAT8_PRIVATE(fmin(fmax(qb, lb), hb), outb);
}

// Row y's new colours (mix space, lane o: column x0 + o) stored where bit o of `take` is set and keep[o] is 0;
// alpha is kept.
inline void fp_store_row(__global PIXEL_T *dst, __global const float *luts, int x0, int x1, int y, int w, uint take,
                         const int *keep, const float *outr, const float *outg, const float *outb)
{
    for (int x = x0; x < x1; ++x) {
        const int o = x - x0;
        if (!((take >> o) & 1u) || keep[o]) continue;
        const float3 c = fxaa_encode(luts, (float3)(outr[o], outg[o], outb[o]));
        const int i = IDX(x, y, w);
#if CHANNELS == 1
        dst[i] = to_pixel(c.x);
#else
        __global PIXEL_T *p = dst + (size_t)i * CHANNELS;
        p[0] = to_pixel(c.x);
        p[1] = to_pixel(c.y);
        p[2] = to_pixel(c.z);
#endif
    }
}

// The footprint table for the pixels (x, y) of the tile x0 .. x1 - 1, y0 .. y1 - 1 (at most FALLBACK_TILE each way)
// whose bit (x - x0) is set in take[y - y0] (footprint.py footprint_reference): dst holds the chain's colours and
// receives the new ones; a pixel whose 5x5 window is one colour and which the chain left is not written. Alpha is
// kept. The tile's windows share their reads: luma over (FALLBACK_TILE + 6)^2 pixels, colours (planar) and gradient
// products over the middle (FALLBACK_TILE + 4)^2; the structure tensor's sums per column of 5 rows (the reference
// sums in the same order). A row's 8 pixels are the 8 lanes of float8 arithmetic (lane o: column x0 + o; lanes past
// x1 compute from clamped reads and store nothing): PoCL does not run a tile's pixels in vector lanes by itself.
RARELY_CALLED void footprint_tile(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                                  __global const float *table, __global PIXEL_T *dst, int x0, int x1, int y0,
                                  int y1, int w, int h, const uint *take)
{
    float wr[FP_CC][FP_CC], wg[FP_CC][FP_CC], wb[FP_CC][FP_CC];  // the colours, one plane per channel
    float wy[FP_CC][FP_CC], pxx[FP_CC][FP_CC], pyy[FP_CC][FP_CC], pxy[FP_CC][FP_CC];
    fp_read_window(src, luts, lin, x0, y0, w, h, wr, wg, wb, wy, pxx, pyy, pxy);
    for (int y = y0; y < y1; ++y) {
        const int r = y - y0;  // the row's windows: rows r .. r + 4 of the colours and of the products
        if (!take[r]) continue;
        // per column: the 5 rows' sums of the products and of the luma, and whether its 5 colours are one (-1 where
        // true); as two overlapping float8 of columns 0 .. 7 and 4 .. 11
        float cxx[FP_CC], cyy[FP_CC], cxy[FP_CC], cy[FP_CC];
        int one[FP_CC];
        for (int k = 0; k <= FP_CC - 8; k += FP_CC - 8) {
            float8 sxx = 0.0f, syy = 0.0f, sxy = 0.0f, sy = 0.0f;
            int8 same = -1;
            const float8 tr_ = LOAD_FLOAT8_PRIVATE(&wr[r][k]), tg = LOAD_FLOAT8_PRIVATE(&wg[r][k]),
                         tb = LOAD_FLOAT8_PRIVATE(&wb[r][k]);
            for (int j = r; j < r + FP_N; ++j) {
                sxx += LOAD_FLOAT8_PRIVATE(&pxx[j][k]);
                syy += LOAD_FLOAT8_PRIVATE(&pyy[j][k]);
                sxy += LOAD_FLOAT8_PRIVATE(&pxy[j][k]);
                sy += LOAD_FLOAT8_PRIVATE(&wy[j][k]);
                same &= (LOAD_FLOAT8_PRIVATE(&wr[j][k]) == tr_) & (LOAD_FLOAT8_PRIVATE(&wg[j][k]) == tg)
                        & (LOAD_FLOAT8_PRIVATE(&wb[j][k]) == tb);
            }
            STORE_FLOAT8_PRIVATE(sxx, &cxx[k]);
            STORE_FLOAT8_PRIVATE(syy, &cyy[k]);
            STORE_FLOAT8_PRIVATE(sxy, &cxy[k]);
            STORE_FLOAT8_PRIVATE(sy, &cy[k]);
            STORE_INT8_PRIVATE(same, &one[k]);
        }
        int chg[FALLBACK_TILE];
        float chr[FALLBACK_TILE], chgr[FALLBACK_TILE], chb[FALLBACK_TILE];  // the chain's colours
        for (int o = 0; o < FALLBACK_TILE; ++o) {
            const int i = IDX(min(x0 + o, w - 1), y, w);
            const float3 c = mix_channels(dst, luts, lin, i);
            chg[o] = -px_differs(src, dst, i);
            chr[o] = c.x;
            chgr[o] = c.y;
            chb[o] = c.z;
        }
        const int8 changed = LOAD_INT8_PRIVATE(chg);
        const float8 mr = LOAD_FLOAT8_PRIVATE(&wr[r + FP_R][FP_R]), mg = LOAD_FLOAT8_PRIVATE(&wg[r + FP_R][FP_R]),
                     mb = LOAD_FLOAT8_PRIVATE(&wb[r + FP_R][FP_R]);
        int8 flat = -1;  // the 5x5 window is one colour
        float8 sxx = 0.0f, syy = 0.0f, sxy = 0.0f, sy = 0.0f;
        for (int k = 0; k < FP_N; ++k) {
            flat &= LOAD_INT8_PRIVATE(&one[k]) & (LOAD_FLOAT8_PRIVATE(&wr[r][k]) == mr)
                    & (LOAD_FLOAT8_PRIVATE(&wg[r][k]) == mg) & (LOAD_FLOAT8_PRIVATE(&wb[r][k]) == mb);
            sxx += LOAD_FLOAT8_PRIVATE(&cxx[k]);
            syy += LOAD_FLOAT8_PRIVATE(&cyy[k]);
            sxy += LOAD_FLOAT8_PRIVATE(&cxy[k]);
            sy += LOAD_FLOAT8_PRIVATE(&cy[k]);
        }
        const int8 bucket = fp_bucket(sxx, syy, sxy, sy, changed, 1);
        const int8 base = bucket * FOOTPRINT_WEIGHTS;
        const float8 cr = LOAD_FLOAT8_PRIVATE(chr), cg = LOAD_FLOAT8_PRIVATE(chgr), cb = LOAD_FLOAT8_PRIVATE(chb);
        float8 qr = mr, qg = mg, qb = mb;
        fp_window_sum(wr, wg, wb, r, table, base, mr, mg, mb, &qr, &qg, &qb);
        const float8 wc = GATHER8(table + FP_N * FP_N, base);
        qr += (cr - mr) * wc;
        qg += (cg - mg) * wc;
        qb += (cb - mb) * wc;
        float outr[FALLBACK_TILE], outg[FALLBACK_TILE], outb[FALLBACK_TILE];
        int keep[FALLBACK_TILE];
        fp_clamp_row(wr, wg, wb, r, cr, cg, cb, qr, qg, qb, outr, outg, outb);  // and the chain's colour
        STORE_INT8_PRIVATE(flat & ~changed, keep);
        fp_store_row(dst, luts, x0, x1, y, w, take[r], keep, outr, outg, outb);
    }
}
#endif

#if REFINE_TABLE
#define RF_IN (FALLBACK_TILE + 2)  // the input's colours: rows y0 - 1 .. y0 + FALLBACK_TILE (columns alike)

// The refine table (spatial/refine.py refine_reference) for the pixels of the tile whose bit is set in take[y - y0]
// and whose input has strong local contrast (refine.py gate: a colour channel spans REFINE_GATE of full scale or
// more over the 3x3 window, in stored values): `mid` holds the colours after the footprint table, dst receives the
// new ones (alpha kept). The same reads and float8 lanes as footprint_tile, on mid's window, plus the input's 3x3.
RARELY_CALLED void refine_tile(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                               __global const float *table, __global const PIXEL_T *mid, __global PIXEL_T *dst,
                               int x0, int x1, int y0, int y1, int w, int h, uint *take)
{
    // the gate, from the input's stored values over the tile and one pixel around it (read once per channel)
    uint open[FALLBACK_TILE] = {0, 0, 0, 0, 0, 0, 0, 0}, any = 0;
    for (int c = 0; c < COLOUR_CH; ++c) {
        float v[RF_IN][RF_IN];
        for (int j = 0; j < RF_IN; ++j) {
            const int row = clamp_to(y0 + j - 1, h - 1) * w;
            for (int k = 0; k < RF_IN; ++k)
                v[j][k] = (float)src[(size_t)(row + clamp_to(x0 + k - 1, w - 1)) * CHANNELS + c];
        }
        for (int r = 0; r < y1 - y0; ++r) {  // a row's 8 pixels as float8 lanes (one by one: 3x the time)
            float8 a = LOAD_FLOAT8_PRIVATE(&v[r][0]), b = a;
            for (int j = r; j < r + 3; ++j)
                for (int k = 0; k < 3; ++k) {
                    const float8 t = LOAD_FLOAT8_PRIVATE(&v[j][k]);
                    a = fmin(a, t);
                    b = fmax(b, t);
                }
            int wide[FALLBACK_TILE];
#ifdef PIXEL_IS_FLOAT
            STORE_INT8_PRIVATE((b - a) * (1.0f / PIXEL_MAX) >= REFINE_GATE, wide);
#else
            STORE_INT8_PRIVATE(b - a >= (float)REFINE_GATE_LEVELS, wide);  // exact: integers in float
#endif
            for (int o = 0; o < FALLBACK_TILE; ++o)
                open[r] |= (uint)(wide[o] & 1) << o;
        }
    }
    for (int r = 0; r < y1 - y0; ++r) {
        take[r] &= open[r];
        any |= take[r];
    }
    if (!any) return;
    float wr[FP_CC][FP_CC], wg[FP_CC][FP_CC], wb[FP_CC][FP_CC];
    float wy[FP_CC][FP_CC], pxx[FP_CC][FP_CC], pyy[FP_CC][FP_CC], pxy[FP_CC][FP_CC];
    fp_read_window(mid, luts, lin, x0, y0, w, h, wr, wg, wb, wy, pxx, pyy, pxy);
    float ir[RF_IN][RF_IN], ig[RF_IN][RF_IN], ib[RF_IN][RF_IN];
    for (int j = 0; j < RF_IN; ++j) {
        const int row = clamp_to(y0 + j - 1, h - 1) * w;
        for (int k = 0; k < RF_IN; ++k) {
            const float3 c = mix_channels(src, luts, lin, row + clamp_to(x0 + k - 1, w - 1));
            ir[j][k] = c.x;
            ig[j][k] = c.y;
            ib[j][k] = c.z;
        }
    }
    const int keep[FALLBACK_TILE] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (int y = y0; y < y1; ++y) {
        const int r = y - y0;
        if (!take[r]) continue;
        // per column of 5 rows, then across (footprint_tile's order)
        float8 sxx = 0.0f, syy = 0.0f, sxy = 0.0f, sy = 0.0f;
        for (int k = 0; k < FP_N; ++k) {
            float8 c8xx = 0.0f, c8yy = 0.0f, c8xy = 0.0f, c8y = 0.0f;
            for (int j = r; j < r + FP_N; ++j) {
                c8xx += LOAD_FLOAT8_PRIVATE(&pxx[j][k]);
                c8yy += LOAD_FLOAT8_PRIVATE(&pyy[j][k]);
                c8xy += LOAD_FLOAT8_PRIVATE(&pxy[j][k]);
                c8y += LOAD_FLOAT8_PRIVATE(&wy[j][k]);
            }
            sxx += c8xx;
            syy += c8yy;
            sxy += c8xy;
            sy += c8y;
        }
        int chg[FALLBACK_TILE];
        for (int o = 0; o < FALLBACK_TILE; ++o)
            chg[o] = -px_differs(src, mid, IDX(min(x0 + o, w - 1), y, w));
        const int8 base = fp_bucket(sxx, syy, sxy, sy, LOAD_INT8_PRIVATE(chg), 0) * REFINE_WEIGHTS;
        const float8 mr = LOAD_FLOAT8_PRIVATE(&wr[r + FP_R][FP_R]), mg = LOAD_FLOAT8_PRIVATE(&wg[r + FP_R][FP_R]),
                     mb = LOAD_FLOAT8_PRIVATE(&wb[r + FP_R][FP_R]);
        float8 qr = mr, qg = mg, qb = mb;
        fp_window_sum(wr, wg, wb, r, table, base, mr, mg, mb, &qr, &qg, &qb);
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k) {
                const float8 wt = GATHER8(table + FP_N * FP_N + j * 3 + k, base);
                qr += (LOAD_FLOAT8_PRIVATE(&ir[r + j][k]) - mr) * wt;
                qg += (LOAD_FLOAT8_PRIVATE(&ig[r + j][k]) - mg) * wt;
                qb += (LOAD_FLOAT8_PRIVATE(&ib[r + j][k]) - mb) * wt;
            }
        float outr[FALLBACK_TILE], outg[FALLBACK_TILE], outb[FALLBACK_TILE];
        fp_clamp_row(wr, wg, wb, r, mr, mg, mb, qr, qg, qb, outr, outg, outb);  // mid's 3x3 range
        fp_store_row(dst, luts, x0, x1, y, w, take[r], keep, outr, outg, outb);
    }
}

// After fxaa_fallback: every pixel of a render region with strong local contrast takes the refine table, but for
// those the chain changed on a straight edge run and quiet ones (noise.cl); `mid` is a copy of fxaa_fallback's
// output. One work item per SEGMENT / FALLBACK_TILE tiles of a tile row, as fxaa_fallback.
__kernel void refine_fallback(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                              __global const uchar *edges, __global const ushort2 *hdist,
                              __global const ushort2 *vdist, __global const uchar *render,
                              __global const float *table, __global const int *noise,
                              __global const uchar *quiet_px, __global const PIXEL_T *mid, __global PIXEL_T *dst,
                              const int w, const int h, const int tiles_x, const int tiles_y)
{
    const int t0 = get_global_id(0) * (SEGMENT / FALLBACK_TILE), ty = get_global_id(1);
    if (t0 >= tiles_x || ty >= tiles_y) return;
    const int t1 = min(t0 + SEGMENT / FALLBACK_TILE, tiles_x), level = noise[0];
    for (int tx = t0; tx < t1; ++tx) {
#if FALLBACK_MIN_CHANGED > 0
        if (!(RENDER_REGIONS && render[ty * tiles_x + tx])) continue;
#endif
        const int x0 = tx * FALLBACK_TILE, y0 = ty * FALLBACK_TILE;
        const int x1 = min(x0 + FALLBACK_TILE, w), y1 = min(y0 + FALLBACK_TILE, h);
        uint take[FALLBACK_TILE], any = 0;
        for (int y = y0; y < y1; ++y) {
            take[y - y0] = 0;
            for (int x = x0; x < x1; ++x)
                if (!(ON_REGION_RUN(edges, hdist, vdist, x, y, w) && px_differs(src, mid, IDX(x, y, w))) &&
                    !noise_quiet(quiet_px, IDX(x, y, w), level))
                    take[y - y0] |= 1u << (x - x0);
            any |= take[y - y0];
        }
        if (any) refine_tile(src, luts, lin, table, mid, dst, x0, x1, y0, y1, w, h, take);
    }
}
#endif

// Tile (tx, ty): nothing to do unless the 3x3 tiles around it show 1-spp aliasing (busy, or evidence and the
// pixel's own window busy) or it lies in a render region; then each eligible pixel that FXAA would change moves
// towards its colour (towards_fxaa), and in a render region every pixel then takes the footprint table, but for
// those the chain changed on a straight edge run. A quiet pixel (noise.cl: its window spans no more than the frame's
// grain) is no render-region pixel.
inline void fallback_tile(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                          __global const uchar *edges,
                          __global const ushort2 *hdist, __global const ushort2 *vdist, __global const uchar *counts,
                          __global const uchar *render, __global const float *table,
                          __global const uchar *quiet_px, __global PIXEL_T *dst, int w, int h, int tiles_x,
                          int tiles_y, int tx, int ty, int noise, int grain_free)
{
#if FALLBACK_MIN_CHANGED > 0
    const int rendered = RENDER_REGIONS && render[ty * tiles_x + tx];
    int changed = 0, bordering = 0, busy_changed = 0;
    for (int j = max(ty - 1, 0); j <= min(ty + 1, tiles_y - 1); ++j)
        for (int k = max(tx - 1, 0); k <= min(tx + 1, tiles_x - 1); ++k) {
            __global const uchar *c = counts + COUNTS * (j * tiles_x + k);
            changed += c[0];
            bordering += c[1];
            busy_changed += tile_busy(c, grain_free);
        }
    const int rich = busy_changed >= FALLBACK_RICH_MIN && busy_changed * FALLBACK_RICH_DIV >= bordering;
    const int evidence = changed >= FALLBACK_MIN_CHANGED;
    if (!rendered && !rich && !evidence) return;
#else
    const int rendered = 1, rich = 0, evidence = 0;
#endif
    const int x0 = tx * FALLBACK_TILE, y0 = ty * FALLBACK_TILE;
    const int x1 = min(x0 + FALLBACK_TILE, w), y1 = min(y0 + FALLBACK_TILE, h);
    uint take[FALLBACK_TILE], any = 0;  // the footprint table's pixels, a bit per column, per row
    for (int y = y0; y < y1; ++y) {
        const int quiet = x1 - x0 == 8 && group_is_quiet(edges, x0, y, w);
        take[y - y0] = 0;
        if (quiet && !(rendered && FOOTPRINT_TABLE)) continue;
        for (int x = x0; x < x1; ++x) {
            const int region = rendered && !noise_quiet(quiet_px, IDX(x, y, w), noise);
            if (!quiet) {
                const int changed_px = px_differs(src, dst, IDX(x, y, w));
                int eligible = borders_edge(edges, x, y, w);
                // outside busy regions only pixels MLAA left, and only in busy windows (flat-colour art stops here)
                eligible = eligible && (region || rich || (evidence && !changed_px && WINDOW_BUSY(src, x, y, w, h)));
                eligible = eligible && !fxaa_keeps(src, x, y, w, h);
                eligible = eligible && !(region ? ON_REGION_RUN(edges, hdist, vdist, x, y, w)
                                                : ON_LONG_RUN(edges, hdist, vdist, x, y, w));
                if (eligible)
                    towards_fxaa(src, luts, dst, changed_px ? dst : src,
                                 changed_px ? FALLBACK_MIX : FALLBACK_WEIGHT, x, y, w, h);
            }
#if FOOTPRINT_TABLE
            // the table too leaves a colour the chain gave a pixel on a straight edge run (REGION_KEEP_RUN)
            if (region && !(ON_REGION_RUN(edges, hdist, vdist, x, y, w) && px_differs(src, dst, IDX(x, y, w))))
                take[y - y0] |= 1u << (x - x0);
#endif
        }
        any |= take[y - y0];
    }
#if FOOTPRINT_TABLE
    if (any) footprint_tile(src, luts, lin, table, dst, x0, x1, y0, y1, w, h, take);
#endif
}

// One work item per SEGMENT / FALLBACK_TILE tiles of a tile row (few work items: PoCL's cost per work group
// is felt at one item per tile).
__kernel void fxaa_fallback(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                            __global const uchar *edges, __global const ushort2 *hdist,
                            __global const ushort2 *vdist, __global const uchar *counts,
                            __global const uchar *render, __global const float *table,
                            __global const int *noise, __global const uchar *quiet_px, __global PIXEL_T *dst,
                            const int w, const int h, const int tiles_x, const int tiles_y)
{
    const int t0 = get_global_id(0) * (SEGMENT / FALLBACK_TILE), ty = get_global_id(1);
    if (t0 >= tiles_x || ty >= tiles_y) return;
    const int t1 = min(t0 + SEGMENT / FALLBACK_TILE, tiles_x), level = noise[0], grain_free = noise[1];
    for (int tx = t0; tx < t1; ++tx)
        fallback_tile(src, luts, lin, edges, hdist, vdist, counts, render, table, quiet_px, dst, w, h, tiles_x,
                      tiles_y, tx, ty, level, grain_free);
}
