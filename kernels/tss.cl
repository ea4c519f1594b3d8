// tss.cl -- temporal supersampling resolve (issue 16; seed 002's T2x generalised to K frames).
// Reference: mlaa_stream.temporal.resolve.tss_reference (the plain statement; the module's header says why).
//
// The ring: K input frames as linear light in 16-bit fixed point, L = floor(clamp(lin, 0, 1) 65535 + 0.5)
// (ltab: the stored code's L, one load; float frames and codes of a transfer: lin / TSS_RANGE, at most TSS_TOP,
// TSS_OVER over range), planar by row
// (row y of a slot: width Ls of R, then G, then B; grey frames one plane), written once per frame by
// tss_ingest. So the resolve reads contiguous 16-bit samples, compares and sums integers and decodes nothing
// per tap; the output is encoded from L by one load of etab (integer frames: 65536 entries; float frames read the tables).
//
// Per output pixel x = (gx, gy) (pixel centres at integer coordinates):
//   box  = the current frame's 3x3 per-plane min/max of L (edges replicated), widened by EPSQ; where
//          min == max in every plane (a flat neighbourhood: no aliasing to resolve, and on the bench no
//          flat pixel ever changed) n = 0 and the spatial pixel stands: the kernels skip the ring
//   for each ring frame j (the current frame included, identity map):
//     p    = x + (dx_j, dy_j)                      translation map (tss_resolve_shift; info kind 0)
//          = x + field_j(x), bilinear at 1/FS       dense map (tss_resolve, kind 1; NaN = no trusted motion)
//     skip where valid_j (1/FS, nearest) is 0, p is NaN, or s = floor(p + 0.5) is outside the frame
//     v    = ring frame j's L at s; skip if outside the box (another surface)
//     o    = s - p in [-0.5, 0.5)^2, cell = floor((o + 0.5) GRID) per axis: the sample's stratum of x's
//            footprint; per cell: integer sum and count
//   n    = filled cells, m = sum over filled cells, ascending, of (float)sum * (1 / count)
//   out  = S + (m / n - S) min(1, n / FULL_CELLS) with S the spatial output's L, rounded to L and encoded
//          (etab), where n >= MIN_CELLS; elsewhere the spatial pixel is copied bit for bit, and so it is
//          where every channel of out is within DEAD (one 8-bit level: DEAD_CODES codes of an integer
//          frame, 1/255 of a float one) of the spatial pixel's (docs/temporal.md: a dead zone against
//          damage). cells[x] = n.
// A gather: one tap per ring frame and pixel, no atomics.
//
// Buffers: ring = RING_SLOTS slots of height * TSS_PLANES * width ushorts; info = 4 ints per ring entry (slot, kind,
// field/valid slot, has valid); shift = 2 floats per entry; fields = (slot, fh, fw, 2) floats; valids =
// (slot, fh, fw) uchar. Defines: GRID, MIN_CELLS, FULL_CELLS, EPSQ (int), LINEAR_INPUT, TSS_RANGE (int).
#pragma OPENCL FP_CONTRACT OFF

#define CELLS (GRID * GRID)
#if CHANNELS == 1
#define TSS_PLANES 1
#else
#define TSS_PLANES 3
#endif
#define TSS_ONE 65535.0f
// Float frames can hold values above 1 (HDR renders, linear EXR). The ring holds [0, TSS_RANGE] (linear
// float frames: LINEAR_RANGE of mlaa_stream.temporal.resolve, else 1); a sample above it is stored as TSS_OVER and
// is never averaged: in-range samples top out at TSS_TOP, the colour box is capped there, and a pixel whose
// 3x3 box or spatial output is over range keeps the spatial pixel. Integer codes of an HDR transfer
// (ENCODE_WARP, device/transfer.py: light up to 49) are held the same way: their ltab maps a code to its light over
// [0, LINEAR_RANGE], TSS_OVER above it, and etab codes the light back (tss.py level_table, encode_table). Other
// integer frames have no over-range code (TSS_TOP = TSS_OVER: the cap changes nothing).
#define TSS_OVER 65535
#if defined(PIXEL_IS_FLOAT) || ENCODE_WARP
#define TSS_TOP 65534
#else
#define TSS_TOP 65535
#endif

