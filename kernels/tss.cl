// tss.cl -- temporal supersampling resolve (issue 16; seed 002's T2x generalised to K frames).
// Reference: mlaa_stream.temporal.tss.tss_reference (the plain statement; the module's header says why).
//
// Per output pixel x = (gx, gy) (pixel centres at integer coordinates):
//   box  = the current input's 3x3 per-channel min/max (edges replicated) in linear light, widened by EPS
//   for each ring frame j (the current frame included, identity map), oldest first:
//     p    = x + (dx_j, dy_j)                      translation map (info kind 0)
//          = x + field_j(x), bilinear at 1/FS       dense map (kind 1; NaN = no trusted motion)
//     skip where valid_j (1/FS, nearest) is 0, p is NaN, or s = floor(p + 0.5) is outside the frame
//     v    = ring frame j's sample at s (linear light); skip if outside the box (another surface)
//     o    = s - p in [-0.5, 0.5)^2, cell = floor((o + 0.5) GRID) per axis: the sample's stratum of x's
//            footprint; per cell: sum and count
//   n    = filled cells, m = mean over filled cells of the cell means
//   out  = S + min(1, n / FULL_CELLS) (m - S) with S the spatial output (linear), encoded by table, where n >= MIN_CELLS;
//          elsewhere the spatial pixel is copied bit for bit. cells[x] = n (debug view, stats).
// A gather: one tap per ring frame and pixel, no atomics.
//
// Buffers: ring = RING_SLOTS frames of the input's type and layout, one after another; info = 4 ints per
// ring entry (slot, kind, field/valid slot, has valid); shift = 2 floats per entry; fields = (slot, fh, fw, 2)
// floats; valids = (slot, fh, fw) uchar. Defines: GRID, MIN_CELLS, FULL_CELLS, EPS (float literal), LINEAR_INPUT.
#pragma OPENCL FP_CONTRACT OFF

#define CELLS (GRID * GRID)

inline float4 tss_linear(__global const float *luts, __global const float *dec,
                         __global const PIXEL_T *img, int i)
{
#if !LINEAR_INPUT && !defined(PIXEL_IS_FLOAT)
    // integer samples: one load of the decode table (temporal.decode_table: the table read's value)
#if CHANNELS == 1
    float v = dec[img[i]];
    return (float4)(v, v, v, 1.0f);
#else
    __global const PIXEL_T *p = img + (size_t)i * CHANNELS;
#if ORDER_BGR
    return (float4)(dec[p[2]], dec[p[1]], dec[p[0]], 1.0f);
#else
    return (float4)(dec[p[0]], dec[p[1]], dec[p[2]], 1.0f);
#endif
#endif
#else
    float4 c = load_px(img, i);
#if LINEAR_INPUT
    return c;
#else
    return (float4)(lut_read(luts, c.x), lut_read(luts, c.y), lut_read(luts, c.z), c.w);
#endif
#endif
}

// min/max by plain comparisons: PoCL calls fmin/fmax out of line (common.cl's note on built-ins)
inline void box_add(float4 *lo, float4 *hi, float4 c)
{
    lo->x = c.x < lo->x ? c.x : lo->x; hi->x = c.x > hi->x ? c.x : hi->x;
    lo->y = c.y < lo->y ? c.y : lo->y; hi->y = c.y > hi->y ? c.y : hi->y;
    lo->z = c.z < lo->z ? c.z : lo->z; hi->z = c.z > hi->z ? c.z : hi->z;
}

