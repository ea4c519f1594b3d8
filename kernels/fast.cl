// fast.cl -- the three-pass MLAA of seed 004 (Kluczek, "Antialiasing in 1 millisecond"): edges, L shapes,
// reconstruction + blend, each a full-frame pass, with a bounded edge length (FAST_MAX_LEN). The preset
// `fast` (mlaa_stream/spatial/fast.py, whose numpy reference mirrors this file rule for rule).
// Work in blocks of 64 columns x FAST_ROWS rows: a work item per block (edges), per 64 pixels of a row (blend),
// per row (bottom-edge shapes), per strip of 64 columns (right-edge shapes). The edge pass marks the blocks
// that hold an edge (`blocks`, a byte per block, row-major); the later passes skip the others.
// Defines: FAST_THRESHOLD (weighted RGB difference, fraction of full scale), FAST_MAX_LEN (<= 31), FAST_ROWS
//          (rows of a block), BLEND_LINEAR / LINEAR_INPUT and SUBPIXEL_ON / SUBPIXEL / SUBPIXEL_END /
//          SUBPIXEL_BG as blend.cl (the Filter's options).

#ifndef FAST_THRESHOLD
#define FAST_THRESHOLD 0.06f
#endif
#ifndef FAST_MAX_LEN
#define FAST_MAX_LEN 31
#endif
#ifndef FAST_ROWS
#define FAST_ROWS 8
#endif
#define FAST_COLS 64   // the 64-bit masks of the shape sweeps
#define BLOCKS_X(width) (((width) + FAST_COLS - 1) / FAST_COLS)

// Pass 1 edge bits (seed 004 "edge buffer"): every edge is kept in both pixels that share it, so the later
// passes read one byte per pixel instead of colours.
#define E_TOP 1
#define E_RIGHT 2
#define E_BOTTOM 4
#define E_LEFT 8

// Seed 004: an edge where the weighted sum of the RGB channels' differences exceeds the threshold
// (Rec. 709 luma weights, on the stored encoded values).
inline float weighted_diff(float4 a, float4 b)
{
    const float4 d = a - b;
    const float x = d.x < 0.0f ? -d.x : d.x, y = d.y < 0.0f ? -d.y : d.y, z = d.z < 0.0f ? -d.z : d.z;
    return 0.2126f * x + 0.7152f * y + 0.0722f * z;
}

#ifndef PIXEL_IS_FLOAT
// Integer frames: the same weighted sum on the stored levels, in integers (weights 54, 183, 19 of 256: Rec. 709
// to 0.002), so a pixel costs a few byte loads and no conversion.
#define W_R 54
#define W_G 183
#define W_B 19
#define FAST_LIMIT ((int)(FAST_THRESHOLD * PIXEL_MAX * 256.0f))
inline int3 raw3(__global const PIXEL_T *src, int i)
{
#if CHANNELS < 3
    return (int3)((int)src[i]);
#else
    __global const PIXEL_T *p = src + (size_t)i * CHANNELS;
    return (int3)((int)p[0], (int)p[1], (int)p[2]);
#endif
}
inline int idiff(int3 a, int3 b)
{
    const int3 d = a - b;
    const int x = d.x < 0 ? -d.x : d.x, y = d.y < 0 ? -d.y : d.y, z = d.z < 0 ? -d.z : d.z;
#if ORDER_BGR
    return W_B * x + W_G * y + W_R * z;
#else
    return W_R * x + W_G * y + W_B * z;
#endif
}

// The scalar path's pixel and edge test: stored levels and idiff for integer frames, float4 and weighted_diff for
// float frames (below, after the #else).
typedef int3 fast_px;
inline fast_px fast_px_at(__global const PIXEL_T *src, int i) { return raw3(src, i); }
inline int fast_edge(fast_px a, fast_px b) { return idiff(a, b) > FAST_LIMIT; }

