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
// frames, decoded through dec8, 256 entries, and encoded through enc8); TILE (edge of a square
// screen tile in pixels).
//
// Per frame (mlaa_stream.overlay.OverlayRenderer): grlaa_segments builds the segment tables from
// the polylines' points and bins each segment into the TILE x TILE tiles it can touch (or, for
// points far off the frame, the host builds the tables in float64 and grlaa_bin bins them); then
// grlaa_draw runs one work-item per tile: for each listed segment it visits, row by row, the
// 8-pixel groups (float8 lanes) that meet the band |perp| <= reach cut to the segment's x-extent
// (linear in the row), so groups away from lines cost nothing; the coverage formula runs on all 8
// lanes at once, with selects (lanes beyond the reach get exactly 0, the stroke's interior exactly
// 1). Each polyline's coverage (max over its segments) is composited, 8 lanes at a time, once it
// is complete; the frame's pixel is read, decoded and put under the layers only once, at
// write-back, and only where some line covers it.
//   segs[2s]    float4 (x0, y0, tx, ty): start and unit tangent, in pixels (pixel centres at integers)
//   segs[2s+1]  float4 (length, r, r_inner, reach): reach = farthest touched pixel centre (-1: cut
//               away by the clipping, not binned)
//   seg_meta[s] (polyline << 3) | flags: 1 flat start, 2 flat end, 4 square (flat ends extended by r)
//   counts[t]   entries of tile t (row-major), at entries[t * cap ..], in any order (grlaa_bin_one;
//               sorted into drawing order by grlaa_draw, which also clears the count)
//   polys[5k..5k+4] float4: (r, r_inner, opacity, 0), fill linear RGB, outline linear RGB,
//                   fill and outline as stored in the frame (normalised), written as-is where covered
//   pcol[1 + 2k], pcol[2 + 2k]  uint8 frames: fill and outline bytes, (R << 16) | (G << 8) | B
//   enc8[i]     uint8 frames: the sRGB byte of linear light i / 65535 (the LUT encode, rounded)
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
// frame's pixels (cold cache lines, a row apart) is what a tile waits on most. Clang's builtin only on
// PoCL: other clang-based compilers (rusticl's SPIR-V path) reject llvm.prefetch.
#ifdef POCL_DEVICE_ADDRESS_BITS
#define PREFETCH(p) __builtin_prefetch(p)
#else
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
        dist = SQRT(vx * vx + vy * vy);
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
#define F8MIN(a, b) ((a) < (b) ? (a) : (b))
INLINE f8 sqrt8(f8 v)
{
#ifdef POCL_DEVICE_ADDRESS_BITS
    return (f8)(SQRT(v.s0), SQRT(v.s1), SQRT(v.s2), SQRT(v.s3), SQRT(v.s4), SQRT(v.s5), SQRT(v.s6),
                SQRT(v.s7));
#else
    return sqrt(v);
#endif
}

