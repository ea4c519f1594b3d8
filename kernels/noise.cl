// noise.cl -- grain over a render (film grain, sensor or path-tracing noise added after the point samples) is no
// aliasing: the render regions' FXAA and footprint / refine tables (fallback.cl) would smooth it as if each grain
// were a sub-pixel feature, which the truth keeps (spatial/noise.py is the reference; docs/spatial_tuning.md,
// "Grain over a render").
//
// The frame's noise level is the median |Laplacian| of its luma (Immerkaer's 3x3 operator [1 -2 1; -2 4 -2;
// 1 -2 1], whose response to white noise of deviation s has deviation 6 s; edges are a minority of the pixels, so
// the median follows the grain, and a clean render's is 0). A render-region pixel whose 3x3 window of luma spans
// under NOISE_SPAN_NUM / NOISE_SPAN_DEN times that level is quiet: the regions' passes leave it as the MLAA passes
// left it. Luma is Rec. 709 in 256ths of 8-bit levels (common.cl levels8): exact on every sample type.
#pragma OPENCL FP_CONTRACT OFF

#ifndef NOISE_SPAN_NUM
#define NOISE_SPAN_NUM 3
#endif
#ifndef NOISE_SPAN_DEN
#define NOISE_SPAN_DEN 2
#endif
#define NOISE_BINS 64      // spatial/noise.py NOISE_BINS: |Laplacian| in whole levels, the last bin for 63 and more
#define NOISE_ROW_STEP 4   // two sampled rows per band of FALLBACK_TILE rows, every other column: ~1/8 of the pixels

inline int luma256(__global const PIXEL_T *src, int i)
{
#if CHANNELS == 1
    return 256 * level8(src[i]);
#else
    __global const PIXEL_T *p = src + (size_t)i * CHANNELS;
    return 54 * level8(p[ORDER_BGR ? 2 : 0]) + 183 * level8(p[1]) + 19 * level8(p[ORDER_BGR ? 0 : 2]);
#endif
}

// Column x's second difference down rows y - 1, y, y + 1 (the operator's separable half).
inline int column_d2(__global const PIXEL_T *src, int x, int y, int w)
{
    return luma256(src, IDX(x, y - 1, w)) - 2 * luma256(src, IDX(x, y, w)) + luma256(src, IDX(x, y + 1, w));
}

// hist[band * NOISE_BINS + b] = the band's sampled pixels whose |Laplacian| of luma is b whole levels (the last bin:
// NOISE_BINS - 1 or more): rows 1 and 1 + NOISE_ROW_STEP of the band of FALLBACK_TILE rows, odd columns, none on the
// frame's border. One work item per band.
__kernel void noise_census(__global const PIXEL_T *src, __global int *hist, const int w, const int h)
{
    const int band = get_global_id(0);
    if (band * FALLBACK_TILE >= h) return;
    int bins[NOISE_BINS];
    for (int b = 0; b < NOISE_BINS; ++b) bins[b] = 0;
    for (int r = 1; r < FALLBACK_TILE; r += NOISE_ROW_STEP) {
        const int y = band * FALLBACK_TILE + r;
        if (y >= h - 1) break;
        int left = column_d2(src, 0, y, w);  // columns x - 1, x, x + 1; x steps by two
        for (int x = 1; x < w - 1; x += 2) {
            const int mid = column_d2(src, x, y, w), right = column_d2(src, x + 1, y, w);
            const int lap = abs(left - 2 * mid + right) >> 8;  // whole levels: luma is in 256ths
            ++bins[min(lap, NOISE_BINS - 1)];
            left = right;
        }
    }
    for (int b = 0; b < NOISE_BINS; ++b) hist[band * NOISE_BINS + b] = bins[b];
}