#if CHANNELS == 3 && SAMPLE_BYTES == 1
#define FAST_VECTOR 1
#define FAST_QUIET (FAST_LIMIT / 256)
#ifdef POCL_DEVICE_ADDRESS_BITS
#define STORE_UCHAR16(v, p) (*(__global uchar16_a1 *)(p) = (v))
#else
#define STORE_UCHAR16(v, p) vstore16(v, 0, p)
#endif
// Does some byte of a differ from the same byte of b by more than FAST_QUIET levels? (nonzero: yes)
inline ulong louder16(uchar16 a, uchar16 b)
{
    const uchar16 d = a > b ? a - b : b - a;
    const ulong2 m = as_ulong2(d > (uchar16)(FAST_QUIET));
    return m.x | m.y;
}

// The weighted differences of 8 RGB pixels at a and at b (24 bytes each), lane k for pixel k: the bytes'
// absolute differences, regrouped by channel, weighted in 16 bits (at most 256 * 255 = 65280).
inline short8 edge8(uchar16 a0, uchar8 a1, __global const uchar *b)
{
    const uchar16 b0 = LOAD_UCHAR16(b);
    const uchar8 b1 = LOAD_UCHAR8(b + 16);
    const uchar16 d0 = a0 > b0 ? a0 - b0 : b0 - a0;
    const uchar8 d1 = a1 > b1 ? a1 - b1 : b1 - a1;
    // no byte differs by more than FAST_QUIET levels: no edge (the weights sum to 256); most of a frame
    const ulong2 q0 = as_ulong2(d0 > (uchar16)(FAST_QUIET));
    if (!(q0.x | q0.y | as_ulong(d1 > (uchar8)(FAST_QUIET)))) return (short8)(0);
    const ushort8 c0 = convert_ushort8((uchar8)(d0.s0, d0.s3, d0.s6, d0.s9, d0.sc, d0.sf, d1.s2, d1.s5));
    const ushort8 c1 = convert_ushort8((uchar8)(d0.s1, d0.s4, d0.s7, d0.sa, d0.sd, d1.s0, d1.s3, d1.s6));
    const ushort8 c2 = convert_ushort8((uchar8)(d0.s2, d0.s5, d0.s8, d0.sb, d0.se, d1.s1, d1.s4, d1.s7));
#if ORDER_BGR
    const ushort8 s = (ushort8)(W_B) * c0 + (ushort8)(W_G) * c1 + (ushort8)(W_R) * c2;
#else
    const ushort8 s = (ushort8)(W_R) * c0 + (ushort8)(W_G) * c1 + (ushort8)(W_B) * c2;
#endif
    return s > (ushort8)(FAST_LIMIT);   // -1 where an edge
}
#endif
#else
typedef float4 fast_px;
inline fast_px fast_px_at(__global const PIXEL_T *src, int i) { return load_px(src, i); }
inline int fast_edge(fast_px a, fast_px b) { return weighted_diff(a, b) > FAST_THRESHOLD; }
#endif

