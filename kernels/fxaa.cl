// fxaa.cl: FXAA 3.11 "quality" in one pass -- the baseline the MLAA passes are measured against.
// Written from the published algorithm (T. Lottes, "FXAA 3.11", NVIDIA 2011, FxaaPixelShader's
// PC quality path): luma, local-contrast early exit, edge direction from a 3x3 second difference,
// end-of-edge search along the edge with bilinear luma reads, sub-pixel aliasing test, and a final
// bilinear read offset across the edge. Reference: mlaa_stream.fxaa.fxaa_reference.
//
// Positions are in pixels (pixel (x, y) has its centre at x + 0.5, y + 0.5; rcpFrame = 1); reads
// between pixels are bilinear with clamp-to-edge, like FxaaTexTop on a linear-filtered texture.
// Defines (mlaa_stream.formats.defines_for, options from mlaa_stream.fxaa.FXAA):
//   FXAA_EDGE_THRESHOLD, FXAA_EDGE_THRESHOLD_MIN, FXAA_SUBPIX   the shader's quality knobs
//   FXAA_PS, FXAA_STEPS    number of search steps and their comma-separated sizes (the preset)
//   LINEAR_INPUT           1: samples are linear light (luma is then sqrt of linear luma)
//   BLEND_LINEAR           1: the final bilinear read mixes linear light (sRGB decoded by table)
#pragma OPENCL FP_CONTRACT OFF

#ifndef FXAA_PS
#define FXAA_PS 5
#define FXAA_STEPS 1.0f, 1.5f, 2.0f, 4.0f, 12.0f
#endif
#ifndef FXAA_EDGE_THRESHOLD
#define FXAA_EDGE_THRESHOLD 0.166f
#endif
#ifndef FXAA_EDGE_THRESHOLD_MIN
#define FXAA_EDGE_THRESHOLD_MIN 0.0833f
#endif
#ifndef FXAA_SUBPIX
#define FXAA_SUBPIX 0.75f
#endif

__constant float fxaa_steps[FXAA_PS] = { FXAA_STEPS };

// v clamped to [0, hi] (inline: PoCL calls the built-in clamp out of line).
inline int clamp_to(int v, int hi) { return v < 0 ? 0 : (v > hi ? hi : v); }

// Luma of pixel (x, y), clamped to the frame: Rec. 601 weights on the stored (gamma) values.
inline float px_luma(__global const PIXEL_T *img, int x, int y, int w, int h)
{
    float4 c = load_px(img, IDX(clamp_to(x, w - 1), clamp_to(y, h - 1), w));
    float l = 0.299f * c.x + 0.587f * c.y + 0.114f * c.z;
#if LINEAR_INPUT
    l = sqrt(fmax(l, 0.0f));
#endif
    return l;
}

// Bilinear luma at pixel-space position p (the shader's FxaaTexTop(tex, pos).w).
inline float luma_at(__global const PIXEL_T *img, float2 p, int w, int h)
{
    float fx = p.x - 0.5f, fy = p.y - 0.5f;
    float x0f = floor(fx), y0f = floor(fy);
    float tx = fx - x0f, ty = fy - y0f;
    int x0 = (int)x0f, y0 = (int)y0f;
    float l00 = px_luma(img, x0, y0, w, h), l10 = px_luma(img, x0 + 1, y0, w, h);
    float l01 = px_luma(img, x0, y0 + 1, w, h), l11 = px_luma(img, x0 + 1, y0 + 1, w, h);
    float top = l00 + (l10 - l00) * tx;
    float bot = l01 + (l11 - l01) * tx;
    return top + (bot - top) * ty;
}

inline float3 blend_rgb(__global const PIXEL_T *img, __global const float *luts, int x, int y,
                        int w, int h)
{
    float4 c = load_px(img, IDX(clamp_to(x, w - 1), clamp_to(y, h - 1), w));
#if DECODE
    return (float3)(srgb_to_linear(luts, c.x), srgb_to_linear(luts, c.y), srgb_to_linear(luts, c.z));
#else
    return c.xyz;
#endif
}

// Bilinear colour at pixel-space position p in mix space (linear light when DECODE).
inline float3 colour_at_mix(__global const PIXEL_T *img, __global const float *luts, float2 p,
                            int w, int h)
{
    float fx = p.x - 0.5f, fy = p.y - 0.5f;
    float x0f = floor(fx), y0f = floor(fy);
    float tx = fx - x0f, ty = fy - y0f;
    int x0 = (int)x0f, y0 = (int)y0f;
    float3 c00 = blend_rgb(img, luts, x0, y0, w, h), c10 = blend_rgb(img, luts, x0 + 1, y0, w, h);
    float3 c01 = blend_rgb(img, luts, x0, y0 + 1, w, h), c11 = blend_rgb(img, luts, x0 + 1, y0 + 1, w, h);
    float3 top = c00 + (c10 - c00) * tx;
    float3 bot = c01 + (c11 - c01) * tx;
    return top + (bot - top) * ty;
}

