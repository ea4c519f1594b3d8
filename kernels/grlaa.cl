// grlaa.cl: GRLAA antialiased polylines (roads, routes) with an outline, composited over a frame.
// Seed 001 (GRadient Line Anti-Aliasing). The seed's fragment shader gets a base value interpolated
// from -1 to +1 across the road, takes distance = 1 - |base| and blend_range = ANTIALIAS_STRENGTH *
// |grad base| (dFdx, dFdy), and ramps alpha over blend_range. Here every pixel computes the exact
// distance to the centre line and the gradient of that distance (the unit normal n, |n| = 1 per
// pixel); the ramp is the pixel's footprint (STRENGTH x STRENGTH box) projected on n, whose widths
// are STRENGTH*|n.x| and STRENGTH*|n.y|, i.e. the gradient's components (docs/grlaa.md).
//
// Defines (mlaa_stream.formats.defines_for): PIXEL_T, CHANNELS, PIXEL_MAX, ORDER_BGR, LUT_SIZE,
// PIXEL_IS_FLOAT; LINEAR_FRAME (1: samples are linear light, not sRGB); DECODE8 (1: uint8 sRGB
// frames, decoded through dec8, 256 entries); TILE (edge of a square screen tile in pixels).
//
// Host data (mlaa_stream.overlay): segments binned into TILE x TILE tiles. One work-item draws one
// non-empty tile: for each listed segment it visits, row by row, only the pixels whose centres lie
// within the segment's reach (an interval per row, linear in the row but for the end discs), so
// pixels away from lines cost nothing; in the stroke's interior it writes 1 without the formula.
// Each polyline's coverage (max over its segments) is composited once it is complete; the frame's
// pixel is read, decoded and put under the layers only once, at write-back, and only where the
// layers are not opaque.
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
#ifndef DECODE8
#define DECODE8 0
#endif

#define LUT_ENCODE (2 * (LUT_SIZE + 1))

// PoCL's CPU build calls even small helpers out of line (a call per pixel); ask for inlining.
#define INLINE inline __attribute__((always_inline))

// A cache prefetch hint. OpenCL's prefetch() is a no-op on PoCL's CPU device, where reading the
// frame's pixels (cold cache lines, a row apart) is what a tile waits on most.
#if defined(__has_builtin)
#if __has_builtin(__builtin_prefetch)
#define PREFETCH(p) __builtin_prefetch(p)
#endif
#endif
#ifndef PREFETCH
#define PREFETCH(p) prefetch(p, 1)
#endif

// PoCL's CPU build here calls OpenCL builtins (fmin, fabs, clamp, mad, floor, ...) out of line, and
// floor/ceil/rint in software; the hot loops below use these plain expressions instead.
#define FMIN(a, b) ((a) < (b) ? (a) : (b))
#define FMAX(a, b) ((a) > (b) ? (a) : (b))
#define FABS(a) ((a) < 0.0f ? -(a) : (a))
#define IMIN(a, b) ((a) < (b) ? (a) : (b))
#define IMAX(a, b) ((a) > (b) ? (a) : (b))
#define HALF_DIAGONAL 0.70711f

// floor / ceil to int for |x| < 2^24 (coordinates are clipped to the frame on the host).
INLINE int ifloor(float x) { int i = (int)x; return i - (x < (float)i); }
INLINE int iceil(float x) { int i = (int)x; return i + (x > (float)i); }

// common.cl's lut_read, written with plain expressions (same arithmetic).
INLINE float lut_fast(__global const float *lut, float x)
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
INLINE float footprint_cdf(float s, float a, float b)
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
INLINE float strip_cover(float d, float r, float a, float b)
{
    return footprint_cdf(r - d, a, b) - footprint_cdf(-r - d, a, b);
}

// LINEAR_FRAME: the frame already holds linear light (e.g. EXR); otherwise it is sRGB-encoded.
INLINE float decode_srgb(__global const float *luts, float v)
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

INLINE float encode_srgb(__global const float *luts, float v)
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
// that distance, n (a unit vector: 1 per pixel; docs/grlaa.md). The general form, with flat caps.
INLINE float2 segment_cover(float px, float py, float4 g, float4 h, int meta, float strength)
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

