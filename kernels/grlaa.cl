// grlaa.cl: GRLAA antialiased polylines (roads, routes) with an outline, composited over a frame.
// Seed 001 (GRadient Line Anti-Aliasing). The seed's fragment shader gets a base value interpolated
// from -1 to +1 across the road, takes distance = 1 - |base| and blend_range = ANTIALIAS_STRENGTH *
// |grad base| (dFdx, dFdy), and ramps alpha over blend_range. Here every pixel computes the exact
// distance to the centre line and the gradient of that distance (the unit normal n, |n| = 1 per
// pixel); the ramp is the pixel's footprint (STRENGTH x STRENGTH box) projected on n, whose widths
// are STRENGTH*|n.x| and STRENGTH*|n.y|, i.e. the gradient's components (docs/grlaa.md).
//
// Defines (mlaa_stream.formats.defines_for): PIXEL_T, CHANNELS, PIXEL_MAX, ORDER_BGR, LUT_SIZE,
// PIXEL_IS_FLOAT; TILE (edge of a square screen tile in pixels, = the work-group's side).
//
// Host data (mlaa_stream.overlay): segments binned into TILE x TILE tiles; each work-group draws one
// non-empty tile and each work-item one pixel, testing only the segments listed for its tile.
//   segs[s]     float4 (x0, y0, x1, y1) in pixels, pixel centres at integer coordinates
//   seg_meta[s] (polyline << 3) | flags: 1 flat start, 2 flat end, 4 square (flat ends extended by r)
//   entries[]   segment indices, grouped by tile, in drawing order (polyline, then segment)
//   tiles[g]    int4 (tile x, tile y, first entry, entry count)
//   polys[5k..5k+4] float4: (r, r_inner, opacity, 0), fill linear RGB, outline linear RGB,
//                   fill sRGB, outline sRGB (sRGB normalised to [0, 1]: stored as-is where covered)
#ifndef TILE
#define TILE 8
#endif

#define LUT_ENCODE (2 * (LUT_SIZE + 1))

// CDF at s of the pixel footprint projected on the normal: U(-a/2, a/2) + U(-b/2, b/2), a >= b >= 0.
// It is the coverage of the half-plane {u <= s} (u along n, from the pixel centre); for b = 0 it is
// the seed's linear ramp clamp(s / a + 0.5) (seed 001, blend_distance).
inline float footprint_cdf(float s, float a, float b)
{
    float x = s + 0.5f * (a + b);
    if (x <= 0.0f) return 0.0f;
    if (x >= a + b) return 1.0f;
    if (x < b) return x * x / (2.0f * a * b);
    if (x <= a) return (x - 0.5f * b) / a;
    float y = a + b - x;
    return 1.0f - y * y / (2.0f * a * b);
}

// Coverage of the strip |u| <= r by a pixel whose centre lies at distance d from the strip's centre.
inline float strip_cover(float d, float r, float a, float b)
{
    return footprint_cdf(r - d, a, b) - footprint_cdf(-r - d, a, b);
}

inline float decode_srgb(__global const float *luts, float v)
{
#ifdef PIXEL_IS_FLOAT
    if (v > 1.0f) return pow((v + 0.055f) * (1.0f / 1.055f), 2.4f);  // HDR float frames only
#endif
    return lut_read(luts, v);
}

inline float encode_srgb(__global const float *luts, float v)
{
#ifdef PIXEL_IS_FLOAT
    if (v > 1.0f) return 1.055f * pow(v, 1.0f / 2.4f) - 0.055f;
#endif
    return lut_read(luts + LUT_ENCODE, v);
}

