"""FXAA 3.11 (quality path) as one OpenCL pass, plus its numpy reference: the baseline to beat.

    with FXAA() as f:
        out = f.process(frame)          # same shape and dtype; the same interface as mlaa.Filter

The kernel is kernels/fxaa.cl (Lottes 2011, "FXAA 3.11", FxaaPixelShader PC quality path);
`fxaa_reference` computes the same thing in float32 numpy, operation for operation.
"""
from __future__ import annotations

import threading

import numpy as np
import pyopencl as cl

from mlaa_stream.device.colour import device_luts, lut_read
from mlaa_stream.device.context import Context, default_context
from mlaa_stream.device.formats import LUT_SIZE, FrameFormat, defines_for, frame_format

# Search step sizes per quality preset (Fxaa3_11.h, FXAA_QUALITY__P0..P11).
QUALITY_STEPS: dict[int, tuple[float, ...]] = {
    10: (1.5, 3.0, 12.0),
    11: (1.0, 1.5, 3.0, 12.0),
    12: (1.0, 1.5, 2.0, 4.0, 12.0),
    13: (1.0, 1.5, 2.0, 2.0, 4.0, 12.0),
    14: (1.0, 1.5, 2.0, 2.0, 2.0, 4.0, 12.0),
    15: (1.0, 1.5, 2.0, 2.0, 2.0, 2.0, 4.0, 12.0),
    20: (1.5, 2.0, 8.0),
    29: (1.0, 1.5, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 4.0, 8.0),
    39: (1.0, 1.0, 1.0, 1.0, 1.0, 1.5, 2.0, 2.0, 2.0, 2.0, 4.0, 8.0),
}
# The shader's defaults (fxaaQualityEdgeThreshold, ...EdgeThresholdMin, fxaaQualitySubpix, preset 12).
EDGE_THRESHOLD, EDGE_THRESHOLD_MIN, SUBPIX, QUALITY = 0.166, 0.0833, 0.75, 12

_MAX = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0, np.dtype(np.float32): 1.0}


def _check_options(edge_threshold: float, edge_threshold_min: float, subpix: float, quality: int) -> None:
    if quality not in QUALITY_STEPS:
        raise ValueError(f"quality: expected one of {', '.join(map(str, QUALITY_STEPS))}, got {quality!r}")
    for name, v in (("edge_threshold", edge_threshold), ("edge_threshold_min", edge_threshold_min),
                    ("subpix", subpix)):
        if not 0.0 <= float(v) <= 1.0:
            raise ValueError(f"{name}: expected a number in [0, 1], got {v!r}")


def fxaa_defines(fmt: FrameFormat, edge_threshold: float = EDGE_THRESHOLD,
                 edge_threshold_min: float = EDGE_THRESHOLD_MIN, subpix: float = SUBPIX,
                 quality: int = QUALITY, linear: bool = True, linear_input: bool = False) -> dict:
    """Build defines for kernels/fxaa.cl (through formats.defines_for, the one place)."""
    steps = QUALITY_STEPS[quality]
    return defines_for(fmt, FXAA_EDGE_THRESHOLD=float(edge_threshold),
                       FXAA_EDGE_THRESHOLD_MIN=float(edge_threshold_min), FXAA_SUBPIX=float(subpix),
                       FXAA_PS=len(steps), FXAA_STEPS=",".join(f"{s!r}f" for s in map(float, steps)),
                       LINEAR_INPUT=int(linear_input), BLEND_LINEAR=int(linear))


class _Pending:
    """A frame in flight; `result()` waits for the download and returns the input's dtype, as an array the caller
    owns (as the Filter's PendingFrame: the first call the download itself, later calls a copy of it)."""

    def __init__(self, host_out: np.ndarray, event, dtype: np.dtype, shape: tuple, keep=()):
        self._out, self._event, self._dtype, self._shape, self._keep = host_out, event, dtype, shape, keep
        self._result: np.ndarray | None = None

    def result(self) -> np.ndarray:
        if self._result is not None:   # a second view of one buffer would change with the first
            return self._result.copy()
        self._event.wait()
        self._keep = ()
        out = self._out.reshape(self._shape)
        self._result = out if out.dtype == self._dtype else out.astype(self._dtype)
        return self._result