// Pass 1, and the copy of the frame into dst (pass 3 then writes only the pixels it changes): the source
// row is read here anyway, so the copy costs a store instead of a separate full-frame copy.
__kernel void fast_edges(__global const PIXEL_T *src, __global uchar *edges, __global PIXEL_T *dst,
                         __global uchar *blocks, const int width, const int height)
{
    // a block per work item: global size (ceil(width / FAST_COLS), ceil(height / FAST_ROWS))
    const int x0 = get_global_id(0) * FAST_COLS, y0 = get_global_id(1) * FAST_ROWS;
    if (x0 >= width || y0 >= height) return;
    const int x1 = x0 + FAST_COLS < width ? x0 + FAST_COLS : width, y1 = y0 + FAST_ROWS < height ? y0 + FAST_ROWS : height;
    uint seen = 0;   // any edge in the block
#ifdef FAST_VECTOR
    uchar8 under[FAST_COLS / 8];   // per group: the row above's bottom edges, which are this row's top edges
    ulong under_any = 0;           // any of them
#endif
    for (int y = y0; y < y1; ++y) {
        const int row = y * width;
        int x = x0;
#ifdef FAST_VECTOR
        // 8 pixels at a time while pixel x + 8 (the right neighbour of the group's last) is in the row: two
        // weighted differences of 8 lanes (right, down; up is the row above's down, but in a work item's first
        // row); the left edges are the right ones shifted by a pixel. Integer sums: the scalar path's bits.
        if (x + 8 < width) {
            __global const uchar *s8 = (__global const uchar *)src;
            __global uchar *d8 = (__global uchar *)dst;
            const size_t stride = 3 * (size_t)width;
            uchar prev = x > 0 && fast_edge(fast_px_at(src, row + x - 1), fast_px_at(src, row + x));   // left of x
            int copied = 0;
            // The block's 64 pixels of this row at once, 16 bytes at a time: where no byte differs from the
            // right or lower neighbour's (in the block's first row the upper's too) by more than FAST_QUIET,
            // and no edge comes from the left or above, the row has no edge (most of a frame).
            if (!prev && !under_any && x1 - x0 == FAST_COLS && x1 < width) {
                ulong loud = 0;
                for (int k = 0; k < 3 * FAST_COLS; k += 16) {
                    const size_t o = 3 * (size_t)row + 3 * x0 + k;
                    const uchar16 a = LOAD_UCHAR16(s8 + o);
                    STORE_UCHAR16(a, d8 + o);
                    loud |= louder16(a, LOAD_UCHAR16(s8 + o + 3));
                    if (y + 1 < height) loud |= louder16(a, LOAD_UCHAR16(s8 + o + stride));
                    if (y == y0 && y > 0) loud |= louder16(a, LOAD_UCHAR16(s8 + o - stride));
                }
                copied = 1;
                if (!loud) {
                    for (int g = 0; g < FAST_COLS / 8; ++g) {
                        STORE_UCHAR8((uchar8)(0), edges + row + x0 + 8 * g);
                        under[g] = (uchar8)(0);
                    }
                    x = x1;
                }
            }
            under_any = 0;
            for (int g = 0; x < x1 && x + 8 < width; x += 8, ++g) {
                const size_t o = 3 * (size_t)(row + x);
                const uchar16 c0 = LOAD_UCHAR16(s8 + o);
                const uchar8 c1 = LOAD_UCHAR8(s8 + o + 16);
                if (!copied) {
                    STORE_UCHAR16(c0, d8 + o);
                    STORE_UCHAR8(c1, d8 + o + 16);
                }
                const uchar8 r = convert_uchar8(-edge8(c0, c1, s8 + o + 3));
                uchar8 t = (uchar8)(0);
                if (y > y0) t = under[g];
                else if (y > 0) t = convert_uchar8(-edge8(c0, c1, s8 + o - stride));
                const uchar8 b = y + 1 < height ? convert_uchar8(-edge8(c0, c1, s8 + o + stride)) : (uchar8)(0);
                under[g] = b;
                under_any |= as_ulong(b);
                const uchar8 l = (uchar8)(prev, r.s0, r.s1, r.s2, r.s3, r.s4, r.s5, r.s6);
                prev = r.s7;
                const uchar8 e = t * (uchar8)(E_TOP) | r * (uchar8)(E_RIGHT) | b * (uchar8)(E_BOTTOM) | l * (uchar8)(E_LEFT);
                STORE_UCHAR8(e, edges + row + x);
                seen |= as_ulong(e) != 0;
            }
        }
#endif
        fast_px left = x > 0 ? fast_px_at(src, row + x - 1) : (fast_px)(0);
        fast_px c = x < x1 ? fast_px_at(src, row + x) : (fast_px)(0);
        for (; x < x1; ++x) {
            const int i = row + x;
            for (int k = 0; k < CHANNELS; ++k) dst[(size_t)i * CHANNELS + k] = src[(size_t)i * CHANNELS + k];
            const fast_px right = x + 1 < width ? fast_px_at(src, i + 1) : c;
            uchar e = 0;
            if (y > 0 && fast_edge(c, fast_px_at(src, i - width))) e |= E_TOP;
            if (x + 1 < width && fast_edge(c, right)) e |= E_RIGHT;
            if (y + 1 < height && fast_edge(c, fast_px_at(src, i + width))) e |= E_BOTTOM;
            if (x > 0 && fast_edge(c, left)) e |= E_LEFT;
            edges[i] = e;
            seen |= e;
            left = c;
            c = right;
        }
    }
    blocks[get_global_id(1) * BLOCKS_X(width) + get_global_id(0)] = seen != 0;
}

