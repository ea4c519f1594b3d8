// distances.cl -- distance from each pixel to both ends of its discontinuity line (seed 000 §3.3).
// The seed propagates distances by recursive doubling and caps lines at 255 px. Here one work item
// walks a whole row (or column) once: the same distances, O(n) instead of O(n log n) work, and no cap
// (16-bit distances: lines up to 65535 px). A line ends where the edge stops or where an edge
// crosses it (the secondary edge of an L shape, seed 004: "inner edges have no side edges").
// Output per pixel, valid only where the pixel has that edge:
//   hdist[i] = (left, right) along its bottom border; vdist[i] = (up, down) along its right border.
#define EDGE_BOTTOM 1
#define EDGE_RIGHT 2

#define BOTTOM_BITS 0x0101010101010101UL   // EDGE_BOTTOM in each of 8 edge bytes
#define RIGHT_BITS 0x0202020202020202UL    // EDGE_RIGHT in each of 8 edge bytes

// Row y: horizontal lines between row y and row y+1. Stretches of 8 pixels with no bottom edge
// and no line open are skipped at once.
__kernel void hline_distances(__global const uchar *edges, __global ushort2 *hdist,
                              const int width, const int height)
{
    const int y = get_global_id(0);
    if (y >= height - 1) return;
    __global const uchar *row = edges + (size_t)y * width;
    __global const uchar *below = row + width;
    __global ushort2 *out = hdist + (size_t)y * width;
    int start = -1;
    for (int x = 0; x <= width;) {
        if (start < 0 && x + GROUP <= width && !(edge_group(row + x) & BOTTOM_BITS)) { x += GROUP; continue; }
        int on = x < width && (row[x] & EDGE_BOTTOM);
        // an edge crossing the line between x-1 and x splits it
        int crossed = x > 0 && x < width && ((row[x - 1] | below[x - 1]) & EDGE_RIGHT);
        if (start >= 0 && (!on || crossed)) {
            for (int k = start; k < x; ++k) out[k] = (ushort2)((ushort)(k - start), (ushort)(x - 1 - k));
            start = -1;
        }
        if (on && start < 0) start = x;
        ++x;
    }
}

// Columns x0 .. x0+SEGMENT-1: vertical lines between column x and x+1. The work item sweeps down
// its columns row by row (memory order), keeping each column's open line; groups of 8 columns with
// no right edge in this row and no open line are skipped at once.
__kernel void vline_distances(__global const uchar *edges, __global ushort2 *vdist,
                              const int width, const int height)
{
    const int x0 = get_global_id(0) * SEGMENT;
    const int x1 = x0 + SEGMENT < width - 1 ? x0 + SEGMENT : width - 1;
    if (x0 >= x1) return;
    int start[SEGMENT];
    int open_in_group[SEGMENT / GROUP];
    for (int k = 0; k < SEGMENT; ++k) start[k] = -1;
    for (int g = 0; g < SEGMENT / GROUP; ++g) open_in_group[g] = 0;
    for (int y = 0; y <= height; ++y) {
        for (int x = x0; x < x1;) {
            const int k = x - x0;
            const size_t i = (size_t)y * width + x;
            if ((k & (GROUP - 1)) == 0 && x + GROUP <= x1 && !open_in_group[k / GROUP]
                && (y == height || !(edge_group(edges + i) & RIGHT_BITS))) { x += GROUP; continue; }
            int on = y < height && (edges[i] & EDGE_RIGHT);
            int crossed = y > 0 && y < height && ((edges[i - width] | edges[i - width + 1]) & EDGE_BOTTOM);
            int s = start[k];
            if (s >= 0 && (!on || crossed)) {
                for (int j = s; j < y; ++j)
                    vdist[(size_t)j * width + x] = (ushort2)((ushort)(j - s), (ushort)(y - 1 - j));
                start[k] = -1;
                open_in_group[k / GROUP]--;
            }
            if (on && start[k] < 0) { start[k] = y; open_in_group[k / GROUP]++; }
            ++x;
        }
    }
}

// The same distances for GPUs (the filter picks it on devices that are not CPUs): one work item per column and
// VCHUNK rows, so a frame has tens of thousands of work items instead of width / SEGMENT, and neighbouring work
// items read neighbouring bytes. A line running into the chunk from above is followed up to its start, one
// running out of it down to its end (read, not written: each chunk writes its own rows).
#ifndef VCHUNK
#define VCHUNK 32
#endif

// Does the line along the right border of column x go on from row y - 1 into row y (1 <= y < height)? Both rows
// have the edge and no bottom edge of row y - 1 (in column x or x + 1) crosses between them.
inline int vline_goes_on(__global const uchar *edges, int x, int y, int width)
{
    const size_t i = (size_t)y * width + x;
    return (edges[i] & EDGE_RIGHT) && (edges[i - width] & EDGE_RIGHT)
           && !((edges[i - width] | edges[i - width + 1]) & EDGE_BOTTOM);
}

__kernel void vline_distances_columns(__global const uchar *edges, __global ushort2 *vdist,
                                      const int width, const int height)
{
    const int x = get_global_id(0), y0 = get_global_id(1) * VCHUNK;
    if (x >= width - 1 || y0 >= height) return;
    const int y1 = y0 + VCHUNK < height ? y0 + VCHUNK : height;
    for (int y = y0; y < y1;) {
        if (!(edges[(size_t)y * width + x] & EDGE_RIGHT)) { ++y; continue; }
        int s = y, e = y;
        if (y == y0)
            while (s > 0 && vline_goes_on(edges, x, s, width)) --s;
        while (e + 1 < height && vline_goes_on(edges, x, e + 1, width)) ++e;
        const int last = e < y1 ? e : y1 - 1;
        for (int j = y; j <= last; ++j) vdist[(size_t)j * width + x] = (ushort2)((ushort)(j - s), (ushort)(e - j));
        y = e + 1;
    }
}
