// bridge.cl -- the second half of the bridging program (kernels/bridge_links.cl comes first: the lattice,
// classification and link search): each link's band coverage, its claim and draw, and the three kernels.

inline float tri_cdf(float t)
{
    if (t <= -1.0f) return 0.0f;
    if (t <= 0.0f) return 0.5f * (t + 1.0f) * (t + 1.0f);
    if (t < 1.0f) return 1.0f - 0.5f * (1.0f - t) * (1.0f - t);
    return 1.0f;
}

// Coverage of a pixel by a band of half thickness `hw` (rows) centred `delta` rows from it: the overlap of
// two intervals on rows and columns; on diagonal lattices the pixel's footprint across the rows is a
// triangle of support +-1.
inline float band_coverage(float delta, float hw, int diagonal)
{
    const float lo = delta - hw, hi = delta + hw;
    if (!diagonal) {
        const float top = hi < 0.5f ? hi : 0.5f, bot = lo > -0.5f ? lo : -0.5f;
        return top > bot ? top - bot : 0.0f;
    }
    return tri_cdf(hi) - tri_cdf(lo);
}

inline float3 to_mix(__global const float *luts, float3 c)
{
#if DECODE
    return (float3)(lut_read(luts, c.x), lut_read(luts, c.y), lut_read(luts, c.z));
#else
    return c;
#endif
}

// RGB only: dst's alpha stays as it is.
inline void store_rgb(__global PIXEL_T *dst, __global const float *luts, int i, float3 v)
{
#if DECODE
    v = (float3)(encode_mix(luts, v.x), encode_mix(luts, v.y), encode_mix(luts, v.z));
#endif
#if CHANNELS == 4
    store_px(dst, i, (float4)(v, load_px(dst, i).w));   // the stored alpha round-trips exactly
#else
    store_px(dst, i, (float4)(v, 1.0f));
#endif
}

// Is dash 1 (bit 0) / dash 2 (bit 1) of `ln` cut by the frame's edge (the step before its first / after its
// last pixel of the ink lies outside)?
inline int cuts(const lattice L, const link_t ln)
{
    return (lat(L, ln.x, ln.y, ln.a - 1, 0) < 0) | (lat(L, ln.x, ln.y, ln.b + 1, ln.d) < 0) << 1;
}

// The dash lengths `ln` is judged and drawn with (bridge_reference's cut_lengths): a dash cut by the frame's
// edge counts as long as the other one when its visible part is shorter.
inline void cut_lengths(const lattice L, const link_t ln, int *n1, int *n2)
{
    const int c = cuts(L, ln);
    *n1 = 1 - ln.a; *n2 = ln.b - ln.s + 1;
    if ((c & 1) && *n2 > *n1) *n1 = *n2;
    if ((c & 2) && *n1 > *n2) *n2 = *n1;
}

// How many steps i0, i0 + di, ... of lattice row j0 lie in the frame before its edge, when that is at most the
// link's gap g = s - 1 and they are all background, and so are those of row j1 inside the frame; else 0 (a chain
// that starts or ends that close to the edge has its previous or next dash, g steps on in row j1, outside it).
inline int to_edge(__global const PIXEL_T *src, const lattice L, const link_t ln, int i0, int di, int j0, int j1)
{
    const int x = ln.x, y = ln.y;
    const float3 ink = rgb_at(src, lat(L, x, y, 0, 0)), bgc = rgb_at(src, lat(L, x, y, 1, 0));
    for (int k = 0; k < ln.s; ++k) {
        const int i = i0 + k * di, p = lat(L, x, y, i, j0), q = lat(L, x, y, i, j1);
        if (p < 0) return k;
        if (k == ln.s - 1 || class_of(src, p, ink, bgc) != 1 || (q >= 0 && class_of(src, q, ink, bgc) != 1)) return 0;
    }
    return 0;
}

// Steps [c0, c1) a link owns: from the middle of dash 1 when a link ends there (inc), else its start; to the middle
// of dash 2 when a link starts there (out), else its end (ceil of the half-integer middles).
inline int own_c0(const link_t ln, int inc) { return inc ? -((-ln.a) / 2) : ln.a; }
inline int own_c1(const link_t ln, int out) { return out ? (ln.s + ln.b + 1) / 2 : ln.b + 1; }