// The current input's 3x3 per-channel min/max (edges replicated) in linear light, widened by EPS.
// Integer frames: min/max of the stored codes, decoded once (the decode table is non-decreasing, so
// this is the min/max of the decoded samples, bit for bit): 6 table reads instead of 27.
inline void colour_box(__global const PIXEL_T *cur, __global const float *luts, __global const float *dec,
                       int gx, int gy, int width, int height, float4 *lo_out, float4 *hi_out)
{
    const int x0 = gx > 0 ? gx - 1 : 0, x2 = gx < width - 1 ? gx + 1 : width - 1;
    const int y0 = gy > 0 ? gy - 1 : 0, y2 = gy < height - 1 ? gy + 1 : height - 1;
    const int xs[3] = {x0, gx, x2}, ys[3] = {y0, gy, y2};
#if !LINEAR_INPUT && !defined(PIXEL_IS_FLOAT)
    const int nch = CHANNELS == 1 ? 1 : 3;
    uint mn[3] = {0xffffffffu, 0xffffffffu, 0xffffffffu}, mx[3] = {0u, 0u, 0u};
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
            __global const PIXEL_T *p = cur + (size_t)(ys[a] * width + xs[b]) * CHANNELS;
            for (int c = 0; c < nch; ++c) {
                uint v = p[c];
                mn[c] = v < mn[c] ? v : mn[c];
                mx[c] = v > mx[c] ? v : mx[c];
            }
        }
#if CHANNELS == 1
    float4 lo = (float4)(dec[mn[0]], dec[mn[0]], dec[mn[0]], 0.0f), hi = (float4)(dec[mx[0]], dec[mx[0]], dec[mx[0]], 0.0f);
#elif ORDER_BGR
    float4 lo = (float4)(dec[mn[2]], dec[mn[1]], dec[mn[0]], 0.0f), hi = (float4)(dec[mx[2]], dec[mx[1]], dec[mx[0]], 0.0f);
#else
    float4 lo = (float4)(dec[mn[0]], dec[mn[1]], dec[mn[2]], 0.0f), hi = (float4)(dec[mx[0]], dec[mx[1]], dec[mx[2]], 0.0f);
#endif
#else
    float4 lo = (float4)(INFINITY), hi = (float4)(-INFINITY);
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
            box_add(&lo, &hi, tss_linear(luts, dec, cur, ys[a] * width + xs[b]));
#endif
    *lo_out = lo - EPS;
    *hi_out = hi + EPS;
}

// The end of every resolve: pixel i's filled-cell count n and the sum of its cells' means (linear light)
// give out = S + min(1, n / FULL_CELLS) (mean - S) over the spatial output S; with fewer than MIN_CELLS
// cells the spatial pixel is copied bit for bit. Alpha stays the spatial pixel's.
inline void tss_store(__global const float *luts, __global const float *dec, __global const PIXEL_T *spatial,
                      __global PIXEL_T *dst, __global uchar *cells, int i, int n, float mr, float mg, float mb)
{
    cells[i] = (uchar)n;
#if CHANNELS == 1
    const int nc = 1;
#else
    const int nc = CHANNELS;
#endif
    if (n < MIN_CELLS) {
        for (int c = 0; c < nc; ++c)
            dst[(size_t)i * nc + c] = spatial[(size_t)i * nc + c];
        return;
    }
    const float fn = (float)n;
    const float4 s = tss_linear(luts, dec, spatial, i);
    const float a = fn < (float)FULL_CELLS ? fn / (float)FULL_CELLS : 1.0f;
    float4 out = s + ((float4)(mr / fn, mg / fn, mb / fn, s.w) - s) * a;
#if !LINEAR_INPUT
    __global const float *enc = luts + 2 * (LUT_SIZE + 1);
    out = (float4)(lut_read(enc, out.x), lut_read(enc, out.y), lut_read(enc, out.z), out.w);
#endif
#if CHANNELS == 4
    out.w = load_px(spatial, i).w;   // store_px re-encodes it exactly
#endif
    store_px(dst, i, out);
}

