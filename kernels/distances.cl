// distances.cl -- distance from each pixel to both ends of its discontinuity line (seed 000 §3.3).
// The seed propagates distances by recursive doubling and caps lines at 255 px. Here one work item
// walks a whole row (or column) once: the same distances, O(n) instead of O(n log n) work, and no cap
// (16-bit distances: lines up to 65535 px). A line ends where the edge stops or where an edge
// crosses it (the secondary edge of an L shape, seed 004: "inner edges have no side edges").
// Output per pixel, valid only where the pixel has that edge:
//   hdist[i] = (left, right) along its bottom border; vdist[i] = (up, down) along its right border.
#define EDGE_BOTTOM 1
#define EDGE_RIGHT 2

// Row y: horizontal lines between row y and row y+1.
__kernel void hline_distances(__global const uchar *edges, __global ushort2 *hdist,
                              const int width, const int height)
{
    const int y = get_global_id(0);
    if (y >= height - 1) return;
    __global const uchar *row = edges + (size_t)y * width;
    __global const uchar *below = row + width;
    __global ushort2 *out = hdist + (size_t)y * width;
    int start = -1;
    for (int x = 0; x <= width; ++x) {
        int on = x < width && (row[x] & EDGE_BOTTOM);
        // an edge crossing the line between x-1 and x splits it
        int crossed = x > 0 && x < width && ((row[x - 1] | below[x - 1]) & EDGE_RIGHT);
        if (start >= 0 && (!on || crossed)) {
            for (int k = start; k < x; ++k) out[k] = (ushort2)((ushort)(k - start), (ushort)(x - 1 - k));
            start = -1;
        }
        if (on && start < 0) start = x;
    }
}

// Column x: vertical lines between column x and column x+1.
__kernel void vline_distances(__global const uchar *edges, __global ushort2 *vdist,
                              const int width, const int height)
{
    const int x = get_global_id(0);
    if (x >= width - 1) return;
    int start = -1;
    for (int y = 0; y <= height; ++y) {
        size_t i = (size_t)y * width + x;
        int on = y < height && (edges[i] & EDGE_RIGHT);
        int crossed = y > 0 && y < height && ((edges[i - width] | edges[i - width + 1]) & EDGE_BOTTOM);
        if (start >= 0 && (!on || crossed)) {
            for (int k = start; k < y; ++k)
                vdist[(size_t)k * width + x] = (ushort2)((ushort)(k - start), (ushort)(y - 1 - k));
            start = -1;
        }
        if (on && start < 0) start = y;
    }
}
