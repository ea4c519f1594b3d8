// bridge_links.cl -- bridging the dash chains of sub-pixel wires (beyond seed 000 §4; docs/reconstruct.md).
// A wire thinner than a pixel at a shallow angle is sampled at 1 spp as dashes: a 1-px-tall run of ink in
// lattice row 0, a gap of background in rows 0 and d, the next run in row d = +-1. Each link found in src is
// drawn into dst: along the steps it owns, rows 0 and d get the coverage of a straight band of width
// W = n / (n + g) (mean dash length n, gap g) from the middle of one dash to the middle of the next.
// Orientations (ORIENTATIONS in mlaa_stream/bridge.py): pixel (i, j) of the lattice at (x, y) is
// (x + i*ax + j*bx, y + i*ay + j*by). bridge_find finds the links of all four at once; bridge_claim and
// bridge_draw run once per orientation, in order (claims, then drawing: a pixel two links of one orientation want
// goes to the lower id, so work items never write the same pixel; the claim pass keeps each link's verdict for
// the draw pass). A chain cut by a crossing (its last link's window held a same-ink wire) is drawn on across the
// cut to the chain that resumes with the same period and phase up to MAX_SKIP rows later, over background pixels,
// by the link that ends the first chain. At the frame's edge: a dash cut by it counts as long as the link's other
// dash (the chain must go on from that one), and a chain of three links or more that starts or ends within a gap
// of the edge draws its band on to it. The end of another wire of the same ink two rows from a dash (beside it, not
// over its step next to the gap) does not refuse a link whose dashes are both POKE_DASH px or longer, nor does
// another wire of the same ink crossing the gap (its runs XING_RUN px or shorter) when they are XING_DASH px or
// longer: the gap runs past it and the band leaves its pixels as they are. Mirrors bridge_reference.
// Defines: MAX_GAP, MAX_RUN (pixels), GAP_PER_RUN, GAP_SLACK (gap <= GAP_PER_RUN * mean dash + GAP_SLACK),
// INK_MIN, BG_TOL, INK_TOL (max-channel, normalised), MIN_DASHES, MAX_SKIP, POKE_RUN, POKE_DASH, XING_RUN,
// XING_DASH, MESH_DASH (0: off), BLEND_LINEAR, LINEAR_INPUT (as blend.cl).
#pragma OPENCL FP_CONTRACT OFF
#ifndef MAX_GAP
#define MAX_GAP 24
#endif
#ifndef MAX_RUN
#define MAX_RUN 32
#endif
#ifndef INK_MIN
#define INK_MIN 0.1f
#endif
#ifndef BG_TOL
#define BG_TOL 0.02f
#endif
#ifndef INK_TOL
#define INK_TOL 0.1f
#endif
#ifndef GAP_PER_RUN
#define GAP_PER_RUN 3
#endif
#ifndef GAP_SLACK
#define GAP_SLACK 2
#endif
#ifndef MIN_DASHES
#define MIN_DASHES 3
#endif
#ifndef MAX_SKIP
#define MAX_SKIP 3
#endif
#ifndef POKE_RUN
#define POKE_RUN 2
#endif
#ifndef POKE_DASH
#define POKE_DASH 3
#endif
#ifndef XING_RUN
#define XING_RUN 3
#endif
#ifndef XING_DASH
#define XING_DASH 4
#endif
#ifndef MESH_DASH
#define MESH_DASH 2
#endif
#ifdef PIXEL_IS_FLOAT
#define FLAT_LEVELS INK_MIN
#else
#define FLAT_LEVELS ((PIXEL_T)(INK_MIN * PIXEL_MAX))
#endif

typedef struct {
    int ax, ay, bx, by, w, h;
} lattice;

typedef struct {
    int x, y, d, a, s, b;   // dash 1 = steps a..0 of row 0 from its end (x, y); dash 2 = steps s..b of row d
} link_t;

// Index of lattice pixel (i, j) from (x, y), or -1 outside the frame.
inline int lat(const lattice L, int x, int y, int i, int j)
{
    const int px = x + i * L.ax + j * L.bx, py = y + i * L.ay + j * L.by;
    return (px < 0 || py < 0 || px >= L.w || py >= L.h) ? -1 : IDX(px, py, L.w);
}