// The link found at (x, y), if it lies in a chain: 1, the link, whether a link ends at its dash 1 (*inc) and one
// starts at its dash 2 (*out), the steps *e0 before c0 and *e1 after c1 its band goes on over to the frame's edge
// (rows -d and 0 / d and 2d), and whether it ends a chain of two links or more (*cut: a link ends at its dash 1,
// none starts at its dash 2); else 0. A link with a dash cut by the frame needs the chain to go on from its other
// dash.
inline int chained(__global const PIXEL_T *src, __global const uchar *found, __global const ushort *links,
                   const lattice L, const int o, int x, int y, link_t *ln, int *inc, int *out, int *e0, int *e1,
                   int *cut)
{
    link_t prev;
    *ln = unpack_link(x, y, links[4 * IDX(x, y, L.w) + o]);
    *inc = incoming(src, found, links, L, o, *ln, &prev);
    *out = outgoing(found, links, L, o, *ln);
    const int cf = cuts(L, *ln);
    if (cf ? !((cf & 1) ? *out : *inc) : (MIN_DASHES >= 3 && !*inc && !*out && !touches(src, L, *ln))) return 0;
    // a chain of three links or more that starts (ends) within a gap of the frame's edge
    *e0 = *e1 = 0;
    if (*out && !*inc && !(cf & 1)) {
        const int q = lat(L, x, y, ln->b, ln->d);
        const link_t next = unpack_link(x + ln->b * L.ax + ln->d * L.bx, y + ln->b * L.ay + ln->d * L.by,
                                        links[4 * q + o]);
        if (outgoing(found, links, L, o, next)) *e0 = to_edge(src, L, *ln, ln->a - 1, -1, 0, -ln->d);
    }
    link_t pp;
    if (*inc && !*out && !(cf & 2) && incoming(src, found, links, L, o, prev, &pp))
        *e1 = to_edge(src, L, *ln, ln->b + 1, 1, ln->d, 2 * ln->d);
    *cut = *inc && !*out && !(cf & 2);
    return 1;
}

// Where a chain cut by a crossing goes on (bridge_reference's _Scan.resumes): `ln` ends a chain of two links or
// more; the first link S, m = 1..MAX_SKIP lattice rows beyond its dash 2, of the same direction and ink, no dash
// cut by the frame, that starts a chain of two links or more with the same period (P2 = s + b - a, twice the
// distance of the dash middles) and whose dash 1's middle lies m periods after the middle of dash 2 of `ln` (both
// within max(12, P2) / 4 half steps): 1, *m, *is (the step of S's dash 1 end) and *sl; else 0.
inline int resumes(__global const PIXEL_T *src, __global const uchar *found, __global const ushort *links,
                   const lattice L, const int o, const link_t ln, int *m_out, int *is_out, link_t *sl)
{
    const int x = ln.x, y = ln.y, d = ln.d;
    const float3 ink = rgb_at(src, lat(L, x, y, 0, 0)), bgc = rgb_at(src, lat(L, x, y, 1, 0));
    const int p2 = ln.s + ln.b - ln.a, q = p2 > 12 ? p2 : 12;
    for (int m = 1; m <= MAX_SKIP; ++m) {
        const int c = ln.s + ln.b + m * p2, j = (m + 1) * d;   // c: twice the middle of S's dash 1 expected
        for (int i = (4 * c - q) / 8; i <= (4 * c + q + 4 * MAX_RUN) / 8; ++i) {
            const int k = lat(L, x, y, i, j);
            if (i <= ln.b || k < 0 || !(found[k] >> o & 1u) || CLS(i, j) != 2 || CLS(i + 1, j) != 1) continue;
            const link_t s = unpack_link(x + i * L.ax + j * L.bx, y + i * L.ay + j * L.by, links[4 * k + o]);
            const int e1 = 2 * i + s.a - c, e2 = s.s + s.b - s.a - p2;
            if (s.d != d || 4 * (e1 < 0 ? -e1 : e1) > q || 4 * (e2 < 0 ? -e2 : e2) > q || cuts(L, s) ||
                !outgoing(found, links, L, o, s))
                continue;
            *m_out = m; *is_out = i; *sl = s;
            return 1;
        }
    }
    return 0;
}