__kernel void tss_resolve(__global const PIXEL_T *ring, __global const PIXEL_T *spatial,
                          __global PIXEL_T *dst, __global uchar *cells,
                          __global const int *info, __global const float *shift,
                          __global const float *fields, __global const uchar *valids,
                          __global const float *luts, __global const float *dec,
                          const int width, const int height, const int fw, const int fh, const int fs,
                          const int n_ring, const int cur_slot)
{
    const int gx = get_global_id(0), gy = get_global_id(1);
    if (gx >= width || gy >= height)
        return;
    const int i = gy * width + gx;
    const size_t frame = (size_t)width * height;
    __global const PIXEL_T *cur = ring + (size_t)cur_slot * frame * CHANNELS;

    // the current input's 3x3 colour box
    float4 lo, hi;
    colour_box(cur, luts, dec, gx, gy, width, height, &lo, &hi);

    float sum[CELLS * 3];
    int cnt[CELLS];
    for (int k = 0; k < CELLS; ++k) {
        cnt[k] = 0;
        sum[3 * k] = sum[3 * k + 1] = sum[3 * k + 2] = 0.0f;
    }
    const float xf = (float)gx, yf = (float)gy;
    const int vx = gx / fs < fw - 1 ? gx / fs : fw - 1, vy = gy / fs < fh - 1 ? gy / fs : fh - 1;
    for (int j = 0; j < n_ring; ++j) {
        const int slot = info[4 * j], kind = info[4 * j + 1], fslot = info[4 * j + 2], has_valid = info[4 * j + 3];
        if (has_valid && valids[(size_t)fslot * fw * fh + vy * fw + vx] == 0)
            continue;
        float px, py;
        if (kind == 0) {
            px = xf + shift[2 * j];
            py = yf + shift[2 * j + 1];
        } else {
            // bilinear read of the field at 1/fs (mlaa_stream.temporal.tss.sample_field)
            float fx = (xf + 0.5f) / (float)fs - 0.5f, fy = (yf + 0.5f) / (float)fs - 0.5f;
            fx = fx > 0.0f ? (fx < (float)(fw - 1) ? fx : (float)(fw - 1)) : 0.0f;
            fy = fy > 0.0f ? (fy < (float)(fh - 1) ? fy : (float)(fh - 1)) : 0.0f;
            int x0 = (int)fx, y0 = (int)fy;
            int x1 = x0 + 1 < fw - 1 ? x0 + 1 : fw - 1, y1 = y0 + 1 < fh - 1 ? y0 + 1 : fh - 1;
            float ax = fx - (float)x0, ay = fy - (float)y0;
            __global const float *f = fields + (size_t)fslot * fw * fh * 2;
            float2 f00 = vload2(y0 * fw + x0, f), f01 = vload2(y0 * fw + x1, f);
            float2 f10 = vload2(y1 * fw + x0, f), f11 = vload2(y1 * fw + x1, f);
            float2 top = f00 + (f01 - f00) * ax, bot = f10 + (f11 - f10) * ax;
            float2 o = top + (bot - top) * ay;
            px = xf + o.x;
            py = yf + o.y;
        }
        if (!(px == px) || !(py == py))
            continue;   // NaN: no trusted motion (forward-backward inconsistency)
        const float sx = floor(px + 0.5f), sy = floor(py + 0.5f);
        if (sx < 0.0f || sx > (float)(width - 1) || sy < 0.0f || sy > (float)(height - 1))
            continue;
        const float4 v = tss_linear(luts, dec, ring + (size_t)slot * frame * CHANNELS,
                                    (int)sy * width + (int)sx);
        if (v.x < lo.x || v.x > hi.x || v.y < lo.y || v.y > hi.y || v.z < lo.z || v.z > hi.z)
            continue;
        float cx = floor((sx - px + 0.5f) * (float)GRID), cy = floor((sy - py + 0.5f) * (float)GRID);
        int ix = cx < 0.0f ? 0 : (cx > (float)(GRID - 1) ? GRID - 1 : (int)cx);
        int iy = cy < 0.0f ? 0 : (cy > (float)(GRID - 1) ? GRID - 1 : (int)cy);
        int k = iy * GRID + ix;
        sum[3 * k] += v.x;
        sum[3 * k + 1] += v.y;
        sum[3 * k + 2] += v.z;
        cnt[k] += 1;
    }
    int n = 0;
    float mr = 0.0f, mg = 0.0f, mb = 0.0f;
    for (int k = 0; k < CELLS; ++k) {
        if (cnt[k] > 0) {
            float c = (float)cnt[k];
            mr += sum[3 * k] / c;
            mg += sum[3 * k + 1] / c;
            mb += sum[3 * k + 2] / c;
            ++n;
        }
    }
    tss_store(luts, dec, spatial, dst, cells, i, n, mr, mg, mb);
}