// segment_cover for a segment with round ends (no flags), the common case, with what is constant
// along the segment passed in: (fx, dy) = p - a, dy1 = p.y - b.y, (sa, sb) the footprint widths on
// the body's normal. Same arithmetic as segment_cover.
INLINE float2 round_cover(float fx, float dy, float dy1, float tx, float ty, float len, float r,
                          float ri, float sa, float sb, float strength)
{
    const float along = fx * tx + dy * ty;
    float dist, fa = sa, fb = sb;
    if (along < 0.0f || along > len) {
        const float vx = along < 0.0f ? fx : fx - len * tx;
        const float vy = along < 0.0f ? dy : dy1;
        dist = sqrt(vx * vx + vy * vy);
        if (dist > 1e-6f) {
            const float na = FABS(vx) * (strength / dist), nb = FABS(vy) * (strength / dist);
            fa = FMAX(na, nb); fb = FMIN(na, nb);
        }
    } else {
        const float perp = tx * dy - ty * fx;
        dist = FABS(perp);
    }
    const float co = strip_cover(dist, r, fa, fb);
    return (float2)(co, ri >= r ? co : (ri > 0.0f ? strip_cover(dist, ri, fa, fb) : 0.0f));
}

// The row's x-interval (relative to a.x) where pixel centres lie within Rr of the segment: the
// capsule is convex, so the hull of the band's interval and the end discs' chords. The band is
// 0 <= along <= len (x in dy * s_a + [a0, a1]) and |perp| <= Rr (x in dy * s_p +- w_p); ok_t / ok_n:
// the tangent / normal has an x component (else that condition does not depend on x). Empty when
// .x > .y.
INLINE float2 row_span(float dy, float dy1, float tx, float ty, float len, float Rr, int ok_t,
                       float s_a, float a0, float a1, int ok_n, float s_p, float w_p)
{
    float blo, bhi, plo, phi;
    if (ok_t) {
        blo = dy * s_a + a0; bhi = dy * s_a + a1;
    } else {
        const float u = dy * ty;
        const int in = u >= 0.0f && u <= len;
        blo = in ? -1e30f : 1e30f; bhi = -blo;
    }
    if (ok_n) {
        const float c = dy * s_p;
        plo = c - w_p; phi = c + w_p;
    } else {
        const int in = FABS(tx * dy) <= Rr;
        plo = in ? -1e30f : 1e30f; phi = -plo;
    }
    float lo = FMAX(blo, plo), hi = FMIN(bhi, phi);
    if (lo > hi) { lo = 1e30f; hi = -1e30f; }
    if (FABS(dy) <= Rr) {                       // disc at the start
        const float w = sqrt(Rr * Rr - dy * dy);
        lo = FMIN(lo, -w); hi = FMAX(hi, w);
    }
    if (FABS(dy1) <= Rr) {                      // disc at the end
        const float w = sqrt(Rr * Rr - dy1 * dy1), ex = len * tx;
        lo = FMIN(lo, ex - w); hi = FMAX(hi, ex + w);
    }
    return (float2)(lo, hi);
}

#define TT (TILE * TILE)

