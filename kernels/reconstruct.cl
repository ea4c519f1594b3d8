// reconstruct.cl -- the second half of the reconstruction program (kernels/reconstruct_rules.cl comes first:
// the cheap test, CIELAB and the rules of seed 000 §4): each group's CIELAB scratch and the kernels.

// ---- CIELAB of a group's pixels into the work item's scratch. A slot holds one row of the segment and its
// two outside neighbours: L, a, b planes of LAB_STRIDE floats, column c = x - x0 + 1.
#define LAB_STRIDE (SEGMENT + 8)
#define SLOT_FLOATS (3 * LAB_STRIDE)
#define EDGE_L (1u << 8)   // slot flags: bit j = group j converted; EDGE_L/R = pixel x0 - 1 / x1
#define EDGE_R (1u << 9)

inline void put_lab(__global float *slot, int c, float3 v)
{
    slot[c] = v.x;
    slot[LAB_STRIDE + c] = v.y;
    slot[2 * LAB_STRIDE + c] = v.z;
}

inline float3 get_lab(__global const float *slot, int c)
{
    return (float3)(slot[c], slot[LAB_STRIDE + c], slot[2 * LAB_STRIDE + c]);
}

#ifndef PIXEL_IS_FLOAT
// CIELAB of 8 pixels: common.cl's LAB8 (checked for every 8-bit colour by tests/test_reconstruct.py).
// Sample c of the 8 pixels from p on.
#define SAMPLES8(p, c) convert_int8((ushort8)((p)[c], (p)[(c) + CHANNELS], (p)[(c) + 2 * CHANNELS],       \
    (p)[(c) + 3 * CHANNELS], (p)[(c) + 4 * CHANNELS], (p)[(c) + 5 * CHANNELS], (p)[(c) + 6 * CHANNELS],   \
    (p)[(c) + 7 * CHANNELS]))
#endif

// Lab of the n pixels from i on into slot columns c.. (n = GROUP: a lane each; else a pixel at a time).
inline void lab_group(__global const PIXEL_T *src, __global const float *luts, __global const float *lin,
                      __global float *slot, int c, int i, int n)
{
#ifndef PIXEL_IS_FLOAT
    if (n == GROUP) {
        __global const PIXEL_T *p = src + (size_t)i * CHANNELS;
        int8 s0, s1, s2;
#if RGB8
        const uchar16 lo = LOAD_UCHAR16(p);   // the group's 24 bytes
        const uchar8 hi = LOAD_UCHAR8(p + 16);
        s0 = convert_int8((uchar8)(lo.s0, lo.s3, lo.s6, lo.s9, lo.sc, lo.sf, hi.s2, hi.s5));
        s1 = convert_int8((uchar8)(lo.s1, lo.s4, lo.s7, lo.sa, lo.sd, hi.s0, hi.s3, hi.s6));
        s2 = convert_int8((uchar8)(lo.s2, lo.s5, lo.s8, lo.sb, lo.se, hi.s1, hi.s4, hi.s7));
#elif CHANNELS >= 3
        s0 = SAMPLES8(p, 0); s1 = SAMPLES8(p, 1); s2 = SAMPLES8(p, 2);
#else
        s0 = SAMPLES8(p, 0); s1 = s0; s2 = s0;
#endif
        float8 L, A, Z;
#if ORDER_BGR
        LAB8(s2, s1, s0, L, A, Z);
#else
        LAB8(s0, s1, s2, L, A, Z);
#endif
        STORE_FLOAT8(L, slot + c);
        STORE_FLOAT8(A, slot + LAB_STRIDE + c);
        STORE_FLOAT8(Z, slot + 2 * LAB_STRIDE + c);
        return;
    }
#endif
    for (int t = 0; t < n; ++t) put_lab(slot, c + t, lab_px(src, luts, lin, i + t));
}

// Ring bits of pixel (x, y) whose max-channel difference reaches NEAR_LIMIT (returned) and FAR_LIMIT (*far).
inline uint ring_masks(__global const PIXEL_T *src, int x, int y, int width, int height, uint *far)
{
    const rawpx a = raw_px(src, IDX(x, y, width));
    const uint valid = valid_ring(x, y, width, height);
    uint maybe = 0, f = 0;
    for (int k = 0; k < 8; ++k) {
        if (!(valid >> k & 1u)) continue;
        const rawdiff d = max_diff(raw_px(src, IDX(x + RX[k], y + RY[k], width)), a);
        maybe |= (uint)(d >= NEAR_LIMIT) << k;
        f |= (uint)(d >= FAR_LIMIT) << k;
    }
    *far = f;
    return maybe;
}