inline float3 rgb_at(__global const PIXEL_T *src, int i) { return load_px(src, i).xyz; }

// Max-channel difference (plain expressions: PoCL's fabs/fmax are out-of-line calls).
inline float diff3(float3 p, float3 q)
{
    float3 t = p - q;
    float x = t.x < 0.0f ? -t.x : t.x, y = t.y < 0.0f ? -t.y : t.y, z = t.z < 0.0f ? -t.z : t.z;
    float m = x > y ? x : y;
    return m > z ? m : z;
}

inline int near_to(__global const PIXEL_T *src, const lattice L, int x, int y, int i, int j, float3 c, float tol)
{
    const int k = lat(L, x, y, i, j);
    return k >= 0 && diff3(rgb_at(src, k), c) <= tol;
}

#define BG(i, j) near_to(src, L, x, y, (i), (j), bgc, BG_TOL)
#define INK(i, j) near_to(src, L, x, y, (i), (j), ink, INK_TOL)

// PoCL's CPU build calls atomic_min out of line; the compiler's builtin is one locked instruction.
#ifdef POCL_DEVICE_ADDRESS_BITS
#define ATOMIC_MIN(p, v) __atomic_fetch_min(p, v, __ATOMIC_RELAXED)
#else
#define ATOMIC_MIN(p, v) atomic_min(p, v)
#endif

// (class_of, classify and classify_o forced inline: PoCL's CPU build calls them per probe otherwise; on dense
// wires bridge_find 0.85x.)
// A pixel as 1 background, 2 ink, 3 another colour (another wire), 0 a mix of ink and background (antialiased
// ink: within INK_TOL of the nearest bgc + t (ink - bgc), t in [0, 1]; it refuses a link as the ink does).
inline __attribute__((always_inline)) int class_of(__global const PIXEL_T *src, int k, float3 ink, float3 bgc)
{
    const float3 c = rgb_at(src, k);
    if (diff3(c, bgc) <= BG_TOL) return 1;
    if (diff3(c, ink) <= INK_TOL) return 2;
    const float3 e = ink - bgc, q = c - bgc;
    float t = (q.x * e.x + q.y * e.y + q.z * e.z) / (e.x * e.x + e.y * e.y + e.z * e.z);
    t = t < 0.0f ? 0.0f : (t > 1.0f ? 1.0f : t);
    return diff3(c, bgc + t * e) <= INK_TOL ? 0 : 3;
}

// Lattice pixel (i, j) as class_of, or 0 outside the frame.
inline __attribute__((always_inline)) int classify(__global const PIXEL_T *src, const lattice L, int x, int y, int i, int j, float3 ink, float3 bgc)
{
    const int k = lat(L, x, y, i, j);
    return k < 0 ? 0 : class_of(src, k, ink, bgc);
}

#define CLS(i, j) classify(src, L, x, y, (i), (j), ink, bgc)
#define CLEAR(c) ((c) & 1)   // background (1), another colour (3: a wire crossing this one) or OUTSIDE
#define OUTSIDE 5

// Lattice pixel (i, j) as class_of, or OUTSIDE the frame (clear in a link's window: nothing there refuses it).
inline __attribute__((always_inline)) int classify_o(__global const PIXEL_T *src, const lattice L, int x, int y, int i, int j, float3 ink,
                      float3 bgc)
{
    const int k = lat(L, x, y, i, j);
    return k < 0 ? OUTSIDE : class_of(src, k, ink, bgc);
}
#define CLSO(i, j) classify_o(src, L, x, y, (i), (j), ink, bgc)
// A window pixel: clear, noting in `reach` one outside the frame (allowed only beside a dash the frame cuts).
#define WIN(c) ((c) == OUTSIDE ? (reach = 1) : CLEAR(c))