// Mix space -> stored (sRGB-encoded when DECODE).
inline float3 fxaa_encode(__global const float *luts, float3 c)
{
#if DECODE
    c = (float3)(encode_mix(luts, c.x), encode_mix(luts, c.y), encode_mix(luts, c.z));
#endif
    return c;
}

// FXAA 3.11 at pixel (x, y): 0 where the local-contrast early exit keeps the pixel, else 1 with *out its
// new colour in mix space (linear light when DECODE).
// FXAA's local-contrast early exit at (x, y): 1 where the pixel keeps its colour (fxaa_pixel returns 0).
inline int fxaa_keeps(__global const PIXEL_T *src, int x, int y, int w, int h)
{
    const float lumaM = px_luma(src, x, y, w, h), lumaS = px_luma(src, x, y + 1, w, h);
    const float lumaE = px_luma(src, x + 1, y, w, h), lumaN = px_luma(src, x, y - 1, w, h);
    const float lumaW = px_luma(src, x - 1, y, w, h);
    const float rangeMax = fmax(fmax(lumaN, lumaW), fmax(lumaE, fmax(lumaS, lumaM)));
    const float rangeMin = fmin(fmin(lumaN, lumaW), fmin(lumaE, fmin(lumaS, lumaM)));
    return rangeMax - rangeMin < fmax(FXAA_EDGE_THRESHOLD_MIN, rangeMax * FXAA_EDGE_THRESHOLD);
}

