// reconstruct.cl -- topological reconstruction of sub-pixel features (seed 000 §4), plus two rules
// beyond the paper (docs/reconstruct.md). Runs before edge detection. dst must hold a copy of src (the host
// enqueues it): the kernel writes reconstructed pixels only.
// The numpy reference is mlaa_stream.reconstruct.reconstruct_reference; this file mirrors it rule for rule.
// Defines (mlaa_stream.reconstruct.Reconstructor):
//   CHEAP_BOUND      max-channel difference below which ΔE76 cannot exceed the threshold (host Lipschitz bound)
//   EXTENDED         1: also the rules beyond the paper (line-relative X, two-pixel gaps)
//   LINEAR_INPUT     1 when samples are linear light: encoded to sRGB (table) before the Lab comparison
//   MAX_LINE_PIXELS  line-coloured pixels a 5x5 window around a gap may hold
//   MIN_AIM          cosine between a line piece's direction and the way to A
//   MAX_OFFSET       px between the lines through the two pieces
// table[mask] (mask: bit k = ring neighbour k differs): bit 0 = gap (T8(A,X)=2, T8(A,X-bar)=1 or the
// straight-gap case, seed 000 eq. 4), bit 1 = some sub-mask is a gap, bits 8..15 = the ring pixels of
// the first 8-component of X.
#ifndef EXTENDED
#define EXTENDED 1
#endif
#ifndef LINEAR_INPUT
#define LINEAR_INPUT 0
#endif
#ifndef CHEAP_BOUND
#define CHEAP_BOUND 0.0f
#endif
#ifndef MAX_LINE_PIXELS
#define MAX_LINE_PIXELS 8
#endif
#ifndef MIN_AIM
#define MIN_AIM 0.7f
#endif
#ifndef MAX_OFFSET
#define MAX_OFFSET 1.01f
#endif

// The ring N8*(A), clockwise from the top-left: bit k of a mask is (RX[k], RY[k]).
__constant int RX[8] = {-1, 0, 1, 1, 1, 0, -1, -1};
__constant int RY[8] = {-1, -1, -1, 0, 1, 1, 1, 0};

inline float3 lab_of(__global const float *luts, float4 c)
{
#if LINEAR_INPUT
    __global const float *enc = luts + 2 * (LUT_SIZE + 1);
    c = (float4)(lut_read(enc, c.x), lut_read(enc, c.y), lut_read(enc, c.z), c.w);
#endif
    return rgb_to_lab(luts, c);
}

inline float3 lab_at(__global const PIXEL_T *src, __global const float *luts, int x, int y, int w)
{
    return lab_of(luts, load_px(src, IDX(x, y, w)));
}

inline float d2(float3 a, float3 b)
{
    float3 d = a - b;
    return d.x * d.x + d.y * d.y + d.z * d.z;
}

inline int inside(int x, int y, int w, int h) { return x >= 0 && y >= 0 && x < w && y < h; }

// All colours of the shape within the threshold of their mean (seed 000 §4.2: "sharing the same color");
// returns the mean Lab in *mean.
inline int one_colour(const float3 *n, uint mask, float t2, float3 *mean)
{
    float3 m = (float3)(0.0f);
    int cnt = 0;
    for (int k = 0; k < 8; ++k)
        if (mask >> k & 1u) { m += n[k]; ++cnt; }
    m /= (float)cnt;
    *mean = m;
    for (int k = 0; k < 8; ++k)
        if ((mask >> k & 1u) && d2(n[k], m) > t2) return 0;
    return 1;
}