// Is lattice pixel (i, j) the end of another wire of the link's ink reaching into row j from beyond it
// (bridge_reference's _Scan.poke): the ink, in a run of at most POKE_RUN steps along row j, with the ink at step
// i - 1, i or i + 1 of row j + out? (The caller has found (i, j) to be the ink.)
inline int poke(__global const PIXEL_T *src, const lattice L, int x, int y, int i, int j, int out, float3 ink,
                float3 bgc)
{
    if (CLS(i - 1, j + out) != 2 && CLS(i, j + out) != 2 && CLS(i + 1, j + out) != 2) return 0;
    int lo = i, hi = i;
    while (lo > i - POKE_RUN && CLS(lo - 1, j) == 2) --lo;
    while (hi < i + POKE_RUN && CLS(hi + 1, j) == 2) ++hi;
    return hi - lo + 1 <= POKE_RUN;
}

// Is lattice pixel (i, j), the ink (the caller has found it so), in a run of at most XING_RUN steps along row j
// (bridge_reference's _Scan.thin)? 1 and the run's ends *lo, *hi, or 0.
inline int thin_run(__global const PIXEL_T *src, const lattice L, int x, int y, int i, int j, float3 ink, float3 bgc,
                    int *lo, int *hi)
{
    int l = i, h = i;
    while (h < i + XING_RUN && CLS(h + 1, j) == 2) ++h;
    if (h - i + 1 > XING_RUN) return 0;
    while (l > i - XING_RUN && CLS(l - 1, j) == 2) --l;
    *lo = l; *hi = h;
    return h - l + 1 <= XING_RUN;
}

// Is lattice pixel (i, j), the ink, part of another wire of the link's ink crossing its lattice rows (_Scan.xing): a
// thin run with a thin run of the ink on both sides across the rows, in row j -+ 1 within a step of its ends or in
// row j -+ 2 within two?
inline int xing(__global const PIXEL_T *src, const lattice L, int x, int y, int i, int j, float3 ink, float3 bgc)
{
    int lo, hi, u, v;
    if (!thin_run(src, L, x, y, i, j, ink, bgc, &lo, &hi)) return 0;
    for (int t = -1; t <= 1; t += 2) {
        int ok = 0;
        for (int r = 1; r <= 2 && !ok; ++r)
            for (int ii = lo - r; ii <= hi + r && !ok; ++ii)
                ok = CLS(ii, j + t * r) == 2 && thin_run(src, L, x, y, ii, j + t * r, ink, bgc, &u, &v);
        if (!ok) return 0;
    }
    return 1;
}

