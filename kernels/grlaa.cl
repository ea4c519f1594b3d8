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
// non-empty tile: for each listed segment it visits, row by row, the 8-pixel groups (float8 lanes)
// that meet the band |perp| <= reach cut to the segment's x-extent (linear in the row), so groups
// away from lines cost nothing; the coverage formula runs on all 8 lanes at once, with selects
// (lanes beyond the reach get exactly 0, the stroke's interior exactly 1). Each polyline's coverage
// (max over its segments) is composited, 8 lanes at a time, once it is complete; the frame's pixel
// is read, decoded and put under the layers only once, at write-back, and only where the layers
// are not opaque.
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

// Eight pixels of a tile row at once (float8 lanes: PoCL maps them onto the CPU's vector unit).
typedef float8 f8;
typedef int8 i8;
#define F8ABS(v) ((v) < 0.0f ? -(v) : (v))
#define F8MAX(a, b) ((a) > (b) ? (a) : (b))

// footprint_cdf per lane, with h = (a + b) / 2 and the inverses ia = 1 / a, i2 = 1 / (2ab) passed in
// (i2 is not used where b = 0). Selects instead of branches: the trapezoid's piece changes from lane
// to lane. Exactly 0 and 1 beyond the ramp, as footprint_cdf.
INLINE f8 fcdf8(f8 s, f8 a, f8 b, f8 h, f8 ia, f8 i2)
{
    const f8 x = s + h, ab = a + b, y = ab - x;
    f8 q = x <= a ? (x - 0.5f * b) * ia : 1.0f - y * y * i2;
    q = x < b ? x * x * i2 : q;
    q = x >= ab ? (f8)1.0f : q;
    return x <= 0.0f ? (f8)0.0f : q;
}

// segment_cover for a segment with round ends (no flags), the common case, at 8 pixel centres of a
// row: (fx, dy) = p - a, dy1 = p.y - b.y; (sa >= sb) the footprint widths on the body's normal.
// Same arithmetic as segment_cover; the end discs' terms only where a lane lies beyond an end.
INLINE void round_cover8(f8 fx, float dy, float dy1, float tx, float ty, float len, float r,
                         float ri, float sa, float sb, float sh, float sia, float si2,
                         float strength, f8 *co, f8 *ci)
{
    const f8 along = fx * tx + dy * ty;
    const f8 perp = tx * dy - ty * fx;
    f8 dist = F8ABS(perp), fa = (f8)sa, fb = (f8)sb, h = (f8)sh, ia = (f8)sia, i2 = (f8)si2;
    const float l0 = along.s0, l7 = along.s7;  // along is linear in x: its extremes are the end lanes
    if (FMIN(l0, l7) < 0.0f || FMAX(l0, l7) > len) {
        const i8 st = along < 0.0f, en = along > len;
        const f8 vx = st ? fx : fx - len * tx, vy = st ? (f8)dy : (f8)dy1;
        const f8 dd = sqrt(vx * vx + vy * vy);
        const i8 disc = st | en, rad = disc & (dd > 1e-6f);  // the footprint on the radial normal
        const f8 ux = F8ABS(vx), uy = F8ABS(vy), k = strength / (rad ? dd : (f8)1.0f);
        dist = disc ? dd : dist;
        fa = rad ? (ux > uy ? ux : uy) * k : fa;
        fb = rad ? (ux > uy ? uy : ux) * k : fb;
        h = 0.5f * (fa + fb); ia = 1.0f / fa; i2 = 0.5f * ia / fb;
    }
    // The strip |u| <= r is F(r - d) - F(-r - d); the second term is 0 when r >= (a + b) / 2, the
    // footprint's half extent, which is at most HALF_DIAGONAL * strength (wide strokes).
    const float wide = HALF_DIAGONAL * strength + 1e-4f;
    f8 o = fcdf8(r - dist, fa, fb, h, ia, i2);
    if (r < wide) o -= fcdf8(-r - dist, fa, fb, h, ia, i2);
    *co = o;
    if (ri >= r) {
        *ci = o;
    } else if (ri > 0.0f) {
        f8 n = fcdf8(ri - dist, fa, fb, h, ia, i2);
        if (ri < wide) n -= fcdf8(-ri - dist, fa, fb, h, ia, i2);
        *ci = n;
    } else {
        *ci = (f8)0.0f;
    }
}

