// edges.cl -- discontinuity detection (seed 000 §3.2; weighted RGB from seed 004).
// For each pixel, whether its colour differs from its bottom and its right neighbour.
// Output: edges[i] bit 0 = discontinuity at the bottom border, bit 1 = at the right border.
// Defines: METRIC 0 = CIELAB ΔE76 (default), 1 = luma (Rec. 709 on encoded values), 2 = weighted RGB.
//          LINEAR_INPUT 1 when samples are linear light (float EXR), 0 when sRGB-encoded.
//          CHEAP_BOUND: for METRIC 0, a max-channel RGB difference below which ΔE cannot exceed
//          THRESHOLD (host-computed Lipschitz bound), so Lab is only computed near real edges.
//          RAMP_TEST / RAMP: leave soft transitions (ramps) alone, see is_ramp.
#ifndef METRIC
#define METRIC 0
#endif
#ifndef RAMP_TEST
#define RAMP_TEST 1
#endif
#ifndef RAMP
#define RAMP 0.5f
#endif

#define EDGE_BOTTOM 1
#define EDGE_RIGHT 2

inline float4 to_encoded(__global const float *luts, float4 c)
{
#if LINEAR_INPUT
    // linear samples: encode for the perceptual comparison (tables hold linear->sRGB after the Lab part)
    __global const float *enc = luts + 2 * (LUT_SIZE + 1);
    return (float4)(lut_read(enc, encode_arg(c.x)), lut_read(enc, encode_arg(c.y)), lut_read(enc, encode_arg(c.z)),
                    c.w);
#else
    return c;
#endif
}

// PoCL calls built-ins (fabs, fmax, dot, ...) out of line: plain expressions in the hot path.
inline float absf(float v) { return v < 0.0f ? -v : v; }
inline float max_abs3(float4 d)
{
    float x = absf(d.x), y = absf(d.y), z = absf(d.z);
    float m = x > y ? x : y;
    return m > z ? m : z;
}

// A pixel's colour as the metric sees it: CIELAB for METRIC 0 (computed only when a cheap test
// needs it: `has_lab`), the encoded RGB otherwise; i = its index (integer frames decode from it).
typedef struct { float4 rgb; float3 lab; int has_lab; int i; } Colour;

inline Colour colour_at(__global const PIXEL_T *src, __global const float *luts, int i)
{
    Colour c;
    c.rgb = to_encoded(luts, load_px(src, i));
    c.lab = (float3)(0.0f);
    c.has_lab = 0;
    c.i = i;
    return c;
}

// CIELAB of pixel c: integer frames decode each stored level with one load from `lin` (common.cl's
// linear_levels: the same numbers as rgb_to_lab's table reads), float frames through the tables.
inline float3 lab_of(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                     const Colour *c)
{
#ifdef PIXEL_IS_FLOAT
    return rgb_to_lab(luts, c->rgb);
#else
    return lab_of_levels(src, luts, lin, c->i);
#endif
}

// Could colours a and b differ by the metric? A cheap necessary test, before the ramp test and
// before any CIELAB conversion.
inline int may_differ(Colour *a, Colour *b, float threshold)
{
    float4 d = a->rgb - b->rgb;
#if METRIC == 0
    return max_abs3(d) >= CHEAP_BOUND;            // below it ΔE cannot reach the threshold
#elif METRIC == 1
    return absf(0.2126f * d.x + 0.7152f * d.y + 0.0722f * d.z) > threshold;
#else
    return 0.2126f * absf(d.x) + 0.7152f * absf(d.y) + 0.0722f * absf(d.z) > threshold;
#endif
}

// Do colours a and b differ (given may_differ)? Lab values are computed once and kept in the Colour.
inline int differs(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                   Colour *a, Colour *b, float threshold)
{
#if METRIC == 0
    if (!a->has_lab) { a->lab = lab_of(src, luts, lin, a); a->has_lab = 1; }
    if (!b->has_lab) { b->lab = lab_of(src, luts, lin, b); b->has_lab = 1; }
    float3 dl = a->lab - b->lab;
    return dl.x * dl.x + dl.y * dl.y + dl.z * dl.z > threshold * threshold;  // ΔE76
#else
    return 1;
#endif
}

// Soft transitions are not jaggies (seed 002's local contrast adaptation, along the gradient):
// for the edge between p and q, with `before` the pixel on p's far side and `after` on q's, take
// the channel where p and q differ most; if the colour keeps moving the same way one more pixel out
// on either side, by more than RAMP times the step itself, the edge is a ramp -- a photograph's or
// an already antialiased edge -- and is left alone. A thin line (before ~ q) is not a ramp.
inline int is_ramp(float4 before, int has_before, float4 p, float4 q, float4 after, int has_after)
{
#if RAMP_TEST
    float4 d = q - p;
    float ax = absf(d.x), ay = absf(d.y), az = absf(d.z);
    int kx = ax >= ay && ax >= az, ky = !kx && ay >= az;
    float d1 = kx ? d.x : (ky ? d.y : d.z);
    float d0 = kx ? p.x - before.x : (ky ? p.y - before.y : p.z - before.z);
    float d2 = kx ? after.x - q.x : (ky ? after.y - q.y : after.z - q.z);
    float lim = RAMP * absf(d1);
    return (has_before && d0 * d1 > 0.0f && absf(d0) > lim) || (has_after && d2 * d1 > 0.0f && absf(d2) > lim);
#else
    return 0;
#endif
}

