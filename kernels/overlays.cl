// overlays.cl -- text drawn over a render (subtitles, a HUD's lettering, a slate) is no part of the render: the
// tiles that hold it leave the render regions (fallback.cl) after render_frame, so the FXAA fallback and the
// footprint and refine tables do not soften it (spatial/overlays.py is the reference; docs/spatial_tuning.md,
// "Text over a render").
//
// What tells it apart: a subtitle renderer blends an exactly flat ink colour into whatever lies behind, so beside
// each pixel of ink there are coverage mixes -- colours on the segment between the ink and the pixel beyond. A 1-spp
// render has no coverage mixes: beside a flat area (sky, a clipped highlight) its pixels are samples of another
// surface. Per pixel p and each of its four neighbours F (the pixel beyond p, away from F, is Q), on 8-bit levels:
//   boundary:  F differs from p, F equals one of its own eight neighbours (a flat colour), F's luma is within
//              OVERLAY_EXTREME levels of the darkest or lightest of the tile's window (ink is an extreme: white
//              letters, a black outline), and |p - F| > OVERLAY_CONTRAST levels;
//   mix:       a boundary where p lies on the segment F -> Q: at t in (1 / OVERLAY_LO, 1 - 1 / OVERLAY_LO) of it and
//              off it by at most 1 / OVERLAY_OFF of its length.
// A video codec leaves no ink exactly flat, so a second test holds for white or black ink (luma within OVERLAY_INK
// levels of either): F within OVERLAY_NOISY_FLAT levels of a neighbour in every channel, within OVERLAY_NOISY_EXTREME
// of the window's extremes, and for a mix the ramp ends at Q (the pixel beyond Q goes on along Q - F by at most
// 1 / OVERLAY_RAMP_END of it: a glyph's edge meets its background, a highlight's falloff goes on).
// Per tile: its boundary pixels (nb) and mixes (nm). A tile is overlay where its 3x3 tiles hold at least
// OVERLAY_SEED_MIN mixes, OVERLAY_SEED_PCT % of their boundary pixels, or where it holds a mix for every
// OVERLAY_GROW_DIV boundary pixels and touches such a tile -- two steps of growth (the ends of a line of text, the
// tiles between its lines). Thin text on a flat box (strokes of one pixel: no flat ink, no monotone ramp) is not
// found: `keep` rectangles (spatial/keep.py) are for it.
#pragma OPENCL FP_CONTRACT OFF

#ifndef OVERLAY_CONTRAST
#define OVERLAY_CONTRAST 64
#endif
#ifndef OVERLAY_EXTREME
#define OVERLAY_EXTREME 2
#endif
#ifndef OVERLAY_LO
#define OVERLAY_LO 20
#endif
#ifndef OVERLAY_OFF
#define OVERLAY_OFF 10
#endif
#ifndef OVERLAY_SEED_MIN
#define OVERLAY_SEED_MIN 32
#endif
#ifndef OVERLAY_SEED_PCT
#define OVERLAY_SEED_PCT 35
#endif
#ifndef OVERLAY_GROW_DIV
#define OVERLAY_GROW_DIV 5
#endif
#ifndef OVERLAY_INK
#define OVERLAY_INK 20
#endif
#ifndef OVERLAY_NOISY_FLAT
#define OVERLAY_NOISY_FLAT 4
#endif
#ifndef OVERLAY_NOISY_EXTREME
#define OVERLAY_NOISY_EXTREME 8
#endif
#ifndef OVERLAY_RAMP_END
#define OVERLAY_RAMP_END 10
#endif
#define OV_R 2                               // the tile's window: 2 pixels around it (F's neighbours)
#define OV_N (FALLBACK_TILE + 2 * OV_R)

