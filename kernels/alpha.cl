// alpha.cl -- alpha as coverage: an RGBA frame's output from its filtered premultiplied colour and its filtered
// alpha plane (mlaa_stream/spatial/alpha.py: AlphaSplit.merge is the numpy reference, MergePass runs this).
// Defines (defines_for + the filter's pass defines): PIXEL_T, PIXEL_MAX, PIXEL_IS_FLOAT, LUT_SIZE, DECODE (the
// mix space is linear light: the tables decode and encode), PREMULTIPLIED (1: the frame's colour is
// premultiplied by its alpha, EXR's convention), RANGE_RADIUS (the window of covered input colours a rim pixel's
// straight colour is clamped to), SAMPLE_LIMIT (float samples beyond it, and non-finite ones, pass through).
// CHANNELS is 4 for `frame` and `out`; the colours are 3 channels, the alpha planes 1.
#ifndef PREMULTIPLIED
#define PREMULTIPLIED 0
#endif
#ifndef RANGE_RADIUS
#define RANGE_RADIUS 2
#endif
#ifndef SAMPLE_LIMIT
#define SAMPLE_LIMIT 1e15f
#endif

// A stored sample as a fraction of full scale (floats as they are).
inline float unit(PIXEL_T v) { return (float)v * (1.0f / PIXEL_MAX); }

// Stored scale -> mix space (linear light where DECODE; the tables clip to [0, 1], as the reference's decode).
inline float to_mix(__global const float *luts, float v)
{
#if DECODE
    return lut_read(luts, v);
#else
    return v;
#endif
}

inline float from_mix(__global const float *luts, float v)
{
#if DECODE
    return encode_mix(luts, v);
#else
    return v;
#endif
}

// A sample the filter takes (finite, within SAMPLE_LIMIT): integers always.
inline int in_range(PIXEL_T v)
{
#ifdef PIXEL_IS_FLOAT
    return (v < 0.0f ? -v : v) <= SAMPLE_LIMIT;   // NaN: false
#else
    return 1;
#endif
}

// Coverage of a stored alpha, clipped to [0, 1] (0 where it is not a sample the filter takes).
inline float coverage(PIXEL_T a)
{
    if (!in_range(a)) return 0.0f;
    const float c = unit(a);
    return c < 0.0f ? 0.0f : (c > 1.0f ? 1.0f : c);
}

// One work item per pixel. frame: the input (RGBA); colour_in: the premultiplied colour the colour filter got
// (AlphaSplit.colour), colour_out: what it returned; alpha_in (the frame's alpha), alpha_out: the alpha plane and
// its filtered copy; out: the merged frame (RGBA).
__kernel void alpha_merge(__global const PIXEL_T *frame, __global const PIXEL_T *colour_in,
                          __global const PIXEL_T *colour_out, __global const PIXEL_T *alpha_out,
                          __global const float *luts, __global PIXEL_T *out, const int w, const int h)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    const int i = y * w + x;
    __global const PIXEL_T *f = frame + (size_t)i * 4;
    __global const PIXEL_T *ci = colour_in + (size_t)i * 3, *co = colour_out + (size_t)i * 3;
    __global PIXEL_T *o = out + (size_t)i * 4;
    const PIXEL_T a_in = f[3], a_out = alpha_out[i];
    const int same_alpha = a_out == a_in;
    int moved = !same_alpha || co[0] != ci[0] || co[1] != ci[1] || co[2] != ci[2];
    const int finite = in_range(f[0]) && in_range(f[1]) && in_range(f[2]) && in_range(f[3]);
    moved = moved && finite && in_range(a_out);
    o[0] = f[0]; o[1] = f[1]; o[2] = f[2]; o[3] = f[3];
    if (!moved) return;
    o[3] = a_out;
    const float cover_in = finite ? coverage(a_in) : 0.0f;
    int inside = cover_in >= 1.0f;
#if PREMULTIPLIED
    inside = inside || (cover_in <= 0.0f && (f[0] != 0 || f[1] != 0 || f[2] != 0));   // emission: light, no cover
#endif
    if (same_alpha && inside) {   // inside the element: the colour filter's output as it is
        o[0] = co[0]; o[1] = co[1]; o[2] = co[2];
        return;
    }
    // the range of the straight colours (mix space) of the covered input pixels in the window
    float lo[3] = {1.0f, 1.0f, 1.0f}, hi[3] = {0.0f, 0.0f, 0.0f};
    int any = 0;
    for (int dy = -RANGE_RADIUS; dy <= RANGE_RADIUS; ++dy) {
        const int yy = y + dy;
        if (yy < 0 || yy >= h) continue;
        for (int dx = -RANGE_RADIUS; dx <= RANGE_RADIUS; ++dx) {
            const int xx = x + dx;
            if (xx < 0 || xx >= w) continue;
            __global const PIXEL_T *n = frame + ((size_t)yy * w + xx) * 4;
            if (!(in_range(n[0]) && in_range(n[1]) && in_range(n[2]) && in_range(n[3]))) continue;
            const float c = coverage(n[3]);
            if (!(c > 0.0f)) continue;
            float s[3];
            int ok = 1;
            for (int k = 0; k < 3; ++k) {
#if PREMULTIPLIED
                s[k] = to_mix(luts, unit(n[k])) / c;
                ok = ok && isfinite(s[k]);
#else
                s[k] = to_mix(luts, unit(n[k]));
#endif
            }
            if (!ok) continue;
            if (!any) {
                for (int k = 0; k < 3; ++k) lo[k] = hi[k] = s[k];
                any = 1;
            } else {
                for (int k = 0; k < 3; ++k) {
                    lo[k] = s[k] < lo[k] ? s[k] : lo[k];
                    hi[k] = s[k] > hi[k] ? s[k] : hi[k];
                }
            }
        }
    }
    const float cover = coverage(a_out);
    for (int k = 0; k < 3; ++k) {
        float s;
        if (cover > 0.0f) {
            s = to_mix(luts, unit(co[k])) / cover;
            if (any) s = s < lo[k] ? lo[k] : (s > hi[k] ? hi[k] : s);
        } else {
            s = to_mix(luts, unit(f[k]));   // alpha 0: as it was
        }
#if PREMULTIPLIED
        s *= cover;
#endif
        o[k] = to_pixel(from_mix(luts, s));
    }
}
