// grlaa.cl: GRLAA antialiased polylines (roads, routes) with an outline, composited over a frame.
// Seed 001 (GRadient Line Anti-Aliasing). The seed's fragment shader gets a base value interpolated
// from -1 to +1 across the road, takes distance = 1 - |base| and blend_range = ANTIALIAS_STRENGTH *
// |grad base| (dFdx, dFdy), and ramps alpha over blend_range. Here every pixel computes the exact
// distance to the centre line and the gradient of that distance (the unit normal n, |n| = 1 per
// pixel); the ramp is the pixel's footprint (STRENGTH x STRENGTH box) projected on n, whose widths
// are STRENGTH*|n.x| and STRENGTH*|n.y|, i.e. the gradient's components (docs/grlaa.md).
//
// Defines (mlaa_stream.formats.defines_for): PIXEL_T, CHANNELS, PIXEL_MAX, ORDER_BGR, LUT_SIZE,
// PIXEL_IS_FLOAT; LINEAR_FRAME (1: samples are linear light, not sRGB); TILE (edge of a square
// screen tile in pixels, = the work-group's side).
//
// Host data (mlaa_stream.overlay): segments binned into TILE x TILE tiles. One work-item draws one
// non-empty tile: for each listed segment it visits, row by row, only the pixels whose centres lie
// within the segment's reach (an interval per row), so pixels away from lines cost nothing.
//   segs[2s]    float4 (x0, y0, tx, ty): start and unit tangent, in pixels (pixel centres at integers)
//   segs[2s+1]  float4 (length, r, r_inner, reach): reach = farthest touched pixel centre
//   seg_meta[s] (polyline << 3) | flags: 1 flat start, 2 flat end, 4 square (flat ends extended by r)
//   entries[]   segment indices, grouped by tile, in drawing order (polyline, then segment)
//   tiles[g]    int4 (tile x, tile y, first entry, entry count)
//   polys[5k..5k+4] float4: (r, r_inner, opacity, 0), fill linear RGB, outline linear RGB,
//                   fill and outline as stored in the frame (normalised), written as-is where covered
#ifndef TILE
#define TILE 16
#endif
#if TILE > 32
#error "TILE must be at most 32 (one bit per column in a uint)"
#endif
#ifndef LINEAR_FRAME
#define LINEAR_FRAME 0
#endif

#define LUT_ENCODE (2 * (LUT_SIZE + 1))

// PoCL's CPU build here calls OpenCL builtins (fmin, fabs, clamp, mad, floor, ...) out of line, and
// floor/ceil/rint in software; the hot loops below use these plain expressions instead.
#define FMIN(a, b) ((a) < (b) ? (a) : (b))
#define FMAX(a, b) ((a) > (b) ? (a) : (b))
#define FABS(a) ((a) < 0.0f ? -(a) : (a))
#define IMIN(a, b) ((a) < (b) ? (a) : (b))
#define IMAX(a, b) ((a) > (b) ? (a) : (b))
#define HALF_DIAGONAL 0.70711f

// floor / ceil to int for |x| < 2^24 (coordinates are clipped to the frame on the host).
inline int ifloor(float x) { int i = (int)x; return i - (x < (float)i); }
inline int iceil(float x) { int i = (int)x; return i + (x > (float)i); }

// common.cl's lut_read, written with plain expressions (same arithmetic).
inline float lut_fast(__global const float *lut, float x)
{
    float t = (x < 0.0f ? 0.0f : (x > 1.0f ? 1.0f : x)) * (float)LUT_SIZE;
    int i = (int)t;
    i = i > LUT_SIZE - 1 ? LUT_SIZE - 1 : i;
    float f = t - (float)i;
    return f * (lut[i + 1] - lut[i]) + lut[i];
}

// CDF at s of the pixel footprint projected on the normal: U(-a/2, a/2) + U(-b/2, b/2), a >= b >= 0.
// It is the coverage of the half-plane {u <= s} (u along n, from the pixel centre); for b = 0 it is
// the seed's linear ramp clamp(s / a + 0.5) (seed 001, blend_distance).
inline float footprint_cdf(float s, float a, float b)
{
    float x = s + 0.5f * (a + b);
    if (x <= 0.0f) return 0.0f;
    if (x >= a + b) return 1.0f;
    if (x < b) return x * x / (2.0f * a * b);
    if (x <= a) return (x - 0.5f * b) / a;
    float y = a + b - x;
    return 1.0f - y * y / (2.0f * a * b);
}

