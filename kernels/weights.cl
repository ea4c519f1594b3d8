// weights.cl -- blending factors from L, Z and U shapes (seed 000 §3.4; corners from seed 002).
// A discontinuity line of length L (from distances.cl) ends at each side in a crossing edge that
// goes up, down, both or nowhere. The silhouette is rebuilt as a line from the middle of a single
// crossing edge (height 1/2) to the middle of the line (height 0); a pixel at position p from that end
// is covered by the trapezoid A = 1/2 (1 - (2p+1)/L) (seed 000 eq. 2), or the triangle 1/(8L) on
// the middle pixel when L is odd; the covered pixel takes A of its neighbour across the line.
// Areas come from a host-built table for L <= AREA_TABLE_L and from the same formula beyond.
// Corners (seed 002): a crossing edge three or more pixels long marks a real corner, not a jaggy:
// its area is scaled by ROUNDING (0 keeps corners sharp). One exactly two pixels long is ambiguous
// (a 2-px stroke's corner, or a thin feature's step): scaled by SHORT_CORNER (0.75: measured on
// the yardstick, docs/bench), and not blended at all on a line of length 1 (a steep staircase). U shapes (both ends to the same side: a bump,
// or the side of a box when a crossing is long) are blended only when BLEND_U is 1 and not a box side. An end crossed on both sides (a thin
// line stepping across this one) continues the silhouette opposite to the other end, which makes
// a Z shape (as SMAA's area patterns do); with no single crossing at the other end it stays unblended.
// A U shape of STEM_MIN_L or more pixels on a 1-px line (the bump's pixels at both ends also have an edge on
// their far side) is a 1-px stroke -- a text stem, a rule -- not a bump of a curve: its ends are square,
// and the U's taper would shave ink off both sides of it; its areas are scaled by STEM_K.
// Output weights[i] = (top, bottom, left, right) as 16-bit fractions: how much pixel i takes from
// each neighbour. Only slots next to an edge are written (and read, by blend.cl): a pixel with a
// bottom edge writes its own bottom slot and the top slot of the pixel below; with a right edge,
// its own right slot and the left slot of the pixel to the right. Pixels without edges exit at once.
#define EDGE_BOTTOM 1
#define EDGE_RIGHT 2
#ifndef AREA_TABLE_L
#define AREA_TABLE_L 64
#endif
#ifndef ROUNDING
#define ROUNDING 0.0f
#endif
#ifndef BLEND_U
#define BLEND_U 1
#endif
#ifndef SHORT_CORNER
#define SHORT_CORNER 0.75f
#endif
#ifndef STEM_MIN_L
#define STEM_MIN_L 8
#endif
#ifndef STEM_K
#define STEM_K 0.25f
#endif
#define IMAX(a, b) ((a) > (b) ? (a) : (b))
#ifndef VALIDATE_CROSSINGS
#define VALIDATE_CROSSINGS 1
#endif

inline float trapezoid_area(__global const float *table, int p, int L)
{
    if (L <= AREA_TABLE_L) return table[L * AREA_TABLE_L + p];
    if (2 * p + 2 <= L) return 0.5f * (1.0f - (float)(2 * p + 1) / (float)L);
    if (2 * p + 1 == L) return 1.0f / (8.0f * (float)L);
    return 0.0f;
}

// clamp(rint(a * 65535), 0, 65535) as a 16-bit weight (NaN -> 0, as clamp's fmax gives).
inline ushort to_u16(float a)
{
    const float r = RINT(a * 65535.0f), lo = r > 0.0f ? r : 0.0f;
    return (ushort)(lo < 65535.0f ? lo : 65535.0f);
}

// Crossing at one end of a line: `a`/`b` say whether an edge crosses on side a (up/left) or side b
// (down/right); `a2`/`b2` how far that crossing edge continues: 0 one pixel, 1 two, 2 three or more
// (run2 below); *long_edge gets the longer one's code for the side(s) crossed.
// Returns +1 for side a, -1 for side b, 0 for none, BOTH for both.
#define BOTH 2
#define run2(e2, e3) ((e2) ? 1 + (e3) : 0)
inline int crossing(int a, int b, int a2, int b2, int *long_edge)
{
    *long_edge = IMAX(a ? a2 : 0, b ? b2 : 0);
    if (a && b) return BOTH;
    return a ? 1 : (b ? -1 : 0);
}