inline int fxaa_pixel(__global const PIXEL_T *src, __global const float *luts, int x, int y, int w, int h,
                      float3 *out)
{
    float lumaM = px_luma(src, x, y, w, h);
    float lumaS = px_luma(src, x, y + 1, w, h);
    float lumaE = px_luma(src, x + 1, y, w, h);
    float lumaN = px_luma(src, x, y - 1, w, h);
    float lumaW = px_luma(src, x - 1, y, w, h);

    // Local contrast early exit.
    float maxSM = fmax(lumaS, lumaM), minSM = fmin(lumaS, lumaM);
    float maxESM = fmax(lumaE, maxSM), minESM = fmin(lumaE, minSM);
    float maxWN = fmax(lumaN, lumaW), minWN = fmin(lumaN, lumaW);
    float rangeMax = fmax(maxWN, maxESM), rangeMin = fmin(minWN, minESM);
    float rangeMaxScaled = rangeMax * FXAA_EDGE_THRESHOLD;
    float range = rangeMax - rangeMin;
    float rangeMaxClamped = fmax(FXAA_EDGE_THRESHOLD_MIN, rangeMaxScaled);
    if (range < rangeMaxClamped)
        return 0;

    float lumaNW = px_luma(src, x - 1, y - 1, w, h);
    float lumaSE = px_luma(src, x + 1, y + 1, w, h);
    float lumaNE = px_luma(src, x + 1, y - 1, w, h);
    float lumaSW = px_luma(src, x - 1, y + 1, w, h);

    // Edge direction: horizontal or vertical span from weighted second differences.
    float lumaNS = lumaN + lumaS;
    float lumaWE = lumaW + lumaE;
    float subpixRcpRange = 1.0f / range;
    float subpixNSWE = lumaNS + lumaWE;
    float edgeHorz1 = (-2.0f * lumaM) + lumaNS;
    float edgeVert1 = (-2.0f * lumaM) + lumaWE;
    float lumaNESE = lumaNE + lumaSE;
    float lumaNWNE = lumaNW + lumaNE;
    float edgeHorz2 = (-2.0f * lumaE) + lumaNESE;
    float edgeVert2 = (-2.0f * lumaN) + lumaNWNE;
    float lumaNWSW = lumaNW + lumaSW;
    float lumaSWSE = lumaSW + lumaSE;
    float edgeHorz4 = (fabs(edgeHorz1) * 2.0f) + fabs(edgeHorz2);
    float edgeVert4 = (fabs(edgeVert1) * 2.0f) + fabs(edgeVert2);
    float edgeHorz3 = (-2.0f * lumaW) + lumaNWSW;
    float edgeVert3 = (-2.0f * lumaS) + lumaSWSE;
    float edgeHorz = fabs(edgeHorz3) + edgeHorz4;
    float edgeVert = fabs(edgeVert3) + edgeVert4;

    float subpixNWSWNESE = lumaNWSW + lumaNESE;
    float lengthSign = 1.0f;
    bool horzSpan = edgeHorz >= edgeVert;
    float subpixA = subpixNSWE * 2.0f + subpixNWSWNESE;
    if (!horzSpan) {
        lumaN = lumaW;
        lumaS = lumaE;
    }
    float subpixB = (subpixA * (1.0f / 12.0f)) - lumaM;

    // Which side of the pixel the edge lies on.
    float gradientN = lumaN - lumaM;
    float gradientS = lumaS - lumaM;
    float lumaNN = lumaN + lumaM;
    float lumaSS = lumaS + lumaM;
    bool pairN = fabs(gradientN) >= fabs(gradientS);
    float gradient = fmax(fabs(gradientN), fabs(gradientS));
    if (pairN)
        lengthSign = -lengthSign;
    float subpixC = clamp(fabs(subpixB) * subpixRcpRange, 0.0f, 1.0f);

    float2 posM = (float2)((float)x + 0.5f, (float)y + 0.5f);
    float2 posB = posM;
    float2 offNP = horzSpan ? (float2)(1.0f, 0.0f) : (float2)(0.0f, 1.0f);
    if (!horzSpan)
        posB.x += lengthSign * 0.5f;
    else
        posB.y += lengthSign * 0.5f;

    // End-of-edge search in both directions along the edge.
    float2 posN = posB - offNP * fxaa_steps[0];
    float2 posP = posB + offNP * fxaa_steps[0];
    float subpixD = ((-2.0f) * subpixC) + 3.0f;
    float lumaEndN = luma_at(src, posN, w, h);
    float subpixE = subpixC * subpixC;
    float lumaEndP = luma_at(src, posP, w, h);

    if (!pairN)
        lumaNN = lumaSS;
    float gradientScaled = gradient * 0.25f;
    float lumaMM = lumaM - lumaNN * 0.5f;
    float subpixF = subpixD * subpixE;
    bool lumaMLTZero = lumaMM < 0.0f;

    lumaEndN -= lumaNN * 0.5f;
    lumaEndP -= lumaNN * 0.5f;
    bool doneN = fabs(lumaEndN) >= gradientScaled;
    bool doneP = fabs(lumaEndP) >= gradientScaled;
    if (!doneN)
        posN -= offNP * fxaa_steps[1];
    if (!doneP)
        posP += offNP * fxaa_steps[1];
    for (int k = 2; k < FXAA_PS; ++k) {
        if (doneN && doneP)
            break;
        if (!doneN)
            lumaEndN = luma_at(src, posN, w, h) - lumaNN * 0.5f;
        if (!doneP)
            lumaEndP = luma_at(src, posP, w, h) - lumaNN * 0.5f;
        doneN = fabs(lumaEndN) >= gradientScaled;
        doneP = fabs(lumaEndP) >= gradientScaled;
        if (!doneN)
            posN -= offNP * fxaa_steps[k];
        if (!doneP)
            posP += offNP * fxaa_steps[k];
    }

    // Offset across the edge: from the span (nearest end that closes the right way), or the
    // sub-pixel aliasing estimate, whichever is larger.
    float dstN = horzSpan ? posM.x - posN.x : posM.y - posN.y;
    float dstP = horzSpan ? posP.x - posM.x : posP.y - posM.y;
    bool goodSpanN = (lumaEndN < 0.0f) != lumaMLTZero;
    float spanLength = dstP + dstN;
    bool goodSpanP = (lumaEndP < 0.0f) != lumaMLTZero;
    float spanLengthRcp = 1.0f / spanLength;
    bool directionN = dstN < dstP;
    float dstMin = fmin(dstN, dstP);
    bool goodSpan = directionN ? goodSpanN : goodSpanP;
    float subpixG = subpixF * subpixF;
    float pixelOffset = (dstMin * (-spanLengthRcp)) + 0.5f;
    float subpixH = subpixG * FXAA_SUBPIX;
    float pixelOffsetGood = goodSpan ? pixelOffset : 0.0f;
    float pixelOffsetSubpix = fmax(pixelOffsetGood, subpixH);
    if (!horzSpan)
        posM.x += pixelOffsetSubpix * lengthSign;
    else
        posM.y += pixelOffsetSubpix * lengthSign;

    *out = colour_at_mix(src, luts, posM, w, h);
    return 1;
}

__kernel void fxaa(__global const PIXEL_T *src, __global const float *luts,
                   __global PIXEL_T *dst, int w, int h)
{
    int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h)
        return;
    int i = IDX(x, y, w);
    float4 rgbyM = load_px(src, i);
    float3 c;
    if (fxaa_pixel(src, luts, x, y, w, h, &c))
        rgbyM.xyz = fxaa_encode(luts, c);
    store_px(dst, i, rgbyM);
}