// Coverage of lattice pixel (i, (r + 1) d) by the band across a cut: from the middle of dash 2 of `ln` (row d)
// to the middle ms of dash 1 of the link S it resumes at (row (m + 1) d), the width of `ln`'s band.
inline float cut_coverage(const link_t ln, int m, float ms, int i, int r, int diagonal)
{
    const float m2 = (float)(ln.s + ln.b) * 0.5f, n = (float)(1 - ln.a + ln.b - ln.s + 1) * 0.5f;
    const float hw = 0.5f * n / (n + (float)(ln.s - 1));
    const float v = (float)m * ((float)i - m2) / (ms - m2);   // the band's centre, rows beyond row d
    return band_coverage(v - (float)r, hw, diagonal);
}

// The claim pass's verdict on the link at (x, y), kept for the draw pass (one uint per pixel, rewritten per
// orientation; the draw pass walks no chain): 0 when it is not drawn, else bit 0 set, bit 1 inc, bit 2 out, bits
// 3-7 e0, bits 8-12 e1 (< MAX_GAP), and where it ends a chain cut by a crossing, bits 13-14 m (1..MAX_SKIP),
// bits 15-23 the step `is` of S's dash 1 end (resumes: is <= (4 c + q + 4 MAX_RUN) / 8 <= 264 for MAX_GAP <= 30,
// MAX_RUN <= 32, MAX_SKIP <= 3), bits 24-28 -a of S.
typedef struct {
    link_t ln;
    int c0, c1, e0, e1, m, is, sa;
} verdict_t;

inline uint judge_link(__global const PIXEL_T *src, __global const uchar *found, __global const ushort *links,
                       const lattice L, const int o, int x, int y)
{
    link_t ln, sl;
    int inc, out, e0, e1, cut, m, is;
    if (!chained(src, found, links, L, o, x, y, &ln, &inc, &out, &e0, &e1, &cut)) return 0u;
    uint v = 1u | (uint)inc << 1 | (uint)out << 2 | (uint)e0 << 3 | (uint)e1 << 8;
    if (cut && resumes(src, found, links, L, o, ln, &m, &is, &sl))
        v |= (uint)m << 13 | (uint)is << 15 | (uint)(-sl.a) << 24;
    return v;
}

inline verdict_t read_verdict(__global const ushort *links, const lattice L, const int o, int x, int y, uint v)
{
    verdict_t r;
    r.ln = unpack_link(x, y, links[4 * IDX(x, y, L.w) + o]);
    r.c0 = own_c0(r.ln, v >> 1 & 1u);
    r.c1 = own_c1(r.ln, v >> 2 & 1u);
    r.e0 = (int)(v >> 3 & 31u);
    r.e1 = (int)(v >> 8 & 31u);
    r.m = (int)(v >> 13 & 3u);
    r.is = (int)(v >> 15 & 511u);
    r.sa = -(int)(v >> 24 & 31u);
    return r;
}

// A pixel of class c the band may write: not another wire's (another colour), and over the gap not the ink (a wire of
// the link's ink crossing it).
inline int writable(int c, int gap) { return c != 3 && !(gap && c == 2); }