// The ΔE² of 8 lanes to their ring neighbour in scratch row `row` at column offset `off`: bit `bit` of M where
// over the threshold less 0.2% (M, within it X: the lanes' sums may round unlike d2()), of S where over it
// plus 0.2% (S within X), of F where over 2 thresholds less 0.5% (F holds reconstruct_at's `far`) and of B
// where over 2.012 thresholds (B within reconstruct_at's `beyond`, over 2.01).
#define RING_DE2(row, off, bit) {                                                                        \
        const float8 l_ = LOAD_FLOAT8((row) + c + (off)) - aL;                                        \
        const float8 a_ = LOAD_FLOAT8((row) + LAB_STRIDE + c + (off)) - aA;                           \
        const float8 b_ = LOAD_FLOAT8((row) + 2 * LAB_STRIDE + c + (off)) - aB;                       \
        const float8 e_ = l_ * l_ + a_ * a_ + b_ * b_;                                                 \
        M |= (e_ > tm) & (int8)(bit);                                                                  \
        S |= (e_ > th) & (int8)(bit);                                                                  \
        F |= (e_ > tf) & (int8)(bit);                                                                  \
        B |= (e_ > tb) & (int8)(bit); }

// dst = src except where a rule fires. `scratch`: 3 * SLOT_FLOATS floats per work item.
__kernel void reconstruct(__global const PIXEL_T *src, __global PIXEL_T *dst, __global const float *luts,
                          __global const float *lin, __global float *scratch, __global const uint *table,
                          const int width, const int height, const float t2)
{
    const int x0 = get_global_id(0) * SEGMENT, y0 = get_global_id(1) * STRIP;
    if (x0 >= width || y0 >= height) return;
    const int x1 = x0 + SEGMENT < width ? x0 + SEGMENT : width, y1 = y0 + STRIP < height ? y0 + STRIP : height;
    const int ngroups = (x1 - x0 + GROUP - 1) / GROUP;
    __global float *slots = scratch + (size_t)(get_global_id(1) * get_global_size(0) + get_global_id(0)) * 3 *
                                          SLOT_FLOATS;
    const float tm = 0.998f * t2, th = 1.002f * t2, tf = 3.98f * t2, tb = 4.05f * t2;
    uint have[3] = {0u, 0u, 0u};   // per slot: what holds CIELAB (group bits, EDGE_L, EDGE_R)
    for (int y = y0; y < y1; ++y) {
        // row yy lives in slot (yy - y0 + 1) % 3: y - 1 in su, y in sm, y + 1 in sd (which held y - 2)
        const int su = (y - y0) % 3, sm = (y - y0 + 1) % 3, sd = (y - y0 + 2) % 3;
        if (y > y0) have[sd] = 0u;
        const int inner = y > 0 && y + 1 < height;
        // a whole interior segment bit-identical at once: 3 rows of x0-1..x1 equal, this row constant
        if (inner && x1 - x0 == SEGMENT && x0 > 0 && x1 < width) {
            const int px = CHANNELS * SAMPLE_BYTES, row = width * px;
            __global const uchar *p = (__global const uchar *)src + (size_t)(IDX(x0, y, width) - 1) * px;
            if (same_bytes(p, p - row, (SEGMENT + 2) * px) && same_bytes(p, p + row, (SEGMENT + 2) * px) &&
                same_bytes(p, p + px, (SEGMENT + 1) * px))
                continue;
        }
        // 1. RGB: lanes[j] = the pixels of interior group j where a rule may fire by the RGB bounds (bit t: pixel
        // g + t; candidate()'s tests, or the first of them); the frame's border groups run the rules here, from
        // CIELAB a pixel at a time
        uchar lanes[SEGMENT / GROUP];
        uint cg = 0u, cl = 0u, cr = 0u;   // groups with such pixels; of those, with one in lane 0 / lane 7
        for (int j = 0; j < ngroups; ++j) {
            const int g = x0 + j * GROUP, ge = g + GROUP < x1 ? g + GROUP : x1, i = IDX(g, y, width);
            lanes[j] = 0;
            if (ge - g == GROUP && g > 0 && g + GROUP < width && inner) {
                if (identical_window(src, i, width)) continue;
                uint on = 0u;
#if RGB8
                on = gate_rgb8(src, i, width);
#else
#ifndef PIXEL_IS_FLOAT
                short8 mv, fv;
                group_masks(src, i, width, &mv, &fv);
                const short4 o = mv.lo | mv.hi;
                if ((o.x | o.y | o.z | o.w) == 0) continue;
                short mb[GROUP], fb[GROUP];
                STORE_SHORT8_PRIVATE(mv, mb);
                STORE_SHORT8_PRIVATE(fv, fb);
#else
                if (smooth_group(src, i, width)) continue;
                uint mb[GROUP], fb[GROUP];
                for (int t = 0; t < GROUP; ++t) mb[t] = ring_masks(src, g + t, y, width, height, fb + t);
#endif
                for (int t = 0; t < GROUP; ++t)
                    if (mb[t] && candidate(src, table, raw_px(src, i + t), (uint)mb[t], (uint)fb[t], g + t, y,
                                           width, height))
                        on |= 1u << t;
#endif
                lanes[j] = (uchar)on;
                cg |= (uint)(on != 0u) << j;
                cl |= (on & 1u) << j;
                cr |= (on >> 7 & 1u) << j;
                continue;
            }
            for (int x = g; x < ge; ++x) {
                uint far;
                const uint maybe = ring_masks(src, x, y, width, height, &far);
                if (!maybe || !candidate(src, table, raw_px(src, IDX(x, y, width)), maybe, far, x, y, width, height))
                    continue;
                float3 ring[8];
                for (int k = 0; k < 8; ++k)
                    if (maybe >> k & 1u) ring[k] = lab_px(src, luts, lin, IDX(x + RX[k], y + RY[k], width));
                reconstruct_at(src, dst, luts, lin, table, x, y, width, height, t2, maybe,
                               lab_px(src, luts, lin, IDX(x, y, width)), ring);
            }
        }
#if STOP_AFTER == 1   // timing split (reconstruct_bench --split): the RGB gate alone, its result kept live
        if ((cg ^ cl ^ cr ^ lanes[0] ^ lanes[SEGMENT / GROUP - 1]) == 0xfffffu) dst[0] = 1;
        continue;
#endif
        if (cg == 0u) continue;
        // 2. CIELAB of rows y-1, y, y+1 over those groups, and the neighbour groups their lanes 0 and 7 read
        // (each once per strip; converting the one pixel alone was slower, measured), or the pixels x0 - 1, x1
        uint need = (cg | cl >> 1 | cr << 1) & ((1u << ngroups) - 1u);
        need |= (cl & 1u ? EDGE_L : 0u) | (cr >> (ngroups - 1) & 1u ? EDGE_R : 0u);
        for (int r = 0; r < 3; ++r) {
            const int sl = r == 0 ? su : (r == 1 ? sm : sd), yy = y - 1 + r;
            const uint todo = need & ~have[sl];
            __global float *slot = slots + sl * SLOT_FLOATS;
            for (int j = 0; j < ngroups; ++j) {
                if (!(todo >> j & 1u)) continue;
                const int g = x0 + j * GROUP;
                lab_group(src, luts, lin, slot, g - x0 + 1, IDX(g, yy, width), g + GROUP < x1 ? GROUP : x1 - g);
            }
            if (todo & EDGE_L) put_lab(slot, 0, lab_px(src, luts, lin, IDX(x0 - 1, yy, width)));
            if (todo & EDGE_R) put_lab(slot, x1 - x0 + 1, lab_px(src, luts, lin, IDX(x1, yy, width)));
            have[sl] |= todo;
            // Lanes 0 and 7 of a group also read one column of each neighbour group; where that neighbour
            // holds no CIELAB (its pixel is no candidate, so those lanes' results are masked out by `lanes`),
            // the column gets a defined value: no lane reads scratch memory that was never written.
            for (int j = 0; j < ngroups; ++j) {
                if (!(cg >> j & 1u)) continue;
                const int c = j * GROUP + 1;
                const uint left = j > 0 ? 1u << (j - 1) : EDGE_L, right = j + 1 < ngroups ? 1u << (j + 1) : EDGE_R;
                if (!(have[sl] & left)) put_lab(slot, c - 1, (float3)(0.0f));
                if (!(have[sl] & right)) put_lab(slot, c + GROUP, (float3)(0.0f));
            }
        }
        // 3. the exact ring masks, a lane per pixel; the rules where X may hold a gap
        __global const float *u = slots + su * SLOT_FLOATS, *m = slots + sm * SLOT_FLOATS,
                             *d = slots + sd * SLOT_FLOATS;
        for (int j = 0; j < ngroups; ++j) {
            if (!(cg >> j & 1u)) continue;
            const int g = x0 + j * GROUP, c = g - x0 + 1, i = IDX(g, y, width);
            const float8 aL = LOAD_FLOAT8(m + c), aA = LOAD_FLOAT8(m + LAB_STRIDE + c),
                         aB = LOAD_FLOAT8(m + 2 * LAB_STRIDE + c);
            int8 M = (int8)(0), S = M, F = M, B = M;
            RING_DE2(u, -1, 1) RING_DE2(u, 0, 2) RING_DE2(u, 1, 4) RING_DE2(m, 1, 8)
            RING_DE2(d, 1, 16) RING_DE2(d, 0, 32) RING_DE2(d, -1, 64) RING_DE2(m, -1, 128)
            const int4 mo = M.lo | M.hi;
            if ((mo.x | mo.y | mo.z | mo.w) == 0) continue;
#if STOP_AFTER == 2   // timing split: the gate, CIELAB and the exact ring masks, without the rules
            if ((M.s0 ^ S.s1 ^ F.s2 ^ B.s3) == 0xfffff) dst[0] = 1;
            continue;
#endif
            int mb[GROUP], sb[GROUP], fb[GROUP], bb[GROUP];
            STORE_INT8_PRIVATE(M, mb);
            STORE_INT8_PRIVATE(S, sb);
            STORE_INT8_PRIVATE(F, fb);
            STORE_INT8_PRIVATE(B, bb);
            for (int t = 0; t < GROUP; ++t) {
                const uint maybe = (uint)mb[t];
                if (!maybe || !(lanes[j] >> t & 1u)) continue;
                // necessary for a rule to fire, on the ΔE masks (S within X within M): the paper's rule needs
                // gap[X] -- exactly that when S = M, else some sub-mask of M a gap; the line-relative rule a gap
                // within reconstruct_at's `far` (inside F); the two-pixel rule a direction k of its `line` (the
                // one bit of `beyond` if it holds one, none if two, else one of X beyond 2 thresholds: `over`
                // = B within `beyond`, F beyond it) with the opposite pixel B not in X (S) and two_gap_possible
                const uint sure = (uint)sb[t], far = (uint)fb[t], over = (uint)bb[t];
                int cand = (table[maybe] & (sure == maybe ? 1u : 2u)) != 0;
#if EXTENDED
                cand = cand || (table[far] & 2u) != 0;
                const uint line = over & (over - 1u) ? 0u : (over ? over : far);
                for (int k = 0; line >> k && !cand; ++k)
                    if ((line >> k & 1u) && !(sure >> ((k + 4) & 7) & 1u))
                        cand = two_gap_possible(src, raw_px(src, i + t), g + t, y, k, width, height);
#endif
                if (!cand) continue;
                float3 ring[8];
                for (int k = 0; k < 8; ++k)
                    if (maybe >> k & 1u) ring[k] = get_lab(RY[k] < 0 ? u : (RY[k] > 0 ? d : m), c + t + RX[k]);
                reconstruct_at(src, dst, luts, lin, table, g + t, y, width, height, t2, maybe, get_lab(m, c + t),
                               ring);
            }
        }
    }
}

// Test support (tests/test_reconstruct.py): bad[j] = how many of the GROUP pixels from j * GROUP on get a
// CIELAB from lab_group (lanes) that differs in some bit from lab_px's (a pixel at a time); `scratch`: a slot
// per work item.
__kernel void reconstruct_lab_check(__global const PIXEL_T *src, __global const float *luts,
                                    __global const float *lin, __global float *scratch, __global int *bad,
                                    const int groups)
{
    __global float *slot = scratch + (size_t)get_global_id(0) * SLOT_FLOATS;
    for (int j = get_global_id(0); j < groups; j += get_global_size(0)) {
        lab_group(src, luts, lin, slot, 1, j * GROUP, GROUP);
        int n = 0;
        for (int t = 0; t < GROUP; ++t) {
            const float3 u = get_lab(slot, 1 + t), v = lab_px(src, luts, lin, j * GROUP + t);
            n += as_uint(u.x) != as_uint(v.x) || as_uint(u.y) != as_uint(v.y) || as_uint(u.z) != as_uint(v.z);
        }
        bad[j] = n;
    }
}