class FXAA:
    """FXAA 3.11 quality on an OpenCL device, for numpy frames; same interface as mlaa.Filter."""

    SLOTS = 2

    def __init__(self, device: str | int | None = None, *, edge_threshold: float = EDGE_THRESHOLD,
                 edge_threshold_min: float = EDGE_THRESHOLD_MIN, subpix: float = SUBPIX,
                 quality: int = QUALITY, linear: bool = True, linear_input: bool = False,
                 bgr: bool = False, context: Context | None = None):
        _check_options(edge_threshold, edge_threshold_min, subpix, quality)
        self.options = dict(edge_threshold=float(edge_threshold), edge_threshold_min=float(edge_threshold_min),
                            subpix=float(subpix), quality=int(quality), linear=bool(linear),
                            linear_input=bool(linear_input))
        self.bgr = bool(bgr)
        self.context = context or default_context(device)
        self.queue = cl.CommandQueue(self.context.ctx, self.context.device)
        self._luts = cl.Buffer(self.context.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                               hostbuf=device_luts())
        self._fmt: FrameFormat | None = None
        self._frame_no = 0
        self._lock = threading.Lock()

    @property
    def device_name(self) -> str:
        return self.context.name

    def _prepare(self, fmt: FrameFormat) -> None:
        """Buffers and the kernel, once per frame format."""
        if self._fmt == fmt:
            return
        self.queue.finish()
        self._kernel = self.context.kernel("fxaa", "fxaa", fxaa_defines(fmt, **self.options))
        self._src = [self.context.buffer(fmt.nbytes) for _ in range(self.SLOTS)]
        self._dst = [self.context.buffer(fmt.nbytes) for _ in range(self.SLOTS)]
        self._staging = [np.empty(fmt.nbytes // fmt.dtype.itemsize, fmt.dtype) for _ in range(self.SLOTS)]
        self._last = [None] * self.SLOTS
        self._fmt = fmt

    def submit(self, frame: np.ndarray) -> _Pending:
        """Enqueue upload, kernel and download of `frame` without waiting."""
        fmt = frame_format(frame, self.bgr)
        with self._lock:
            self._prepare(fmt)
            slot = self._frame_no % self.SLOTS
            self._frame_no += 1
            if self._last[slot] is not None:
                self._last[slot].wait()  # that slot's previous frame has been downloaded
            staging = self._staging[slot]
            np.copyto(staging.reshape(frame.shape), frame, casting="unsafe")
            cl.enqueue_copy(self.queue, self._src[slot], staging, is_blocking=False)
            self._kernel(self.queue, (fmt.width, fmt.height), None, self._src[slot], self._luts,
                         self._dst[slot], np.int32(fmt.width), np.int32(fmt.height))
            host_out = np.empty_like(staging)
            down = cl.enqueue_copy(self.queue, host_out, self._dst[slot], is_blocking=False)
            self._last[slot] = down
            self.queue.flush()
        return _Pending(host_out, down, np.dtype(frame.dtype), frame.shape, keep=(staging,))

    def process(self, frame: np.ndarray) -> np.ndarray:
        """Antialias one frame and return it (same shape and dtype)."""
        return self.submit(frame).result()

    def close(self) -> None:
        """Wait for work in flight and drop the device buffers."""
        try:
            self.queue.finish()
        finally:
            self._fmt = None
            self._src = self._dst = self._staging = []

    def __enter__(self) -> "FXAA":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# --- numpy reference ------------------------------------------------------------------------------
def fxaa_reference(frame: np.ndarray, *, edge_threshold: float = EDGE_THRESHOLD,
                   edge_threshold_min: float = EDGE_THRESHOLD_MIN, subpix: float = SUBPIX,
                   quality: int = QUALITY, linear: bool = True, linear_input: bool = False,
                   bgr: bool = False) -> np.ndarray:
    """What kernels/fxaa.cl computes, in float32 numpy with the same operation order (slow, plain)."""
    fmt = frame_format(frame, bgr)
    f32 = np.float32
    pmax = f32(_MAX[fmt.dtype])
    early, c = fxaa_mix_reference(frame, edge_threshold=edge_threshold, edge_threshold_min=edge_threshold_min,
                                  subpix=subpix, quality=quality, linear=linear, linear_input=linear_input,
                                  bgr=bgr)
    if linear and not linear_input:
        c = lut_read(device_luts()[2 * (LUT_SIZE + 1):], c).astype(f32)
    a = np.asarray(frame).reshape(fmt.height, fmt.width, fmt.channels).astype(f32) * (f32(1.0) / pmax)
    res = a.copy()
    if fmt.channels == 1:
        res[..., 0] = np.where(early, a[..., 0], c[..., 0])
    else:
        c = c[..., ::-1] if fmt.bgr else c
        res[..., :3] = np.where(early[..., None], a[..., :3], c)
    if fmt.dtype == np.float32:
        out = res
    else:
        out = np.clip(np.rint(res * pmax), 0, pmax)
    return out.astype(frame.dtype).reshape(frame.shape)


def luma_reference(rgb: np.ndarray, linear_input: bool = False) -> np.ndarray:
    """kernels/fxaa.cl px_luma of normalised RGB (float32, (..., 3) in RGB order)."""
    f32 = np.float32
    luma = f32(0.299) * rgb[..., 0] + f32(0.587) * rgb[..., 1] + f32(0.114) * rgb[..., 2]
    return np.sqrt(np.maximum(luma, f32(0))) if linear_input else luma


def fxaa_mix_reference(frame: np.ndarray, *, edge_threshold: float = EDGE_THRESHOLD,
                       edge_threshold_min: float = EDGE_THRESHOLD_MIN, subpix: float = SUBPIX,
                       quality: int = QUALITY, linear: bool = True,
                       linear_input: bool = False, bgr: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """kernels/fxaa.cl's fxaa_pixel for every pixel: (early, colour), `early` where the local-contrast
    exit keeps the pixel, `colour` (h, w, 3) in RGB order in mix space (linear light where sRGB is decoded)."""
    _check_options(edge_threshold, edge_threshold_min, subpix, quality)
    fmt = frame_format(frame, bgr)
    f32 = np.float32
    pmax = f32(_MAX[fmt.dtype])
    h, w = fmt.height, fmt.width
    a = np.asarray(frame).reshape(h, w, fmt.channels).astype(f32) * (f32(1.0) / pmax)
    rgb = np.repeat(a[..., :1], 3, axis=-1) if fmt.channels == 1 else a[..., :3]
    if fmt.bgr:
        rgb = rgb[..., ::-1]
    luma = luma_reference(rgb, linear_input)
    decode = linear and not linear_input
    luts = device_luts()
    blend_rgb = lut_read(luts, rgb).astype(f32) if decode else rgb

    ys, xs = np.mgrid[0:h, 0:w]

    def L(xi, yi):
        return luma[np.clip(yi, 0, h - 1), np.clip(xi, 0, w - 1)]

    def bilinear(src, px, py):
        fx, fy = px - f32(0.5), py - f32(0.5)
        x0f, y0f = np.floor(fx), np.floor(fy)
        tx, ty = fx - x0f, fy - y0f
        x0, y0 = x0f.astype(np.int64), y0f.astype(np.int64)
        xa, xb = np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1)
        ya, yb = np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1)
        if src.ndim == 3:
            tx, ty = tx[..., None], ty[..., None]
        top = src[ya, xa] + (src[ya, xb] - src[ya, xa]) * tx
        bot = src[yb, xa] + (src[yb, xb] - src[yb, xa]) * tx
        return top + (bot - top) * ty

    lumaM = luma
    lumaS, lumaE, lumaN, lumaW = L(xs, ys + 1), L(xs + 1, ys), L(xs, ys - 1), L(xs - 1, ys)
    rangeMax = np.maximum(np.maximum(lumaN, lumaW), np.maximum(lumaE, np.maximum(lumaS, lumaM)))
    rangeMin = np.minimum(np.minimum(lumaN, lumaW), np.minimum(lumaE, np.minimum(lumaS, lumaM)))
    rng = rangeMax - rangeMin
    early = rng < np.maximum(f32(edge_threshold_min), rangeMax * f32(edge_threshold))

    lumaNW, lumaSE = L(xs - 1, ys - 1), L(xs + 1, ys + 1)
    lumaNE, lumaSW = L(xs + 1, ys - 1), L(xs - 1, ys + 1)
    lumaNS, lumaWE = lumaN + lumaS, lumaW + lumaE
    # Early-exit pixels keep their colour; give them a harmless range so nothing below is NaN.
    subpixRcpRange = f32(1.0) / np.where(early, f32(1.0), rng)
    subpixNSWE = lumaNS + lumaWE
    edgeHorz1 = (f32(-2.0) * lumaM) + lumaNS
    edgeVert1 = (f32(-2.0) * lumaM) + lumaWE
    lumaNESE, lumaNWNE = lumaNE + lumaSE, lumaNW + lumaNE
    edgeHorz2 = (f32(-2.0) * lumaE) + lumaNESE
    edgeVert2 = (f32(-2.0) * lumaN) + lumaNWNE
    lumaNWSW, lumaSWSE = lumaNW + lumaSW, lumaSW + lumaSE
    edgeHorz4 = (np.abs(edgeHorz1) * f32(2.0)) + np.abs(edgeHorz2)
    edgeVert4 = (np.abs(edgeVert1) * f32(2.0)) + np.abs(edgeVert2)
    edgeHorz3 = (f32(-2.0) * lumaW) + lumaNWSW
    edgeVert3 = (f32(-2.0) * lumaS) + lumaSWSE
    edgeHorz = np.abs(edgeHorz3) + edgeHorz4
    edgeVert = np.abs(edgeVert3) + edgeVert4
    subpixNWSWNESE = lumaNWSW + lumaNESE
    horz = edgeHorz >= edgeVert
    subpixA = subpixNSWE * f32(2.0) + subpixNWSWNESE
    lumaN = np.where(horz, lumaN, lumaW)
    lumaS = np.where(horz, lumaS, lumaE)
    subpixB = (subpixA * (f32(1.0) / f32(12.0))) - lumaM
    gradientN, gradientS = lumaN - lumaM, lumaS - lumaM
    lumaNN, lumaSS = lumaN + lumaM, lumaS + lumaM
    pairN = np.abs(gradientN) >= np.abs(gradientS)
    gradient = np.maximum(np.abs(gradientN), np.abs(gradientS))
    lengthSign = np.where(pairN, f32(-1.0), f32(1.0))
    subpixC = np.clip(np.abs(subpixB) * subpixRcpRange, f32(0), f32(1))

    mx, my = xs.astype(f32) + f32(0.5), ys.astype(f32) + f32(0.5)
    offx, offy = np.where(horz, f32(1), f32(0)), np.where(horz, f32(0), f32(1))
    bx = np.where(horz, mx, mx + lengthSign * f32(0.5))
    by = np.where(horz, my + lengthSign * f32(0.5), my)
    steps = [f32(s) for s in QUALITY_STEPS[quality]]
    nx, ny = bx - offx * steps[0], by - offy * steps[0]
    px, py = bx + offx * steps[0], by + offy * steps[0]
    subpixD = (f32(-2.0) * subpixC) + f32(3.0)
    lumaEndN = bilinear(luma, nx, ny)
    subpixE = subpixC * subpixC
    lumaEndP = bilinear(luma, px, py)
    lumaNN = np.where(pairN, lumaNN, lumaSS)
    gradientScaled = gradient * f32(0.25)
    lumaMM = lumaM - lumaNN * f32(0.5)
    subpixF = subpixD * subpixE
    lumaMLTZero = lumaMM < f32(0.0)
    lumaEndN = lumaEndN - lumaNN * f32(0.5)
    lumaEndP = lumaEndP - lumaNN * f32(0.5)
    doneN = np.abs(lumaEndN) >= gradientScaled
    doneP = np.abs(lumaEndP) >= gradientScaled
    nx, ny = np.where(doneN, nx, nx - offx * steps[1]), np.where(doneN, ny, ny - offy * steps[1])
    px, py = np.where(doneP, px, px + offx * steps[1]), np.where(doneP, py, py + offy * steps[1])
    for step in steps[2:]:
        lumaEndN = np.where(doneN, lumaEndN, bilinear(luma, nx, ny) - lumaNN * f32(0.5))
        lumaEndP = np.where(doneP, lumaEndP, bilinear(luma, px, py) - lumaNN * f32(0.5))
        doneN = np.abs(lumaEndN) >= gradientScaled
        doneP = np.abs(lumaEndP) >= gradientScaled
        nx, ny = np.where(doneN, nx, nx - offx * step), np.where(doneN, ny, ny - offy * step)
        px, py = np.where(doneP, px, px + offx * step), np.where(doneP, py, py + offy * step)

    dstN = np.where(horz, mx - nx, my - ny)
    dstP = np.where(horz, px - mx, py - my)
    goodSpanN = (lumaEndN < f32(0.0)) != lumaMLTZero
    goodSpanP = (lumaEndP < f32(0.0)) != lumaMLTZero
    spanLengthRcp = f32(1.0) / (dstP + dstN)
    goodSpan = np.where(dstN < dstP, goodSpanN, goodSpanP)
    subpixG = subpixF * subpixF
    pixelOffset = (np.minimum(dstN, dstP) * (-spanLengthRcp)) + f32(0.5)
    subpixH = subpixG * f32(subpix)
    pixelOffsetSubpix = np.maximum(np.where(goodSpan, pixelOffset, f32(0.0)), subpixH)
    qx = np.where(horz, mx, mx + pixelOffsetSubpix * lengthSign)
    qy = np.where(horz, my + pixelOffsetSubpix * lengthSign, my)
    return early, bilinear(blend_rgb, qx, qy).astype(f32)