// Areas for the pixel at distances (d0, d1) from the two ends with crossings s0, s1: *ta = area
// taken by the side-a pixel from side b, *tb = the reverse. Crossing edges of 2+ pixels mark corners
// (seed 002): a U shape with one (the side of a box) is left sharp, other shapes are scaled by
// SHORT_CORNER (2 px) or ROUNDING (3+ px).
// (always_inline here and below: PoCL's CPU build otherwise calls these per pixel; mixed frame 0.95x)
inline __attribute__((always_inline)) void line_areas(__global const float *table, int d0, int d1, int s0, int s1,
                       int long0, int long1, int stem, float *ta, float *tb)
{
    *ta = 0.0f; *tb = 0.0f;
    if (s0 == BOTH && s1 != BOTH) s0 = -s1;   // a thin line steps across: continue as a Z
    if (s1 == BOTH && s0 != BOTH) s1 = -s0;
    if (s0 == BOTH) s0 = 0;
    if (s1 == BOTH) s1 = 0;
    if (s0 == 0 && s1 == 0) return;
    float k0 = long0 == 2 ? ROUNDING : (long0 == 1 ? SHORT_CORNER : 1.0f);
    float k1 = long1 == 2 ? ROUNDING : (long1 == 1 ? SHORT_CORNER : 1.0f);
    if (s0 == s1) {
        if (!BLEND_U || long0 || long1) return;
        if (stem) { k0 *= STEM_K; k1 *= STEM_K; }   // a 1-px stroke (caller's test), not a bump
    }
    int L = d0 + d1 + 1;
    // A line of length 1 between crossing edges two pixels long is a step of a steep staircase
    // (slope 2): the perpendicular lines blend it; blending it here too over-smooths (measured).
    if (L == 1) { if (long0 == 1) k0 = 0.0f; if (long1 == 1) k1 = 0.0f; }
    if (s0 != 0) { float a = k0 * trapezoid_area(table, d0, L); if (s0 > 0) *ta += a; else *tb += a; }
    if (s1 != 0) { float a = k1 * trapezoid_area(table, d1, L); if (s1 > 0) *ta += a; else *tb += a; }
}

// A crossing edge turns the silhouette only if the pixel beyond it belongs to the other side: for
// a crossing on side a, the pixel past it (pa) is closer in colour to the line's side-b pixel B
// than to its side-a pixel A (and the reverse for side b). Texture next to a straight border
// (a photograph under a frame) crosses the border without turning it and must not bend it.
inline float dist2(float4 p, float4 q) { float4 d = p - q; return d.x * d.x + d.y * d.y + d.z * d.z; }

inline int end_type(__global const PIXEL_T *src, int a, int b, int a2, int b2,
                    int pa, int pb, int iA, int iB, int *long_edge)
{
#if VALIDATE_CROSSINGS
    if (a || b) {
        float4 A = load_px(src, iA), B = load_px(src, iB);
        if (a) { float4 p = load_px(src, pa); a = dist2(p, B) < dist2(p, A); }
        if (b) { float4 p = load_px(src, pb); b = dist2(p, A) < dist2(p, B); }
    }
#endif
    return crossing(a, b, a2, b2, long_edge);
}

inline int has(__global const uchar *edges, int x, int y, int width, int height, uchar bit)
{
    return x >= 0 && y >= 0 && x < width && y < height && (edges[IDX(x, y, width)] & bit);
}

// A stroke's end (seed 002's corners, extended): a crossing exactly two pixels long at the end of a line of
// CAP_MIN_L or more pixels, whose far end turns back along the line for three pixels (the stroke's other
// border), is the square end of a 2-px stroke -- hinted text stems, UI rules -- not a step of a staircase
// (there the border goes on the other way): a corner, as a crossing of three or more pixels.
#ifndef CAP_MIN_L
#define CAP_MIN_L 8
#endif