// Claim the pixels the link at (x, y) would write (rows 0 and d over the steps it owns, rows -d and 0 / d and 2d
// over the steps to the frame's edge, not a pixel of another colour or of the ink over the gap, nor outside the
// frame; across a cut, the background pixels the band covers): claims[k] = the lowest id (pixel index of the dash
// end) of the links of this orientation that want k. Its verdict goes to verdicts[id].
inline void claim_link(__global const PIXEL_T *src, __global const uchar *found, __global const ushort *links,
                       volatile __global uint *claims, __global uint *verdicts, const lattice L, const int o, int x,
                       int y, int diagonal)
{
    const uint id = (uint)IDX(x, y, L.w);
    const uint v = judge_link(src, found, links, L, o, x, y);
    verdicts[id] = v;
    if (!v) return;
    const verdict_t r = read_verdict(links, L, o, x, y, v);
    const link_t ln = r.ln;
    const float3 ink = rgb_at(src, lat(L, x, y, 0, 0)), bgc = rgb_at(src, lat(L, x, y, 1, 0));
    for (int i = r.c0 - r.e0; i < r.c1 + r.e1; ++i) {
        const int r0 = i < r.c0 ? -ln.d : (i >= r.c1 ? ln.d : 0);   // the band crosses rows r0 and r0 + d here
        const int k0 = lat(L, x, y, i, r0), k1 = lat(L, x, y, i, r0 + ln.d), gap = i > 0 && i < ln.s;
        if (k0 >= 0 && writable(class_of(src, k0, ink, bgc), gap)) ATOMIC_MIN(claims + k0, id);
        if (k1 >= 0 && writable(class_of(src, k1, ink, bgc), gap)) ATOMIC_MIN(claims + k1, id);
    }
    if (!r.m) return;
    const float ms = (float)r.is + (float)r.sa * 0.5f;
    for (int i = ln.b + 1; i < r.is + r.sa; ++i)
        for (int q = 0; q <= r.m; ++q) {
            const int k = lat(L, x, y, i, (q + 1) * ln.d);
            if (cut_coverage(ln, r.m, ms, i, q, diagonal) > 0.0f && k >= 0 && class_of(src, k, ink, bgc) == 1)
                ATOMIC_MIN(claims + k, id);
        }
}

// Draw the link found at (x, y), if the claim pass judged it drawn: rows 0 and d over the steps it owns (and on to
// the frame's edge), and across a cut, the pixels it claimed (then their claim is reset for the next orientation).
inline void draw_link(__global const PIXEL_T *src, __global PIXEL_T *dst, __global const float *luts,
                      __global const ushort *links, __global uint *claims, __global const uint *verdicts,
                      const lattice L, const int o, int x, int y, int diagonal)
{
    const uint id = (uint)IDX(x, y, L.w);
    const uint v = verdicts[id];
    if (!v) return;
    const verdict_t r = read_verdict(links, L, o, x, y, v);
    const link_t ln = r.ln;
    int n1, n2;
    cut_lengths(L, ln, &n1, &n2);   // dash middles of the lengths judged (dash 1 ends at step 0, dash 2 starts at s)
    const int g = ln.s - 1;
    const float m1 = (float)(1 - n1) * 0.5f, m2 = (float)(2 * ln.s + n2 - 1) * 0.5f;
    const float n = (float)(n1 + n2) * 0.5f;
    const float hw = 0.5f * n / (n + (float)g);   // W = n / (n + g) rows
    const float3 bgc = to_mix(luts, rgb_at(src, lat(L, x, y, 1, 0)));
    const float3 ink = (to_mix(luts, rgb_at(src, lat(L, x, y, 0, 0))) +
                        to_mix(luts, rgb_at(src, lat(L, x, y, ln.s, ln.d)))) * 0.5f;
    for (int i = r.c0 - r.e0; i < r.c1 + r.e1; ++i) {
        const float u = ((float)i - m1) / (m2 - m1);   // the band's centre, rows from row 0 toward row d
        const int r0 = i < r.c0 ? -1 : (i >= r.c1 ? 1 : 0);   // the band crosses rows r0 d and (r0 + 1) d here
        const int k0 = lat(L, x, y, i, r0 * ln.d), k1 = lat(L, x, y, i, (r0 + 1) * ln.d);
        if (k0 >= 0 && claims[k0] == id) {
            store_rgb(dst, luts, k0, bgc + band_coverage(u - (float)r0, hw, diagonal) * (ink - bgc));
            claims[k0] = 0xffffffffu;
        }
        if (k1 >= 0 && claims[k1] == id) {
            store_rgb(dst, luts, k1, bgc + band_coverage(u - (float)(r0 + 1), hw, diagonal) * (ink - bgc));
            claims[k1] = 0xffffffffu;
        }
    }
    if (!r.m) return;
    const float ms = (float)r.is + (float)r.sa * 0.5f;
    for (int i = ln.b + 1; i < r.is + r.sa; ++i)
        for (int q = 0; q <= r.m; ++q) {
            const int k = lat(L, x, y, i, (q + 1) * ln.d);
            if (k >= 0 && claims[k] == id) {
                store_rgb(dst, luts, k, bgc + cut_coverage(ln, r.m, ms, i, q, diagonal) * (ink - bgc));
                claims[k] = 0xffffffffu;
            }
        }
}