// (boundary pixels, mixes) of the tile whose top-left pixel is (x0, y0). The window's levels in plain int arrays, one
// per channel (private arrays of 3-vectors and all() of their comparisons came out wrong on Mesa's llvmpipe); most
// pairs fail the contrast test, tested for a row's 8 pixels at once, and only the pairs that pass take the luma
// extremes (once per tile), the flat test and the mix test (lazily: 56 -> 7.5 ms per 1080p render here).
inline int2 tile_overlay_counts(__global const PIXEL_T *src, int x0, int y0, int w, int h)
{
    int qr[OV_N][OV_N], qg[OV_N][OV_N], qb[OV_N][OV_N];  // -1 outside the frame
    const int interior = x0 >= OV_R && y0 >= OV_R && x0 + FALLBACK_TILE + OV_R <= w && y0 + FALLBACK_TILE + OV_R <= h;
    for (int j = 0; j < OV_N; ++j) {
        const int y = y0 + j - OV_R;
        for (int k = 0; k < OV_N; ++k) {
            const int x = x0 + k - OV_R;
            if (interior || (x >= 0 && y >= 0 && x < w && y < h)) {  // common.cl levels8, written out: no array
#if CHANNELS == 1
                qr[j][k] = qg[j][k] = qb[j][k] = level8(src[IDX(x, y, w)]);
#else
                __global const PIXEL_T *p = src + (size_t)IDX(x, y, w) * CHANNELS;
                qr[j][k] = level8(p[ORDER_BGR ? 2 : 0]);
                qg[j][k] = level8(p[1]);
                qb[j][k] = level8(p[ORDER_BGR ? 0 : 2]);
#endif
            } else {
                qr[j][k] = qg[j][k] = qb[j][k] = -1;
            }
        }
    }
#define OV_IN(j, k) (qr[j][k] >= 0)
#define OV_SAME(j0, k0, j1, k1) (qr[j0][k0] == qr[j1][k1] && qg[j0][k0] == qg[j1][k1] && qb[j0][k0] == qb[j1][k1])
#define OV_LUM(j, k) (54 * qr[j][k] + 183 * qg[j][k] + 19 * qb[j][k])
    int lmax = -1, lmin = -1;  // the window's luma extremes, found at the first pair of enough contrast
    const int ext = OVERLAY_EXTREME * 256, ext_noisy = OVERLAY_NOISY_EXTREME * 256;
    uint boundary[FALLBACK_TILE] = {0, 0, 0, 0, 0, 0, 0, 0}, mix[FALLBACK_TILE] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (int d = 0; d < 4; ++d) {
        const int dj = d == 2 ? 1 : (d == 3 ? -1 : 0), dk = d == 0 ? 1 : (d == 1 ? -1 : 0);
        for (int r = 0; r < FALLBACK_TILE; ++r) {
            const int j = OV_R + r, fj = j + dj, bj = j - dj;
            // the contrast test for the row's 8 pixels at once, as int8 lanes (one by one: 3x the time)
            const int8 vr8 = LOAD_INT8_PRIVATE(&qr[j][OV_R]) - LOAD_INT8_PRIVATE(&qr[fj][OV_R + dk]);
            const int8 vg8 = LOAD_INT8_PRIVATE(&qg[j][OV_R]) - LOAD_INT8_PRIVATE(&qg[fj][OV_R + dk]);
            const int8 vb8 = LOAD_INT8_PRIVATE(&qb[j][OV_R]) - LOAD_INT8_PRIVATE(&qb[fj][OV_R + dk]);
            int strong[FALLBACK_TILE];
            STORE_INT8_PRIVATE(vr8 * vr8 + vg8 * vg8 + vb8 * vb8 > OVERLAY_CONTRAST * OVERLAY_CONTRAST, strong);
            for (int o = 0; o < FALLBACK_TILE; ++o) {
                const int k = OV_R + o, fk = k + dk, bk = k - dk;  // p, F beside it, Q beyond p
                if (!strong[o] || !OV_IN(j, k) || !OV_IN(fj, fk)) continue;
                if (lmax < 0) {
                    lmin = 1 << 30;
                    for (int a = 0; a < OV_N; ++a)
                        for (int b = 0; b < OV_N; ++b)
                            if (OV_IN(a, b)) {
                                lmax = max(lmax, OV_LUM(a, b));
                                lmin = min(lmin, OV_LUM(a, b));
                            }
                }
                const int lf = OV_LUM(fj, fk);
                // the exact test: F equals a neighbour, its luma within OVERLAY_EXTREME of the window's extremes
                int exact = lf >= lmax - ext || lf <= lmin + ext;
                // the codec's test: white or black ink, F within OVERLAY_NOISY_FLAT of a neighbour in every channel,
                // its luma within OVERLAY_NOISY_EXTREME of the extremes (and below, the ramp ends at Q)
                int noisy = (lf >= (255 - OVERLAY_INK) * 256 || lf <= OVERLAY_INK * 256) &&
                            (lf >= lmax - ext_noisy || lf <= lmin + ext_noisy);
                if (!exact && !noisy) continue;
                int flat = 0, near = 0;  // F equals one of its eight neighbours / is within the codec's tolerance
                for (int a = -1; a <= 1; ++a)
                    for (int b = -1; b <= 1; ++b) {
                        if (!(a || b) || !OV_IN(fj + a, fk + b)) continue;
                        flat |= OV_SAME(fj + a, fk + b, fj, fk);
                        near |= abs(qr[fj + a][fk + b] - qr[fj][fk]) <= OVERLAY_NOISY_FLAT &&
                                abs(qg[fj + a][fk + b] - qg[fj][fk]) <= OVERLAY_NOISY_FLAT &&
                                abs(qb[fj + a][fk + b] - qb[fj][fk]) <= OVERLAY_NOISY_FLAT;
                    }
                exact &= flat;
                noisy &= near;
                if (!exact && !noisy) continue;
                boundary[r] |= 1u << o;
                if (!OV_IN(bj, bk)) continue;
                const int vr = qr[j][k] - qr[fj][fk], vg = qg[j][k] - qg[fj][fk], vb = qb[j][k] - qb[fj][fk];
                const int vv = vr * vr + vg * vg + vb * vb;  // at most 3 * 255^2
                const int er = qr[bj][bk] - qr[fj][fk], eg = qg[bj][bk] - qg[fj][fk], eb = qb[bj][bk] - qb[fj][fk];
                const int dd = er * er + eg * eg + eb * eb, vd = vr * er + vg * eg + vb * eb;
                // products of two such sums need 64 bits
                if (!(dd > 0 && OVERLAY_LO * vd > dd && OVERLAY_LO * vd < (OVERLAY_LO - 1) * dd &&
                      OVERLAY_OFF * OVERLAY_OFF * ((long)vv * dd - (long)vd * vd) <= (long)dd * dd)) continue;
                if (!exact) {  // the codec's test: the pixel beyond Q goes on along Q - F by <= 1 / OVERLAY_RAMP_END
                    const int cj = bj - dj, ck = bk - dk;
                    if (!OV_IN(cj, ck)) continue;
                    const int go = (qr[cj][ck] - qr[bj][bk]) * er + (qg[cj][ck] - qg[bj][bk]) * eg +
                                   (qb[cj][ck] - qb[bj][bk]) * eb;
                    if (OVERLAY_RAMP_END * go > dd) continue;
                }
                mix[r] |= 1u << o;
            }
        }
    }
    int nb = 0, nm = 0;
    for (int r = 0; r < FALLBACK_TILE; ++r) {
        nb += popcount(boundary[r]);
        nm += popcount(mix[r]);
    }
#undef OV_IN
#undef OV_SAME
#undef OV_LUM
    return (int2)(nb, nm);
}