// PoCL calls vload16 / convert_* out of line (common.cl's note); a load through an aligned vector type
// and clang's vector conversion are inline, with the same results.
#ifdef POCL_DEVICE_ADDRESS_BITS
typedef ushort16 tss_ushort16_a2 __attribute__((aligned(2)));
typedef uchar16 tss_uchar16_a1 __attribute__((aligned(1)));
#define TSS_LOAD16(p) (*(__global const tss_ushort16_a2 *)(p))
#define TSS_LOADU16(p) (*(__global const tss_uchar16_a1 *)(p))
#define TSS_INT16(v) __builtin_convertvector((v), int16)
#define TSS_FLOAT16(v) __builtin_convertvector((v), float16)
#else
#define TSS_LOAD16(p) vload16(0, p)
#define TSS_LOADU16(p) vload16(0, p)
#define TSS_INT16(v) convert_int16(v)
#define TSS_FLOAT16(v) convert_float16(v)
#endif

// The L of sample (plane c) of pixel i of a frame in its own type: ltab for integer frames, the tables
// (linear input: the value over TSS_RANGE) and the rounding of ring_of for float frames, TSS_OVER over range.
inline int tss_level(__global const float *luts, __global const ushort *ltab, __global const PIXEL_T *img,
                     int i, int c)
{
#if !LINEAR_INPUT && !defined(PIXEL_IS_FLOAT)
#if CHANNELS == 1
    return ltab[img[i]];
#elif ORDER_BGR
    return ltab[img[(size_t)i * CHANNELS + 2 - c]];
#else
    return ltab[img[(size_t)i * CHANNELS + c]];
#endif
#else
    const float4 raw = load_px(img, i);
    const float e = c == 0 ? raw.x : (c == 1 ? raw.y : raw.z);
    if (e > (float)TSS_RANGE)
        return TSS_OVER;   // over range (also +inf); NaN reads 0 below
#if LINEAR_INPUT
    const float x = TSS_RANGE == 1 ? e : e * (1.0f / (float)TSS_RANGE);
#else
    const float x = lut_read(luts, e);
#endif
    const float t = x * TSS_ONE + 0.5f;
    return (int)(x > 0.0f ? (t < (float)TSS_TOP ? t : (float)TSS_TOP) : 0.0f);
#endif
}

// The current frame into ring slot `slot`: one work item per 16 pixels of a row.
__kernel void tss_ingest(__global const PIXEL_T *src, __global ushort *ring, __global const float *luts,
                         __global const ushort *ltab, const int width, const int height, const int slot)
{
    const int x0 = get_global_id(0) * 16, gy = get_global_id(1);
    if (x0 >= width || gy >= height)
        return;
    const int len = width - x0 < 16 ? width - x0 : 16;
    __global ushort *r = ring + ((size_t)slot * height + gy) * TSS_PLANES * width + x0;
    for (int p = 0; p < len; ++p)
        for (int c = 0; c < TSS_PLANES; ++c)
            r[c * width + p] = (ushort)tss_level(luts, ltab, src, gy * width + x0 + p, c);
}