// is_ramp on stored integer samples (QUIET_LEVELS >= 0: 8/16-bit frames, sRGB): the same test,
// exact, with RAMP as the fraction RAMP_NUM / RAMP_DEN (the host's; the reference uses the same), so
// no float conversion is needed to reject the ramps of a photograph. Channels in R, G, B order.
#ifndef RAMP_NUM
#define RAMP_NUM 7
#define RAMP_DEN 20
#endif
#if ORDER_BGR && CHANNELS >= 3
#define CH_R 2
#define CH_B 0
#elif CHANNELS >= 3
#define CH_R 0
#define CH_B 2
#endif
inline int3 raw_rgb(__global const PIXEL_T *src, int i)
{
    __global const PIXEL_T *a = src + (size_t)i * CHANNELS;
#if CHANNELS < 3
    return (int3)((int)a[0]);
#else
    return (int3)((int)a[CH_R], (int)a[1], (int)a[CH_B]);
#endif
}
inline int iabs(int v) { return v < 0 ? -v : v; }
inline int ramp_tested(void) { return 0; }   // the float path's ramp test, already done in integers
inline int is_ramp_int(__global const PIXEL_T *src, int ib, int has_before, int ip, int iq, int ia, int has_after)
{
#if RAMP_TEST
    const int3 p = raw_rgb(src, ip), q = raw_rgb(src, iq);
    const int3 d = q - p;
    const int ax = iabs(d.x), ay = iabs(d.y), az = iabs(d.z);
    const int kx = ax >= ay && ax >= az, ky = !kx && ay >= az;
    const int d1 = kx ? d.x : (ky ? d.y : d.z);
    const int lim = RAMP_NUM * iabs(d1);
    if (has_before) {
        const int3 b = raw_rgb(src, ib);
        const int d0 = kx ? p.x - b.x : (ky ? p.y - b.y : p.z - b.z);
        if ((d0 > 0) == (d1 > 0) && d0 != 0 && iabs(d0) * RAMP_DEN > lim) return 1;
    }
    if (has_after) {
        const int3 a = raw_rgb(src, ia);
        const int d2 = kx ? a.x - q.x : (ky ? a.y - q.y : a.z - q.z);
        if ((d2 > 0) == (d1 > 0) && d2 != 0 && iabs(d2) * RAMP_DEN > lim) return 1;
    }
#endif
    return 0;
}

// Already antialiased content (AA text, AA lines, downscaled images): a step between p and q whose
// neighbours along the step hold a colour *between* p's and q's, or where p lies between the pixel
// before it and q, or q between p and the pixel after it, is a rendered coverage ramp, not a 1-spp
// jaggy: it is not an edge. 1-spp renders have the two sides' colours there.
// "Between" is narrow (seed 002's local contrast adaptation: a colour is judged against what texture and
// shading alone would give): projected on the step at t in (lo, hi), and off the segment by at most
// AA_OFF of the step. A coverage mix of two colours lies on the segment up to the sRGB curve and
// rounding (measured on the antialiased bench scenes: 75 % within 0.02 of the step), a textured or
// shaded surface beside a 1-spp edge anywhere near it (rendered scenes: median 0.04, a quarter over
// 0.1): AA_OFF 0.08. A neighbour along the step beside p that stays within AA_NEAR of p (beside q:
// within AA_NEAR of q) is p's own surface varying -- texture, lighting -- not a coverage ramp: the
// window is (AA_NEAR, 1 - AA_LO) beside p, (AA_LO, 1 - AA_NEAR) beside q (tuning: docs/spatial_tuning.md).
#ifndef AA_GUARD
#define AA_GUARD 1
#endif
#ifndef AA_LO
#define AA_LO 0.1f
#endif
#ifndef AA_OFF
#define AA_OFF 0.08f
#endif
#ifndef AA_NEAR
#define AA_NEAR 0.3f
#endif   // (the host passes filter.AA_LO / AA_OFF / AA_NEAR)
inline int between(float4 m, float4 p, float4 d, float dd, float lo, float hi)
{
    const float4 v = m - p;
    const float t = (v.x * d.x + v.y * d.y + v.z * d.z) / dd;
    if (t <= lo || t >= hi) return 0;
    const float4 r = v - t * d;
    return r.x * r.x + r.y * r.y + r.z * r.z <= AA_OFF * AA_OFF * dd;
}
// p at i, q at j; s = the index step along the edge (1 for a bottom edge, width for a right edge);
// has_a / has_b: the neighbours before / after along the edge exist. Across the edge too: p between
// the pixel before it and q, or q between p and the pixel after it (t = j - i: the step's index).
inline int antialiased(__global const PIXEL_T *src, __global const float *luts, float4 p, float4 q,
                       int i, int j, int s, int has_a, int has_b, int has_before, int has_after)
{
#if AA_GUARD
    const float4 d = q - p;
    const float dd = d.x * d.x + d.y * d.y + d.z * d.z;
    if (!(dd > 0.0f)) return 0;
    const int t = j - i;
    if (has_before) {
        const float4 b = to_encoded(luts, load_px(src, i - t)), db = q - b;
        if (between(p, b, db, db.x * db.x + db.y * db.y + db.z * db.z, AA_LO, 1.0f - AA_LO)) return 1;
    }
    if (has_after) {
        const float4 a = to_encoded(luts, load_px(src, j + t)), da = a - p;
        if (between(q, p, da, da.x * da.x + da.y * da.y + da.z * da.z, AA_LO, 1.0f - AA_LO)) return 1;
    }
    if (has_a && (between(to_encoded(luts, load_px(src, i - s)), p, d, dd, AA_NEAR, 1.0f - AA_LO) ||
                  between(to_encoded(luts, load_px(src, j - s)), p, d, dd, AA_LO, 1.0f - AA_NEAR))) return 1;
    if (has_b && (between(to_encoded(luts, load_px(src, i + s)), p, d, dd, AA_NEAR, 1.0f - AA_LO) ||
                  between(to_encoded(luts, load_px(src, j + s)), p, d, dd, AA_LO, 1.0f - AA_NEAR))) return 1;
#endif
    return 0;
}