// level[0] = the lower median bin of the bands' histograms summed (0 where nothing was sampled). One work item.
__kernel void noise_level(__global const int *hist, __global int *level, const int bands)
{
    if (get_global_id(0) != 0) return;
    int total[NOISE_BINS], n = 0;
    for (int b = 0; b < NOISE_BINS; ++b) total[b] = 0;
    for (int band = 0; band < bands; ++band)
        for (int b = 0; b < NOISE_BINS; ++b) total[b] += hist[band * NOISE_BINS + b];
    for (int b = 0; b < NOISE_BINS; ++b) n += total[b];
    int cum = 0, m = 0;
    for (int b = 0; b < NOISE_BINS; ++b) {
        cum += total[b];
        if (2 * cum >= n) {
            m = b;
            break;
        }
    }
    level[0] = n ? m : 0;
}

// A 3x3 window whose luma (in 256ths of levels) spans `span` lies within the grain of `level` whole levels.
#define SPAN_QUIET(span, level) ((span) * NOISE_SPAN_DEN < NOISE_SPAN_NUM * 256 * (level))

// quiet[i] = 1 where pixel i's 3x3 window of luma (clamped to the frame) spans under NOISE_SPAN_NUM / NOISE_SPAN_DEN
// times the frame's noise level (in whole levels), else 0; nothing is written where the level is 0 (no pixel is
// quiet: readers test the level first, noise_quiet), nor in a row segment whose tiles hold no render region (only
// region pixels read the flags; a noisy photograph has none). One work item per SEGMENT pixels of a row; the
// window's columns slide along it (three luma reads per pixel).
__kernel void noise_mask(__global const PIXEL_T *src, __global const int *noise, __global const uchar *render,
                         __global uchar *quiet, const int w, const int h, const int tiles_x)
{
    const int x0 = get_global_id(0) * SEGMENT, y = get_global_id(1), level = noise[0];
    if (level <= 0 || x0 >= w || y >= h) return;
#if FALLBACK_MIN_CHANGED > 0   // render regions found per tile (else every tile is one: "everywhere")
    int regions = 0;
    for (int t = x0 / FALLBACK_TILE; t <= (min(x0 + SEGMENT, w) - 1) / FALLBACK_TILE; ++t)
        regions |= render[(y / FALLBACK_TILE) * tiles_x + t];
    if (!regions) return;
#endif
    const int x1 = min(x0 + SEGMENT, w), above = max(y - 1, 0) * w, here = y * w, below = min(y + 1, h - 1) * w;
    int lo[3], hi[3];  // columns x - 1, x, x + 1: their min and max over the three rows
    for (int k = 0; k < 3; ++k) {
        const int x = clamp_to(x0 - 1 + k, w - 1);
        const int a = luma256(src, above + x), b = luma256(src, here + x), c = luma256(src, below + x);
        lo[k] = min(a, min(b, c));
        hi[k] = max(a, max(b, c));
    }
    for (int x = x0; x < x1; ++x) {
        const int span = max(hi[0], max(hi[1], hi[2])) - min(lo[0], min(lo[1], lo[2]));
        quiet[here + x] = (uchar)SPAN_QUIET(span, level);
        const int n = clamp_to(x + 2, w - 1);
        const int a = luma256(src, above + n), b = luma256(src, here + n), c = luma256(src, below + n);
        lo[0] = lo[1];
        hi[0] = hi[1];
        lo[1] = lo[2];
        hi[1] = hi[2];
        lo[2] = min(a, min(b, c));
        hi[2] = max(a, max(b, c));
    }
}

// Whether pixel i is quiet (noise_mask's flag, read only where the frame's level is over 0).
#define noise_quiet(quiet, i, level) ((level) > 0 && (quiet)[i])

// Whether pixel (x, y) is quiet, computed here (noise_mask's rule for one pixel; 0 where the level is 0): for the
// few pixels read before the mask is made (count_changed's busy pixels).
inline int pixel_quiet(__global const PIXEL_T *src, int x, int y, int w, int h, int level)
{
    if (level <= 0) return 0;
    int lo = 1 << 30, hi = -1;
    for (int dy = -1; dy <= 1; ++dy) {
        const int row = clamp_to(y + dy, h - 1) * w;
        for (int dx = -1; dx <= 1; ++dx) {
            const int l = luma256(src, row + clamp_to(x + dx, w - 1));
            lo = min(lo, l);
            hi = max(hi, l);
        }
    }
    return SPAN_QUIET(hi - lo, level);
}
