// moire.cl -- point-sampled moire in two-colour art, low-passed (issue 15: the perspective
// checkerboard). Reference: mlaa_stream.spatial.moire.moire_reference (the module's header says why).
//
// A pattern finer than the pixel grid (a checkerboard towards its horizon, a far grid of wires) is sampled
// at 1 spp into dashed lines one pixel thick that alternate row by row (or column by column): each row
// of it is another phase of the pattern, so the truth is close to the mean of neighbouring rows, not the
// stair steps MLAA reads in them. Per pixel (edges: detect_edges' output; neighbours clamped to the frame):
//   line_v = edges at the pixel's top and bottom borders, the pixels above and below the same colour, its
//            left and right neighbours each one of those two colours (an isolated row pixel in two-colour
//            surroundings: photographs and renders give almost none); line_h the same across the columns
//   in the pixel's window of (2 MOIRE_RADIUS + 1)^2 pixels (the part inside the frame):
//     lines = line_v pixels, ends = line_v pixels whose left or right neighbour is not one (a dash's end:
//             a ruled line or a 1-px checker fill runs through the window without ends and is left alone)
//     the window holds at most two colours (photographs, renders and anything through a lossy codec hold
//             more and are never touched)
//   and in the 3 x 3 tiles of MOIRE_TILE^2 pixels around the pixel's tile (the part inside the frame):
//     region = line_v pixels (a band of moire, not one line of tiny text: its glyphs' bars are line pixels too)
//   fire_v = two colours && lines >= MOIRE_LINES && MOIRE_ENDS * ends >= lines && region >= MOIRE_REGION;
//   fire_h alike with line_h
//   fire_v or fire_h: out = the input's 3 x 3 binomial ([1 2 1] / 4 along the row, then down the column) in mix
//   space (linear light when DECODE), encoded; else the pixel stays (dst: the passes' output). Alpha stays.
// Two kernels: moire_lines writes each pixel's line bits (bit 0 line_v, bit 1 line_h) and each tile's counts;
// moire_lowpass, one work item per tile of MOIRE_TILE^2 pixels, skips every tile whose region holds under
// MOIRE_REGION lines of both kinds: a frame without such patterns costs little more than a read of its edge
// bytes.
// Defines: MOIRE_RADIUS, MOIRE_LINES, MOIRE_ENDS, MOIRE_REGION, MOIRE_TILE (8), MOIRE_SEGMENT (a multiple of it).
#pragma OPENCL FP_CONTRACT OFF

#define EDGE_BOTTOM 1
#define EDGE_RIGHT 2
#define MOIRE_SPAN (MOIRE_TILE + 2 * MOIRE_RADIUS)

// Pixel (x, y)'s index with coordinates clamped to the frame.
inline int moire_at(int x, int y, int w, int h)
{
    x = x < 0 ? 0 : (x > w - 1 ? w - 1 : x);
    y = y < 0 ? 0 : (y > h - 1 ? h - 1 : y);
    return y * w + x;
}

// Candidate bits of pixel (x, y) from the edges alone: bit 0 edges at its top and bottom borders, bit 1 at
// its left and right ones (none at the frame's border).
inline int moire_candidates(__global const uchar *edges, int x, int y, int w, int h)
{
    const int i = y * w + x;
    const int v = y > 0 && y < h - 1 && (edges[i - w] & EDGE_BOTTOM) && (edges[i] & EDGE_BOTTOM);
    const int hz = x > 0 && x < w - 1 && (edges[i - 1] & EDGE_RIGHT) && (edges[i] & EDGE_RIGHT);
    return v | (hz << 1);
}

// The line bits of pixel (x, y) with candidate bits `cand`: the colour tests.
inline uchar moire_bits(__global const PIXEL_T *src, int x, int y, int w, int h, int cand)
{
    const int i = y * w + x;
    const int n = moire_at(x, y - 1, w, h), s = moire_at(x, y + 1, w, h);
    const int o = moire_at(x - 1, y, w, h), e = moire_at(x + 1, y, w, h);
    int bits = 0;
    if ((cand & 1) && same_px(src, n, s) && (same_px(src, o, i) || same_px(src, o, n))
        && (same_px(src, e, i) || same_px(src, e, n)))
        bits |= 1;
    if ((cand & 2) && same_px(src, o, e) && (same_px(src, n, i) || same_px(src, n, o))
        && (same_px(src, s, i) || same_px(src, s, o)))
        bits |= 2;
    return (uchar)bits;
}