// GROUP pixels whose samples differ from the same sample of the right neighbour and of the pixel
// below by at most QUIET_LEVELS stored levels: no edge there, by the metric's cheap bound (may_differ;
// the host derives QUIET_LEVELS from it with a margin: mlaa.quiet_levels). Flat areas (most of a
// rendered frame) and smooth photographs cost just this compare. QUIET_LEVELS < 0 (float frames,
// linear input): sample-for-sample equality only.
#ifndef QUIET_LEVELS
#define QUIET_LEVELS -1
#endif
inline int flat_group(__global const PIXEL_T *src, int i, int width)
{
    __global const PIXEL_T *p = src + (size_t)i * CHANNELS, *q = p + (size_t)width * CHANNELS;
    int quiet = 1;
#if QUIET_LEVELS >= 0
    for (int k = 0; k < GROUP * CHANNELS; ++k) {
        const int a = (int)p[k], r = (int)p[k + CHANNELS] - a, b = (int)q[k] - a;
        quiet &= (r <= QUIET_LEVELS) & (r >= -QUIET_LEVELS) & (b <= QUIET_LEVELS) & (b >= -QUIET_LEVELS);
    }
#else
    for (int k = 0; k < GROUP * CHANNELS; ++k)
        quiet &= (p[k] == p[k + CHANNELS]) & (p[k] == q[k]);
#endif
    return quiet;
}

// One pair of pixels below the metric's cheap bound (QUIET_LEVELS), or equal: cannot be an edge.
inline int quiet_px(__global const PIXEL_T *src, int i, int j)
{
#if QUIET_LEVELS >= 0
    __global const PIXEL_T *a = src + (size_t)i * CHANNELS, *b = src + (size_t)j * CHANNELS;
    int quiet = 1;
    for (int k = 0; k < (CHANNELS < 3 ? CHANNELS : 3); ++k) {
        const int d = (int)b[k] - (int)a[k];
        quiet &= (d <= QUIET_LEVELS) & (d >= -QUIET_LEVELS);
    }
    return quiet;
#else
    return same_px(src, i, j);
#endif
}

#if QUIET_LEVELS >= 0
// ---- integer frames, interior groups: the quiet and integer ramp tests of GROUP pixels at once, a lane
// per pixel (OpenCL vectors: SIMD on a CPU, registers on a GPU) -- quiet_px and is_ramp_int exactly.
// r*: one sample of the pixels x-1 .. x+9 of row y (lanes 0..10); u*, d*, e*: of x .. x+7 of rows y-1,
// y+1, y+2. Channels in R, G, B order (the ramp test's tie-break); grey: one channel. int lanes: the
// ramp test's products reach 65535 * RAMP_DEN. Macros, not functions (PoCL passes wide vectors through
// memory).
#define VCH (CHANNELS < 3 ? 1 : 3)
#define ROW11(p, c) ((int16)((p)[c], (p)[(c) + CHANNELS], (p)[(c) + 2 * CHANNELS], (p)[(c) + 3 * CHANNELS], \
    (p)[(c) + 4 * CHANNELS], (p)[(c) + 5 * CHANNELS], (p)[(c) + 6 * CHANNELS], (p)[(c) + 7 * CHANNELS],     \
    (p)[(c) + 8 * CHANNELS], (p)[(c) + 9 * CHANNELS], (p)[(c) + 10 * CHANNELS], 0, 0, 0, 0, 0))