// The set bits of an 8-bit mask: their indices as the bytes of a ulong, lowest bit first in the
// lowest byte (LANES), and their count (POPC). The write-back lists a chunk's pixels with them.
__constant ulong LANES[256] = {
    0x0UL, 0x0UL, 0x1UL, 0x100UL, 0x2UL,
    0x200UL, 0x201UL, 0x20100UL, 0x3UL, 0x300UL,
    0x301UL, 0x30100UL, 0x302UL, 0x30200UL, 0x30201UL,
    0x3020100UL, 0x4UL, 0x400UL, 0x401UL, 0x40100UL,
    0x402UL, 0x40200UL, 0x40201UL, 0x4020100UL, 0x403UL,
    0x40300UL, 0x40301UL, 0x4030100UL, 0x40302UL, 0x4030200UL,
    0x4030201UL, 0x403020100UL, 0x5UL, 0x500UL, 0x501UL,
    0x50100UL, 0x502UL, 0x50200UL, 0x50201UL, 0x5020100UL,
    0x503UL, 0x50300UL, 0x50301UL, 0x5030100UL, 0x50302UL,
    0x5030200UL, 0x5030201UL, 0x503020100UL, 0x504UL, 0x50400UL,
    0x50401UL, 0x5040100UL, 0x50402UL, 0x5040200UL, 0x5040201UL,
    0x504020100UL, 0x50403UL, 0x5040300UL, 0x5040301UL, 0x504030100UL,
    0x5040302UL, 0x504030200UL, 0x504030201UL, 0x50403020100UL, 0x6UL,
    0x600UL, 0x601UL, 0x60100UL, 0x602UL, 0x60200UL,
    0x60201UL, 0x6020100UL, 0x603UL, 0x60300UL, 0x60301UL,
    0x6030100UL, 0x60302UL, 0x6030200UL, 0x6030201UL, 0x603020100UL,
    0x604UL, 0x60400UL, 0x60401UL, 0x6040100UL, 0x60402UL,
    0x6040200UL, 0x6040201UL, 0x604020100UL, 0x60403UL, 0x6040300UL,
    0x6040301UL, 0x604030100UL, 0x6040302UL, 0x604030200UL, 0x604030201UL,
    0x60403020100UL, 0x605UL, 0x60500UL, 0x60501UL, 0x6050100UL,
    0x60502UL, 0x6050200UL, 0x6050201UL, 0x605020100UL, 0x60503UL,
    0x6050300UL, 0x6050301UL, 0x605030100UL, 0x6050302UL, 0x605030200UL,
    0x605030201UL, 0x60503020100UL, 0x60504UL, 0x6050400UL, 0x6050401UL,
    0x605040100UL, 0x6050402UL, 0x605040200UL, 0x605040201UL, 0x60504020100UL,
    0x6050403UL, 0x605040300UL, 0x605040301UL, 0x60504030100UL, 0x605040302UL,
    0x60504030200UL, 0x60504030201UL, 0x6050403020100UL, 0x7UL, 0x700UL,
    0x701UL, 0x70100UL, 0x702UL, 0x70200UL, 0x70201UL,
    0x7020100UL, 0x703UL, 0x70300UL, 0x70301UL, 0x7030100UL,
    0x70302UL, 0x7030200UL, 0x7030201UL, 0x703020100UL, 0x704UL,
    0x70400UL, 0x70401UL, 0x7040100UL, 0x70402UL, 0x7040200UL,
    0x7040201UL, 0x704020100UL, 0x70403UL, 0x7040300UL, 0x7040301UL,
    0x704030100UL, 0x7040302UL, 0x704030200UL, 0x704030201UL, 0x70403020100UL,
    0x705UL, 0x70500UL, 0x70501UL, 0x7050100UL, 0x70502UL,
    0x7050200UL, 0x7050201UL, 0x705020100UL, 0x70503UL, 0x7050300UL,
    0x7050301UL, 0x705030100UL, 0x7050302UL, 0x705030200UL, 0x705030201UL,
    0x70503020100UL, 0x70504UL, 0x7050400UL, 0x7050401UL, 0x705040100UL,
    0x7050402UL, 0x705040200UL, 0x705040201UL, 0x70504020100UL, 0x7050403UL,
    0x705040300UL, 0x705040301UL, 0x70504030100UL, 0x705040302UL, 0x70504030200UL,
    0x70504030201UL, 0x7050403020100UL, 0x706UL, 0x70600UL, 0x70601UL,
    0x7060100UL, 0x70602UL, 0x7060200UL, 0x7060201UL, 0x706020100UL,
    0x70603UL, 0x7060300UL, 0x7060301UL, 0x706030100UL, 0x7060302UL,
    0x706030200UL, 0x706030201UL, 0x70603020100UL, 0x70604UL, 0x7060400UL,
    0x7060401UL, 0x706040100UL, 0x7060402UL, 0x706040200UL, 0x706040201UL,
    0x70604020100UL, 0x7060403UL, 0x706040300UL, 0x706040301UL, 0x70604030100UL,
    0x706040302UL, 0x70604030200UL, 0x70604030201UL, 0x7060403020100UL, 0x70605UL,
    0x7060500UL, 0x7060501UL, 0x706050100UL, 0x7060502UL, 0x706050200UL,
    0x706050201UL, 0x70605020100UL, 0x7060503UL, 0x706050300UL, 0x706050301UL,
    0x70605030100UL, 0x706050302UL, 0x70605030200UL, 0x70605030201UL, 0x7060503020100UL,
    0x7060504UL, 0x706050400UL, 0x706050401UL, 0x70605040100UL, 0x706050402UL,
    0x70605040200UL, 0x70605040201UL, 0x7060504020100UL, 0x706050403UL, 0x70605040300UL,
    0x70605040301UL, 0x7060504030100UL, 0x70605040302UL, 0x7060504030200UL, 0x7060504030201UL,
    0x706050403020100UL
};
__constant uchar POPC[256] = {
    0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4, 1, 2, 2, 3, 2, 3, 3, 4, 2, 3, 3, 4, 3, 4, 4, 5,
    1, 2, 2, 3, 2, 3, 3, 4, 2, 3, 3, 4, 3, 4, 4, 5, 2, 3, 3, 4, 3, 4, 4, 5, 3, 4, 4, 5, 4, 5, 5, 6,
    1, 2, 2, 3, 2, 3, 3, 4, 2, 3, 3, 4, 3, 4, 4, 5, 2, 3, 3, 4, 3, 4, 4, 5, 3, 4, 4, 5, 4, 5, 5, 6,
    2, 3, 3, 4, 3, 4, 4, 5, 3, 4, 4, 5, 4, 5, 5, 6, 3, 4, 4, 5, 4, 5, 5, 6, 4, 5, 5, 6, 5, 6, 6, 7,
    1, 2, 2, 3, 2, 3, 3, 4, 2, 3, 3, 4, 3, 4, 4, 5, 2, 3, 3, 4, 3, 4, 4, 5, 3, 4, 4, 5, 4, 5, 5, 6,
    2, 3, 3, 4, 3, 4, 4, 5, 3, 4, 4, 5, 4, 5, 5, 6, 3, 4, 4, 5, 4, 5, 5, 6, 4, 5, 5, 6, 5, 6, 6, 7,
    2, 3, 3, 4, 3, 4, 4, 5, 3, 4, 4, 5, 4, 5, 5, 6, 3, 4, 4, 5, 4, 5, 5, 6, 4, 5, 5, 6, 5, 6, 6, 7,
    3, 4, 4, 5, 4, 5, 5, 6, 4, 5, 5, 6, 5, 6, 6, 7, 4, 5, 5, 6, 5, 6, 6, 7, 5, 6, 6, 7, 6, 7, 7, 8};