// scratch: the line bits (a byte per pixel), then the tile counts (two bytes per tile: line_v, line_h).
// One work item per MOIRE_TILE rows x MOIRE_SEGMENT pixels: its pixels' line bits and its tiles' counts. A group of
// eight pixels inside the frame without a candidate (almost every group of a photograph or a render) costs
// three edge words.
__kernel void moire_lines(__global const PIXEL_T *src, __global const uchar *edges, __global uchar *scratch,
                          const int w, const int h, const int tiles_x)
{
    __global uchar *lines = scratch, *counts = scratch + (size_t)w * h;
    const int x0 = get_global_id(0) * MOIRE_SEGMENT, ty = get_global_id(1), y0 = ty * MOIRE_TILE;
    if (x0 >= w || y0 >= h)
        return;
    const int x1 = x0 + MOIRE_SEGMENT < w ? x0 + MOIRE_SEGMENT : w;
    const int y1 = y0 + MOIRE_TILE < h ? y0 + MOIRE_TILE : h;
    for (int t = x0; t < x1; t += MOIRE_TILE) {   // one tile at a time
        const int t1 = t + MOIRE_TILE < x1 ? t + MOIRE_TILE : x1;
        int nv = 0, nh = 0;
        for (int y = y0; y < y1; ++y) {
            __global uchar *l = lines + (size_t)y * w;
            if (t > 0 && t + MOIRE_TILE < w && y > 0 && y < h - 1) {
                // inside the frame: the candidates of the eight pixels as bits of edge words (byte k: pixel t + k)
                const ulong b = edge_group(edges + (size_t)y * w + t);
                const ulong above = edge_group(edges + (size_t)(y - 1) * w + t);
                const ulong left = edge_group(edges + (size_t)y * w + t - 1);
                if (((above & b & 0x0101010101010101UL) | (left & b & 0x0202020202020202UL)) == 0) {
                    STORE_UCHAR8((uchar8)(0), l + t);
                    continue;
                }
            }
            for (int x = t; x < t1; ++x) {
                const int c = moire_candidates(edges, x, y, w, h);
                const uchar bits = c ? moire_bits(src, x, y, w, h, c) : (uchar)0;
                l[x] = bits;
                nv += bits & 1;
                nh += bits >> 1;
            }
        }
        const int tile = ty * tiles_x + t / MOIRE_TILE;
        counts[2 * tile] = (uchar)nv;
        counts[2 * tile + 1] = (uchar)nh;
    }
}

// Does the window around (x, y) (inside the frame) hold at most two colours?
inline int moire_two_colours(__global const PIXEL_T *src, int x, int y, int w, int h)
{
    const int c = y * w + x;
    int other = -1;   // the first pixel of another colour than the centre's, in scan order
    for (int yy = y - MOIRE_RADIUS; yy <= y + MOIRE_RADIUS; ++yy) {
        if (yy < 0 || yy >= h)
            continue;
        for (int xx = x - MOIRE_RADIUS; xx <= x + MOIRE_RADIUS; ++xx) {
            if (xx < 0 || xx >= w)
                continue;
            const int j = yy * w + xx;
            if (same_px(src, j, c))
                continue;
            if (other < 0)
                other = j;
            else if (!same_px(src, j, other))
                return 0;
        }
    }
    return 1;
}

// Mix-space value of channel c of pixel i (linear light when DECODE).
inline float moire_mix(__global const float *luts, __global const PIXEL_T *src, int i, int c)
{
    const float v = (float)src[(size_t)i * CHANNELS + c] * (1.0f / PIXEL_MAX);
#if DECODE
    return lut_read(luts, v);
#else
    return v;
#endif
}