// The 5x5 checks the paper's 3x3 rule lacks: every pixel is line-coloured (within the threshold of c)
// or background (within it of A; `relaxed`: nearer to A than to c and within 2 thresholds of A), at most
// MAX_LINE_PIXELS are line-coloured, each piece of the shape continues outward and aims at A, and the
// lines through the two pieces are at most MAX_OFFSET apart (one line, not two parallel strokes).
inline int thin_gap(__global const PIXEL_T *src, __global const float *luts, int x, int y, int w, int h,
                    float3 a, float3 c, uint mask, uint comp1, float t2, int relaxed)
{
    int line = 0;
    float ox[2] = {0.0f, 0.0f}, oy[2] = {0.0f, 0.0f};
    int on[2] = {0, 0};
    for (int dy = -2; dy <= 2; ++dy) {
        for (int dx = -2; dx <= 2; ++dx) {
            if ((dx == 0 && dy == 0) || !inside(x + dx, y + dy, w, h)) continue;
            float3 q = lab_at(src, luts, x + dx, y + dy, w);
            float dc = d2(q, c), da = d2(q, a);
            if (dc <= t2) {
                ++line;
                if (abs(dx) == 2 || abs(dy) == 2) {
                    for (int p = 0; p < 2; ++p) {
                        uint comp = p == 0 ? comp1 : (mask & ~comp1);
                        int touches = 0;
                        for (int k = 0; k < 8; ++k)
                            if ((comp >> k & 1u) && abs(dx - RX[k]) <= 1 && abs(dy - RY[k]) <= 1) touches = 1;
                        if (touches) { ox[p] += (float)dx; oy[p] += (float)dy; ++on[p]; }
                    }
                }
            } else if (relaxed ? (da >= dc || da > 4.0f * t2) : (da > t2)) {
                return 0;
            }
        }
    }
    if (line > MAX_LINE_PIXELS || on[0] == 0 || on[1] == 0) return 0;
    float px[2], py[2], ux[2], uy[2];
    for (int p = 0; p < 2; ++p) {
        uint comp = p == 0 ? comp1 : (mask & ~comp1);
        float sx = 0.0f, sy = 0.0f;
        int cnt = 0;
        for (int k = 0; k < 8; ++k)
            if (comp >> k & 1u) { sx += (float)RX[k]; sy += (float)RY[k]; ++cnt; }
        px[p] = sx / (float)cnt;
        py[p] = sy / (float)cnt;
        float vx = px[p] - ox[p] / (float)on[p], vy = py[p] - oy[p] / (float)on[p];
        float vn = sqrt(vx * vx + vy * vy);
        if (vn == 0.0f || -(px[p] * vx + py[p] * vy) < MIN_AIM * sqrt(px[p] * px[p] + py[p] * py[p]) * vn)
            return 0;
        ux[p] = vx / vn;
        uy[p] = vy / vn;
    }
    float dx = ux[0] - ux[1], dy = uy[0] - uy[1];
    float un = sqrt(dx * dx + dy * dy);
    return un > 0.0f && fabs((px[1] - px[0]) * dy - (py[1] - py[0]) * dx) <= MAX_OFFSET * un;
}

// Mean colour of the ring pixels in `mask` (stored values, normalised), alpha from A.
inline void store_mean(__global const PIXEL_T *src, __global PIXEL_T *dst, int x, int y, int w, uint mask)
{
    float4 s = (float4)(0.0f);
    int cnt = 0;
    for (int k = 0; k < 8; ++k)
        if (mask >> k & 1u) { s += load_px(src, IDX(x + RX[k], y + RY[k], w)); ++cnt; }
    float4 m = s / (float)cnt;
    m.w = load_px(src, IDX(x, y, w)).w;
    store_px(dst, IDX(x, y, w), m);
}

__kernel void reconstruct(__global const PIXEL_T *src, __global PIXEL_T *dst, __global const float *luts,
                          __global const uint *table, const int width, const int height, const float t2)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    const int i = IDX(x, y, width);

    // cheap RGB test: no neighbour far enough from A in any channel to reach the ΔE threshold.
    // dst already holds a copy of src (Reconstructor.enqueue): pixels that stay need no write.
    float4 ca = load_px(src, i);
    float near;
    if (x > 0 && y > 0 && x < width - 1 && y < height - 1) {
        float4 d = fmax(fmax(fmax(fabs(load_px(src, i - width - 1) - ca), fabs(load_px(src, i - width) - ca)),
                             fmax(fabs(load_px(src, i - width + 1) - ca), fabs(load_px(src, i - 1) - ca))),
                        fmax(fmax(fabs(load_px(src, i + 1) - ca), fabs(load_px(src, i + width - 1) - ca)),
                             fmax(fabs(load_px(src, i + width) - ca), fabs(load_px(src, i + width + 1) - ca))));
        near = fmax(fmax(d.x, d.y), d.z);
    } else {
        near = 0.0f;
        for (int k = 0; k < 8; ++k) {
            if (inside(x + RX[k], y + RY[k], width, height)) {
                float4 d = fabs(load_px(src, IDX(x + RX[k], y + RY[k], width)) - ca);
                near = fmax(near, fmax(fmax(d.x, d.y), d.z));
            }
        }
    }
    if (near < CHEAP_BOUND) return;
    // second cheap test, per neighbour: X lies within `maybe` (ΔE <= Lipschitz * max-channel difference),
    // so the paper's rule needs a gap mask inside it (table bit 1); the extended rules need a neighbour
    // more than 2 thresholds away in ΔE (their line contrast), so more than 2 * CHEAP_BOUND in RGB.
    int valid[8];
    uint maybe = 0;
    float far = 0.0f;
    for (int k = 0; k < 8; ++k) {
        valid[k] = inside(x + RX[k], y + RY[k], width, height);
        if (valid[k]) {
            float4 d = fabs(load_px(src, IDX(x + RX[k], y + RY[k], width)) - ca);
            float m = fmax(fmax(d.x, d.y), d.z);
            if (m >= CHEAP_BOUND) maybe |= 1u << k;
            far = fmax(far, m);
        }
    }