// Coverage of the strip |u| <= r by a pixel whose centre lies at distance d from the strip's centre.
inline float strip_cover(float d, float r, float a, float b)
{
    return footprint_cdf(r - d, a, b) - footprint_cdf(-r - d, a, b);
}

// LINEAR_FRAME: the frame already holds linear light (e.g. EXR); otherwise it is sRGB-encoded.
inline float decode_srgb(__global const float *luts, float v)
{
#if LINEAR_FRAME
    return v;
#else
#ifdef PIXEL_IS_FLOAT
    if (v > 1.0f) return pow((v + 0.055f) * (1.0f / 1.055f), 2.4f);  // HDR float frames only
#endif
    return lut_fast(luts, v);
#endif
}

inline float encode_srgb(__global const float *luts, float v)
{
#if LINEAR_FRAME
    return v;
#else
#ifdef PIXEL_IS_FLOAT
    if (v > 1.0f) return 1.055f * pow(v, 1.0f / 2.4f) - 0.055f;
#endif
    return lut_fast(luts + LUT_ENCODE, v);
#endif
}

// Coverage of one segment's stroke (outer: .x, inner: .y) at pixel centre p. Seed 001's relative
// distance and its gradient become the exact distance `dist` to the centre line and the gradient of
// that distance, n (a unit vector: 1 per pixel; docs/grlaa.md).
inline float2 segment_cover(float px, float py, float4 g, float4 h, int meta, float strength)
{
    const float apx = px - g.x, apy = py - g.y, tx = g.z, ty = g.w;
    const float len = h.x, r = h.y, ri = h.z;
    const float along = apx * tx + apy * ty, perp = tx * apy - ty * apx;
    float nx = -ty, ny = tx, dist;
    // Round ends (joins and round caps): distance to the end point, normal along it.
    if ((len <= 0.0f && !(meta & 3)) || (along < 0.0f && !(meta & 1))
        || (along > len && !(meta & 2))) {
        const float vx = along < 0.0f ? apx : apx - len * tx;
        const float vy = along < 0.0f ? apy : apy - len * ty;
        dist = sqrt(vx * vx + vy * vy);
        if (dist > 1e-6f) { nx = vx / dist; ny = vy / dist; }
    } else {
        dist = FABS(perp);
    }
    const float na = FABS(nx) * strength, nb = FABS(ny) * strength;
    const float fa = FMAX(na, nb), fb = FMIN(na, nb);
    float co = strip_cover(dist, r, fa, fb);
    float ci = ri >= r ? co : (ri > 0.0f ? strip_cover(dist, ri, fa, fb) : 0.0f);
    if (meta & 3) {  // flat (butt / square) caps: times the coverage of the half-plane past the end
        const float ta_ = FABS(tx) * strength, tb_ = FABS(ty) * strength;
        const float ta = FMAX(ta_, tb_), tb = FMIN(ta_, tb_);
        const float ext = (meta & 4) ? r : 0.0f, ext_i = ext - (r - ri);
        if (meta & 1) {
            co *= footprint_cdf(along + ext, ta, tb);
            ci *= footprint_cdf(along + ext_i, ta, tb);
        }
        if (meta & 2) {
            co *= footprint_cdf(len - along + ext, ta, tb);
            ci *= footprint_cdf(len - along + ext_i, ta, tb);
        }
    }
    return (float2)(co, ci);
}

// The x-interval (relative to a.x) of the row at dy below a.y where pixel centres lie within R of
// the segment: the row's intersection with the capsule, which is convex, so the hull of the band
// and the end discs. Empty when .x > .y.
inline float2 row_span(float dy, float tx, float ty, float len, float R)
{
    float lo = 1e30f, hi = -1e30f;
    if (FABS(dy) <= R) {                       // disc at the start
        const float w = sqrt(R * R - dy * dy);
        lo = -w; hi = w;
    }
    const float dy1 = dy - len * ty, ex = len * tx;
    if (FABS(dy1) <= R) {                      // disc at the end
        const float w = sqrt(R * R - dy1 * dy1);
        lo = FMIN(lo, ex - w); hi = FMAX(hi, ex + w);
    }
    // band: 0 <= along <= len and |perp| <= R, both linear in x
    float blo = -1e30f, bhi = 1e30f;
    if (FABS(tx) > 1e-6f) {
        const float u0 = -dy * ty / tx, u1 = (len - dy * ty) / tx;
        blo = FMIN(u0, u1); bhi = FMAX(u0, u1);
    } else if (dy * ty < 0.0f || dy * ty > len) {
        blo = 1e30f;
    }
    if (FABS(ty) > 1e-6f) {
        const float v0 = (tx * dy - R) / ty, v1 = (tx * dy + R) / ty;
        blo = FMAX(blo, FMIN(v0, v1)); bhi = FMIN(bhi, FMAX(v0, v1));
    } else if (FABS(tx * dy) > R) {
        blo = 1e30f;
    }
    if (blo <= bhi) { lo = FMIN(lo, blo); hi = FMAX(hi, bhi); }
    return (float2)(lo, hi);
}