// The four orientations (ORIENTATIONS in mlaa_stream/bridge.py): along (AX, AY), across (BX, BY).
__constant int AX[4] = {1, 0, 1, 1}, AY[4] = {0, 1, 1, -1}, BX[4] = {0, 1, 1, 1}, BY[4] = {1, 0, 0, 0};

inline lattice lattice_of(int o, int width, int height)
{
    const lattice L = {AX[o], AY[o], BX[o], BY[o], width, height};
    return L;
}

// Pass 1, all orientations at once: bit o of found[i] set, and links[4 i + o] = the packed link, where dash 1
// of a link of orientation o ends at pixel i (links untouched elsewhere); segments[] = the OR of found over
// the work item's pixels. One work item per SEGMENT pixels of a row. Every candidate differs from its right
// neighbour (x + 1, y) by INK_MIN or more (that pixel is P(1, 0) or P(0, 1) in every orientation), or lies in the
// last column (P(0, 1) outside the frame), so a group of GROUP pixels short of the last column where no sample
// differs from the same sample of the right neighbour by FLAT_LEVELS (<= INK_MIN * PIXEL_MAX) is settled at
// once, and so is a pixel.
// Integer frames: necessary conditions of find_link checked on stored levels first, each rounded so that it
// never rejects a link the float test accepts (the outputs are those of find_link alone). Photographs fail
// them almost everywhere, before any float conversion: MAY_CLEAR on the pixels beside the dash end, then the
// float INK_MIN tests, then may_link.
#ifndef PIXEL_IS_FLOAT
#define BG_LEVELS ((int)(BG_TOL * PIXEL_MAX * 1.0001f) + 1)    // within BG_TOL: every channel <= BG_LEVELS
#define INK_LEVELS ((int)(INK_TOL * PIXEL_MAX * 0.9999f) - 1)  // every channel <= INK_LEVELS: within INK_TOL
#define INK_UP ((int)(INK_TOL * PIXEL_MAX * 1.0001f) + 1)      // within INK_TOL: every channel <= INK_UP
#define SEG_L2 (0.99f * INK_TOL * PIXEL_MAX)                   // L2 (levels) surely within INK_TOL (max-channel)
#define SEG_INK ((int)(SEG_L2 * 0.5769f))  // every channel <= SEG_INK: L2 <= sqrt(3) SEG_INK <= 0.9993 SEG_L2
inline int near_ptr(__global const PIXEL_T *a, __global const PIXEL_T *b, int levels)
{
    int ok = 1;
    for (int k = 0; k < (CHANNELS < 3 ? CHANNELS : 3); ++k) {
        const int d = (int)a[k] - (int)b[k];
        ok &= (d <= levels) & (d >= -levels);
    }
    return ok;
}
#define near_int(src, i, j, levels) near_ptr((src) + (size_t)(i) * CHANNELS, (src) + (size_t)(j) * CHANNELS, levels)
// Pixel q may be clear beside the dash end i (r the pixel after it): near r's colour, or surely not the ink.
#define MAY_CLEAR(q) (near_int(src, (q), r, BG_LEVELS) || !near_int(src, (q), i, INK_LEVELS))

inline float3 levels_at(__global const PIXEL_T *src, int k)
{
#if CHANNELS == 1
    const float v = (float)src[k];
    return (float3)(v, v, v);
#else
    __global const PIXEL_T *p = src + (size_t)k * CHANNELS;
    return (float3)((float)p[0], (float)p[1], (float)p[2]);
#endif
}