// Pass 2 (seed 004 "L-shape buffer"): four L shapes per pixel, one byte each: from the pixel along its bottom
// edge to the left and to the right (hshapes), and along its right edge up and down (vshapes). A shape runs
// along its line to the line's end and ends in a crossing edge to one side, to both, or none. Byte: bits 0-4
// the distance to the end, bits 5-6 the crossing (1 = on the side of this pixel's row or column, 2 = the
// other side, 3 = both, 0 none), bit 7 a long crossing (3+ pixels: a real corner, kept sharp as seed 002
// does). A line's end more than FAST_MAX_LEN - 1 pixels away is not known: distance FAST_MAX_LEN - 1, no
// crossing (the seed's bounded edge length). Each line is walked once, by a sweep along it: one work item
// per row for the bottom edges, one per strip of 64 columns for the right edges.
#define L_SIDE_A 1
#define L_SIDE_B 2
#define L_UNKNOWN (FAST_MAX_LEN - 1)

inline int edge_bit(__global const uchar *edges, int x, int y, int width, int height, uchar bit)
{
    return x >= 0 && y >= 0 && x < width && y < height && (edges[y * width + x] & bit);
}

// The crossing at the end of a line of bottom edges in row y, across the right edge of column xc (rows y and
// y + 1), as bits 5-7 of a shape byte.
inline uchar h_crossing(__global const uchar *edges, int xc, int y, int width, int height)
{
    const int a = edge_bit(edges, xc, y, width, height, E_RIGHT), b = edge_bit(edges, xc, y + 1, width, height, E_RIGHT);
    const int side = (a ? L_SIDE_A : 0) | (b ? L_SIDE_B : 0);
    const int lg = side == L_SIDE_A ? (edge_bit(edges, xc, y - 1, width, height, E_RIGHT) &&
                                       edge_bit(edges, xc, y - 2, width, height, E_RIGHT))
                 : side == L_SIDE_B ? (edge_bit(edges, xc, y + 2, width, height, E_RIGHT) &&
                                       edge_bit(edges, xc, y + 3, width, height, E_RIGHT)) : 0;
    return (uchar)(side << 5 | lg << 7);
}

// The same for a line of right edges in column x ending across the bottom edge of row yc (columns x, x + 1).
inline uchar v_crossing(__global const uchar *edges, int x, int yc, int width, int height)
{
    const int a = edge_bit(edges, x, yc, width, height, E_BOTTOM), b = edge_bit(edges, x + 1, yc, width, height, E_BOTTOM);
    const int side = (a ? L_SIDE_A : 0) | (b ? L_SIDE_B : 0);
    const int lg = side == L_SIDE_A ? (edge_bit(edges, x - 1, yc, width, height, E_BOTTOM) &&
                                       edge_bit(edges, x - 2, yc, width, height, E_BOTTOM))
                 : side == L_SIDE_B ? (edge_bit(edges, x + 2, yc, width, height, E_BOTTOM) &&
                                       edge_bit(edges, x + 3, yc, width, height, E_BOTTOM)) : 0;
    return (uchar)(side << 5 | lg << 7);
}

// A shape byte for a pixel `d` pixels from its line's end with crossing bits `cross`.
inline uchar shape_byte(int d, uchar cross) { return d <= L_UNKNOWN ? (uchar)(d | cross) : (uchar)L_UNKNOWN; }

// Bit b of each of 8 edge bytes (a word as edge_group loads it), as bits 0-7 of a byte.
inline uint gather8(ulong g, int b) { return (uint)((((g >> b) & 0x0101010101010101UL) * 0x0102040810204080UL) >> 56); }