__kernel void grlaa_draw(__global PIXEL_T *img, __global const float *luts,
                         __global const float *dec8, __global const float4 *segs,
                         __global const int *seg_meta, __global const int *entries,
                         __global const int4 *tiles, __global const float4 *polys,
                         const int width, const int height, const float strength, const int ntiles)
{
    const int gid = (int)get_global_id(0);
    if (gid >= ntiles) return;
    const int4 tile = tiles[gid];
    const int x0 = tile.x * TILE, y0 = tile.y * TILE;
    const int xmax = IMIN(x0 + TILE, width) - 1, ymax = IMIN(y0 + TILE, height) - 1;
    const float inner_pad = HALF_DIAGONAL * strength + 1e-4f;

    float cov_out[TT], cov_in[TT];      // current polyline's coverage (max over its segments)
    // Layers so far, premultiplied "over" without the frame: colour acc, transmittance trans; the
    // frame's pixel joins once, at write-back (valid where `touched`).
    float acc_r[TT], acc_g[TT], acc_b[TT], trans[TT];
    int exact[TT];                      // 1 + 2*poly (fill) or 2 + 2*poly (outline): stored as-is
    uint touched[TILE];                 // one bit per column
    int run_lo[TILE], run_hi[TILE];     // columns the current polyline touched, per row
    for (int i = 0; i < TT; ++i) { cov_out[i] = 0.0f; cov_in[i] = 0.0f; }
    for (int j = 0; j < TILE; ++j) { touched[j] = 0u; run_lo[j] = TILE; run_hi[j] = -1; }
    // The tile's rows of the frame are read at write-back: ask for them now.
    for (int j = 0; j <= ymax - y0; ++j) {
        PREFETCH(img + (size_t)IDX(x0, y0 + j, width) * CHANNELS);
        PREFETCH(img + (size_t)IDX(xmax, y0 + j, width) * CHANNELS);
    }

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
            // Composite the finished polyline over the layers below (linear light, alpha "over").
            const float4 prm = polys[5 * cur];
            const float4 fill = polys[5 * cur + 1], outl = polys[5 * cur + 2];
            const float op = prm.z;
            for (int j = 0; j < TILE; ++j) {
                uint tb = touched[j];
                for (int i = run_lo[j]; i <= run_hi[j]; ++i) {
                    const int k = j * TILE + i;
                    const float ao = cov_out[k], ai = cov_in[k];
                    if (ao <= 0.0f) continue;
                    cov_out[k] = 0.0f; cov_in[k] = 0.0f;
                    const float A = ao * op, T = 1.0f - A;
                    const uint bit = 1u << i;
                    const int seen = (tb & bit) != 0u;
                    acc_r[k] = op * (ai * fill.x + (ao - ai) * outl.x) + T * (seen ? acc_r[k] : 0.0f);
                    acc_g[k] = op * (ai * fill.y + (ao - ai) * outl.y) + T * (seen ? acc_g[k] : 0.0f);
                    acc_b[k] = op * (ai * fill.z + (ao - ai) * outl.z) + T * (seen ? acc_b[k] : 0.0f);
                    trans[k] = T * (seen ? trans[k] : 1.0f);
                    exact[k] = A >= 1.0f ? (ai >= 1.0f ? 1 + 2 * cur : (ai <= 0.0f ? 2 + 2 * cur : 0)) : 0;
                    tb |= bit;
                }
                touched[j] = tb;
                run_lo[j] = TILE; run_hi[j] = -1;
            }
        }
        if (e == end) break;
        cur = poly;

        const float4 g = segs[2 * sidx];      // a.x, a.y, unit tangent t.x, t.y
        const float4 h = segs[2 * sidx + 1];  // length, r, r_inner, reach
        const float ax = g.x, ay = g.y, tx = g.z, ty = g.w;
        const float len = h.x, r = h.y, ri = h.z, R = h.w, by = ay + len * ty;
        const int ya = IMAX(y0, iceil(FMIN(ay, by) - R));
        const int yb = IMIN(ymax, ifloor(FMAX(ay, by) + R));
        // Row spans: x - a.x = (along - dy t.y) / t.x and (t.x dy - perp) / t.y, linear in dy.
        const int ok_t = FABS(tx) > 1e-6f, ok_n = FABS(ty) > 1e-6f;
        const float itx = ok_t ? 1.0f / tx : 0.0f, ity = ok_n ? 1.0f / ty : 0.0f;
        const float s_a = -ty * itx, a0 = FMIN(0.0f, len * itx), a1 = FMAX(0.0f, len * itx);
        const float s_p = tx * ity, w_p = R * FABS(ity);
        // Pixels within Ri of a segment with round ends are covered fully by both the stroke and
        // its inner part (the footprint reaches HALF_DIAGONAL * strength at most): no formula.
        const float Ri = (meta & 3) ? -1.0f : FMIN(r, ri) - inner_pad, w_pi = Ri * FABS(ity);
        // the footprint widths on the body's normal n = (-t.y, t.x)
        const float sa = FMAX(FABS(ty), FABS(tx)) * strength, sb = FMIN(FABS(ty), FABS(tx)) * strength;
        for (int y = ya; y <= yb; ++y) {
            const float dy = (float)y - ay, dy1 = (float)y - by;
            const float2 sp = row_span(dy, dy1, tx, ty, len, R, ok_t, s_a, a0, a1, ok_n, s_p, w_p);
            const int xa = IMAX(x0, iceil(ax + sp.x)), xb = IMIN(xmax, ifloor(ax + sp.y));
            if (xa > xb) continue;
            const int j = y - y0;
            run_lo[j] = IMIN(run_lo[j], xa - x0);
            run_hi[j] = IMAX(run_hi[j], xb - x0);
            int ia = xb + 1, ib = xb;  // the fully covered columns [ia, ib], if any
            if (Ri > 0.0f) {
                const float2 si = row_span(dy, dy1, tx, ty, len, Ri, ok_t, s_a, a0, a1, ok_n, s_p, w_pi);
                if (si.x <= si.y) {
                    ia = IMAX(xa, iceil(ax + si.x));
                    ib = IMIN(xb, ifloor(ax + si.y));
                    if (ia > ib) { ia = xb + 1; ib = xb; }
                }
            }
            const int row = j * TILE - x0;
            // One polyline is one shape: its segments' coverages merge by max, so joins are not
            // blended twice.
            if (meta & 3) {
                for (int x = xa; x <= xb; ++x) {
                    const float2 cv = segment_cover((float)x, (float)y, g, h, meta, strength);
                    cov_out[row + x] = FMAX(cov_out[row + x], cv.x);
                    cov_in[row + x] = FMAX(cov_in[row + x], cv.y);
                }
                continue;
            }
            for (int x = xa; x < ia; ++x) {
                const float2 cv = round_cover((float)x - ax, dy, dy1, tx, ty, len, r, ri, sa, sb, strength);
                cov_out[row + x] = FMAX(cov_out[row + x], cv.x);
                cov_in[row + x] = FMAX(cov_in[row + x], cv.y);
            }
            for (int x = ia; x <= ib; ++x) { cov_out[row + x] = 1.0f; cov_in[row + x] = 1.0f; }
            for (int x = ib + 1; x <= xb; ++x) {
                const float2 cv = round_cover((float)x - ax, dy, dy1, tx, ty, len, r, ri, sa, sb, strength);
                cov_out[row + x] = FMAX(cov_out[row + x], cv.x);
                cov_in[row + x] = FMAX(cov_in[row + x], cv.y);
            }
        }
    }

    // Write back only the pixels some line covered; the others keep their exact values.
    for (int j = 0; j < TILE; ++j) {
        uint bits = touched[j];
        for (int i = 0; bits; ++i, bits >>= 1) {
            if (!(bits & 1u)) continue;
            const int k = j * TILE + i;
            const int idx = IDX(x0 + i, y0 + j, width);
            float4 outc;
            if (exact[k]) {
                const int q = (exact[k] - 1) >> 1;
                outc = polys[5 * q + 3 + ((exact[k] - 1) & 1)];
                outc.w = 1.0f;
            } else {
                const float T = trans[k];
                float cr = acc_r[k], cg = acc_g[k], cb = acc_b[k], a = 1.0f;
                if (T > 0.0f) {  // the frame shows through: decode it and put it under the layers
#if DECODE8
                    __global const uchar *p = (__global const uchar *)img + (size_t)idx * CHANNELS;
#if CHANNELS == 1
                    const float br = dec8[p[0]], bg_ = br, bb = br;
#elif ORDER_BGR
                    const float br = dec8[p[2]], bg_ = dec8[p[1]], bb = dec8[p[0]];
#else
                    const float br = dec8[p[0]], bg_ = dec8[p[1]], bb = dec8[p[2]];
#endif
#if CHANNELS == 4
                    const float ba = (float)p[3] * (1.0f / 255.0f);
#else
                    const float ba = 1.0f;
#endif
#else
                    const float4 bgp = load_px(img, idx);
                    const float br = decode_srgb(luts, bgp.x), bg_ = decode_srgb(luts, bgp.y);
                    const float bb = decode_srgb(luts, bgp.z), ba = bgp.w;
#endif
#if CHANNELS == 4
                    // straight alpha: premultiplied sum over the frame's premultiplied colour
                    a = 1.0f - T * (1.0f - ba);
                    const float wb = T * ba, wc = a > 0.0f ? 1.0f / a : 0.0f;
                    cr = (cr + wb * br) * wc; cg = (cg + wb * bg_) * wc; cb = (cb + wb * bb) * wc;
#else
                    cr += T * br; cg += T * bg_; cb += T * bb;
#endif
                }
                outc = (float4)(encode_srgb(luts, cr), encode_srgb(luts, cg), encode_srgb(luts, cb), a);
            }
            store_px(img, idx, outc);
        }
    }
}