// ROW11 with lanes 1 .. 8 given (mid: an int8 of the same samples)
#define ROW11_MID(p, c, mid) ((int16)((p)[c], (mid), (p)[(c) + 9 * CHANNELS], (p)[(c) + 10 * CHANNELS], 0, 0, 0, 0, 0))
#define ROW8(p, c) ((int8)((p)[c], (p)[(c) + CHANNELS], (p)[(c) + 2 * CHANNELS], (p)[(c) + 3 * CHANNELS], \
    (p)[(c) + 4 * CHANNELS], (p)[(c) + 5 * CHANNELS], (p)[(c) + 6 * CHANNELS], (p)[(c) + 7 * CHANNELS]))
#define VABS(v) ((v) < 0 ? -(v) : (v))
#define VQUIET(d) (((d) <= QUIET_LEVELS) & ((d) >= -QUIET_LEVELS))
// is_ramp_int's verdict for the lanes, given the step q - p (dx, dy, dz), p - before (bx, by, bz) and
// after - q (ax, ay, az) per channel; out: -1 where a ramp.
#define VRAMP3(dx, dy, dz, bx, by, bz, ax, ay, az, out) {                                                \
        const int8 m_x = VABS(dx), m_y = VABS(dy), m_z = VABS(dz);                                     \
        const int8 k_x = (m_x >= m_y) & (m_x >= m_z), k_y = ~k_x & (m_y >= m_z);                       \
        const int8 s_1 = k_x ? (dx) : (k_y ? (dy) : (dz)), s_0 = k_x ? (bx) : (k_y ? (by) : (bz));      \
        const int8 s_2 = k_x ? (ax) : (k_y ? (ay) : (az));                                             \
        VRAMP1(s_1, s_0, s_2, out) }
#define VRAMP1(dx, bx, ax, out) {                                                                        \
        const int8 l_m = RAMP_NUM * VABS(dx), p_1 = (dx) > 0, b_0 = (bx), a_2 = (ax);                  \
        out = (((b_0 > 0) == p_1) & (b_0 != 0) & (VABS(b_0) * RAMP_DEN > l_m)) |                       \
              (((a_2 > 0) == p_1) & (a_2 != 0) & (VABS(a_2) * RAMP_DEN > l_m)); }
// Lanes of a group that must need the float path for the group to take the lane path (CIELAB and the
// antialiased guard a lane each): 1, always (measured: 4 -> 1 is 5 % faster on a detailed photograph,
// 9 % on one with camera noise; the mixed frame and the upscaled photograph unchanged).
#ifndef VECTOR_LAB_LANES
#define VECTOR_LAB_LANES 1
#endif
// `between` (the antialiased guard) on 8 lanes, decided exactly on the stored levels where the float path
// could not decide otherwise. Levels are integers: V = m - p and D = q - p exactly, t = V.D / D.D, and the
// squared distance off the segment is r^2 = |V x D|^2 / D.D. The float path works on samples / PIXEL_MAX,
// each within 2^-24 of its level (one common scale factor aside, which t and r^2 / dd do not see): so its
// V, D are within VB_A = 2^-22 PIXEL_MAX levels, and mt, mr below bound how far its t and r^2 can be from
// the exact ones (the rounding of every product and sum at 2^-20 relative, the products' sums at 2^-17).
// yes: between() is 1 whatever the rounding; no: it is 0; neither: the float path decides.
#define VB_A ((float)PIXEL_MAX * (1.0f / 4194304.0f))
#define VABSF(v) ((v) < 0.0f ? -(v) : (v))
#define VBETWEEN(mx, my, mz, px, py, pz, qx, qy, qz, LO, HI, yes, no) {                                            \
        const float8 vx_ = convert_float8((mx) - (px)), vy_ = convert_float8((my) - (py));                 \
        const float8 vz_ = convert_float8((mz) - (pz)), dx_ = convert_float8((qx) - (px));                 \
        const float8 dy_ = convert_float8((qy) - (py)), dz_ = convert_float8((qz) - (pz));                 \
        const float8 sv_ = VABSF(vx_) + VABSF(vy_) + VABSF(vz_), sd_ = VABSF(dx_) + VABSF(dy_) + VABSF(dz_); \
        const float8 vd_ = vx_ * dx_ + vy_ * dy_ + vz_ * dz_, dd_ = dx_ * dx_ + dy_ * dy_ + dz_ * dz_;     \
        const float8 s_ = VABSF(vx_ * dx_) + VABSF(vy_ * dy_) + VABSF(vz_ * dz_);                          \
        /* t within (LO, HI), as the float path sees it: both sides by mt of the bounds */               \
        const float8 mt_ = VB_A * (sv_ + 3.0f * sd_) + 6.0f * VB_A * VB_A + (1.0f / 1048576.0f) * (s_ + dd_); \
        const float8 lo_ = vd_ - (LO) * dd_, hi_ = (HI) * dd_ - vd_;                            \
        const int8 tin_ = (lo_ > mt_) & (hi_ > mt_), tout_ = (lo_ < -mt_) | (hi_ < -mt_) | (dd_ == 0.0f);  \
        const float8 cx_ = vy_ * dz_ - vz_ * dy_, cy_ = vz_ * dx_ - vx_ * dz_, cz_ = vx_ * dy_ - vy_ * dx_;  \
        const float8 inv_ = 1.0f / dd_, r2_ = (cx_ * cx_ + cy_ * cy_ + cz_ * cz_) * inv_;                  \
        /* the float path's r^2 within mr of r2 (its t within dt of t, t <= 1): r within E in L1 */       \
        const float8 dt_ = 1.01f * mt_ * inv_ + (1.0f / 16777216.0f), w_ = sv_ + sd_;                      \
        const float8 e_ = 6.0f * VB_A + sd_ * dt_ + (1.0f / 8388608.0f) * w_;                              \
        const float8 mr_ = 2.0f * w_ * e_ + e_ * e_ + (1.0f / 131072.0f) * w_ * w_                          \
            + AA_OFF * AA_OFF * (2.0f * VB_A * sd_ + 3.0f * VB_A * VB_A + (1.0f / 4194304.0f) * dd_);      \
        const float8 c_ = AA_OFF * AA_OFF * dd_;                                                           \
        yes = tin_ & (r2_ < c_ - mr_);                                                                     \
        no = tout_ | (r2_ > c_ + mr_); }