// The end of every resolve: pixel i's filled-cell count n and the sum m of its cells' means (L units)
// give out = S + (m / n - S) min(1, n / FULL_CELLS) over the spatial output's L, S, rounded to L and
// encoded; with fewer than MIN_CELLS cells, or an output within DEAD of the spatial pixel in every
// channel, the spatial pixel is copied bit for bit. Alpha stays the spatial pixel's.
inline void tss_store(__global const float *luts, __global const ushort *ltab, __global const PIXEL_T *etab,
                      __global const PIXEL_T *spatial, __global PIXEL_T *dst, __global uchar *cells,
                      int i, int n, float mr, float mg, float mb)
{
    cells[i] = (uchar)n;
#if CHANNELS == 1
    const int nc = 1;
#else
    const int nc = CHANNELS;
#endif
    __global PIXEL_T *d = dst + (size_t)i * nc;
    __global const PIXEL_T *sp = spatial + (size_t)i * nc;
    int sl[3];   // the spatial pixel's L per plane
    for (int c = 0; c < TSS_PLANES && n >= MIN_CELLS; ++c) {
        sl[c] = tss_level(luts, ltab, spatial, i, c);
        n = sl[c] > TSS_TOP ? 0 : n;    // an over-range spatial pixel (float frames) stands
    }
    if (n < MIN_CELLS) {
        for (int c = 0; c < nc; ++c)
            d[c] = sp[c];
        return;
    }
    const float fn = (float)n;
    const float a = fn < (float)FULL_CELLS ? fn / (float)FULL_CELLS : 1.0f;
    const float mm[3] = {mr, mg, mb};
    PIXEL_T ev[3];
    int dead = 1;
#if ENCODE_WARP
    // codes of a transfer: also dead where every plane's L is within one ring step of the spatial pixel's. The
    // ring's step (LINEAR_RANGE / 65535 of reference white, 0.05 cd/m2 for PQ) spans more than DEAD_CODES codes
    // below ~0.2 cd/m2: there the round trip through the ring alone would move a code by up to 2000
    int ldead = 1;
#endif
    for (int c = 0; c < TSS_PLANES; ++c) {
        const float s = (float)sl[c];
        float t = s + (mm[c] / fn - s) * a + 0.5f;
        const int q = (int)(t > 0.0f ? (t < TSS_ONE ? t : TSS_ONE) : 0.0f);
#if ENCODE_WARP
        ldead &= abs(q - sl[c]) <= 1;
#endif
#if !LINEAR_INPUT && !defined(PIXEL_IS_FLOAT)
        const PIXEL_T e = etab[q];
#elif LINEAR_INPUT
        const PIXEL_T e = to_pixel((float)q * ((float)TSS_RANGE / TSS_ONE));
#else
        const PIXEL_T e = to_pixel(lut_read(luts + 2 * (LUT_SIZE + 1), (float)q * (1.0f / TSS_ONE)));
#endif
#if CHANNELS == 1
        const PIXEL_T sv = sp[0];
#elif ORDER_BGR
        const PIXEL_T sv = sp[2 - c];
#else
        const PIXEL_T sv = sp[c];
#endif
#if LINEAR_INPUT
        {   // one level of the sRGB-encoded values, as for display-encoded frames; above 1 as if the brighter
            // of the two were shown at white
            __global const float *enc = luts + 2 * (LUT_SIZE + 1);
            const float a = (float)e * (1.0f / PIXEL_MAX), b = (float)sv * (1.0f / PIXEL_MAX);
            const float top = a > b ? a : b, k = top > 1.0f ? 1.0f / top : 1.0f;
            dead &= fabs(lut_read(enc, a * k) - lut_read(enc, b * k)) <= (1.0f / 255.0f);
        }
#elif defined(PIXEL_IS_FLOAT)
        dead &= fabs(e - sv) <= (1.0f / 255.0f);
#else
        dead &= abs((int)e - (int)sv) <= DEAD_CODES;
#endif
        ev[c] = e;
    }
#if ENCODE_WARP
    dead |= ldead;
#endif
    for (int c = 0; c < TSS_PLANES; ++c) {
        const PIXEL_T e = dead ? (CHANNELS == 1 ? sp[0] : sp[ORDER_BGR ? 2 - c : c]) : ev[c];
#if CHANNELS == 1
        d[0] = e;
#elif ORDER_BGR
        d[2 - c] = e;
#else
        d[c] = e;
#endif
    }
#if CHANNELS == 4
    d[3] = sp[3];
#endif
}