// counts[2 tile] = boundary pixels, counts[2 tile + 1] = mixes, for tiles within three tiles of a render region
// (what overlay_tiles reads for a region: the rest stay 0). One work item per SEGMENT / FALLBACK_TILE tiles of a
// tile row.
__kernel void overlay_counts(__global const PIXEL_T *src, __global const uchar *render, __global uchar *counts,
                             const int w, const int h, const int tiles_x, const int tiles_y)
{
    const int t0 = get_global_id(0) * (SEGMENT / FALLBACK_TILE), ty = get_global_id(1);
    if (t0 >= tiles_x || ty >= tiles_y) return;
    const int t1 = min(t0 + SEGMENT / FALLBACK_TILE, tiles_x);
    for (int tx = t0; tx < t1; ++tx) {
        int near = 0;
        for (int j = max(ty - 3, 0); j <= min(ty + 3, tiles_y - 1); ++j)
            for (int k = max(tx - 3, 0); k <= min(tx + 3, tiles_x - 1); ++k)
                near |= render[j * tiles_x + k];
        const int2 n = near ? tile_overlay_counts(src, tx * FALLBACK_TILE, ty * FALLBACK_TILE, w, h) : (int2)(0, 0);
        counts[2 * (ty * tiles_x + tx)] = (uchar)n.x;
        counts[2 * (ty * tiles_x + tx) + 1] = (uchar)n.y;
    }
}