__kernel void grlaa_draw(__global PIXEL_T *img, __global const float *luts,
                         __global const float4 *segs, __global const int *seg_meta,
                         __global const int *entries, __global const int4 *tiles,
                         __global const float4 *polys, const int width, const int height,
                         const float strength)
{
    const int4 tile = tiles[get_group_id(0)];
    const int lid = (int)get_local_id(0);
    const int px = tile.x * TILE + lid % TILE, py = tile.y * TILE + lid / TILE;
    if (px >= width || py >= height) return;  // no barriers in this kernel
    const float2 p = (float2)((float)px, (float)py);
    const int pix = IDX(px, py, width);
    const float reach_pad = 0.70711f * strength;  // half the footprint's diagonal

    float3 lin = (float3)(0.0f);
    float bg_alpha = 1.0f;
    int loaded = 0, exact = 0;  // exact: 1 + 2*poly (fill) or 2 + 2*poly (outline) where fully covered
    int cur = -1;
    float a_out = 0.0f, a_in = 0.0f;
    const int end = tile.z + tile.w;

    for (int e = tile.z; e <= end; ++e) {
        int sidx = 0, meta = -1, poly = -1;
        if (e < end) {
            sidx = entries[e];
            meta = seg_meta[sidx];
            poly = meta >> 3;
        }
        if (poly != cur) {
            // Composite the finished polyline over what is below, in linear light (alpha "over").
            if (cur >= 0 && a_out > 0.0f) {
                if (!loaded) {
                    float4 bg = load_px(img, pix);
                    lin = (float3)(decode_srgb(luts, bg.x), decode_srgb(luts, bg.y),
                                   decode_srgb(luts, bg.z));
                    bg_alpha = bg.w;
                    loaded = 1;
                }
                const float4 prm = polys[5 * cur];
                const float A = a_out * prm.z;
                const float3 col = prm.z * (a_in * polys[5 * cur + 1].xyz
                                            + (a_out - a_in) * polys[5 * cur + 2].xyz);
#if CHANNELS == 4
                const float na = A + (1.0f - A) * bg_alpha;  // straight alpha
                lin = na > 0.0f ? (col + (1.0f - A) * bg_alpha * lin) / na : (float3)(0.0f);
                bg_alpha = na;
#else
                lin = col + (1.0f - A) * lin;
#endif
                exact = (A >= 1.0f && a_in >= 1.0f) ? 1 + 2 * cur
                      : (A >= 1.0f && a_in <= 0.0f) ? 2 + 2 * cur : 0;
            }
            if (e == end) break;
            cur = poly;
            a_out = 0.0f;
            a_in = 0.0f;
        }

        const float4 prm = polys[5 * poly];
        const float r = prm.x, ri = prm.y;
        const float4 s = segs[sidx];
        const float2 d = s.zw - s.xy, ap = p - s.xy;
        const float len = length(d);
        const float2 t = len > 0.0f ? d / len : (float2)(1.0f, 0.0f);
        const float along = dot(ap, t);
        float2 n = (float2)(-t.y, t.x);
        float dist;
        // Round ends (joins and round caps): distance to the end point, normal along it.
        if ((along < 0.0f && !(meta & 1)) || (along > len && !(meta & 2))) {
            const float2 v = along < 0.0f ? ap : p - s.zw;
            dist = length(v);
            if (dist > 1e-6f) n = v / dist;
        } else {
            dist = fabs(t.x * ap.y - t.y * ap.x);
        }
        if (dist > r + reach_pad) continue;
        const float na_ = fabs(n.x) * strength, nb_ = fabs(n.y) * strength;
        const float fa = fmax(na_, nb_), fb = fmin(na_, nb_);
        float co = strip_cover(dist, r, fa, fb);
        float ci = ri > 0.0f ? strip_cover(dist, ri, fa, fb) : 0.0f;
        if (meta & 3) {  // flat (butt / square) caps: times the coverage of the half-plane past the end
            const float ta_ = fabs(t.x) * strength, tb_ = fabs(t.y) * strength;
            const float ta = fmax(ta_, tb_), tb = fmin(ta_, tb_);
            const float ext = (meta & 4) ? r : 0.0f, ext_i = ext - (r - ri);
            if (meta & 1) {
                co *= footprint_cdf(along + ext, ta, tb);
                ci *= footprint_cdf(along + ext_i, ta, tb);
            }
            if (meta & 2) {
                co *= footprint_cdf(len - along + ext, ta, tb);
                ci *= footprint_cdf(len - along + ext_i, ta, tb);
            }
        }
        // One polyline is one shape: its segments' coverages merge by max, so joins are not
        // blended twice.
        a_out = fmax(a_out, co);
        a_in = fmax(a_in, ci);
    }

    if (!loaded) return;  // untouched pixels keep their exact values
    float4 outc;
    if (exact) {
        const int k = (exact - 1) >> 1;
        outc = polys[5 * k + 3 + ((exact - 1) & 1)];
    } else {
        outc = (float4)(encode_srgb(luts, lin.x), encode_srgb(luts, lin.y),
                        encode_srgb(luts, lin.z), 0.0f);
    }
    outc.w = exact ? 1.0f : bg_alpha;
    store_px(img, pix, outc);
}