// antialiased() of 8 pairs p -> q: before / after across the step, a0 / b0 along it beside p, a1 / b1
// beside q (the four neighbours of an interior group exist). aa_yes: certainly 1; aa_no: certainly 0.
#define VANTIALIASED(P, Q, BEF, AFT, A0, A1, B0, B1, aa_yes, aa_no) {                                     \
        int8 y_, n_;                                                                                       \
        VBETWEEN(P##x, P##y, P##z, BEF##x, BEF##y, BEF##z, Q##x, Q##y, Q##z, AA_LO, 1.0f - AA_LO, aa_yes, aa_no)               \
        VBETWEEN(Q##x, Q##y, Q##z, P##x, P##y, P##z, AFT##x, AFT##y, AFT##z, AA_LO, 1.0f - AA_LO, y_, n_)                      \
        aa_yes |= y_; aa_no &= n_;                                                                         \
        VBETWEEN(A0##x, A0##y, A0##z, P##x, P##y, P##z, Q##x, Q##y, Q##z, AA_NEAR, 1.0f - AA_LO, y_, n_) aa_yes |= y_; aa_no &= n_; \
        VBETWEEN(A1##x, A1##y, A1##z, P##x, P##y, P##z, Q##x, Q##y, Q##z, AA_LO, 1.0f - AA_NEAR, y_, n_) aa_yes |= y_; aa_no &= n_; \
        VBETWEEN(B0##x, B0##y, B0##z, P##x, P##y, P##z, Q##x, Q##y, Q##z, AA_NEAR, 1.0f - AA_LO, y_, n_) aa_yes |= y_; aa_no &= n_; \
        VBETWEEN(B1##x, B1##y, B1##z, P##x, P##y, P##z, Q##x, Q##y, Q##z, AA_LO, 1.0f - AA_NEAR, y_, n_) aa_yes |= y_; aa_no &= n_; }
// CIELAB of 8 pixels: common.cl's LAB8.
#if CHANNELS >= 3
#define C0 CH_R
#define C2 CH_B
#else
#define C0 0
#define C2 0
#endif
#endif

// The float path for pixel i (x, y) given which pairs survived the cheap tests: c holds pixel x's colour
// when *c_valid; it becomes its right neighbour's, so each colour is converted to CIELAB at most twice
// (as a right and as a bottom neighbour), not four times.
inline uchar float_edges(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                         int i, int x, int y,
                         int width, int height, float threshold, int test_b, int test_r, Colour *c, int *c_valid)
{
    uchar e = 0;
#if QUIET_LEVELS >= 0
#define FLOAT_RAMP(before, has_before, p, q, after, has_after) ramp_tested()
#else
#define FLOAT_RAMP(before, has_before, p, q, after, has_after) \
        is_ramp(before, has_before, p, q, after, has_after)
#endif
    if ((test_b || test_r) && !*c_valid) *c = colour_at(src, luts, i);
    if (test_b) {
        Colour b = colour_at(src, luts, i + width);
        if (may_differ(c, &b, threshold)
            && !FLOAT_RAMP(y > 0 ? to_encoded(luts, load_px(src, i - width)) : c->rgb, y > 0, c->rgb, b.rgb,
                           y + 2 < height ? to_encoded(luts, load_px(src, i + 2 * width)) : b.rgb, y + 2 < height)
            && differs(src, luts, lin, c, &b, threshold)
            && !antialiased(src, luts, c->rgb, b.rgb, i, i + width, 1, x > 0, x + 1 < width, y > 0, y + 2 < height))
            e |= EDGE_BOTTOM;
    }
    *c_valid = 0;
    if (test_r) {
        Colour r = colour_at(src, luts, i + 1);
        if (may_differ(c, &r, threshold)
            && !FLOAT_RAMP(x > 0 ? to_encoded(luts, load_px(src, i - 1)) : c->rgb, x > 0, c->rgb, r.rgb,
                           x + 2 < width ? to_encoded(luts, load_px(src, i + 2)) : r.rgb, x + 2 < width)
            && differs(src, luts, lin, c, &r, threshold)
            && !antialiased(src, luts, c->rgb, r.rgb, i, i + 1, width, y > 0, y + 1 < height, x > 0, x + 2 < width))
            e |= EDGE_RIGHT;
        *c = r;
        *c_valid = 1;
    }
#undef FLOAT_RAMP
    return e;
}

// Work item: the SEGMENT pixels from x0 of EDGE_ROWS consecutive rows from y0. Flat groups first, row by
// row, in a loop of their own (a bit each in `flat`); then the others GROUP columns at a time (segment-
// aligned), top to bottom, so each row's CIELAB (computed as the bottom neighbours of the row above) serves
// that row's own pairs too: one LAB8 per row instead of two, and the lane path's rows y - 1, y + 1 and
// y + 2 are the row above's, shifted: one row loaded per row instead of four. Global size
// (ceil(W / SEGMENT), ceil(H / EDGE_ROWS)) (mlaa.py; on a CPU one work item per work group).
#ifndef EDGE_ROWS
#define EDGE_ROWS 1
#endif
#define ROW_BITS (SEGMENT / GROUP)
#if EDGE_ROWS * ROW_BITS > 64
#error "EDGE_ROWS * SEGMENT / GROUP must fit the 64 bits of `flat`"
#endif
__kernel void detect_edges(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                           __global uchar *edges, const int width, const int height,
                           const float threshold)
{
    const int x0 = get_global_id(0) * SEGMENT, y0 = get_global_id(1) * EDGE_ROWS;
    if (x0 >= width || y0 >= height) return;
    const int x1 = x0 + SEGMENT < width ? x0 + SEGMENT : width, y1 = y0 + EDGE_ROWS < height ? y0 + EDGE_ROWS : height;
    // flat_group needs the right neighbour of the group's last pixel and the row below
    const int xf = x1 < width - 1 ? x1 : width - 1, yf = y1 < height - 1 ? y1 : height - 1;
    ulong flat = 0;   // bit (y - y0) * ROW_BITS + (x - x0) / GROUP: group x of row y is flat
    for (int y = y0; y < yf; ++y) {
        int i = IDX(x0, y, width);
        for (int x = x0, b = (y - y0) * ROW_BITS; x + GROUP <= xf; x += GROUP, i += GROUP, ++b)
            if (flat_group(src, i, width)) {
                STORE_UCHAR8((uchar8)(0), edges + i);
                flat |= (ulong)1 << b;
            }
    }
    ulong col = 0;   // the bits of column block 0's rows
    for (int y = y0; y < y1; ++y) col |= (ulong)1 << ((y - y0) * ROW_BITS);
    if (flat == col * (((ulong)1 << ROW_BITS) - 1)) return;   // all flat (flat, rendered frames)
    Colour c;
    int c_valid;   // c holds pixel x (converted only when some pair may be an edge)
    for (int x = x0, g = 0; x < x1; x += GROUP, ++g) {
        if (((flat >> g) & col) == col) continue;
        const int n = x1 - x < GROUP ? x1 - x : GROUP;   // this column block's pixels
#if QUIET_LEVELS >= 0
        const int can_vec = n == GROUP && x > 0 && x + GROUP + 1 < width;
#if METRIC == 0
        float8 pL, pA, pZ;   // CIELAB of row y's 8 pixels when lab_valid: row y - 1's bottom neighbours
        int lab_valid = 0;
#endif
        // rows_valid: row y - 1 took the lane path; su*, sd*, se*: its rows y - 1, y + 1, y + 2 (x .. x + 7)
        int8 su0, sd0, se0;
#if VCH == 3
        int8 su1, sd1, se1, su2, sd2, se2;
#endif
        int rows_valid = 0;
#endif
        for (int y = y0; y < y1; ++y) {
            const int i = IDX(x, y, width);
#if QUIET_LEVELS >= 0
            const int rows_above = rows_valid;
            rows_valid = 0;
#if METRIC == 0
            const int lab_above = lab_valid;
            lab_valid = 0;
#endif
#endif
            if ((flat >> ((y - y0) * ROW_BITS + g)) & 1) continue;
            c_valid = 0;
#if QUIET_LEVELS >= 0
            // Integer frames reject quiet pairs and ramps on the stored samples first (no conversion):
            // interior groups a lane per pixel, the others a pixel at a time.
            if (can_vec && y > 0 && y + 2 < height) {
                __global const PIXEL_T *p = src + (size_t)(i - 1) * CHANNELS;
                const size_t rs = (size_t)width * CHANNELS;
                // rows y - 1, y (x - 1 .. x + 9), y + 1, y + 2: those of the row above's lanes, shifted,
                // when it took this path, and row y + 2 loaded
                int16 r0;
                int8 u0, d0, e0 = ROW8(p + CHANNELS + 2 * rs, C0);
#if VCH == 3
                int16 r1, r2;
                int8 u1, d1, e1 = ROW8(p + CHANNELS + 2 * rs, 1);
                int8 u2, d2, e2 = ROW8(p + CHANNELS + 2 * rs, C2);
#endif
                if (rows_above) {
                    r0 = ROW11_MID(p, C0, sd0); u0 = su0; d0 = se0;
#if VCH == 3
                    r1 = ROW11_MID(p, 1, sd1); u1 = su1; d1 = se1;
                    r2 = ROW11_MID(p, C2, sd2); u2 = su2; d2 = se2;
#endif
                } else {
                    r0 = ROW11(p, C0); u0 = ROW8(p + CHANNELS - rs, C0); d0 = ROW8(p + CHANNELS + rs, C0);
#if VCH == 3
                    r1 = ROW11(p, 1); u1 = ROW8(p + CHANNELS - rs, 1); d1 = ROW8(p + CHANNELS + rs, 1);
                    r2 = ROW11(p, C2); u2 = ROW8(p + CHANNELS - rs, C2); d2 = ROW8(p + CHANNELS + rs, C2);
#endif
                }
                su0 = r0.s12345678; sd0 = d0; se0 = e0;
#if VCH == 3
                su1 = r1.s12345678; sd1 = d1; se1 = e1;
                su2 = r2.s12345678; sd2 = d2; se2 = e2;
#endif
                rows_valid = 1;
                const int8 p0 = r0.s12345678, qb0 = d0 - p0, qr0 = r0.s23456789 - p0;
                int8 quiet_b = VQUIET(qb0), quiet_r = VQUIET(qr0), ramp_b, ramp_r;
#if VCH == 3
                const int8 p1 = r1.s12345678, p2 = r2.s12345678;
                const int8 qb1 = d1 - p1, qb2 = d2 - p2, qr1 = r1.s23456789 - p1, qr2 = r2.s23456789 - p2;
                quiet_b &= VQUIET(qb1) & VQUIET(qb2);
                quiet_r &= VQUIET(qr1) & VQUIET(qr2);
#endif
#if RAMP_TEST && VCH == 3
                VRAMP3(qb0, qb1, qb2, p0 - u0, p1 - u1, p2 - u2, e0 - d0, e1 - d1, e2 - d2, ramp_b)
                VRAMP3(qr0, qr1, qr2, p0 - r0.s01234567, p1 - r1.s01234567, p2 - r2.s01234567,
                       r0.s3456789a - r0.s23456789, r1.s3456789a - r1.s23456789, r2.s3456789a - r2.s23456789, ramp_r)
#elif RAMP_TEST
                VRAMP1(qb0, p0 - u0, e0 - d0, ramp_b)
                VRAMP1(qr0, p0 - r0.s01234567, r0.s3456789a - r0.s23456789, ramp_r)
#else
                ramp_b = (int8)(0); ramp_r = ramp_b;
#endif
                int8 need = (~quiet_b & ~ramp_b & EDGE_BOTTOM) | (~quiet_r & ~ramp_r & EDGE_RIGHT);
                int8 found = (int8)(0);   // edge bits decided in the lanes
#if METRIC == 0
                const int8 nz = need != 0;   // -1 per lane that needs the float path
                const int4 n4 = nz.lo + nz.hi;
                if (n4.x + n4.y + n4.z + n4.w <= -VECTOR_LAB_LANES) {
                    // CIELAB of the 8 pixels, their right and their bottom neighbours, a lane each (the scalar
                    // path's arithmetic): pairs surely under the threshold (0.1 % margin for rounding) need no
                    // float path. Camera noise and photographs' texture end here.
#if VCH == 3
                    const int8 pG = r1.s12345678, pB = r2.s12345678;
#else
                    const int8 pG = p0, pB = p0, d1 = d0, d2 = d0;
#endif
                    float8 bL, bA, bZ;
                    if (!lab_above) LAB8(p0, pG, pB, pL, pA, pZ);
                    LAB8(d0, d1, d2, bL, bA, bZ);
                    // the right neighbours: the group's own lanes shifted by one, and the pixel after the group
                    const float3 l8 = lab_of_levels(src, luts, lin, i + GROUP);
                    const float8 qL = (float8)(pL.s1234, pL.s567, l8.x), qA = (float8)(pA.s1234, pA.s567, l8.y);
                    const float8 qZ = (float8)(pZ.s1234, pZ.s567, l8.z);
                    const float t2 = (0.999f * threshold) * (0.999f * threshold);
                    const float t3 = (1.001f * threshold) * (1.001f * threshold);
                    const float8 eb_l = bL - pL, eb_a = bA - pA, eb_z = bZ - pZ;
                    const float8 er_l = qL - pL, er_a = qA - pA, er_z = qZ - pZ;
                    const float8 de_b = eb_l * eb_l + eb_a * eb_a + eb_z * eb_z, de_r = er_l * er_l + er_a * er_a + er_z * er_z;
                    need &= ((de_b > t2) & EDGE_BOTTOM) | ((de_r > t2) & EDGE_RIGHT);
                    pL = bL; pA = bA; pZ = bZ;   // the next row's own CIELAB
                    lab_valid = 1;
                    // pairs surely over it (0.1 %) are edges unless antialiased(): decided on the levels where
                    // VANTIALIASED is sure, which is nearly always; the rest (and the pairs near the
                    // threshold) go on to the float path.
                    const int8 cand_b = ((need & EDGE_BOTTOM) != 0) & (de_b > t3);
                    const int8 cand_r = ((need & EDGE_RIGHT) != 0) & (de_r > t3);
                    const int4 c4 = (cand_b | cand_r).lo | (cand_b | cand_r).hi;
                    if (c4.x | c4.y | c4.z | c4.w) {
#if AA_GUARD
                        // rows y - 1 and y + 1 from x - 1; the aliases name each pixel's R, G, B lanes
                        const int16 U0 = ROW11(p - rs, C0), D0 = ROW11(p + rs, C0);
#if VCH == 3
                        const int16 U1 = ROW11(p - rs, 1), D1 = ROW11(p + rs, 1);
                        const int16 U2 = ROW11(p - rs, C2), D2 = ROW11(p + rs, C2);
                        const int16 R0 = r0, R1 = r1, R2 = r2;
#else
                        const int16 U1 = U0, D1 = D0, U2 = U0, D2 = D0, R0 = r0, R1 = r0, R2 = r0;
#endif
#define LANES(name, V, sw) const int8 name##x = (V##0).sw, name##y = (V##1).sw, name##z = (V##2).sw;
                        LANES(P, R, s12345678) LANES(RT, R, s23456789) LANES(LF, R, s01234567)
                        LANES(RR, R, s3456789a) LANES(UP, U, s12345678) LANES(UR, U, s23456789)
                        LANES(DN, D, s12345678) LANES(DL, D, s01234567) LANES(DR, D, s23456789)
#undef LANES
#if VCH == 3
                        const int8 E2x = e0, E2y = e1, E2z = e2;
#else
                        const int8 E2x = e0, E2y = e0, E2z = e0;
#endif
                        int8 yes_b = (int8)(0), no_b = yes_b, yes_r = yes_b, no_r = yes_b;
                        const int4 b4 = cand_b.lo | cand_b.hi, r4 = cand_r.lo | cand_r.hi;
                        if (b4.x | b4.y | b4.z | b4.w)   // bottom: across UP / E2, along LF DL, RT DR
                            VANTIALIASED(P, DN, UP, E2, LF, DL, RT, DR, yes_b, no_b)
                        if (r4.x | r4.y | r4.z | r4.w)   // right: across LF / RR, along UP UR, DN DR
                            VANTIALIASED(P, RT, LF, RR, UP, UR, DN, DR, yes_r, no_r)
                        const int8 sure_b = cand_b & no_b, sure_r = cand_r & no_r;
                        need &= ~(((sure_b | yes_b) & EDGE_BOTTOM) | ((sure_r | yes_r) & EDGE_RIGHT));
#else
                        const int8 sure_b = cand_b, sure_r = cand_r;
                        need &= ~((sure_b & EDGE_BOTTOM) | (sure_r & EDGE_RIGHT));
#endif
                        found = (sure_b & EDGE_BOTTOM) | (sure_r & EDGE_RIGHT);
                    }
                }
#endif
                const int4 o = need.lo | need.hi;
                if ((o.x | o.y | o.z | o.w) == 0) {
                    STORE_UCHAR8(convert_uchar8(found), edges + i);
                } else {
                    uchar nb[GROUP], fb[GROUP];
                    STORE_UCHAR8_PRIVATE(convert_uchar8(need), nb);
                    STORE_UCHAR8_PRIVATE(convert_uchar8(found), fb);
                    for (int t = 0; t < GROUP; ++t)
                        edges[i + t] = fb[t] | float_edges(src, luts, lin, i + t, x + t, y, width, height, threshold,
                                                           nb[t] & EDGE_BOTTOM, nb[t] & EDGE_RIGHT, &c, &c_valid);
                }
                continue;
            }
#endif
            for (int t = 0; t < n; ++t) {
                const int it = i + t, xt = x + t;
#if QUIET_LEVELS >= 0
                const int test_b = y + 1 < height && !quiet_px(src, it, it + width)
                    && !is_ramp_int(src, it - width, y > 0, it, it + width, it + 2 * width, y + 2 < height);
                const int test_r = xt + 1 < width && !quiet_px(src, it, it + 1)
                    && !is_ramp_int(src, it - 1, xt > 0, it, it + 1, it + 2, xt + 2 < width);
#else
                const int test_b = y + 1 < height && !same_px(src, it, it + width);
                const int test_r = xt + 1 < width && !same_px(src, it, it + 1);
#endif
                edges[it] = float_edges(src, luts, lin, it, xt, y, width, height, threshold, test_b, test_r,
                                        &c, &c_valid);
            }
        }
    }
}