// Pixel k is surely not clear for the link with background level rl and ink rl + e: not background (a
// channel more than BG_LEVELS from rl) and within SEG_L2 (L2, levels) of the segment rl .. rl + e. Then the
// nearest mix point, which class_of's clamped projection finds to float precision, is within INK_TOL
// (max-channel <= L2; 1 % margin): class_of is 2 or 0. Any t in [0, 1] bounds the distance from above, so
// t uses 1 / |e|^2 (no division per pixel). Branch-free: photographs make these outcomes unpredictable.
inline int not_clear(__global const PIXEL_T *src, int k, float3 rl, float3 e, float ee_inv)
{
    const float3 u = levels_at(src, k) - rl;
    float t = (u.x * e.x + u.y * e.y + u.z * e.z) * ee_inv;
    t = t < 0.0f ? 0.0f : t;
    t = t > 1.0f ? 1.0f : t;
    const float3 w = u - t * e;
    const float ax = u.x < 0.0f ? -u.x : u.x, ay = u.y < 0.0f ? -u.y : u.y, az = u.z < 0.0f ? -u.z : u.z;
    const float m = ax > ay ? ax : ay, mm = m > az ? m : az;
    return (w.x * w.x + w.y * w.y + w.z * w.z <= SEG_L2 * SEG_L2) & (mm > (float)BG_LEVELS);
}

// not_clear for lattice pixel k, or 0 outside the frame (k < 0: clear in a link's window). Branch-free: pixel 0
// is read in its place.
inline int not_clear_at(__global const PIXEL_T *src, int k, float3 rl, float3 e, float ee_inv)
{
    return (k >= 0) & not_clear(src, k < 0 ? 0 : k, rl, e, ee_inv);
}

// not_clear's outcome 1 on stored levels, no float work: lattice pixel k within SEG_INK levels of the ink i in
// every channel (its L2 distance to the segment's ink end, so to the segment, at most sqrt(3) SEG_INK, 0.07 % under
// SEG_L2: far beyond float rounding) and more than BG_LEVELS from the background r in some channel (exactly
// not_clear's second test).
inline int ink_near(__global const PIXEL_T *src, int k, int i, int r)
{
    return k >= 0 && near_int(src, k, i, SEG_INK) && !near_int(src, k, r, BG_LEVELS);
}

// Can find_link(src, L, x, y) succeed (i the dash end, r the pixel after it)? 0 only where it fails:
//  - (1, -1), (1, 1), (0, -1), (0, 1) clear or outside the frame: every direction d's gap starts with (1, -d),
//    (1, d) clear (a crossing lies in steps 2 .. s - 2), and rows -1 and 1 beside the dash end are clear;
//  - dash 1, walked back along row 0, reaches a background pixel or the frame's edge within MAX_RUN steps, and
//    before it every (-k, 0) is no mix (the ink or another colour) and (-k, -1), (-k, 1) are clear or outside.
//    Before the first pixel that may be background, every pixel is before the first background pixel.
inline int may_link(__global const PIXEL_T *src, const lattice L, int x, int y, int i, int r)
{
    const int p1 = lat(L, x, y, 1, 1), p2 = lat(L, x, y, 1, -1);
    const float3 rl = levels_at(src, r), e = levels_at(src, i) - rl;
    const float ee_inv = 1.0f / (e.x * e.x + e.y * e.y + e.z * e.z);   // e != 0: diff3(ink, bgc) >= INK_MIN
    if (not_clear_at(src, p1, rl, e, ee_inv) | not_clear_at(src, p2, rl, e, ee_inv)) return 0;
    if (not_clear_at(src, lat(L, x, y, 0, 1), rl, e, ee_inv) | not_clear_at(src, lat(L, x, y, 0, -1), rl, e, ee_inv))
        return 0;
    // dash 1's end: the first step back along row 0 that leaves the frame or may be background (0: none within
    // MAX_RUN, so find_link fails); integer only, before the float tests of the steps before it
    __global const PIXEL_T *bg = src + (size_t)r * CHANNELS;
    int end = 0;
    for (int k = 1; k <= MAX_RUN && !end; ++k) {
        const int p = lat(L, x, y, -k, 0);
        end = (p < 0 || near_ptr(src + (size_t)p * CHANNELS, bg, BG_LEVELS)) ? k : 0;
    }
    if (!end) return 0;
    __global const PIXEL_T *ink = src + (size_t)i * CHANNELS;
    for (int k = 1; k < end; ++k) {
        const int p = lat(L, x, y, -k, 0);
        const int s1 = lat(L, x, y, -k, -1), s2 = lat(L, x, y, -k, 1);
        if (not_clear_at(src, s1, rl, e, ee_inv) || not_clear_at(src, s2, rl, e, ee_inv) ||
            (!near_ptr(src + (size_t)p * CHANNELS, ink, INK_UP) && not_clear(src, p, rl, e, ee_inv))) return 0;
    }
    return 1;
}
#define MAY_LINK(L, x, y, i, r) may_link(src, L, x, y, i, r)
// 0 where may_link's first test surely fails ((1, 1) or (1, -1) surely not clear, on stored levels): rejects most
// candidates of photographs before the float INK_MIN tests and may_link's float set-up
#define INK_FAR(L, x, y, i, r) (!(ink_near(src, lat(L, x, y, 1, 1), i, r) | ink_near(src, lat(L, x, y, 1, -1), i, r)))
#else
#define MAY_LINK(L, x, y, i, r) 1
#define INK_FAR(L, x, y, i, r) 1
#endif