// Bit c of the result: edge bit b (1: E_RIGHT, 2: E_BOTTOM) of pixel x0 + c of row y, for n <= 64 columns.
inline ulong strip_bits(__global const uchar *edges, int x0, int n, int y, int width, int b)
{
    __global const uchar *p = edges + y * width + x0;
    ulong m = 0;
    if (n == 64) {
        for (int g = 0; g < 8; ++g) m |= (ulong)gather8(edge_group(p + 8 * g), b) << (8 * g);
    } else {
        for (int c = 0; c < n; ++c) m |= (ulong)((p[c] >> b) & 1) << c;
    }
    return m;
}

// The index of the lowest set bit of a nonzero word (taken as 64 bits).
#ifdef POCL_DEVICE_ADDRESS_BITS
#define LOWEST_BIT(m) __builtin_ctzl((ulong)(m))
#else
#define LOWEST_BIT(m) (63 - (int)clz((ulong)(m) & (~(ulong)(m) + 1)))
#endif

__kernel void fast_hshapes(__global const uchar *edges, __global const uchar *blocks, __global uchar2 *hshapes,
                           const int width, const int height)
{
    // One row, 64 columns at a time as bit masks (as fast_vshapes): a bottom-edge line goes on from x to x + 1
    // where x + 1 has a bottom edge and no right edge at x crosses it in this row or the next.
    const int y = get_global_id(0);
    if (y >= height) return;
    int start = -1;   // the first column of a line that goes on past the previous 64 columns
    for (int x0 = 0; x0 < width; x0 += 64) {
        const int n = x0 + 64 < width ? 64 : width - x0;
        if (!blocks[(y / FAST_ROWS) * BLOCKS_X(width) + x0 / FAST_COLS]) continue;   // (as !bottom below)
        const ulong bottom = strip_bits(edges, x0, n, y, width, 2);
        if (!bottom) continue;   // (a line going on from before would have its next pixel here)
        const ulong right = strip_bits(edges, x0, n, y, width, 1) |
                            (y + 1 < height ? strip_bits(edges, x0, n, y + 1, width, 1) : 0);
        const ulong beyond = x0 + n < width ? (ulong)((edges[y * width + x0 + n] >> 2) & 1) << (n - 1) : 0;
        const ulong cont = bottom & ((bottom >> 1) | beyond) & ~right;
        ulong starts = bottom & ~((cont << 1) | (start >= 0 ? 1UL : 0UL)), ends = bottom & ~cont;
        while (ends) {   // lines alternate: each end's start is the lowest start left, or the one carried in
            const int ce = LOWEST_BIT(ends), xe = x0 + ce;
            int x = start;
            if (starts && LOWEST_BIT(starts) <= ce) {
                x = x0 + LOWEST_BIT(starts);
                starts &= starts - 1;
            }
            start = -1;
            const uchar c0 = h_crossing(edges, x - 1, y, width, height), c1 = h_crossing(edges, xe, y, width, height);
            for (int t = x; t <= xe; ++t) hshapes[y * width + t] = (uchar2)(shape_byte(t - x, c0), shape_byte(xe - t, c1));
            ends &= ends - 1;
        }
        if (starts) start = x0 + LOWEST_BIT(starts);   // a line going on into the next 64 columns
    }
}