// The same resolve when every ring frame's map is one translation (static and global models: the
// default path). The tap pattern is the same for every pixel, so the host gives each ring frame its
// whole-pixel offset (sx - x, sy - y) and its footprint cell, and orders the frames by cell (ring order
// inside a cell): the kernel sums one cell's samples in registers and adds its mean when the cell
// changes -- no per-pixel cell arrays, the same sums in the same order as tss_reference.
// taps: 4 ints per ring frame (slot, dx, dy, cell), frames with a valid mask: vslot >= 0 in vslots.
__kernel void tss_resolve_shift(__global const PIXEL_T *ring, __global const PIXEL_T *spatial,
                                __global PIXEL_T *dst, __global uchar *cells,
                                __global const int *taps, __global const int *vslots,
                                __global const uchar *valids,
                                __global const float *luts, __global const float *dec,
                                const int width, const int height, const int fw, const int fh, const int fs,
                                const int n_ring, const int cur_slot)
{
    const int gx = get_global_id(0), gy = get_global_id(1);
    if (gx >= width || gy >= height)
        return;
    const int i = gy * width + gx;
    const size_t frame = (size_t)width * height;
    __global const PIXEL_T *cur = ring + (size_t)cur_slot * frame * CHANNELS;
    float4 lo, hi;
    colour_box(cur, luts, dec, gx, gy, width, height, &lo, &hi);
    const int vx = gx / fs < fw - 1 ? gx / fs : fw - 1, vy = gy / fs < fh - 1 ? gy / fs : fh - 1;
    int n = 0, cell = -1, cnt = 0;
    float mr = 0.0f, mg = 0.0f, mb = 0.0f, sr = 0.0f, sg = 0.0f, sb = 0.0f;
    for (int j = 0; j < n_ring; ++j) {
        const int slot = taps[4 * j], k = taps[4 * j + 3];
        if (k != cell) {           // a new cell: close the previous one
            if (cnt > 0) {
                float c = (float)cnt;
                mr += sr / c; mg += sg / c; mb += sb / c;
                ++n;
            }
            cell = k; cnt = 0; sr = sg = sb = 0.0f;
        }
        const int vs = vslots[j];
        if (vs >= 0 && valids[(size_t)vs * fw * fh + vy * fw + vx] == 0)
            continue;
        const int sx = gx + taps[4 * j + 1], sy = gy + taps[4 * j + 2];
        if (sx < 0 || sx > width - 1 || sy < 0 || sy > height - 1)
            continue;
        const float4 v = tss_linear(luts, dec, ring + (size_t)slot * frame * CHANNELS, sy * width + sx);
        if (v.x < lo.x || v.x > hi.x || v.y < lo.y || v.y > hi.y || v.z < lo.z || v.z > hi.z)
            continue;
        sr += v.x; sg += v.y; sb += v.z;
        ++cnt;
    }
    if (cnt > 0) {
        float c = (float)cnt;
        mr += sr / c; mg += sg / c; mb += sb / c;
        ++n;
    }
    tss_store(luts, dec, spatial, dst, cells, i, n, mr, mg, mb);
}