// seeds[tile] = 1 where the tile's 3x3 tiles hold OVERLAY_SEED_MIN mixes or more, OVERLAY_SEED_PCT % of their
// boundary pixels. One work item per tile row.
__kernel void overlay_seeds(__global const uchar *counts, __global uchar *seeds, const int tiles_x, const int tiles_y)
{
    const int ty = get_global_id(0);
    if (ty >= tiles_y) return;
    for (int tx = 0; tx < tiles_x; ++tx) {
        int sb = 0, sm = 0;
        for (int j = max(ty - 1, 0); j <= min(ty + 1, tiles_y - 1); ++j)
            for (int k = max(tx - 1, 0); k <= min(tx + 1, tiles_x - 1); ++k) {
                sb += counts[2 * (j * tiles_x + k)];
                sm += counts[2 * (j * tiles_x + k) + 1];
            }
        seeds[ty * tiles_x + tx] = (uchar)(sm >= OVERLAY_SEED_MIN && 100 * sm >= OVERLAY_SEED_PCT * sb);
    }
}

// The tile holds a mix for every OVERLAY_GROW_DIV boundary pixels (one a seed may grow into).
inline int overlay_grows(__global const uchar *counts, int tile)
{
    const int nb = counts[2 * tile], nm = counts[2 * tile + 1];
    return nm >= 1 && OVERLAY_GROW_DIV * nm >= nb;
}

// One growth step's verdict for tile (tx, ty): a seed, or a tile that grows beside a seed.
inline int overlay_once(__global const uchar *counts, __global const uchar *seeds, int tx, int ty, int tiles_x,
                        int tiles_y)
{
    const int tile = ty * tiles_x + tx;
    if (seeds[tile]) return 1;
    if (!overlay_grows(counts, tile)) return 0;
    for (int j = max(ty - 1, 0); j <= min(ty + 1, tiles_y - 1); ++j)
        for (int k = max(tx - 1, 0); k <= min(tx + 1, tiles_x - 1); ++k)
            if (seeds[j * tiles_x + k]) return 1;
    return 0;
}

// A render region that is overlay after two growth steps from the seeds (the ends of a line of text, the tiles
// between its lines) stops being one. One work item per tile row.
__kernel void overlay_tiles(__global const uchar *counts, __global const uchar *seeds, __global uchar *render,
                            const int tiles_x, const int tiles_y)
{
    const int ty = get_global_id(0);
    if (ty >= tiles_y) return;
    for (int tx = 0; tx < tiles_x; ++tx) {
        const int tile = ty * tiles_x + tx;
        if (!render[tile]) continue;
        int overlay = overlay_once(counts, seeds, tx, ty, tiles_x, tiles_y);
        if (!overlay && overlay_grows(counts, tile))
            for (int j = max(ty - 1, 0); j <= min(ty + 1, tiles_y - 1) && !overlay; ++j)
                for (int k = max(tx - 1, 0); k <= min(tx + 1, tiles_x - 1) && !overlay; ++k)
                    overlay = overlay_once(counts, seeds, k, j, tiles_x, tiles_y);
        if (overlay) render[tile] = 0;
    }
}