__kernel void bridge_find(__global const PIXEL_T *src, __global uchar *found, __global ushort *links,
                          __global uchar *segments, const int width, const int height)
{
    const int x0 = get_global_id(0) * SEGMENT, y = get_global_id(1);
    if (x0 >= width || y >= height) return;
    const int x1 = x0 + SEGMENT < width ? x0 + SEGMENT : width;
    const int px = CHANNELS;
    uchar any = 0;
    for (int g = x0; g < x1; g += GROUP) {
        const int ge = g + GROUP < x1 ? g + GROUP : x1;
        const int last = ge < width ? ge : width - 1;   // the right neighbour of the group's last pixel
        __global const PIXEL_T *p = src + (size_t)IDX(g, y, width) * px;
        const int nb = (last - g) * px;
        int flat = 1;
#if CHANNELS == 3 && SAMPLE_BYTES == 1
        if (ge - g == GROUP && ge < width) {
            // 8-bit RGB, a whole group and its right neighbour (27 bytes): every sample against the
            // next pixel's at once (detailed photo: the pass 0.91x)
            const uchar16 a0 = LOAD_UCHAR16(p), a1 = LOAD_UCHAR16(p + 3);
            const uchar8 c0 = LOAD_UCHAR8(p + 16), c1 = LOAD_UCHAR8(p + 19);
            const uchar16 d0 = a0 > a1 ? a0 - a1 : a1 - a0;
            const uchar8 d1 = c0 > c1 ? c0 - c1 : c1 - c0;
            const ulong2 m0 = as_ulong2(d0 >= (uchar16)FLAT_LEVELS);
            const ulong m1 = as_ulong(d1 >= (uchar8)FLAT_LEVELS);
            flat = (m0.x | m0.y | m1) == 0;
        } else
#endif
        {
            for (int t = 0; t < nb; ++t) flat &= p[t] == p[t + px];
            if (!flat) {
                flat = 1;
                for (int t = 0; t < nb; ++t) {
                    const PIXEL_T u = p[t], v = p[t + px];
                    flat &= (u > v ? u - v : v - u) < FLAT_LEVELS;
                }
            }
        }
        if (flat && ge - g == GROUP && ge < width) {
            STORE_UCHAR8((uchar8)(0), found + IDX(g, y, width));
            continue;
        }
        for (int x = g; x < ge; ++x) {
            const int i = IDX(x, y, width);
            int near = x + 1 < width;   // the last column: (x + 1, y) is outside (a candidate in all but rows)
            for (int t = 0; t < px && x + 1 < width; ++t) {
                const PIXEL_T u = p[(x - g) * px + t], v = p[(x - g + 1) * px + t];
                near &= (u > v ? u - v : v - u) < FLAT_LEVELS;
            }
            uchar hits = 0;
            if (!near) {
                const float3 c = rgb_at(src, i);
                if (x + 1 == width || diff3(c, rgb_at(src, i + 1)) >= INK_MIN) {
                    for (int o = 0; o < 4; ++o) {
                        const lattice L = lattice_of(o, width, height);
                        const int q = lat(L, x, y, 0, 1), r = lat(L, x, y, 1, 0);
#ifndef PIXEL_IS_FLOAT
                        const int qm = lat(L, x, y, 0, -1);
                        if (r < 0 || (q >= 0 && !MAY_CLEAR(q)) || (qm >= 0 && !MAY_CLEAR(qm))) continue;
#endif
                        link_t ln;
                        if (r >= 0 && INK_FAR(L, x, y, i, r) && (q < 0 || diff3(c, rgb_at(src, q)) >= INK_MIN) &&
                            diff3(c, rgb_at(src, r)) >= INK_MIN && MAY_LINK(L, x, y, i, r) &&
                            find_link(src, L, x, y, &ln)) {
                            links[4 * i + o] = pack_link(ln);
                            hits |= (uchar)(1u << o);
                        }
                    }
                }
            }
            found[i] = hits;
            any |= hits;
        }
    }
    segments[get_global_id(1) * get_global_size(0) + get_global_id(0)] = any;
}

