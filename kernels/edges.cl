// edges.cl -- discontinuity detection (seed 000 §3.2; weighted RGB from seed 004).
// For each pixel, whether its colour differs from its bottom and its right neighbour.
// Output: edges[i] bit 0 = discontinuity at the bottom border, bit 1 = at the right border.
// Defines: METRIC 0 = CIELAB ΔE76 (default), 1 = luma (Rec. 709 on encoded values), 2 = weighted RGB.
//          LINEAR_INPUT 1 when samples are linear light (float EXR), 0 when sRGB-encoded.
//          CHEAP_BOUND: for METRIC 0, a max-channel RGB difference below which ΔE cannot exceed
//          THRESHOLD (host-computed Lipschitz bound), so Lab is only computed near real edges.
#ifndef METRIC
#define METRIC 0
#endif
#ifndef LINEAR_INPUT
#define LINEAR_INPUT 0
#endif

#define EDGE_BOTTOM 1
#define EDGE_RIGHT 2

inline float4 to_encoded(__global const float *luts, float4 c)
{
#if LINEAR_INPUT
    // linear samples: encode for the perceptual comparison (tables hold linear->sRGB after the Lab part)
    __global const float *enc = luts + 2 * (LUT_SIZE + 1);
    return (float4)(lut_read(enc, c.x), lut_read(enc, c.y), lut_read(enc, c.z), c.w);
#else
    return c;
#endif
}

inline float max3(float4 d) { return fmax(fmax(d.x, d.y), d.z); }

// Does colour a differ from colour b? (both encoded, normalised)
inline int differs(__global const float *luts, float4 a, float4 b, float threshold)
{
    float4 d = fabs(a - b);
#if METRIC == 0
    if (max3(d) < CHEAP_BOUND) return 0;          // cannot reach the ΔE threshold
    float3 la = rgb_to_lab(luts, a), lb = rgb_to_lab(luts, b);
    float3 dl = la - lb;
    return dot(dl, dl) > threshold * threshold;   // ΔE76 = Euclidean distance in CIELAB
#elif METRIC == 1
    return fabs(dot(a.xyz - b.xyz, (float3)(0.2126f, 0.7152f, 0.0722f))) > threshold;
#else
    return dot(d.xyz, (float3)(0.2126f, 0.7152f, 0.0722f)) > threshold;
#endif
}

__kernel void detect_edges(__global const PIXEL_T *src, __global const float *luts,
                           __global uchar *edges, const int width, const int height,
                           const float threshold)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    const int i = IDX(x, y, width);
    const int below = y + 1 < height && !same_px(src, i, i + width);
    const int right = x + 1 < width && !same_px(src, i, i + 1);
    uchar e = 0;
    if (below || right) {   // flat areas (most of a rendered frame) stop here
        float4 c = to_encoded(luts, load_px(src, i));
        if (below && differs(luts, c, to_encoded(luts, load_px(src, i + width)), threshold))
            e |= EDGE_BOTTOM;
        if (right && differs(luts, c, to_encoded(luts, load_px(src, i + 1)), threshold))
            e |= EDGE_RIGHT;
    }
    edges[i] = e;
}