// General maps (dense fields with NaN, valid masks): one work item per pixel, per-pixel cell arrays.
__kernel void tss_resolve(__global const ushort *ring, __global const PIXEL_T *spatial,
                          __global PIXEL_T *dst, __global uchar *cells,
                          __global const int *info, __global const float *shift,
                          __global const float *fields, __global const uchar *valids,
                          __global const float *luts, __global const ushort *ltab, __global const PIXEL_T *etab,
                          const int width, const int height, const int fw, const int fh, const int fs,
                          const int n_ring, const int cur_slot)
{
    const int gx = get_global_id(0), gy = get_global_id(1);
    if (gx >= width || gy >= height)
        return;
    const int i = gy * width + gx;
    const size_t frame = (size_t)width * height;
    const int rowlen = TSS_PLANES * width;
    __global const ushort *cur = ring + (size_t)cur_slot * height * rowlen;

    // the current frame's 3x3 box of L per plane
    const int x0 = gx > 0 ? gx - 1 : 0, x2 = gx < width - 1 ? gx + 1 : width - 1;
    const int y0 = gy > 0 ? gy - 1 : 0, y2 = gy < height - 1 ? gy + 1 : height - 1;
    int lo[3], hi[3];
    int flat = 1, over = 0;
    for (int c = 0; c < TSS_PLANES; ++c) {
        __global const ushort *pl = cur + c * width;
        int mn = 65536, mx = -1;
        for (int yy = y0; yy <= y2; ++yy)
            for (int xx = x0; xx <= x2; ++xx) {
                int v = pl[yy * rowlen + xx];
                mn = v < mn ? v : mn;
                mx = v > mx ? v : mx;
            }
        lo[c] = mn - EPSQ;
        hi[c] = mx + EPSQ < TSS_TOP ? mx + EPSQ : TSS_TOP;
        flat &= mn == mx;
        over |= mx > TSS_TOP;
    }
    if (flat | over) {
        tss_store(luts, ltab, etab, spatial, dst, cells, i, 0, 0.0f, 0.0f, 0.0f);
        return;
    }

    // per footprint cell: integer sums and a count, written from a cell's first sample on (used: the cells
    // with one, a bit each; CELLS <= 64)
    int sum[CELLS * 3];
    int cnt[CELLS];
    ulong used = 0;
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
            // bilinear read of the field at 1/fs (mlaa_stream.temporal.stage.sample_field)
            float fx = (xf + 0.5f) / (float)fs - 0.5f, fy = (yf + 0.5f) / (float)fs - 0.5f;
            fx = fx > 0.0f ? (fx < (float)(fw - 1) ? fx : (float)(fw - 1)) : 0.0f;
            fy = fy > 0.0f ? (fy < (float)(fh - 1) ? fy : (float)(fh - 1)) : 0.0f;
            int x0 = (int)fx, y0 = (int)fy;
            int x1 = x0 + 1 < fw - 1 ? x0 + 1 : fw - 1, y1 = y0 + 1 < fh - 1 ? y0 + 1 : fh - 1;
            float ax = fx - (float)x0, ay = fy - (float)y0;
            __global const float *f = fields + (size_t)fslot * fw * fh * 2;
            float2 f00 = LOAD_FLOAT2(f, y0 * fw + x0), f01 = LOAD_FLOAT2(f, y0 * fw + x1);
            float2 f10 = LOAD_FLOAT2(f, y1 * fw + x0), f11 = LOAD_FLOAT2(f, y1 * fw + x1);
            float2 top = f00 + (f01 - f00) * ax, bot = f10 + (f11 - f10) * ax;
            float2 o = top + (bot - top) * ay;
            px = xf + o.x;
            py = yf + o.y;
        }
        if (!(px == px) || !(py == py))
            continue;   // NaN: no trusted motion (forward-backward inconsistency)
        const float sx = FLOOR(px + 0.5f), sy = FLOOR(py + 0.5f);
        if (sx < 0.0f || sx > (float)(width - 1) || sy < 0.0f || sy > (float)(height - 1))
            continue;
        __global const ushort *r = ring + ((size_t)slot * height + (size_t)sy) * rowlen + (size_t)sx;
        int v[3];
        int ok = 1;
        for (int c = 0; c < TSS_PLANES; ++c) {
            v[c] = r[c * width];
            ok &= (v[c] >= lo[c]) & (v[c] <= hi[c]);
        }
        if (!ok)
            continue;
        float cx = FLOOR((sx - px + 0.5f) * (float)GRID), cy = FLOOR((sy - py + 0.5f) * (float)GRID);
        int ix = cx < 0.0f ? 0 : (cx > (float)(GRID - 1) ? GRID - 1 : (int)cx);
        int iy = cy < 0.0f ? 0 : (cy > (float)(GRID - 1) ? GRID - 1 : (int)cy);
        const int k = iy * GRID + ix;
        if ((used >> k) & 1) {
            for (int c = 0; c < TSS_PLANES; ++c)
                sum[3 * k + c] += v[c];
            cnt[k] += 1;
        } else {
            for (int c = 0; c < TSS_PLANES; ++c)
                sum[3 * k + c] = v[c];
            cnt[k] = 1;
            used |= (ulong)1 << k;
        }
    }
    int n = 0;
    float m[3] = {0.0f, 0.0f, 0.0f};
    for (int k = 0; used != 0; ++k, used >>= 1) {   // the filled cells in ascending order (tss_reference's)
        if (used & 1) {
            const float inv = 1.0f / (float)cnt[k];
            for (int c = 0; c < TSS_PLANES; ++c)
                m[c] += (float)sum[3 * k + c] * inv;
            ++n;
        }
    }
    tss_store(luts, ltab, etab, spatial, dst, cells, i, n, m[0], m[1], m[2]);
}