#define TT (TILE * TILE)

__kernel void grlaa_draw(__global PIXEL_T *img, __global const float *luts,
                         __global const float4 *segs, __global const int *seg_meta,
                         __global const int *entries, __global const int4 *tiles,
                         __global const float4 *polys, const int width, const int height,
                         const float strength, const int ntiles)
{
    const int gid = (int)get_global_id(0);
    if (gid >= ntiles) return;
    const int4 tile = tiles[gid];
    const int x0 = tile.x * TILE, y0 = tile.y * TILE;
    const int xmax = IMIN(x0 + TILE, width) - 1, ymax = IMIN(y0 + TILE, height) - 1;
    const float inner_pad = HALF_DIAGONAL * strength + 1e-4f;

    float cov_out[TT], cov_in[TT];      // current polyline's coverage (max over its segments)
    float lin_r[TT], lin_g[TT], lin_b[TT], alpha[TT];  // composited so far, valid where `loaded`
    int exact[TT];                      // 1 + 2*poly (fill) or 2 + 2*poly (outline): stored as-is
    uint loaded[TILE];                  // one bit per column
    int run_lo[TILE], run_hi[TILE];     // columns the current polyline touched, per row
    for (int i = 0; i < TT; ++i) { cov_out[i] = 0.0f; cov_in[i] = 0.0f; }
    for (int j = 0; j < TILE; ++j) { loaded[j] = 0u; run_lo[j] = TILE; run_hi[j] = -1; }

    int cur = -1;
    const int end = tile.z + tile.w;
    for (int e = tile.z; e <= end; ++e) {
        int sidx = 0, meta = -1, poly = -1;
        if (e < end) {
            sidx = entries[e];
            meta = seg_meta[sidx];
            poly = meta >> 3;
        }
        if (poly != cur && cur >= 0) {
            // Composite the finished polyline over what is below, in linear light (alpha "over").
            const float4 prm = polys[5 * cur];
            const float4 fill = polys[5 * cur + 1], outl = polys[5 * cur + 2];
            for (int j = 0; j < TILE; ++j) {
                for (int i = run_lo[j]; i <= run_hi[j]; ++i) {
                    const int k = j * TILE + i;
                    const float ao = cov_out[k], ai = cov_in[k];
                    if (ao <= 0.0f) continue;
                    cov_out[k] = 0.0f; cov_in[k] = 0.0f;
                    const float A = ao * prm.z;
                    const float cr = prm.z * (ai * fill.x + (ao - ai) * outl.x);
                    const float cg = prm.z * (ai * fill.y + (ao - ai) * outl.y);
                    const float cb = prm.z * (ai * fill.z + (ao - ai) * outl.z);
                    const uint bit = 1u << i;
                    if (A >= 1.0f) {  // opaque: what was below does not matter
                        lin_r[k] = cr; lin_g[k] = cg; lin_b[k] = cb; alpha[k] = 1.0f;
                        exact[k] = ai >= 1.0f ? 1 + 2 * cur : (ai <= 0.0f ? 2 + 2 * cur : 0);
                        loaded[j] |= bit;
                        continue;
                    }
                    float br, bg_, bb, ba;
                    if (loaded[j] & bit) {
                        br = lin_r[k]; bg_ = lin_g[k]; bb = lin_b[k]; ba = alpha[k];
                    } else {
                        const float4 bg = load_px(img, IDX(x0 + i, y0 + j, width));
                        br = decode_srgb(luts, bg.x);
                        bg_ = decode_srgb(luts, bg.y);
                        bb = decode_srgb(luts, bg.z);
                        ba = bg.w;
                        loaded[j] |= bit;
                    }
#if CHANNELS == 4
                    const float na = A + (1.0f - A) * ba;  // straight alpha
                    const float wb = na > 0.0f ? (1.0f - A) * ba / na : 0.0f;
                    const float wc = na > 0.0f ? 1.0f / na : 0.0f;
                    lin_r[k] = cr * wc + wb * br; lin_g[k] = cg * wc + wb * bg_;
                    lin_b[k] = cb * wc + wb * bb;
                    alpha[k] = na;
#else
                    lin_r[k] = cr + (1.0f - A) * br; lin_g[k] = cg + (1.0f - A) * bg_;
                    lin_b[k] = cb + (1.0f - A) * bb;
                    alpha[k] = ba;
#endif
                    exact[k] = 0;
                }
                run_lo[j] = TILE; run_hi[j] = -1;
            }
        }
        if (e == end) break;
        cur = poly;

        const float4 g = segs[2 * sidx];      // a.x, a.y, unit tangent t.x, t.y
        const float4 h = segs[2 * sidx + 1];  // length, r, r_inner, reach
        const float R = h.w, len = h.x, by = g.y + len * g.w;
        // Pixels within Ri of a segment with round ends are covered fully by both the stroke and
        // its inner part (the footprint reaches HALF_DIAGONAL * strength at most): no formula.
        const float Ri = (meta & 3) ? -1.0f : FMIN(h.y, h.z) - inner_pad;
        const int ya = IMAX(y0, iceil(FMIN(g.y, by) - R));
        const int yb = IMIN(ymax, ifloor(FMAX(g.y, by) + R));
        for (int y = ya; y <= yb; ++y) {
            const float dy = (float)y - g.y;
            const float2 sp = row_span(dy, g.z, g.w, len, R);
            const int xa = IMAX(x0, iceil(g.x + sp.x)), xb = IMIN(xmax, ifloor(g.x + sp.y));
            if (xa > xb) continue;
            const int j = y - y0;
            run_lo[j] = IMIN(run_lo[j], xa - x0);
            run_hi[j] = IMAX(run_hi[j], xb - x0);
            int ia = xb + 1, ib = xb;  // the fully covered columns [ia, ib], if any
            if (Ri > 0.0f) {
                const float2 si = row_span(dy, g.z, g.w, len, Ri);
                if (si.x <= si.y) {
                    ia = IMAX(xa, iceil(g.x + si.x));
                    ib = IMIN(xb, ifloor(g.x + si.y));
                    if (ia > ib) { ia = xb + 1; ib = xb; }
                }
            }
            const int row = j * TILE - x0;
            for (int x = xa; x < ia; ++x) {
                const float2 cv = segment_cover((float)x, (float)y, g, h, meta, strength);
                // One polyline is one shape: its segments' coverages merge by max, so joins are
                // not blended twice.
                cov_out[row + x] = FMAX(cov_out[row + x], cv.x);
                cov_in[row + x] = FMAX(cov_in[row + x], cv.y);
            }
            for (int x = ia; x <= ib; ++x) { cov_out[row + x] = 1.0f; cov_in[row + x] = 1.0f; }
            for (int x = ib + 1; x <= xb; ++x) {
                const float2 cv = segment_cover((float)x, (float)y, g, h, meta, strength);
                cov_out[row + x] = FMAX(cov_out[row + x], cv.x);
                cov_in[row + x] = FMAX(cov_in[row + x], cv.y);
            }
        }
    }

    // Write back only the pixels some line covered; the others keep their exact values.
    for (int j = 0; j < TILE; ++j) {
        uint bits = loaded[j];
        for (int i = 0; bits; ++i, bits >>= 1) {
            if (!(bits & 1u)) continue;
            const int k = j * TILE + i;
            float4 outc;
            if (exact[k]) {
                const int q = (exact[k] - 1) >> 1;
                outc = polys[5 * q + 3 + ((exact[k] - 1) & 1)];
                outc.w = 1.0f;
            } else {
                outc = (float4)(encode_srgb(luts, lin_r[k]), encode_srgb(luts, lin_g[k]),
                                encode_srgb(luts, lin_b[k]), alpha[k]);
            }
            store_px(img, IDX(x0 + i, y0 + j, width), outc);
        }
    }
}