// tss_resolve_shift over a segment of SEG pixels of one row per work item (the default path): for a
// fixed ring frame the taps of neighbouring pixels are neighbouring samples, so the inner loops over
// the segment stream through memory without branches (accept as a 0/1 factor) and the compiler can
// vectorise them; the sums are the same as tss_resolve_shift's, in the same order.
#ifndef SEG
#define SEG 32
#endif
__kernel void tss_resolve_shift_rows(__global const PIXEL_T *ring, __global const PIXEL_T *spatial,
                                     __global PIXEL_T *dst, __global uchar *cells,
                                     __global const int *taps, __global const int *vslots,
                                     __global const uchar *valids,
                                     __global const float *luts, __global const float *dec,
                                     const int width, const int height, const int fw, const int fh, const int fs,
                                     const int n_ring, const int cur_slot)
{
    const int x0 = get_global_id(0) * SEG, gy = get_global_id(1);
    if (x0 >= width || gy >= height)
        return;
    const int len = width - x0 < SEG ? width - x0 : SEG;
    const size_t frame = (size_t)width * height;
    __global const PIXEL_T *cur = ring + (size_t)cur_slot * frame * CHANNELS;
    float lo[3][SEG], hi[3][SEG], m[3][SEG], s[3][SEG];
    int n[SEG], cnt[SEG];
    for (int p = 0; p < len; ++p) {
        float4 l, h;
        colour_box(cur, luts, dec, x0 + p, gy, width, height, &l, &h);
        lo[0][p] = l.x; lo[1][p] = l.y; lo[2][p] = l.z;
        hi[0][p] = h.x; hi[1][p] = h.y; hi[2][p] = h.z;
        m[0][p] = m[1][p] = m[2][p] = 0.0f;
        s[0][p] = s[1][p] = s[2][p] = 0.0f;
        n[p] = 0;
        cnt[p] = 0;
    }
    const int vy = gy / fs < fh - 1 ? gy / fs : fh - 1;
    int cell = -1;
    for (int j = 0; j <= n_ring; ++j) {
        const int k = j < n_ring ? taps[4 * j + 3] : -2;
        if (k != cell) {          // close the previous cell (and at the end)
            if (cell >= 0)
                for (int p = 0; p < len; ++p) {
                    if (cnt[p] > 0) {
                        float c = (float)cnt[p];
                        m[0][p] += s[0][p] / c; m[1][p] += s[1][p] / c; m[2][p] += s[2][p] / c;
                        ++n[p];
                    }
                    cnt[p] = 0;
                    s[0][p] = s[1][p] = s[2][p] = 0.0f;
                }
            cell = k;
        }
        if (j == n_ring)
            break;
        const int slot = taps[4 * j], dx = taps[4 * j + 1], sy = gy + taps[4 * j + 2], vs = vslots[j];
        if (sy < 0 || sy > height - 1)
            continue;
        __global const PIXEL_T *row = ring + ((size_t)slot * frame + (size_t)sy * width) * CHANNELS;
        __global const uchar *vrow = vs >= 0 ? valids + (size_t)vs * fw * fh + (size_t)vy * fw : 0;
        // the segment's taps that stay inside the row, branch-free (accept as 0/1)
        const int pa = -(x0 + dx) > 0 ? -(x0 + dx) : 0;
        const int pb = width - 1 - x0 - dx + 1 < len ? width - 1 - x0 - dx + 1 : len;
        for (int p = pa; p < pb; ++p) {
            const int gx = x0 + p;
            const float4 v = tss_linear(luts, dec, row, gx + dx);
            int ok = (v.x >= lo[0][p]) & (v.x <= hi[0][p]) & (v.y >= lo[1][p]) & (v.y <= hi[1][p]) &
                     (v.z >= lo[2][p]) & (v.z <= hi[2][p]);
            if (vrow)
                ok &= vrow[gx / fs < fw - 1 ? gx / fs : fw - 1] != 0;
            const float f = ok ? 1.0f : 0.0f;
            s[0][p] += f * v.x; s[1][p] += f * v.y; s[2][p] += f * v.z;
            cnt[p] += ok;
        }
    }
    for (int p = 0; p < len; ++p)
        tss_store(luts, dec, spatial, dst, cells, gy * width + x0 + p, n[p], m[0][p], m[1][p], m[2][p]);
}