__kernel void fast_vshapes(__global const uchar *edges, __global const uchar *blocks, __global uchar2 *vshapes,
                           const int width, const int height)
{
    // One strip of up to 64 columns, row by row, each row's right and bottom edges as 64-bit masks: a column
    // costs something only where its run of right edges starts or ends. Global size ceil(width / 64).
    const int x0 = get_global_id(0) * FAST_COLS;
    if (x0 >= width) return;
    const int n = x0 + 64 < width ? 64 : width - x0;
    int start[64];   // per column of the strip: the first row of the run in progress (where `open` has it)
    ulong open = 0;
    __global const uchar *marks = blocks + get_global_id(0);   // this strip's blocks, a row of blocks apart
    const int stride = BLOCKS_X(width);
    ulong right = marks[0] ? strip_bits(edges, x0, n, 0, width, 1) : 0;
    for (int y = 0; y < height; ++y) {
        const ulong next = y + 1 < height && marks[((y + 1) / FAST_ROWS) * stride] ?
                           strip_bits(edges, x0, n, y + 1, width, 1) : 0;
        if (!(right | open)) { right = next; continue; }
        ulong fresh = right & ~open;
        while (fresh) {
            const int c = LOWEST_BIT(fresh);
            start[c] = y;
            fresh &= fresh - 1;
        }
        open |= right;
        // a run goes on to the next row where that has a right edge and no bottom edge is under this pixel or
        // its right neighbour (no crossing line between)
        const ulong bottom = strip_bits(edges, x0, n, y, width, 2);   // (this block has edges: `right | open`)
        const ulong beyond = x0 + n < width ? (ulong)((edges[y * width + x0 + n] >> 2) & 1) << (n - 1) : 0;
        const ulong cont = next & ~bottom & ~((bottom >> 1) | beyond);
        ulong ends = open & ~cont;
        open &= cont;
        while (ends) {   // the runs start[c] .. y end here
            const int c = LOWEST_BIT(ends), x = x0 + c, ys = start[c];
            const uchar c0 = v_crossing(edges, x, ys - 1, width, height), c1 = v_crossing(edges, x, y, width, height);
            for (int t = ys; t <= y; ++t) vshapes[t * width + x] = (uchar2)(shape_byte(t - ys, c0), shape_byte(y - t, c1));
            ends &= ends - 1;
        }
        right = next;
    }
}

// fast_vshapes for GPUs (FastPasses picks it on devices that are not CPUs): one work item per column and
// FAST_VCHUNK rows instead of one per strip of 64 columns, so a frame has tens of thousands of work items and
// neighbouring work items read neighbouring bytes. A run reaching into the chunk from above is followed up to its
// start, one leaving it down to its end, each at most L_UNKNOWN + 1 rows past the chunk: a pixel farther than
// L_UNKNOWN from its run's end gets L_UNKNOWN whatever lies beyond. The same bytes as fast_vshapes.
#ifndef FAST_VCHUNK
#define FAST_VCHUNK 32
#endif

// Does the run of right edges in column x go on from row y - 1 into row y (1 <= y < height)? Both rows have the
// right edge and no bottom edge of row y - 1 in column x or x + 1 lies between (fast_vshapes' `cont`).
inline int vrun_goes_on(__global const uchar *edges, int x, int y, int width)
{
    const int i = y * width + x;
    return (edges[i] & E_RIGHT) && (edges[i - width] & E_RIGHT) && !(edges[i - width] & E_BOTTOM)
           && !(x + 1 < width && (edges[i - width + 1] & E_BOTTOM));
}

__kernel void fast_vshapes_columns(__global const uchar *edges, __global uchar2 *vshapes, const int width,
                                   const int height)
{
    const int x = get_global_id(0), y0 = get_global_id(1) * FAST_VCHUNK;
    if (x >= width || y0 >= height) return;
    const int y1 = y0 + FAST_VCHUNK < height ? y0 + FAST_VCHUNK : height;
    for (int y = y0; y < y1;) {
        if (!(edges[y * width + x] & E_RIGHT)) { ++y; continue; }
        int s = y, e = y;
        if (y == y0)
            while (s > 0 && y0 - s <= L_UNKNOWN && vrun_goes_on(edges, x, s, width)) --s;
        while (e + 1 < height && e - (y1 - 1) <= L_UNKNOWN && vrun_goes_on(edges, x, e + 1, width)) ++e;
        const uchar c0 = v_crossing(edges, x, s - 1, width, height), c1 = v_crossing(edges, x, e, width, height);
        const int last = e < y1 ? e : y1 - 1;
        for (int t = y; t <= last; ++t) vshapes[t * width + x] = (uchar2)(shape_byte(t - s, c0), shape_byte(e - t, c1));
        y = e + 1;
    }
}