#define TT (TILE * TILE)
#define CH (TILE / 8)   // float8 chunks per tile row

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
    const f8 lane = (f8)(0.0f, 1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 6.0f, 7.0f);

    f8 cov_out[TT / 8], cov_in[TT / 8];  // current polyline's coverage (max over its segments)
    // Layers so far, premultiplied "over" without the frame: colour acc, transmittance trans (the
    // frame's pixel joins once, at write-back); hit > 0 where some line covers the pixel.
    f8 acc_r[TT / 8], acc_g[TT / 8], acc_b[TT / 8], trans[TT / 8], hit[TT / 8];
    i8 exact[TT / 8];                   // 1 + 2*poly (fill) or 2 + 2*poly (outline): stored as-is
    uint rows_cur[TILE], rows_all[TILE];  // per row, one bit per chunk: the current / any polyline
    for (int k = 0; k < TT / 8; ++k) {
        cov_out[k] = 0.0f; cov_in[k] = 0.0f; acc_r[k] = 0.0f; acc_g[k] = 0.0f; acc_b[k] = 0.0f;
        trans[k] = 1.0f; hit[k] = 0.0f; exact[k] = 0;
    }
    for (int j = 0; j < TILE; ++j) { rows_cur[j] = 0u; rows_all[j] = 0u; }
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
            // Where it does not reach, A = 0 and the layers stay as they are.
            const float4 prm = polys[5 * cur];
            const float4 fill = polys[5 * cur + 1], outl = polys[5 * cur + 2];
            const float op = prm.z;
            const int ef = 1 + 2 * cur, eo = 2 + 2 * cur;
            for (int j = 0; j < TILE; ++j) {
                const uint bits = rows_cur[j];
                if (!bits) continue;
                rows_all[j] |= bits;
                rows_cur[j] = 0u;
                for (int c = 0; c < CH; ++c) {
                    if (!(bits & (1u << c))) continue;
                    const int k = j * CH + c;
                    const f8 ao = cov_out[k], ai = cov_in[k];
                    cov_out[k] = 0.0f; cov_in[k] = 0.0f;
                    const f8 A = ao * op, T = 1.0f - A, ae = ao - ai;
                    acc_r[k] = op * (ai * fill.x + ae * outl.x) + T * acc_r[k];
                    acc_g[k] = op * (ai * fill.y + ae * outl.y) + T * acc_g[k];
                    acc_b[k] = op * (ai * fill.z + ae * outl.z) + T * acc_b[k];
                    trans[k] = T * trans[k];
                    hit[k] = F8MAX(hit[k], ao);
                    const i8 ex = ai >= 1.0f ? (i8)ef : (ai <= 0.0f ? (i8)eo : (i8)0);
                    exact[k] = A >= 1.0f ? ex : (ao > 0.0f ? (i8)0 : exact[k]);
                }
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
        // Row spans (conservative): the band |perp| <= R, x - a.x = dy t.x / t.y +- R / |t.y|, cut to
        // the segment's x-extent grown by R. Lanes beyond the reach get coverage 0.
        const int ok_n = FABS(ty) > 1e-6f;
        const float s_p = ok_n ? tx / ty : 0.0f, w_p = ok_n ? R / FABS(ty) : 1e30f;
        const float bxl = FMIN(0.0f, len * tx) - R, bxh = FMAX(0.0f, len * tx) + R;
        // the footprint on the body's normal n = (-t.y, t.x): widths, half sum, inverses (fcdf8)
        const float sa = FMAX(FABS(ty), FABS(tx)) * strength, sb = FMIN(FABS(ty), FABS(tx)) * strength;
        const float sh = 0.5f * (sa + sb), sia = 1.0f / sa, si2 = 0.5f * sia / sb;
        const f8 fx0 = ((float)x0 - ax) + lane;
        for (int y = ya; y <= yb; ++y) {
            const float dy = (float)y - ay, dy1 = (float)y - by, c = dy * s_p;
            const float lo = FMAX(c - w_p, bxl), hi = FMIN(c + w_p, bxh);
            const int xa = IMAX(x0, iceil(ax + lo)), xb = IMIN(x0 + TILE - 1, ifloor(ax + hi));
            if (xa > xb) continue;
            const int j = y - y0, ca = (xa - x0) >> 3, cb = (xb - x0) >> 3;
            rows_cur[j] |= ((2u << cb) - 1u) & ~((1u << ca) - 1u);
            // One polyline is one shape: its segments' coverages merge by max, so joins are not
            // blended twice. Lanes beyond the segment's reach get exactly 0.
            for (int c = ca; c <= cb; ++c) {
                const int k = j * CH + c;
                const f8 fx = fx0 + (float)(8 * c);
                f8 co, ci;
                if (meta & 3) {
                    const float xs = (float)(x0 + 8 * c), yf = (float)y;
                    float o[8], n[8];
                    for (int i = 0; i < 8; ++i) {
                        const float2 cv = segment_cover(xs + (float)i, yf, g, h, meta, strength);
                        o[i] = cv.x; n[i] = cv.y;
                    }
                    co = vload8(0, o); ci = vload8(0, n);
                } else {
                    round_cover8(fx, dy, dy1, tx, ty, len, r, ri, sa, sb, sh, sia, si2, strength,
                                 &co, &ci);
                }
                cov_out[k] = F8MAX(cov_out[k], co);
                cov_in[k] = F8MAX(cov_in[k], ci);
            }
        }
    }

    // Write back only the pixels some line covered; the others keep their exact values.
    __private const float *hs = (__private const float *)hit;
    __private const float *ar = (__private const float *)acc_r;
    __private const float *ag = (__private const float *)acc_g;
    __private const float *ab = (__private const float *)acc_b;
    __private const float *tr = (__private const float *)trans;
    __private const int *exs = (__private const int *)exact;
    for (int j = 0; j <= ymax - y0; ++j) {
        const uint bits = rows_all[j];
        if (!bits) continue;
        const int xe = IMIN(TILE, xmax - x0 + 1);
        for (int i = 0; i < xe; ++i) {
            if (!(bits & (1u << (i >> 3)))) { i |= 7; continue; }
            const int k = j * TILE + i;
            if (!(hs[k] > 0.0f)) continue;
            const int idx = IDX(x0 + i, y0 + j, width);
            float4 outc;
            const int ex = exs[k];
            if (ex) {
                outc = polys[5 * ((ex - 1) >> 1) + 3 + ((ex - 1) & 1)];
                outc.w = 1.0f;
            } else {
                const float T = tr[k];
                float cr = ar[k], cg = ag[k], cb = ab[k], a = 1.0f;
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