// One work item per tile of MOIRE_TILE^2 pixels.
__kernel void moire_lowpass(__global const PIXEL_T *src, __global const uchar *scratch, __global const float *luts,
                            __global PIXEL_T *dst, const int w, const int h, const int tiles_x, const int tiles_y)
{
    __global const uchar *lines = scratch, *counts = scratch + (size_t)w * h;
    const int tx = get_global_id(0), ty = get_global_id(1);
    if (tx >= tiles_x || ty >= tiles_y)
        return;
    int sv = 0, sh = 0;
    for (int j = ty - 1; j <= ty + 1; ++j)
        for (int i = tx - 1; i <= tx + 1; ++i)
            if (i >= 0 && i < tiles_x && j >= 0 && j < tiles_y) {
                sv += counts[2 * (j * tiles_x + i)];
                sh += counts[2 * (j * tiles_x + i) + 1];
            }
    if (sv < MOIRE_REGION && sh < MOIRE_REGION)
        return;   // too few lines around this tile (its windows lie inside these tiles too)
    // The tile's windows lie in a region of MOIRE_SPAN^2 pixels around it: per region pixel (none outside the
    // frame) its line bits and dash ends packed in 10-bit fields (line_v, line_h, end_v, end_h), summed into
    // 2-D prefix sums, so each window's four counts are four lookups (sums of two fields stay under 1024).
    const int rx0 = tx * MOIRE_TILE - MOIRE_RADIUS, ry0 = ty * MOIRE_TILE - MOIRE_RADIUS;
    ulong P[MOIRE_SPAN + 1][MOIRE_SPAN + 1];
    for (int k = 0; k <= MOIRE_SPAN; ++k)
        P[0][k] = P[k][0] = 0;
    int first = -1, other = -1, two = 1;   // the region's colours: the first pixel's, the first other one's
    for (int ry = 0; ry < MOIRE_SPAN; ++ry) {
        const int gy = ry0 + ry;
        ulong row = 0;
        for (int rx = 0; rx < MOIRE_SPAN; ++rx) {
            const int gx = rx0 + rx;
            ulong f = 0;
            if (gx >= 0 && gx < w && gy >= 0 && gy < h) {
                const int j = gy * w + gx;
                const int b = lines[j];
                const int lv = b & 1, lh = (b >> 1) & 1;
                // dash ends: a neighbour along the line (clamped) without the bit
                const int ev = lv && !((lines[moire_at(gx - 1, gy, w, h)] & 1)
                                       && (lines[moire_at(gx + 1, gy, w, h)] & 1));
                const int eh = lh && !(((lines[moire_at(gx, gy - 1, w, h)] >> 1) & 1)
                                       && ((lines[moire_at(gx, gy + 1, w, h)] >> 1) & 1));
                f = (ulong)lv | ((ulong)lh << 10) | ((ulong)ev << 20) | ((ulong)eh << 30);
                if (first < 0)
                    first = j;
                else if (two && !same_px(src, j, first)) {
                    if (other < 0)
                        other = j;
                    else if (!same_px(src, j, other))
                        two = 0;
                }
            }
            row += f;
            P[ry + 1][rx + 1] = P[ry][rx + 1] + row;
        }
    }
    const int x1 = (tx + 1) * MOIRE_TILE < w ? (tx + 1) * MOIRE_TILE : w;
    const int y1 = (ty + 1) * MOIRE_TILE < h ? (ty + 1) * MOIRE_TILE : h;
    for (int y = ty * MOIRE_TILE; y < y1; ++y)
        for (int x = tx * MOIRE_TILE; x < x1; ++x) {
            const int px = x - tx * MOIRE_TILE, py = y - ty * MOIRE_TILE, q = 2 * MOIRE_RADIUS + 1;
            const ulong sum = (P[py + q][px + q] + P[py][px]) - (P[py][px + q] + P[py + q][px]);
            const int nv = (int)(sum & 1023), nh = (int)((sum >> 10) & 1023);
            const int ev = (int)((sum >> 20) & 1023), eh = (int)((sum >> 30) & 1023);
            const int fire = (sv >= MOIRE_REGION && nv >= MOIRE_LINES && MOIRE_ENDS * ev >= nv)
                             || (sh >= MOIRE_REGION && nh >= MOIRE_LINES && MOIRE_ENDS * eh >= nh);
            if (!fire || !(two || moire_two_colours(src, x, y, w, h)))
                continue;
            const int i = y * w + x;
            // the 3 x 3 window (clamped), row by row: k[3 r + c] is pixel (x + c - 1, y + r - 1)
            int k[9];
            for (int r = 0; r < 3; ++r)
                for (int c = 0; c < 3; ++c)
                    k[3 * r + c] = moire_at(x + c - 1, y + r - 1, w, h);
            const int planes = CHANNELS == 1 ? 1 : 3;
#if DECODE && defined(PIXEL_IS_FLOAT)
            // display-encoded float frames: the tables span [0, 1]; a value outside it keeps the pixel
            int outside = 0;
            for (int c = 0; c < planes; ++c)
                for (int t = 0; t < 9; ++t) {
                    const float v = src[(size_t)k[t] * CHANNELS + c];
                    outside |= !(v >= 0.0f && v <= 1.0f);
                }
            if (outside)
                continue;
#endif
            for (int c = 0; c < planes; ++c) {
                float row[3];   // [1 2 1] / 4 along each row, then the same down the three
                for (int r = 0; r < 3; ++r)
                    row[r] = 0.25f * (moire_mix(luts, src, k[3 * r], c) + moire_mix(luts, src, k[3 * r + 2], c))
                             + 0.5f * moire_mix(luts, src, k[3 * r + 1], c);
                float m = 0.25f * (row[0] + row[2]) + 0.5f * row[1];
#if DECODE
                m = encode_mix(luts, m);
#endif
                dst[(size_t)i * CHANNELS + c] = to_pixel(m);
            }
        }
}