// Pass 3 (seed 004 "edge reconstruction"): each edge of the pixel rebuilt from its two L shapes (the line's
// ends and crossings) as seed 000's silhouette: from half a pixel at an end with a crossing to nothing at the
// line's middle; where it covers this pixel, the colour across the edge is mixed in (seed 000 eq. 2's
// trapezoid areas, tabled on the host: spatial/fast.py trapezoid). U shapes (both ends turn the same way: a bump,
// or a box side) are left as they are.
// Pixel i in the mixing space: linear light (DECODE) or as stored. Integer frames decode each level with one
// load from `lin` (common.cl's linear_levels: the same numbers as lut_read gives).
inline float4 fast_to_mix(__global const PIXEL_T *src, __global const float *luts, __global const float *lin, int i)
{
#if DECODE && !defined(PIXEL_IS_FLOAT) && CHANNELS >= 3
    __global const PIXEL_T *p = src + (size_t)i * CHANNELS;
#if ORDER_BGR
    return (float4)(lin[p[2]], lin[p[1]], lin[p[0]], CHANNELS == 4 ? (float)p[3] * (1.0f / PIXEL_MAX) : 1.0f);
#else
    return (float4)(lin[p[0]], lin[p[1]], lin[p[2]], CHANNELS == 4 ? (float)p[3] * (1.0f / PIXEL_MAX) : 1.0f);
#endif
#elif DECODE
    const float4 c = load_px(src, i);
    return (float4)(lut_read(luts, c.x), lut_read(luts, c.y), lut_read(luts, c.z), c.w);
#else
    return load_px(src, i);
#endif
}

// The area a line with shapes s.x (towards its start) and s.y (its end) gives the pixel on `side` (L_SIDE_A or
// L_SIDE_B): the rule of line_areas in spatial/fast.py for one side (an end counts where its crossing is on
// this side alone, the other end's is not, and it is no corner), its trapezoids read from `trap`
// (trapezoid(p, len) at len * 32 + p: spatial/fast.py trapezoid_table) without branches.
inline float side_area(__global const float *trap, uchar2 s, int side)
{
    const int a0 = (s.x >> 5) & 3, a1 = (s.y >> 5) & 3;
    const int e0 = a0 == side && a1 != side && !(s.x & 128), e1 = a1 == side && a0 != side && !(s.y & 128);
    const int d0 = s.x & 31, d1 = s.y & 31, row = (d0 + d1 + 1) * 32;
    const float t0 = trap[row + d0], t1 = trap[row + d1];
    return (e0 ? t0 : 0.0f) + (e1 ? t1 : 0.0f);
}

#if SUBPIXEL_ON
// blend.cl's sub-pixel rule (SUBPIXEL, SUBPIXEL_END, SUBPIXEL_BG from the filter's options): a pixel with edges
// on three or four sides -- a dot, a 1-px line's end or bump, smaller than the pixel -- that is a luma extremum
// on one background moves SUBPIXEL (four sides) or SUBPIXEL_END (three) of the way from `*out` to the mean of
// its 3x3 window (clamped at the frame's edge), in the mixing space. Returns whether it moved. In place of the
// default's grain guard, the feature must be isolated: no neighbour across its edges has three or four edges
// itself (noise and fine texture are such clusters; docs/fast.md has the numbers).
inline float fast_luma(float4 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }   // Rec. 709
inline int subpixel(__global const PIXEL_T *src, __global const uchar *edges, __global const float *luts, __global const float *lin, uchar e,
                    int x, int y, int width, int height, float4 c, int sides, float4 *out)
{
    const int i = y * width + x;
    const float yc = fast_luma(c);
    int lo = 0, hi = 0;
    float ymin = 1e30f, ymax = -1e30f;
    for (int k = 0; k < 4; ++k) {   // the neighbours across its edges: top, right, bottom, left
        if (!(e & (1 << k))) continue;
        const int j = k == 0 ? i - width : k == 1 ? i + 1 : k == 2 ? i + width : i - 1;
        const uchar en = edges[j];
        if ((en & 1) + ((en >> 1) & 1) + ((en >> 2) & 1) + ((en >> 3) & 1) >= 3) return 0;   // not isolated
        const float yn = fast_luma(fast_to_mix(src, luts, lin, j));
        lo |= yn < yc;
        hi |= yn > yc;
        ymin = yn < ymin ? yn : ymin;
        ymax = yn > ymax ? yn : ymax;
    }
    const float contrast = hi ? ymin - yc : yc - ymax;
    if ((lo && hi) || ymax - ymin > SUBPIXEL_BG * contrast) return 0;
    float4 box = (float4)(0.0f);
    for (int dy = -1; dy <= 1; ++dy) {
        const int yy = y + dy < 0 ? 0 : (y + dy >= height ? height - 1 : y + dy);
        for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx < 0 ? 0 : (x + dx >= width ? width - 1 : x + dx);
            box += fast_to_mix(src, luts, lin, yy * width + xx);
        }
    }
    *out += (sides == 4 ? SUBPIXEL : SUBPIXEL_END) * (box * (1.0f / 9.0f) - *out);
    return 1;
}
#endif