// Pass 2, once per orientation o in order, two kernels: bridge_claim, then bridge_draw. Every link of
// orientation o that lies in a chain claims the pixels it would write (atomic_min of its id: links whose
// windows hold each other's wires may want the same pixel; the lowest id draws it, whatever the order the work
// items run in); then each draws the pixels it won. A segment with no link of orientation o (bit o of
// segments[] from pass 1) returns at once; groups of GROUP pixels with none are skipped with one 8-byte read.
// This work item's SEGMENT pixels of row y (from x0) lie in the frame and hold a link of orientation o
// (bit o of segments[], set by pass 1): the common early exit of bridge_claim and bridge_draw.
inline int segment_has_links(__global const uchar *segments, int width, int height, int o, int x0, int y)
{
    return x0 < width && y < height &&
           (segments[get_global_id(1) * get_global_size(0) + get_global_id(0)] >> o & 1u);
}

__kernel void bridge_claim(__global const PIXEL_T *src, __global const uchar *found, __global const ushort *links,
                           __global const uchar *segments, volatile __global uint *claims, __global uint *verdicts,
                           const int width, const int height, const int o)
{
    const int x0 = get_global_id(0) * SEGMENT, y = get_global_id(1);
    if (!segment_has_links(segments, width, height, o, x0, y)) return;
    const int x1 = x0 + SEGMENT < width ? x0 + SEGMENT : width;
    const lattice L = lattice_of(o, width, height);
    const ulong bits = 0x0101010101010101UL << o;
    for (int x = x0; x < x1; ++x) {
        const int i = IDX(x, y, width);
        if (x + GROUP <= x1 && (edge_group(found + i) & bits) == 0) { x += GROUP - 1; continue; }
        if (found[i] >> o & 1u) claim_link(src, found, links, claims, verdicts, L, o, x, y, o >= 2);
    }
}

__kernel void bridge_draw(__global const PIXEL_T *src, __global PIXEL_T *dst, __global const float *luts,
                          __global const uchar *found, __global const ushort *links,
                          __global const uchar *segments, __global uint *claims, __global const uint *verdicts,
                          const int width, const int height, const int o)
{
    const int x0 = get_global_id(0) * SEGMENT, y = get_global_id(1);
    if (!segment_has_links(segments, width, height, o, x0, y)) return;
    const int x1 = x0 + SEGMENT < width ? x0 + SEGMENT : width;
    const lattice L = lattice_of(o, width, height);
    const int diagonal = o >= 2;
    const ulong bits = 0x0101010101010101UL << o;
    for (int x = x0; x < x1; ++x) {
        const int i = IDX(x, y, width);
        if (x + GROUP <= x1 && (edge_group(found + i) & bits) == 0) { x += GROUP - 1; continue; }
        if (found[i] >> o & 1u) draw_link(src, dst, luts, links, claims, verdicts, L, o, x, y, diagonal);
    }
}