// enc8 index rint(v * 65535) (the float's low bits after + 2^23). What is encoded lies in [0, 1] up
// to a few ulp of rounding, which rounds to the table's ends; FMAX and the mask keep anything else
// (NaN included) inside the table, with two operations instead of a clamp's three.
#define Q16(v) (as_int(FMAX(v, 0.0f) * 65535.0f + 8388608.0f) & 0xFFFF)


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

// segment_cover for a segment with round ends (no flags), the common case, at 8 pixel centres: a
// chunk of a row, or two runs of 4 pixels on two rows (narrow rows, grlaa_draw); (fx, dy) = p - a,
// dy1 = p.y - b.y; (sa >= sb) the footprint widths on the body's normal. Same arithmetic as
// segment_cover; the end discs' terms only where a lane lies beyond an end. A lane's value does
// not depend on the others (with no lane beyond an end, the disc branch gives the body's values).
INLINE void round_cover8(f8 fx, f8 dy, f8 dy1, float tx, float ty, float len, float r,
                         float ri, float sa, float sb, float sh, float sia, float si2,
                         float strength, f8 *co, f8 *ci)
{
    const f8 along = fx * tx + dy * ty;
    const f8 perp = tx * dy - ty * fx;
    f8 dist = F8ABS(perp), fa = (f8)sa, fb = (f8)sb, h = (f8)sh, ia = (f8)sia, i2 = (f8)si2;
    // along is linear in x along each run of 4 lanes: its extremes are the runs' end lanes
    const float lmin = FMIN(FMIN(along.s0, along.s3), FMIN(along.s4, along.s7));
    const float lmax = FMAX(FMAX(along.s0, along.s3), FMAX(along.s4, along.s7));
    if (lmin < 0.0f || lmax > len) {
        const i8 st = along < 0.0f, en = along > len;
        const f8 vx = st ? fx : fx - len * tx, vy = st ? dy : dy1;
        const f8 dd = sqrt8(vx * vx + vy * vy);
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

// A tile's list of covered pixels: q = row * TILE + column in a byte up to 16 x 16 tiles. A
// chunk's entries (8 lanes) are written at once, unaligned: on PoCL's CPU build as one scalar
// store (vstore8 is an out-of-line call there), elsewhere with vstore8.
#if TT <= 256
typedef uchar qidx_t;
#define LANE_LIST(mask, k) (LANES[mask] + (ulong)(8 * (k)) * 0x0101010101010101UL)
#ifdef POCL_DEVICE_ADDRESS_BITS
typedef ulong ulong_u __attribute__((aligned(1)));
#define STORE_LANES(v, p) (*(__private ulong_u *)(p) = (v))
#else
#define STORE_LANES(v, p) vstore8(as_uchar8(v), 0, p)
#endif
#else
typedef ushort qidx_t;
#define LANE_LIST(mask, k) (convert_ushort8(as_uchar8(LANES[mask])) + (ushort8)(8 * (k)))
#ifdef POCL_DEVICE_ADDRESS_BITS
typedef ushort8 ushort8_u __attribute__((aligned(2)));
#define STORE_LANES(v, p) (*(__private ushort8_u *)(p) = (v))
#else
#define STORE_LANES(v, p) vstore8(v, 0, p)
#endif
#endif

// The write-back's list of covered pixels (uint8 frames): chunk k's lanes covered (hit > 0) and in
// the frame (up to lane lim) go to `part`, those fully covered by one polyline's fill or outline
// (exact != 0) to `full`; keep = 0 lists nothing (branch-free: 8-bit masks, LANES, POPC).
INLINE void list_chunk(f8 hit, i8 exact, int lim, int k, uint keep, qidx_t *part, qidx_t *full,
                       int *np, int *nf)
{
    const i8 cov = (hit > 0.0f) & (i8)(1, 2, 4, 8, 16, 32, 64, 128);
    const i8 exl = (exact != 0) & (i8)(1, 2, 4, 8, 16, 32, 64, 128);
    const int4 c4 = cov.lo | cov.hi, e4 = exl.lo | exl.hi;
    const int2 c2 = c4.lo | c4.hi, e2 = e4.lo | e4.hi;
    uint mask = (uint)(c2.x | c2.y) & (lim < 0 ? 0u : (2u << IMIN(7, lim)) - 1u) & keep;
    const uint fm = mask & (uint)(e2.x | e2.y);
    mask &= ~fm;
    STORE_LANES(LANE_LIST(mask, k), part + *np);
    STORE_LANES(LANE_LIST(fm, k), full + *nf);
    *np += POPC[mask];
    *nf += POPC[fm];
}

// p.x - a.x at tile columns `col` (dx0 = x0 - a.x), rounded as a chunk's lanes are: (dx0 + column % 8) +
// 8 * (column / 8), so a pixel's coverage does not depend on how its row was evaluated.
INLINE f8 run_dx(i8 col, float dx0)
{
    return (dx0 + convert_float8(col & 7)) + convert_float8(col & ~7);
}

// Four lanes of coverage (co, ci) at columns q .. q + 3 of tile row j merged into the current
// polyline's coverage by max (grlaa_draw keeps it 0 where the polyline has not reached).
typedef float4 float4_u __attribute__((aligned(4)));
INLINE void merge_run4(f8 *cov_out, f8 *cov_in, uint *rows_cur, int banded, int j, int q,
                       float4 co, float4 ci)
{
    rows_cur[j] |= (1u << (q >> 3)) | (1u << ((q + 3) >> 3));
    __private float4_u *po = (__private float4_u *)((__private float *)cov_out + j * TILE + q);
    *po = FMAX(*po, co);
    if (banded) {
        __private float4_u *pi = (__private float4_u *)((__private float *)cov_in + j * TILE + q);
        *pi = FMAX(*pi, ci);
    }
}

__kernel void grlaa_draw(__global PIXEL_T *img, __global const float *luts,
                         __global const float *dec8, __global const uchar *enc8,
                         __global const uint *pcol, __global const float4 *segs,
                         __global const int *seg_meta, __global int *entries,
                         __global int *counts, __global const int *overflow,
                         __global const float4 *polys, const int width, const int height,
                         const float strength, const int tiles_x, const int cap)
{
    // One work-item per tile of the frame, in row-major order: the binning (grlaa_bin_one) left
    // counts[t] entries at entries[t * cap ..]; the count is cleared here for the next frame.
    // If a tile overflowed its room, nothing is drawn and the host bins again with more.
    const int gid = (int)get_global_id(0), tiles_y = (height + TILE - 1) / TILE;
    if (gid >= tiles_x * tiles_y) return;
    const int count = counts[gid];
    if (!count) return;
    counts[gid] = 0;
    if (*overflow) return;
    const int4 tile = (int4)(gid % tiles_x, gid / tiles_x, gid * cap, count);
    // Ask for the entries of the tile two work-items ahead (on a CPU, one this thread runs next).
    if (gid + 2 < tiles_x * tiles_y) PREFETCH(entries + (gid + 2) * cap);
    const int x0 = tile.x * TILE, y0 = tile.y * TILE;
    const int xmax = IMIN(x0 + TILE, width) - 1, ymax = IMIN(y0 + TILE, height) - 1;
    const f8 lane = (f8)(0.0f, 1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 6.0f, 7.0f);

    // current polyline's coverage (max over its segments), outer and inner (with an outline band)
    f8 cov_out[TT / 8], cov_in[TT / 8];
    // Layers so far, premultiplied "over" without the frame: colour acc, transmittance trans (the
    // frame's pixel joins once, at write-back); hit > 0 where some line covers the pixel.
    f8 acc_r[TT / 8], acc_g[TT / 8], acc_b[TT / 8], trans[TT / 8], hit[TT / 8];
    i8 exact[TT / 8];                   // 1 + 2*poly (fill) or 2 + 2*poly (outline): stored as-is
    uint rows_cur[TILE], rows_all[TILE];  // per row, one bit per chunk: the current / any polyline
    // The layers' chunks are set up when first touched (rows_all bits), not here: a thin line
    // touches a few of a tile's 32 chunks. The coverage starts at 0 and the compositing puts
    // back 0 where it read, so segments always merge by max (outside its span a segment's
    // coverage is exactly 0 anyway).
    for (int j = 0; j < TILE; ++j) { rows_cur[j] = 0u; rows_all[j] = 0u; }
    for (int k = 0; k < TT / 8; ++k) { cov_out[k] = (f8)0.0f; cov_in[k] = (f8)0.0f; }
    // The tile's rows of the frame are read at write-back: ask for them now.
    for (int j = 0; j <= ymax - y0; ++j) {
        PREFETCH(img + (size_t)IDX(x0, y0 + j, width) * CHANNELS);
        PREFETCH(img + (size_t)IDX(xmax, y0 + j, width) * CHANNELS);
    }

#if DECODE8
    // the write-back's lists of covered pixels (+ 8: a chunk's 8 entries are stored at once)
    qidx_t part[TT + 8], full[TT + 8];
    int np = 0, nf = 0;
#endif
    int cur = -1, layers = 0;  // polylines composited so far
    const int end = tile.z + tile.w;
    // The binning lists a tile's segments in any order: sort them (by index: drawing order).
    for (int a = tile.z + 1; a < end; ++a) {
        const int v = entries[a];
        int b = a - 1;
        for (; b >= tile.z && entries[b] > v; --b) entries[b + 1] = entries[b];
        entries[b + 1] = v;
    }
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
            // an outline band: inner coverage kept (cov_in); none: inner = outer; all outline: 0
            const int solid = prm.y >= prm.x, banded = prm.y < prm.x && prm.y > 0.0f;
            const int ef = 1 + 2 * cur, eo = 2 + 2 * cur;
            // The tile's only polyline (most tiles of thin lines): its pixels are listed for the
            // write-back here, as the general listing after the loop would list them.
            const int only = DECODE8 && e == end && layers == 0;
            ++layers;
            for (int j = 0; j < TILE; ++j) {
                const uint bits = rows_cur[j], old = rows_all[j];
                if (!bits) continue;
                rows_all[j] = old | bits;
                rows_cur[j] = 0u;
                for (int c = 0; c < CH; ++c) {
                    if (!(bits & (1u << c))) continue;
                    const int k = j * CH + c;
                    const f8 ao = cov_out[k];
                    const f8 ai = banded ? cov_in[k] : (solid ? ao : (f8)0.0f);
                    cov_out[k] = (f8)0.0f;
                    cov_in[k] = (f8)0.0f;
                    const f8 A = ao * op, T = 1.0f - A, ae = ao - ai;
                    const f8 cr = op * (ai * fill.x + ae * outl.x), cg = op * (ai * fill.y + ae * outl.y);
                    const f8 cb = op * (ai * fill.z + ae * outl.z);
                    const i8 ex = ai >= 1.0f ? (i8)ef : (ai <= 0.0f ? (i8)eo : (i8)0);
                    if (old & (1u << c)) {
                        acc_r[k] = cr + T * acc_r[k];
                        acc_g[k] = cg + T * acc_g[k];
                        acc_b[k] = cb + T * acc_b[k];
                        trans[k] = T * trans[k];
                        hit[k] = F8MAX(hit[k], ao);
                        exact[k] = A >= 1.0f ? ex : (ao > 0.0f ? (i8)0 : exact[k]);
                    } else {  // first layer of this chunk: over nothing (acc 0, trans 1)
                        acc_r[k] = cr; acc_g[k] = cg; acc_b[k] = cb; trans[k] = T;
                        const i8 exk = A >= 1.0f ? ex : (i8)0;
                        exact[k] = exk;
#if DECODE8
                        if (only) {
                            list_chunk(ao, exk, xmax - x0 - 8 * c, k, ~0u, part, full, &np, &nf);
                            continue;
                        }
#endif
                        hit[k] = ao;
                    }
                }
            }
        }
        if (e == end) break;
        cur = poly;

        const float4 g = segs[2 * sidx];      // a.x, a.y, unit tangent t.x, t.y
        const float4 h = segs[2 * sidx + 1];  // length, r, r_inner, reach
        const float ax = g.x, ay = g.y, tx = g.z, ty = g.w;
        const float len = h.x, r = h.y, ri = h.z, R = h.w, by = ay + len * ty;
        const int banded = ri < r && ri > 0.0f;  // else the inner coverage is co or 0: not kept
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
        // The spans of the tile's rows, 8 rows at once (a lane per row); then only the rows from
        // the first to the last with a span are visited (the band is convex: they follow each other).
        i8 span_a8[TILE / 8], span_b8[TILE / 8];  // (vectors: PoCL calls vstore8 out of line)
        __private const int *span_a = (__private const int *)span_a8;
        __private const int *span_b = (__private const int *)span_b8;
        int jlo = TILE, jhi = -1;
        for (int q = 0; q < TILE / 8; ++q) {
            const f8 cv = (((float)(y0 + 8 * q) - ay) + lane) * s_p;
            const f8 lo = F8MAX(cv - w_p, (f8)bxl) + ax, hi = F8MIN(cv + w_p, (f8)bxh) + ax;
            i8 xa8 = convert_int8(lo), xb8 = convert_int8(hi);  // truncation: then iceil / ifloor
            xa8 -= lo > convert_float8(xa8);                    // (a true comparison is -1)
            xb8 += hi < convert_float8(xb8);
            xa8 = xa8 < (i8)x0 ? (i8)x0 : xa8;
            xb8 = xb8 > (i8)(x0 + TILE - 1) ? (i8)(x0 + TILE - 1) : xb8;
            const i8 row = (i8)(8 * q) + (i8)(0, 1, 2, 3, 4, 5, 6, 7), yrow = row + y0;
            const i8 ok = (xa8 <= xb8) & (yrow >= ya) & (yrow <= yb);
            span_a8[q] = xa8;
            span_b8[q] = xb8;
            const i8 mn = ok ? row : (i8)TILE, mx = ok ? row : (i8)(-1);
            int4 m4 = mn.lo < mn.hi ? mn.lo : mn.hi, x4 = mx.lo > mx.hi ? mx.lo : mx.hi;
            int2 m2 = m4.lo < m4.hi ? m4.lo : m4.hi, x2 = x4.lo > x4.hi ? x4.lo : x4.hi;
            jlo = IMIN(jlo, IMIN(m2.x, m2.y));
            jhi = IMAX(jhi, IMAX(x2.x, x2.y));
        }
        // Rows whose span is at most 4 px (most rows of a thin stroke) are paired: one f8 holds
        // a run of 4 pixels of each (q1, q2: their first columns); one left over pairs with itself.
        const int4 run4 = (int4)(0, 1, 2, 3);
        int pend = -1, pend_q = 0;
        for (int j = jlo; j <= jhi + 1; ++j) {
            int xa = 0, xb = -1;
            if (j <= jhi) {
                xa = span_a[j];
                xb = span_b[j];
                if (xa > xb) continue;  // (only where rounding leaves a row inside without a pixel)
            }
            const int narrow = j <= jhi && !(meta & 3) && xb - xa < 4;
            if (narrow && pend < 0) {
                pend = j;
                pend_q = IMIN(xa - x0, TILE - 4);
                continue;
            }
            if (pend >= 0 && (narrow || j > jhi)) {
                const int j2 = narrow ? j : pend, q2 = narrow ? IMIN(xa - x0, TILE - 4) : pend_q;
                const f8 fxr = run_dx((i8)(pend_q + run4, q2 + run4), (float)x0 - ax);
                const f8 yr = (f8)((float4)((float)(y0 + pend)), (float4)((float)(y0 + j2)));
                f8 co, ci;
                round_cover8(fxr, yr - ay, yr - by, tx, ty, len, r, ri, sa, sb, sh, sia, si2,
                             strength, &co, &ci);
                merge_run4(cov_out, cov_in, rows_cur, banded, pend, pend_q, co.lo, ci.lo);
                if (j2 != pend) merge_run4(cov_out, cov_in, rows_cur, banded, j2, q2, co.hi, ci.hi);
                pend = -1;
                if (narrow) continue;
            }
            if (j > jhi) break;
            const int y = y0 + j;
            const float dy = (float)y - ay, dy1 = (float)y - by;
            const int ca = (xa - x0) >> 3, cb = (xb - x0) >> 3;
            if (ca != cb && xb - xa < 8 && !(meta & 3)) {  // 5 to 8 px across two chunks: one f8
                const int q = IMIN(xa - x0, TILE - 8);
                const f8 fxr = run_dx((i8)(q + run4, q + 4 + run4), (float)x0 - ax);
                f8 co, ci;
                round_cover8(fxr, (f8)dy, (f8)dy1, tx, ty, len, r, ri, sa, sb, sh, sia, si2,
                             strength, &co, &ci);
                merge_run4(cov_out, cov_in, rows_cur, banded, j, q, co.lo, ci.lo);
                merge_run4(cov_out, cov_in, rows_cur, banded, j, q + 4, co.hi, ci.hi);
                continue;
            }
            rows_cur[j] |= ((2u << cb) - 1u) & ~((1u << ca) - 1u);
            // One polyline is one shape: its segments' coverages merge by max, so joins are not
            // blended twice. Lanes beyond the segment's reach get exactly 0.
            for (int c = ca; c <= cb; ++c) {
                const int k = j * CH + c;
                const f8 fx = fx0 + (float)(8 * c);
                f8 co, ci;
                if (meta & 3) {
                    const float xs = (float)(x0 + 8 * c), yf = (float)y;
                    __private float *o = (__private float *)&co, *n = (__private float *)&ci;
                    for (int i = 0; i < 8; ++i) {
                        const float2 cv = segment_cover(xs + (float)i, yf, g, h, meta, strength);
                        o[i] = cv.x; n[i] = cv.y;
                    }
                } else {
                    round_cover8(fx, (f8)dy, (f8)dy1, tx, ty, len, r, ri, sa, sb, sh, sia, si2,
                                 strength, &co, &ci);
                }
                cov_out[k] = F8MAX(cov_out[k], co);
                if (banded) cov_in[k] = F8MAX(cov_in[k], ci);
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
#if DECODE8
    // uint8 sRGB frames. The covered pixels are first listed per tile, branch-free per chunk (8
    // pixels of a row): the chunk's 8-bit masks of covered and of fully covered pixels give their
    // indices at once (LANES, POPC). Then one loop visits them: a loop per chunk would mispredict
    // its exit once per chunk, and a thin line leaves a few pixels per chunk. Each partly covered
    // pixel is decoded (dec8, 256 entries), composited and encoded (enc8: linear light rounded to
    // 1/65535 -> sRGB byte); fully covered ones take their polyline's colour bytes (pcol).
#if CHANNELS == 1
#define IR 0
#define IB 0
#elif ORDER_BGR
#define IR 2
#define IB 0
#else
#define IR 0
#define IB 2
#endif
    for (int j = 0; j <= ymax - y0 && layers > 1; ++j) {  // (one polyline: listed above)
        const uint bits = rows_all[j];
        if (!bits) continue;
        for (int c = 0; c < CH; ++c) {  // lanes up to lim: in the frame; untouched chunks: stale
            const int k = j * CH + c;
            list_chunk(hit[k], exact[k], xmax - x0 - 8 * c, k, (bits >> c) & 1u ? ~0u : 0u, part,
                       full, &np, &nf);
        }
    }
    __global uchar *const timg = (__global uchar *)img + (size_t)IDX(x0, y0, width) * CHANNELS;
    const size_t pitch = (size_t)width * CHANNELS;
    for (int t = 0; t < np; ++t) {  // partly covered: the frame's pixel under the layers
        const int q = part[t];
        __global uchar *o = timg + (size_t)(q / TILE) * pitch + CHANNELS * (q % TILE);
        const float T = tr[q];
#if CHANNELS == 1
        o[0] = enc8[Q16(ar[q] + T * dec8[o[0]])];
#else
        float cr = ar[q], cg = ag[q], cb = ab[q];
#if CHANNELS == 4
        // straight alpha: premultiplied sum over the frame's premultiplied colour
        const float ba = (float)o[3] * (1.0f / 255.0f), a = 1.0f - T * (1.0f - ba);
        const float wb = T * ba, wc = a > 0.0f ? 1.0f / a : 0.0f;
        cr = (cr + wb * dec8[o[IR]]) * wc; cg = (cg + wb * dec8[o[1]]) * wc;
        cb = (cb + wb * dec8[o[IB]]) * wc;
        o[3] = (uchar)(a * 255.0f + 0.5f);  // common.cl to_pixel
#else
        cr += T * dec8[o[IR]]; cg += T * dec8[o[1]]; cb += T * dec8[o[IB]];
#endif
        o[IR] = enc8[Q16(cr)];
        o[1] = enc8[Q16(cg)];
        o[IB] = enc8[Q16(cb)];
#endif
    }
    for (int t = 0; t < nf; ++t) {  // fully covered by a fill or an outline: its colour's bytes
        const int q = full[t];
        __global uchar *o = timg + (size_t)(q / TILE) * pitch + CHANNELS * (q % TILE);
        const uint pc = pcol[exs[q]];
#if CHANNELS == 1
        o[0] = (uchar)pc;
#else
#if CHANNELS == 4
        o[3] = (uchar)255;
#endif
        o[IR] = (uchar)(pc >> 16);
        o[1] = (uchar)(pc >> 8);
        o[IB] = (uchar)pc;
#endif
    }
#undef IR
#undef IB
#else
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
                    const float4 bgp = load_px(img, idx);
                    const float br = decode_srgb(luts, bgp.x), bg_ = decode_srgb(luts, bgp.y);
                    const float bb = decode_srgb(luts, bgp.z), ba = bgp.w;
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
#endif
}

// ---------------------------------------------------------------------------------------- binning
// Segments into TILE x TILE screen tiles, on the device (mlaa_stream.overlay.OverlayRenderer):
// each segment appends itself to the tiles it can touch, tile t's entries living at
// entries[t * cap ..] (an atomic counter per tile, cleared by grlaa_draw); a tile that would list
// more than cap sets *overflow, grlaa_draw then draws nothing and the host bins again with more
// room. Per row of tiles, the segment is cut to the rows' pixel centres grown by its reach and
// the tiles whose columns meet that piece's x-range grown by the reach are listed: every pixel
// within reach of the segment lies in a listed tile (a few listed tiles may have none).
// BIN_SLACK absorbs the float32 rounding of the end point a + length * t. A tile's entries come
// in any order; grlaa_draw sorts them into drawing order.
#define BIN_SLACK 0.01f
// PoCL's CPU build calls atomic_inc out of line; the compiler's builtin is one locked instruction.
#ifdef POCL_DEVICE_ADDRESS_BITS
#define ATOMIC_INC(p) __atomic_fetch_add(p, 1, __ATOMIC_RELAXED)
#else
#define ATOMIC_INC(p) atomic_inc(p)
#endif

INLINE void grlaa_bin_one(int s, float4 g, float4 h, int tiles_x, int tiles_y, int cap,
                          __global int *counts, __global int *entries, __global int *overflow)
{
    if (h.w < 0.0f) return;  // cut away by grlaa_segments' clipping
    const float ax = g.x, ay = g.y, dx = h.x * g.z, dy = h.x * g.w, R = h.w + BIN_SLACK;
    const float inv = 1.0f / (float)TILE, idy = dy != 0.0f ? 1.0f / dy : 0.0f;
    const int r0 = IMAX(ifloor((FMIN(ay, ay + dy) - R) * inv), 0);
    const int r1 = IMIN(ifloor((FMAX(ay, ay + dy) + R) * inv), tiles_y - 1);
    for (int row = r0; row <= r1; ++row) {
        float tlo = 0.0f, thi = 1.0f;  // a horizontal segment lies in every row band listed
        if (dy != 0.0f) {
            const float ta = ((float)(row * TILE) - R - ay) * idy;
            const float tb = ((float)(row * TILE + TILE - 1) + R - ay) * idy;
            tlo = FMIN(FMAX(FMIN(ta, tb), 0.0f), 1.0f);
            thi = FMIN(FMAX(FMAX(ta, tb), 0.0f), 1.0f);
        }
        const float xa = ax + tlo * dx, xb = ax + thi * dx;
        const int c0 = IMAX(ifloor((FMIN(xa, xb) - R) * inv), 0);
        const int c1 = IMIN(ifloor((FMAX(xa, xb) + R) * inv), tiles_x - 1);
        for (int col = c0; col <= c1; ++col) {
            const int t = row * tiles_x + col, e = ATOMIC_INC(counts + t);
            if (e < cap) entries[t * cap + e] = s; else *overflow = 1;
        }
    }
}

// Binning of segment tables built on the host (mlaa_stream.overlay.segment_tables).
__kernel void grlaa_bin(__global const float4 *segs, const int nseg, const int tiles_x,
                        const int tiles_y, const int cap, __global int *counts,
                        __global int *entries, __global int *overflow)
{
    const int s = (int)get_global_id(0);
    if (s < nseg)
        grlaa_bin_one(s, segs[2 * s], segs[2 * s + 1], tiles_x, tiles_y, cap, counts, entries,
                      overflow);
}

// ------------------------------------------------------------------------------- segment tables
// The kernel's segment tables from the polylines' points, on the device (the numpy
// mlaa_stream.overlay.segment_tables does the same in float64; the host uses that one when some
// point lies so far off the frame that float32 would not clip it precisely).
//   pts[p]     float2 all polylines' points, one after the other
//   line_i[l]  int4 (first point, first segment, number of points, cap flags of CAPS)
//   line_f[l]  float4 (r, r_inner, reach, 0)
// Segment s of a polyline of n points joins its points s and s + 1 (a single point is a
// zero-length segment). Segments with an end beyond the frame grown by m = reach + 1 are cut to
// that box (Liang-Barsky); what lies beyond touches no pixel, and the cut end's cap shows nowhere.
// A segment outside the box gets reach -1 and is not binned. Each segment is then binned
// (grlaa_bin_one).
__kernel void grlaa_segments(__global const float2 *pts, __global const int4 *line_i,
                             __global const float4 *line_f, const int nlines, const int nseg,
                             const int width, const int height, __global float4 *segs,
                             __global int *seg_meta, const int tiles_x, const int tiles_y,
                             const int cap, __global int *counts, __global int *entries,
                             __global int *overflow)
{
    const int s = (int)get_global_id(0);
    if (s >= nseg) return;
    int lo = 0, hi = nlines - 1;  // the polyline: the last whose first segment is <= s
    while (lo < hi) {
        const int mid = (lo + hi + 1) >> 1;
        if (line_i[mid].y <= s) lo = mid; else hi = mid - 1;
    }
    const int4 L = line_i[lo];
    const float4 F = line_f[lo];
    const int k = s - L.y, ia = L.x + k, ib = L.z > 1 ? ia + 1 : ia, last = IMAX(L.z - 1, 1) - 1;
    const float2 a = pts[ia], b = pts[ib];
    const float dx = b.x - a.x, dy = b.y - a.y, len = SQRT(dx * dx + dy * dy);
    float t0 = 0.0f, t1 = 1.0f, reach = F.z;
    const float m = reach + 1.0f, xh = (float)(width - 1) + m, yh = (float)(height - 1) + m;
    if (FMIN(a.x, b.x) < -m || FMAX(a.x, b.x) > xh || FMIN(a.y, b.y) < -m || FMAX(a.y, b.y) > yh) {
        const float p[4] = {-dx, dx, -dy, dy};
        const float q[4] = {a.x + m, xh - a.x, a.y + m, yh - a.y};
        int ok = 1;
        for (int i = 0; i < 4; ++i) {
            if (p[i] == 0.0f) {
                ok &= q[i] >= 0.0f;
            } else {
                const float r = q[i] / p[i];
                if (p[i] < 0.0f) t0 = FMAX(t0, r); else t1 = FMIN(t1, r);
            }
        }
        if (!ok || t0 > t1) reach = -1.0f;
    }
    const int caps = L.w;
    int meta = lo << 3;
    if (caps) {  // flat caps: flags on the polyline's first and last segment
        if (k == 0) meta |= 1 | (caps & 4);
        if (k == last) meta |= 2 | (caps & 4);
    }
    const float il = len > 0.0f ? 1.0f / len : 0.0f;
    const float4 g = (float4)(a.x + t0 * dx, a.y + t0 * dy, len > 0.0f ? dx * il : 1.0f, dy * il);
    const float4 h = (float4)((t1 - t0) * len, F.x, F.y, reach);
    segs[2 * s] = g;
    segs[2 * s + 1] = h;
    seg_meta[s] = meta;
    grlaa_bin_one(s, g, h, tiles_x, tiles_y, cap, counts, entries, overflow);
}