// The rest of find_link for direction d, once the walk has found dash 2's start s (rows d and -d over steps 1..s
// judged: `reach` whether row -d or the rows beside dash 1 left the frame, `crossed` whether a crossing was let
// through, `xmax` its last step): rows 0 and 2d over the gap, dash 2 and rows 0, -d, 2d beside it, the link's
// length rules. 1 and *out, or 0.
inline int finish_link(__global const PIXEL_T *src, const lattice L, int x, int y, float3 ink, float3 bgc, int a,
                       int a0, int cut1, int d, int s, int reach, int crossed, int xmax, link_t *out)
{
    // row 2d beside dash 1 (another wire's end allowed but over step 0: poked), rows 0 and 2d over the gap (a
    // crossing allowed in steps 2 .. s - 2)
    int poked = 0;
    for (int i = a0; i <= 0; ++i) {
        const int c = CLSO(i, 2 * d);
        if (WIN(c)) continue;
        if (c == 2 && i < 0 && poke(src, L, x, y, i, 2 * d, d, ink, bgc)) poked = 1; else return 0;
    }
    for (int k = 1; k <= s; ++k) {
        const int c0 = CLSO(k, 0), c2 = CLSO(k, 2 * d);
        if (!WIN(c0)) {
            if (c0 == 2 && k >= 2 && k <= s - 2 && xing(src, L, x, y, k, 0, ink, bgc)) crossed = 1; else return 0;
        }
        if (!WIN(c2)) {
            if (c2 == 2 && k >= 2 && k <= s - 2 && xing(src, L, x, y, k, 2 * d, ink, bgc)) crossed = 1; else return 0;
        }
    }
    // dash 2: ink (or another colour over it) in row d from s to the background, or to the frame's edge (cut2:
    // its ink reaches it); b = its last pixel of the ink; rows 0, -d, 2d clear beside it (row -d: or another wire's
    // end, but over step s)
    int b = 0, last2 = s, cut2 = 0;
    for (int k = s; k <= s + MAX_RUN; ++k) {
        const int c = CLSO(k, d);
        if (c == OUTSIDE) {
            if (last2 == k - 1) { b = last2; cut2 = 1; }
            break;
        }
        if (c == 1 && k > s) { b = last2; break; }
        if (c == 0 || c == 1 || !WIN(CLSO(k, 0)) || !WIN(CLSO(k, 2 * d))) break;
        const int cm = CLSO(k, -d);
        if (!WIN(cm)) {
            if (cm == 2 && k > s && poke(src, L, x, y, k, -d, -d, ink, bgc)) poked = 1; else break;
        }
        if (c == 2) last2 = k;
    }
    if (b == 0 || (cut1 && cut2) || (reach && !cut1 && !cut2) || xmax > s - 2) return 0;
    // a dash cut by the frame counts as long as the other one when its visible part is shorter
    int n1 = 1 - a, n2 = b - s + 1;
    if (cut1 && n2 > n1) n1 = n2;
    if (cut2 && n1 > n2) n2 = n1;
    if (poked && (n1 < POKE_DASH || n2 < POKE_DASH)) return 0;   // another wire's end: only beside long dashes
    if (crossed && (n1 < XING_DASH || n2 < XING_DASH)) return 0;  // a crossing: likewise
    // a wire at least 1 / (GAP_PER_RUN + 1) px wide: gap <= GAP_PER_RUN * mean dash + GAP_SLACK
    if (2 * (s - 1) > GAP_PER_RUN * (n1 + n2) + 2 * GAP_SLACK) return 0;
#if MESH_DASH > 0
    // a mesh of wires (a chain-link fence far away, #15): dots (both dashes MESH_DASH px or shorter) with more of
    // the ink (or a mix of it) one row further out, in row -2d or 3d over steps a - 1 .. b + 1, are the fence's
    // scattered samples, not one wire's dashes: no link (bridging them drew false bands across the fence's cells)
    if (n1 <= MESH_DASH && n2 <= MESH_DASH)
        for (int k = a - 1; k <= b + 1; ++k) {
            const int u = CLSO(k, -2 * d), v = CLSO(k, 3 * d);
            if (u == 0 || u == 2 || v == 0 || v == 2) return 0;
        }
#endif
    out->x = x; out->y = y; out->d = d; out->a = a; out->s = s; out->b = b;
    return 1;
}