__kernel void fast_blend(__global const PIXEL_T *src, __global const uchar *edges, __global const uchar *blocks,
                         __global const uchar2 *hshapes, __global const uchar2 *vshapes, __global const float *luts,
                         __global const float *lin, __global const float *trap, __global PIXEL_T *dst,
                         const int width, const int height)
{
    // 64 pixels of a row per work item: global size (ceil(width / FAST_COLS), height)
    const int x0 = get_global_id(0) * FAST_COLS, y = get_global_id(1);
    if (x0 >= width || y >= height || !blocks[(y / FAST_ROWS) * BLOCKS_X(width) + get_global_id(0)]) return;
    const int x1 = x0 + FAST_COLS < width ? x0 + FAST_COLS : width;
    for (int g = x0; g < x1; g += 8) {   // 8 pixels at a time: their edge bytes as one word
        ulong m = 0;
        if (g + 8 <= width) m = edge_group(edges + y * width + g);
        else for (int k = 0; g + k < width; ++k) m |= (ulong)edges[y * width + g + k] << (8 * k);
        ulong any = m | (m >> 4);
        any |= any >> 2;
        any |= any >> 1;   // bit 0 of each byte: the byte is not 0
        for (uint nz = gather8(any, 0); nz; nz &= nz - 1) {   // the group's pixels with an edge
            const int k = LOWEST_BIT(nz), x = g + k;
            const uchar e = (uchar)(m >> (8 * k));
            const int i = y * width + x;
            const float wb = (e & E_BOTTOM) ? side_area(trap, hshapes[i], L_SIDE_A) : 0.0f;
            const float wt = (e & E_TOP) ? side_area(trap, hshapes[y > 0 ? i - width : i], L_SIDE_B) : 0.0f;
            const float wr = (e & E_RIGHT) ? side_area(trap, vshapes[i], L_SIDE_A) : 0.0f;
            const float wl = (e & E_LEFT) ? side_area(trap, vshapes[x > 0 ? i - 1 : i], L_SIDE_B) : 0.0f;
            const float sum = wt + wb + wl + wr;
#if SUBPIXEL_ON
            const int sides = (e & 1) + ((e >> 1) & 1) + ((e >> 2) & 1) + ((e >> 3) & 1);
            if (sum <= 0.0f && sides < 3) continue;
#else
            if (sum <= 0.0f) continue;
#endif
            // each neighbour mixed in by its area; together never more than the largest area (blend.cl's rule)
            const float4 c = fast_to_mix(src, luts, lin, i);
            float4 acc = (float4)(0.0f);
            if (wt > 0.0f) acc += wt * wt * (fast_to_mix(src, luts, lin, i - width) - c);
            if (wb > 0.0f) acc += wb * wb * (fast_to_mix(src, luts, lin, i + width) - c);
            if (wl > 0.0f) acc += wl * wl * (fast_to_mix(src, luts, lin, i - 1) - c);
            if (wr > 0.0f) acc += wr * wr * (fast_to_mix(src, luts, lin, i + 1) - c);
            float4 out = sum > 0.0f ? c + acc / sum : c;
#if SUBPIXEL_ON
            if (sides >= 3 && !subpixel(src, edges, luts, lin, e, x, y, width, height, c, sides, &out) && sum <= 0.0f) continue;
#endif
            out.w = c.w;
#if DECODE
            out = (float4)(encode_mix(luts, out.x), encode_mix(luts, out.y), encode_mix(luts, out.z), out.w);
#endif
            store_px(dst, i, out);
        }
    }
}