#if EXTENDED
    if (!(table[maybe] & 2u) && far < 2.0f * CHEAP_BOUND) return;
#else
    if (!(table[maybe] & 2u)) return;
#endif

    float3 a = lab_of(luts, ca);
    float3 n[8];
    float da[8];
    uint X = 0;
    for (int k = 0; k < 8; ++k) {
        n[k] = valid[k] ? lab_at(src, luts, x + RX[k], y + RY[k], width) : a;
        da[k] = d2(n[k], a);
        if (valid[k] && da[k] > t2) X |= 1u << k;
    }
    if (X == 0) return;

    // seed 000 §4.2-4.3: T8(A, X) = 2 and T8(A, X-bar) = 1 (table), X of one colour; plus the 5x5 checks
    float3 c;
    uint e = table[X];
    if ((e & 1u) && one_colour(n, X, t2, &c) && thin_gap(src, luts, x, y, width, height, a, c, X, e >> 8, t2, 0)) {
        store_mean(src, dst, x, y, width, X);
        return;
    }
#if EXTENDED
    // beyond the paper (1): X relative to a line colour n[k] -- the neighbours nearer to it than to A
    for (int k = 0; k < 8; ++k) {
        if (!(X >> k & 1u)) continue;
        uint xk = 0;
        for (int j = 0; j < 8; ++j)
            if ((X >> j & 1u) && d2(n[j], n[k]) < da[j]) xk |= 1u << j;
        uint ek = table[xk];
        if (xk != X && (ek & 1u) && one_colour(n, xk, t2, &c) && d2(c, a) > 9.0f * t2 &&
            thin_gap(src, luts, x, y, width, height, a, c, xk, ek >> 8, t2, 1)) {
            store_mean(src, dst, x, y, width, xk);
            return;
        }
    }
    // beyond the paper (2): a gap of two pixels, A and B, in a straight line q2 q1 A B q3 q4
    for (int k = 0; k < 8; ++k) {
        if (!(X >> k & 1u)) continue;
        // necessary conditions from the ring alone first (implied by the full test below): B = the
        // opposite neighbour is A's colour, q1 is more than 2 thresholds away, the rest of the ring is
        // background (within the threshold of A or B)
        const int kb = (k + 4) & 7;
        if (!valid[kb] || da[kb] > t2 || da[k] <= 4.0f * t2) continue;
        int plain = 1;
        for (int j = 0; j < 8; ++j)
            if (j != k && j != kb && valid[j] && da[j] > t2 && d2(n[j], n[kb]) > t2) plain = 0;
        if (!plain) continue;
        const int dx = RX[k], dy = RY[k];
        const int bx = x - dx, by = y - dy;
        int qx[4] = {x + dx, x + 2 * dx, x - 2 * dx, x - 3 * dx};
        int qy[4] = {y + dy, y + 2 * dy, y - 2 * dy, y - 3 * dy};
        int ok = inside(bx, by, width, height);
        for (int q = 0; q < 4; ++q) ok = ok && inside(qx[q], qy[q], width, height);
        if (!ok) continue;
        float3 l[4];
        float3 m = (float3)(0.0f);
        for (int q = 0; q < 4; ++q) { l[q] = lab_at(src, luts, qx[q], qy[q], width); m += l[q]; }
        m /= 4.0f;
        for (int q = 0; q < 4; ++q) ok = ok && d2(l[q], m) <= t2;
        if (!ok) continue;
        float3 b = lab_at(src, luts, bx, by, width);
        if (!(d2(a, b) <= t2 && d2(a, m) > 9.0f * t2 && d2(b, m) > 9.0f * t2)) continue;
        // thin, on a plain background: every other pixel around A or B is background, none line-coloured
        for (int s = 0; s < 2 && ok; ++s) {
            int cx = s == 0 ? x : bx, cy = s == 0 ? y : by;
            for (int j = 0; j < 8 && ok; ++j) {
                int px = cx + RX[j], py = cy + RY[j];
                if (!inside(px, py, width, height) || (px == x && py == y) || (px == bx && py == by) ||
                    (px == qx[0] && py == qy[0]) || (px == qx[2] && py == qy[2]))
                    continue;
                float3 q = lab_at(src, luts, px, py, width);
                ok = d2(q, m) > t2 && fmin(d2(q, a), d2(q, b)) <= t2;
            }
        }
        if (!ok) continue;
        float4 sum = (float4)(0.0f);
        for (int q = 0; q < 4; ++q) sum += load_px(src, IDX(qx[q], qy[q], width));
        sum *= 0.25f;
        sum.w = ca.w;
        store_px(dst, i, sum);
        return;
    }
#endif
}