// 16 samples of a ring row from x on, clamped to the row (the caller masks the clamped ones).
inline int16 tss_row16(__global const ushort *row, int x, int width)
{
    if (x >= 0 && x + 16 <= width)
        return TSS_INT16(TSS_LOAD16(row + x));
    ushort16 t;
    __private ushort *e = (__private ushort *)&t;
    for (int p = 0; p < 16; ++p) {
        int xx = x + p;
        e[p] = row[xx < 0 ? 0 : (xx > width - 1 ? width - 1 : xx)];
    }
    return TSS_INT16(t);
}

// -1 where the 16 mask bytes from x on (clamped to the row) are non-zero, else 0.
inline int16 tss_mask16(__global const uchar *row, int x, int width)
{
    uchar16 t;
    if (x + 16 <= width) {
        t = TSS_LOADU16(row + x);
    } else {
        __private uchar *e = (__private uchar *)&t;
        for (int p = 0; p < 16; ++p)
            e[p] = row[x + p < width ? x + p : width - 1];
    }
    return TSS_INT16(t) != (int16)(0);
}

#define TSS_MIN(a, b) ((a) < (b) ? (a) : (b))
#define TSS_MAX(a, b) ((a) > (b) ? (a) : (b))

// The resolve when every ring frame's map is one translation (static and global models: the default
// path). The tap pattern is the same for every pixel, so the host gives each ring frame its whole-pixel
// offset (sx - x, sy - y), orders the frames by footprint cell (ring order inside a cell) and marks the
// last frame of each cell with the cell's frame count: a small table read alike by every work item.
// One work item = 16 pixels of a row as int16 / float16 vectors: per ring frame one contiguous load per
// plane, integer compares against the box and masked integer sums; a one-frame cell (a well-spread pan)
// adds its sample, no division. The sums and their order are tss_reference's (and tss_resolve's).
// taps: 4 ints per ring frame (slot, dx, dy, close: 0 inside a cell, the cell's frame count on its last
// frame); vslots[j] >= 0: ring frame j has a valid mask (the per-tile check's output) in that slot of
// valids, (fh, width) per slot: the flow-size mask with each column repeated FS times (vrows_of).
// Projective maps (a turning camera: a homography per ring frame) are a translation to within ~0.01 px over a
// tile of tile_rows x 16 pixels: the host then gives one such table per tile (tiles_x tiles per row of tiles),
// each from the homography at the tile's centre; one table for the frame otherwise.
// Global size (ceil(width / 16), height); on CPUs work-groups along the row (TSS_LOCAL in tss.py: the
// neighbouring work items read the neighbouring 32 bytes of every stream; (1, 8) ran 1.5-3x slower).
__kernel void tss_resolve_shift(__global const ushort *ring, __global const PIXEL_T *spatial,
                                __global PIXEL_T *dst, __global uchar *cells,
                                __global const int *taps, __global const int *vslots,
                                __global const uchar *valids,
                                __global const float *luts, __global const ushort *ltab,
                                __global const PIXEL_T *etab,
                                const int width, const int height, const int fw, const int fh, const int fs,
                                const int n_ring, const int cur_slot, const int tile_rows, const int tiles_x)
{
    const int x0 = get_global_id(0) * 16, gy = get_global_id(1);
    if (x0 >= width || gy >= height)
        return;
    {   // projective maps: each tile of tile_rows x 16 pixels has its own table (one table: tiles_x 1, a tile
        // as tall as the frame)
        const int tile = (gy / tile_rows) * tiles_x + (tiles_x > 1 ? x0 / 16 : 0);
        taps += 4 * n_ring * tile;
        vslots += n_ring * tile;
    }
    const size_t frame = (size_t)width * height;
    const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const int rowlen = TSS_PLANES * width;
    __global const ushort *cur = ring + (size_t)cur_slot * height * rowlen;
    const int y0 = gy > 0 ? gy - 1 : 0, y2 = gy < height - 1 ? gy + 1 : height - 1;
    int16 lo[TSS_PLANES], hi[TSS_PLANES], s[TSS_PLANES];
    float16 m[TSS_PLANES];
    int16 flat = (int16)(-1), over = (int16)(0);
    for (int c = 0; c < TSS_PLANES; ++c) {
        __global const ushort *pl = cur + c * width;
        int16 mn = (int16)(65536), mx = (int16)(-1);
        for (int yy = 0; yy < 3; ++yy) {
            __global const ushort *row = pl + (yy == 0 ? y0 : yy == 1 ? gy : y2) * rowlen;
            for (int dx = -1; dx <= 1; ++dx) {
                const int16 v = tss_row16(row, x0 + dx, width);
                mn = TSS_MIN(v, mn);
                mx = TSS_MAX(v, mx);
            }
        }
        lo[c] = mn - (int16)(EPSQ);
        hi[c] = TSS_MIN(mx + (int16)(EPSQ), (int16)(TSS_TOP));
        s[c] = (int16)(0);
        m[c] = (float16)(0.0f);
        flat &= mn == mx;
        over |= mx > (int16)(TSS_TOP);
    }
    flat |= over;                           // over range: the spatial pixel stands, as on a flat one
    const int len = width - x0 < 16 ? width - x0 : 16;
    {
        // a group of 16 flat pixels (most of a frame with flat areas): no ring reads at all
        __private const int *fl = (__private const int *)&flat;
        int all_flat = 1;
        for (int p = 0; p < len; ++p)
            all_flat &= fl[p] != 0;
        if (all_flat) {
            for (int p = 0; p < len; ++p)
                tss_store(luts, ltab, etab, spatial, dst, cells, gy * width + x0 + p, 0, 0.0f, 0.0f, 0.0f);
            return;
        }
    }
    int16 n = (int16)(0), cnt = (int16)(0);
    const int vy = gy / fs < fh - 1 ? gy / fs : fh - 1;
    for (int j = 0; j < n_ring; ++j) {
        const int slot = taps[4 * j], dx = taps[4 * j + 1], close = taps[4 * j + 3], vs = vslots[j];
        int sy = gy + taps[4 * j + 2];
        const int16 xs = lane + (int16)(x0 + dx);
        int16 ok = (xs >= (int16)(0)) & (xs < (int16)(width));
        if (sy < 0 || sy > height - 1) {
            ok = (int16)(0);
            sy = sy < 0 ? 0 : height - 1;
        }
        if (vs >= 0) {                      // the mask's row, widened to full-size columns on the host
            ok &= tss_mask16(valids + ((size_t)vs * fh + (size_t)vy) * width, x0, width);
        }
        __global const ushort *r = ring + ((size_t)slot * height + (size_t)sy) * rowlen;
        int16 v[TSS_PLANES];
        for (int c = 0; c < TSS_PLANES; ++c) {
            v[c] = tss_row16(r + c * width, x0 + dx, width);
            ok &= (v[c] >= lo[c]) & (v[c] <= hi[c]);
        }
        for (int c = 0; c < TSS_PLANES; ++c)
            s[c] += v[c] & ok;
        cnt -= ok;                          // ok is -1 where the sample is taken
        if (close == 1) {                   // a one-frame cell: its mean is its sample (0 where rejected)
            for (int c = 0; c < TSS_PLANES; ++c) {
                m[c] += TSS_FLOAT16(s[c]);
                s[c] = (int16)(0);
            }
            n += cnt;
            cnt = (int16)(0);
        } else if (close > 1) {
            const float16 inv = (float16)(1.0f) / TSS_FLOAT16(cnt + ((cnt == (int16)(0)) & (int16)(1)));
            for (int c = 0; c < TSS_PLANES; ++c) {
                m[c] += TSS_FLOAT16(s[c]) * inv;
                s[c] = (int16)(0);
            }
            n += (cnt > (int16)(0)) & (int16)(1);
            cnt = (int16)(0);
        }
    }
    n = n & ~flat;                          // flat pixels: n = 0, the spatial pixel stands
    __private const int *ne = (__private const int *)&n;
    __private const float *m0 = (__private const float *)&m[0];
#if TSS_PLANES == 3
    __private const float *m1 = (__private const float *)&m[1], *m2 = (__private const float *)&m[2];
#else
    __private const float *m1 = m0, *m2 = m0;
#endif
    for (int p = 0; p < len; ++p)
        tss_store(luts, ltab, etab, spatial, dst, cells, gy * width + x0 + p, ne[p], m0[p], m1[p], m2[p]);
}