// The far border of a 2-px stroke's end: bottom edges of row r from column x on, three pixels in direction
// dir (along the line); right edges of column c from row y on, three rows in direction dir.
inline int stroke_end_h(__global const uchar *edges, int x, int r, int dir, int width, int height)
{
    return has(edges, x, r, width, height, EDGE_BOTTOM) && has(edges, x + dir, r, width, height, EDGE_BOTTOM) &&
           has(edges, x + 2 * dir, r, width, height, EDGE_BOTTOM);
}

inline int stroke_end_v(__global const uchar *edges, int c, int y, int dir, int width, int height)
{
    return has(edges, c, y, width, height, EDGE_RIGHT) && has(edges, c, y + dir, width, height, EDGE_RIGHT) &&
           has(edges, c, y + 2 * dir, width, height, EDGE_RIGHT);
}

inline __attribute__((always_inline)) void pixel_weights(__global const PIXEL_T *src, __global const uchar *edges, __global const ushort2 *hdist,
                          __global const ushort2 *vdist, __global const float *table,
                          __global ushort *weights, int x, int y, int width, int height)
{
    const int i = IDX(x, y, width);
    const uchar e = edges[i];
    if (e == 0) return;
    float up = 0.0f, down = 0.0f, left = 0.0f, right = 0.0f;
    if (e & EDGE_BOTTOM) {   // horizontal line between rows y and y+1, ends at x0 and x1
        ushort2 d = hdist[i];
        int x0 = x - d.x, x1 = x + d.y;
        int k0, k1;
        int s0 = end_type(src, has(edges, x0 - 1, y, width, height, EDGE_RIGHT),
                          has(edges, x0 - 1, y + 1, width, height, EDGE_RIGHT),
                          run2(has(edges, x0 - 1, y - 1, width, height, EDGE_RIGHT), has(edges, x0 - 1, y - 2, width, height, EDGE_RIGHT)),
                          run2(has(edges, x0 - 1, y + 2, width, height, EDGE_RIGHT), has(edges, x0 - 1, y + 3, width, height, EDGE_RIGHT)),
                          IDX(x0 - 1, y, width), IDX(x0 - 1, y + 1, width),
                          IDX(x0, y, width), IDX(x0, y + 1, width), &k0);
        int s1 = end_type(src, has(edges, x1, y, width, height, EDGE_RIGHT),
                          has(edges, x1, y + 1, width, height, EDGE_RIGHT),
                          run2(has(edges, x1, y - 1, width, height, EDGE_RIGHT), has(edges, x1, y - 2, width, height, EDGE_RIGHT)),
                          run2(has(edges, x1, y + 2, width, height, EDGE_RIGHT), has(edges, x1, y + 3, width, height, EDGE_RIGHT)),
                          IDX(x1 + 1, y, width), IDX(x1 + 1, y + 1, width),
                          IDX(x1, y, width), IDX(x1, y + 1, width), &k1);
        if ((int)d.x + (int)d.y + 1 >= CAP_MIN_L) {   // stroke ends: the far border in row y -/+ 2
            if ((s0 == 1 || s0 == -1) && k0 == 1 && stroke_end_h(edges, x0, s0 == 1 ? y - 2 : y + 2, 1, width, height))
                k0 = 2;
            if ((s1 == 1 || s1 == -1) && k1 == 1 && stroke_end_h(edges, x1, s1 == 1 ? y - 2 : y + 2, -1, width, height))
                k1 = 2;
        }
        // a 1-px stroke: a U whose bump row (y for side a, y + 1 for side b) is bordered on its far side too
        const int stem = s0 == s1 && (s0 == 1 || s0 == -1) && (int)d.x + (int)d.y + 1 >= STEM_MIN_L &&
                         has(edges, x0, s0 == 1 ? y - 1 : y + 1, width, height, EDGE_BOTTOM) &&
                         has(edges, x1, s0 == 1 ? y - 1 : y + 1, width, height, EDGE_BOTTOM);
        line_areas(table, d.x, d.y, s0, s1, k0, k1, stem, &up, &down);
    }
    if (e & EDGE_RIGHT) {    // vertical line between columns x and x+1, ends at y0 and y1
        ushort2 d = vdist[i];
        int y0 = y - d.x, y1 = y + d.y;
        int k0, k1;
        int s0 = end_type(src, has(edges, x, y0 - 1, width, height, EDGE_BOTTOM),
                          has(edges, x + 1, y0 - 1, width, height, EDGE_BOTTOM),
                          run2(has(edges, x - 1, y0 - 1, width, height, EDGE_BOTTOM), has(edges, x - 2, y0 - 1, width, height, EDGE_BOTTOM)),
                          run2(has(edges, x + 2, y0 - 1, width, height, EDGE_BOTTOM), has(edges, x + 3, y0 - 1, width, height, EDGE_BOTTOM)),
                          IDX(x, y0 - 1, width), IDX(x + 1, y0 - 1, width),
                          IDX(x, y0, width), IDX(x + 1, y0, width), &k0);
        int s1 = end_type(src, has(edges, x, y1, width, height, EDGE_BOTTOM),
                          has(edges, x + 1, y1, width, height, EDGE_BOTTOM),
                          run2(has(edges, x - 1, y1, width, height, EDGE_BOTTOM), has(edges, x - 2, y1, width, height, EDGE_BOTTOM)),
                          run2(has(edges, x + 2, y1, width, height, EDGE_BOTTOM), has(edges, x + 3, y1, width, height, EDGE_BOTTOM)),
                          IDX(x, y1 + 1, width), IDX(x + 1, y1 + 1, width),
                          IDX(x, y1, width), IDX(x + 1, y1, width), &k1);
        if ((int)d.x + (int)d.y + 1 >= CAP_MIN_L) {   // stroke ends: the far border in column x -/+ 2
            if ((s0 == 1 || s0 == -1) && k0 == 1 && stroke_end_v(edges, s0 == 1 ? x - 2 : x + 2, y0, 1, width, height))
                k0 = 2;
            if ((s1 == 1 || s1 == -1) && k1 == 1 && stroke_end_v(edges, s1 == 1 ? x - 2 : x + 2, y1, -1, width, height))
                k1 = 2;
        }
        const int stem = s0 == s1 && (s0 == 1 || s0 == -1) && (int)d.x + (int)d.y + 1 >= STEM_MIN_L &&
                         has(edges, s0 == 1 ? x - 1 : x + 1, y0, width, height, EDGE_RIGHT) &&
                         has(edges, s0 == 1 ? x - 1 : x + 1, y1, width, height, EDGE_RIGHT);
        line_areas(table, d.x, d.y, s0, s1, k0, k1, stem, &left, &right);
    }
    __global ushort *w = weights + (size_t)i * 4;   // (top, bottom, left, right)
    if (e & EDGE_BOTTOM) {
        w[1] = to_u16(up);      // this pixel (above the line) takes `up` from the one below
        weights[(size_t)(i + width) * 4 + 0] = to_u16(down);
    }
    if (e & EDGE_RIGHT) {
        w[3] = to_u16(left);    // this pixel (left of the line) takes `left` from the right one
        weights[(size_t)(i + 1) * 4 + 2] = to_u16(right);
    }
}

__kernel void blend_weights(__global const PIXEL_T *src, __global const uchar *edges, __global const ushort2 *hdist,
                            __global const ushort2 *vdist, __global const float *table,
                            __global ushort *weights, const int width, const int height)
{
    const int x0 = get_global_id(0) * SEGMENT, y = get_global_id(1);
    if (x0 >= width || y >= height) return;
    const int x1 = min(x0 + SEGMENT, width);
    for (int x = x0; x < x1;) {
        if (x + GROUP <= x1 && edge_group(edges + IDX(x, y, width)) == 0) { x += GROUP; continue; }
        pixel_weights(src, edges, hdist, vdist, table, weights, x, y, width, height);
        ++x;
    }
}