// The link whose dash 1 ends at (x, y): 1 and *out, or 0. Rows -d .. 2d over steps a..b hold only the two
// dashes (one ink), background (one colour), other colours (crossing wires) and, when a dash is cut by the
// frame's edge (its ink reaches it: judged with the length cut_lengths gives it), pixels outside the frame; a
// dash may run under another colour and start or end under it (it then spans its first to last pixel of the
// ink; the window covers the occluding pixels too); beside a dash, two rows from it (row 2d beside dash 1, row -d
// beside dash 2, not over the dash's step next to the gap), the end of another wire of the same ink (poke) counts as
// clear when both dashes are at least POKE_DASH long; over steps 2 .. s - 2 of the gap, another wire of the same
// ink crossing the rows (xing) counts as clear, and the gap in row d runs past its runs that could not start dash 2,
// when both dashes are at least XING_DASH long; exactly one direction d qualifies. The predicate of
// bridge_reference's _Scan.link, evaluated in an order that rejects early: rows -1 and 1 beside dash 1 (both
// directions need them), then rows 1 and -1 walked together over the gap, then the rest for the direction(s) whose
// dash 2 was found (finish_link).
inline int find_link(__global const PIXEL_T *src, const lattice L, int x, int y, link_t *out)
{
    const int i0 = lat(L, x, y, 0, 0), i1 = lat(L, x, y, 1, 0);
    if (i0 < 0 || i1 < 0) return 0;
    const float3 ink = rgb_at(src, i0), bgc = rgb_at(src, i1);
    if (diff3(ink, bgc) < INK_MIN) return 0;
    int reach = 0;
    if (!WIN(CLSO(0, -1)) || !WIN(CLSO(0, 1))) return 0;
    // dash 1: ink (or another colour over it) back to the background before a0, or to the frame's edge (cut1:
    // its ink must reach it); a = its first pixel of the ink; rows -1 and 1 clear beside it
    int a = 1, a0 = 1, last = 0, cut1 = 0;
    for (int k = 1; k <= MAX_RUN; ++k) {
        const int c = CLSO(-k, 0);
        if (c == OUTSIDE) {
            if (last != 1 - k) return 0;
            a = a0 = last; cut1 = 1;
            break;
        }
        if (c == 1) { a = last; a0 = 1 - k; break; }
        if (c == 0 || !WIN(CLSO(-k, -1)) || !WIN(CLSO(-k, 1))) return 0;
        if (c == 2) last = -k;
    }
    if (a == 1) return 0;
    // the directions: rows 1 and -1 walked together from step 1, t = 0 for d = 1 (gap row 1, window row -1), t = 1
    // for d = -1. Direction d lives while row -d is clear or a crossing (a window row) and row d is clear inside the
    // frame or a crossing that cannot start dash 2 (the gap: its run is skipped, up to sk); dash 2 starts where row d
    // then holds the ink, at s >= 2. Usually one direction's dash 2 ends the other (in its row -d); both are finished
    // only where a crossing let both through.
    // A crossing refuses a link of dashes shorter than XING_DASH, and where the gap runs past one, the link that would
    // start dash 2 there is refused too (the ink beside it): with a short dash 1 (not cut by the frame) crossings are
    // not looked for (the same links, fewer reads).
    const int xok = cut1 || 1 - a >= XING_DASH;
    // per direction (p: d = 1, m: d = -1): alive, dash 2's start, last step of a skipped crossing run, crossing let
    // through, its last step, row -d left the frame
    int alp = 1, alm = 1, sp = 0, sm = 0, skp = 0, skm = 0, xcp = 0, xcm = 0, xmp = 0, xmm = 0, otp = 0, otm = 0;
    for (int k = 1; k <= MAX_GAP + 1 && ((alp && !sp) || (alm && !sm)); ++k) {
        const int cp = CLSO(k, 1), cm = CLSO(k, -1);
        const int wp = alp && !sp, wm = alm && !sm;   // directions still walking
        // is the ink at (k, 1) / (k, -1) a crossing (k >= 2), where a walking direction needs to know
        const int xp = xok && cp == 2 && k >= 2 && (wm || (wp && k > skp)) && xing(src, L, x, y, k, 1, ink, bgc);
        const int xm = xok && cm == 2 && k >= 2 && (wp || (wm && k > skm)) && xing(src, L, x, y, k, -1, ink, bgc);
        if (wp) {   // d = 1: window row -1, gap row 1
            otp |= cm == OUTSIDE;
            if (!CLEAR(cm) && !xm) alp = 0;
            else {
                if (!CLEAR(cm)) { xcp = 1; xmp = k > xmp ? k : xmp; }
                if (k > skp && !(CLEAR(cp) && cp != OUTSIDE)) {
                    int lo, hi, adj = 0;
                    if (cp != 2 || k < 2) alp = 0;
                    else {
                        if (xp && thin_run(src, L, x, y, k, 1, ink, bgc, &lo, &hi))
                            for (int i = k - 1; i <= hi && !adj; ++i) adj = CLS(i, 0) == 2 || CLS(i, 2) == 2;
                        if (adj) { skp = hi; xcp = 1; xmp = hi; }   // a crossing that cannot start dash 2
                        else sp = k;
                    }
                }
            }
        }
        if (wm) {   // d = -1: window row 1, gap row -1
            otm |= cp == OUTSIDE;
            if (!CLEAR(cp) && !xp) alm = 0;
            else {
                if (!CLEAR(cp)) { xcm = 1; xmm = k > xmm ? k : xmm; }
                if (k > skm && !(CLEAR(cm) && cm != OUTSIDE)) {
                    int lo, hi, adj = 0;
                    if (cm != 2 || k < 2) alm = 0;
                    else {
                        if (xm && thin_run(src, L, x, y, k, -1, ink, bgc, &lo, &hi))
                            for (int i = k - 1; i <= hi && !adj; ++i) adj = CLS(i, 0) == 2 || CLS(i, -2) == 2;
                        if (adj) { skm = hi; xcm = 1; xmm = hi; }
                        else sm = k;
                    }
                }
            }
        }
    }
    link_t l0, l1;
    const int f0 = alp && sp && finish_link(src, L, x, y, ink, bgc, a, a0, cut1, 1, sp, reach | otp, xcp, xmp, &l0);
    const int f1 = alm && sm && finish_link(src, L, x, y, ink, bgc, a, a0, cut1, -1, sm, reach | otm, xcm, xmm, &l1);
    if (f0 == f1) return 0;
    *out = f0 ? l0 : l1;
    return 1;
}

// Links found by bridge_find, one ushort per pixel and orientation where its `found` bit is set: bit 0 d < 0,
// bits 1-5 -a, bits 6-10 s, bits 11-15 b - s (MAX_RUN <= 32 and MAX_GAP <= 30: the host checks).
inline ushort pack_link(const link_t ln)
{
    return (ushort)((uint)(ln.d < 0) | (uint)(-ln.a) << 1 | (uint)ln.s << 6 | (uint)(ln.b - ln.s) << 11);
}

inline link_t unpack_link(int x, int y, uint v)
{
    link_t ln;
    ln.x = x; ln.y = y;
    ln.d = (v & 1u) ? -1 : 1;
    ln.a = -(int)(v >> 1 & 31u);
    ln.s = (int)(v >> 6 & 31u);
    ln.b = ln.s + (int)(v >> 11 & 31u);
    return ln;
}

// Does a link of the same direction end at dash 1 of `ln` (a dash before it, one lattice row back, past
// background, other colours and, before a dash 1 of XING_DASH or more, a wire of the same ink crossing the gap)? 1
// and that link in *prev, or 0.
inline int incoming(__global const PIXEL_T *src, __global const uchar *found, __global const ushort *links,
                    const lattice L, const int o, const link_t ln, link_t *prev)
{
    const int x = ln.x, y = ln.y;
    const float3 ink = rgb_at(src, lat(L, x, y, 0, 0)), bgc = rgb_at(src, lat(L, x, y, 1, 0));
    {
        const int j = -ln.d;   // a straight wire's chain steps one way: the dash before lies in row -d (#15)
        for (int k = 1; k <= MAX_GAP + 1; ++k) {
            const int c = CLS(ln.a - k, j);
            if (CLEAR(c)) continue;
            if (c == 0) break;
            const int q = lat(L, x, y, ln.a - k, j);
            if (found[q] >> o & 1u) {
                *prev = unpack_link(x + (ln.a - k) * L.ax + j * L.bx, y + (ln.a - k) * L.ay + j * L.by,
                                    links[4 * q + o]);
                if (j + prev->d == 0 && prev->s == k) return 1;
            }
            if (c == 2 && 1 - ln.a >= XING_DASH && xing(src, L, x, y, ln.a - k, j, ink, bgc)) continue;
            break;
        }
    }
    return 0;
}

// Does a link of the same direction start at the end of dash 2 of `ln`? (A straight wire's chain steps one way;
// dots that zig-zag between two rows are a mesh's samples -- a fence far away -- not a wire: #15.)
inline int outgoing(__global const uchar *found, __global const ushort *links, const lattice L, const int o,
                    const link_t ln)
{
    const int q = lat(L, ln.x, ln.y, ln.b, ln.d);
    return (found[q] >> o & 1u) && ((links[4 * q + o] & 1u) ? -1 : 1) == ln.d;
}

// Does the line go on without a gap: a dash of the same ink touching dash 1 diagonally one row before it, or
// dash 2 one row after it (background beyond it across the line, and beyond the dash it touches)?
inline int touches(__global const PIXEL_T *src, const lattice L, const link_t ln)
{
    const int x = ln.x, y = ln.y, d = ln.d;
    const float3 ink = rgb_at(src, lat(L, x, y, 0, 0)), bgc = rgb_at(src, lat(L, x, y, 1, 0));
    if (INK(ln.a - 1, -d) && BG(ln.a - 1, -2 * d) && BG(ln.a, -2 * d)) return 1;
    return INK(ln.b + 1, 2 * d) && BG(ln.b + 1, 3 * d) && BG(ln.b, 3 * d);
}
