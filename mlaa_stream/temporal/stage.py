"""Temporal stability: reproject the previous output along the motion of the input, reject it where it
cannot be trusted, blend it with the spatially antialiased frame (seed 002, "Temporal Reprojection").

    stage = TemporalStage(bgr=True)
    out = stage(frame_in, frame_filtered, index)     # per frame, in order; history kept inside

Per frame the stage picks the least motion model that explains the input (`choose_model`): "static"
(no flow; the history is used unwarped), "global" (one translation for the whole frame: coarse phase
correlation refined by a global Lucas-Kanade step), or "dense" (DIS optical flow, forward and
backward, at the lowest resolution that keeps sub-pixel accuracy); "reset" at the first frame,
a scene cut, a jump in the frame index or a new frame size. kernels/temporal.cl then warps, clips
and blends in one pass; `temporal_reference` is its numpy twin. See docs/temporal.md.
"""
from __future__ import annotations

import functools
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import cv2
import numpy as np
import pyopencl as cl

from mlaa_stream.device.colour import device_luts, lut_read
from mlaa_stream.device.context import Context, default_context
from mlaa_stream.device.formats import LUT_SIZE, FrameFormat, defines_for, frame_format
from mlaa_stream.device.transfer import with_transfer_tables
from mlaa_stream.spatial.fallback import FALLBACK_TILE
from mlaa_stream.spatial.exposure import HeldExposure, exposed
from mlaa_stream.spatial.nonfinite import SAMPLE_LIMIT, replace_non_finite, restore_out_of_range
from mlaa_stream.spatial.shots import CUT_HIST, histogram_distance

MODES = ("adaptive", "dense", "global", "static", "off")
SHOWS = (None, "history")
# where="everywhere": history wherever the motion and the clip box allow it; "render": only on pixels of the
# spatial filter's render regions (1-spp rendered content, spatial/fallback.py) where the input moved
# (`moving_in_regions`). docs/temporal.md measures why: on flat-colour art the blend is worse than spatial
# only, on a 1-spp render it removes more error, and away from moving edges it adds damage.
WHERE = ("everywhere", "render")
# where="render": a pixel is moving when some colour channel of the raw input changed by at least
# MOVED_LEVELS 8-bit levels since the previous input, at the pixel or one of its 8 neighbours, and the
# frame the stage blends differs from the raw input there by CHANGED_LEVELS or more (an edge the spatial
# filter or TSS worked on; a pixel they left is more often one the input already has right).
MOVED_LEVELS, CHANGED_LEVELS = 32, 2
# where="render": no history within BLOB_MARGIN pixels of a blob the motion does not explain (unexplained_blobs):
# DIS misses a fast mover's motion (23 px per frame measured as 2-3), and the background it uncovers would take
# the mover's colour from the history (docs/temporal.md, "A fast mover over a render").
BLOB_MARGIN = 16

# History weight at zero velocity difference: seed 002's 0.5. Longer histories (0.8, 0.9) were
# measured steadier on nothing and blurrier on everything (docs/temporal.md).
DEFAULT_STRENGTH = 0.5
# The seed's K in pixel units: w falls to 0 at |v_c - v_p| = 1/K^2 px per frame (here 4 px). The
# seed's velocities are in texture units (v_px / width): K_tex = K_px * sqrt(width), docs/temporal.md.
DEFAULT_K = 0.5
REJECT = 2.0        # history beyond this many clip-box half-widths is dropped (kernels/temporal.cl)
EXT_FLOOR = 0.0005  # linear half-width added to every clip box (kernels/temporal.cl)
GAMMA = 1.25        # variance clip: mean +- GAMMA * stddev of the current 3x3 neighbourhood
FB_ABS, FB_REL = 0.5, 0.1   # forward-backward tolerance in px: FB_ABS + FB_REL * |v|

# Cheap measurements that choose the model (grey levels 0..255 of the "small" frame).
SMALL_WIDTH = 320        # measurements run on a frame at most this wide
FLOW_WIDTH = 1024        # dense flow and the global refinement run at most this wide (1080p: half)
# scene cut: half the L1 distance of 32-bin grey histograms above CUT_HIST (spatial/shots.py) ...
CUT_RESIDUAL = 24.0      # ... or mean |difference| after the best global alignment above this
STATIC_LEVEL, STATIC_FRACTION = 3.0, 0.002   # static: under this share of pixels differ by > level
GLOBAL_LEVEL, GLOBAL_FRACTION = 10.0, 0.005  # global accepted: blobs of residual outliers under this share
LK_SIGMA, LK_ITERATIONS, LK_ROBUST = 1.0, 4, 64.0            # global Lucas-Kanade on Gaussian-blurred grey
LK_TOL = 0.01              # px: a Gauss-Newton step under this ends the refinement
LK_FINE_ITERATIONS = 1     # on the flow frame, after converging on the small one
GLOBAL_MIN_SHIFT = 0.1     # px: a frame that changes but whose best translation is ~0 has local motion

_PMAX = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0, np.dtype(np.float32): 1.0}
CUR_RESET, CUR_AFFINE, CUR_DENSE = 0, 1, 2
PREV_NONE, PREV_AFFINE, PREV_DENSE = 0, 1, 2
N_PARAMS = 20
IDENTITY = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)


# --- cheap measurements and the model choice -------------------------------------------------------
def grey8(frame: np.ndarray, bgr: bool, linear: bool = False) -> np.ndarray:
    """The frame's luma as uint8 (what optical flow and the measurements run on). `linear`: the frame is
    linear light (EXR): its luma is sRGB-encoded first, so dark and bright parts keep their contrast."""
    f = np.asarray(frame)
    if f.dtype == np.float16 or f.dtype == np.float64:
        f = f.astype(np.float32)
    if f.ndim == 3 and f.shape[2] == 1:
        f = f[..., 0]
    if f.ndim == 3:
        code = {(3, True): cv2.COLOR_BGR2GRAY, (3, False): cv2.COLOR_RGB2GRAY,
                (4, True): cv2.COLOR_BGRA2GRAY, (4, False): cv2.COLOR_RGBA2GRAY}[(f.shape[2], bool(bgr))]
        f = cv2.cvtColor(np.ascontiguousarray(f), code)
    if linear:
        x = np.nan_to_num(f.astype(np.float32) * np.float32(_GREY_STEPS / _PMAX[f.dtype]), nan=0.0,
                          posinf=_GREY_STEPS, neginf=0.0)   # NaN and inf pixels (EXR) read as black and white
        f = _ENCODE_GREY[np.clip(x, 0, _GREY_STEPS).astype(np.int32)]
    if f.dtype == np.uint8:
        return np.ascontiguousarray(f)
    if f.dtype == np.uint16:
        return (f >> 8).astype(np.uint8)
    return np.clip(np.nan_to_num(f * np.float32(255.0) + np.float32(0.5), nan=0.0), 0, 255).astype(np.uint8)


# grey8's linear -> sRGB-encoded uint8 table (IEC 61966-2-1), over linear values in steps of 1 / _GREY_STEPS: a
# step is under half an 8-bit level everywhere (the steepest part, at 0, has slope 12.92 * 255 levels per unit)
_GREY_STEPS = 8192
_lin = np.arange(_GREY_STEPS + 1, dtype=np.float64) / _GREY_STEPS
_ENCODE_GREY = np.clip(255.0 * np.where(_lin <= 0.0031308, 12.92 * _lin, 1.055 * _lin ** (1 / 2.4) - 0.055) + 0.5,
                       0, 255).astype(np.uint8)
del _lin


def _downscale(img: np.ndarray, factor: int) -> np.ndarray:
    if factor <= 1:
        return img
    h, w = img.shape[:2]
    return cv2.resize(img, (max(1, w // factor), max(1, h // factor)), interpolation=cv2.INTER_AREA)


def scale_for(width: int, target: int) -> int:
    """The smallest integer factor that brings `width` to at most `target` pixels."""
    return max(1, -(-int(width) // int(target)))


# OpenCV's DIS flow (patches of 8 px) raises on images under 8 px in height or width, or under 12 in both: a thin
# or tiny frame (3x4097, 5x7, 10x10) takes the global translation as its flow instead (_flow)
DIS_MIN_SIDE, DIS_MIN_LONG_SIDE = 8, 12


def dis_refuses(shape: tuple[int, ...]) -> bool:
    """True where OpenCV's DIS flow raises on an image of this (height, width)."""
    return min(shape[:2]) < DIS_MIN_SIDE or max(shape[:2]) < DIS_MIN_LONG_SIDE


@dataclass
class Pyramid:
    """One input frame's grey levels at the two resolutions the stage measures on."""

    flow: np.ndarray      # uint8, 1/flow_scale of the frame
    small: np.ndarray     # uint8, 1/(flow_scale * small_scale)
    flow_scale: int
    small_scale: int
    grey: np.ndarray | None = None   # uint8, full size (the identical-frame test)
    _blur: dict = field(default_factory=dict, repr=False, compare=False)   # see blurred()

    @staticmethod
    def of(frame: np.ndarray, bgr: bool, grey: np.ndarray | None = None, linear: bool = False) -> "Pyramid":
        g = grey8(frame, bgr, linear) if grey is None else grey
        fs = scale_for(g.shape[1], FLOW_WIDTH)
        flow = _downscale(g, fs)
        # at least half size: there the aliasing of 1-spp edges averages out (choose_model)
        ss = max(scale_for(flow.shape[1], SMALL_WIDTH), 2 if min(flow.shape) >= 64 else 1)
        return Pyramid(flow, _downscale(flow, ss), fs, ss, g)

    def blurred(self, level: str) -> np.ndarray:
        """The "flow" or "small" grey as float32 blurred by LK_SIGMA, computed once per frame (a
        frame is the current one, then the previous one)."""
        if level not in self._blur:
            self._blur[level] = cv2.GaussianBlur(getattr(self, level).astype(np.float32), (0, 0), LK_SIGMA)
        return self._blur[level]

    def gradients(self, level: str = "flow") -> tuple[np.ndarray, ...]:
        """The blurred grey's (`blurred`) Sobel gradients and their products, float32: (gx, gy, gx gx, gx gy,
        gy gy). The current frame's choose_model (global_translation) and its direct refiner (tss._Refiner) read
        the same; kept until drop_gradients() (five frame-size planes, 10 MB at 1080p flow size)."""
        key = "gradients_" + level
        if key not in self._blur:
            b = self.blurred(level)
            gx = cv2.Sobel(b, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
            gy = cv2.Sobel(b, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
            self._blur[key] = (gx, gy, gx * gx, gx * gy, gy * gy)
        return self._blur[key]

    def drop_gradients(self) -> None:
        """Free what gradients() kept (a frame whose motion is measured needs them no more)."""
        for key in [k for k in self._blur if k.startswith("gradients_")]:
            del self._blur[key]


def changed_fraction(a: np.ndarray, b: np.ndarray, level: float) -> float:
    """Share of pixels whose (slightly blurred) grey level differs by more than `level`."""
    d = cv2.absdiff(cv2.GaussianBlur(a, (3, 3), 0), cv2.GaussianBlur(b, (3, 3), 0))
    return float(np.count_nonzero(d > level)) / d.size


def global_translation(prev: np.ndarray, cur: np.ndarray, start: tuple[float, float] = (0.0, 0.0),
                       iterations: int = LK_ITERATIONS, sigma: float | None = LK_SIGMA,
                       tol: float = LK_TOL, grads: tuple[np.ndarray, ...] | None = None) -> tuple[float, float]:
    """Translation d with cur(x) ~ prev(x + d), by robust Gauss-Newton on the whole frame (global
    Lucas-Kanade on blurred grey, residuals weighted 1 / (1 + (r / LK_ROBUST)^2) so that a mover does not
    pull the estimate; blurring first keeps the aliasing of 1-spp frames out of the gradients).
    The gradients are the current frame's, computed once (inverse-additive form: at the solution
    the warped previous frame matches the current one); stops when a step is under `tol` px.
    sigma=None: prev and cur are float32 frames already blurred (Pyramid.blurred). `grads`: cur's
    (gx, gy, gx gx, gx gy, gy gy) where the caller has them (Pyramid.gradients; sigma None)."""
    if sigma is None:
        p, c = prev, cur
    else:
        p = cv2.GaussianBlur(prev.astype(np.float32), (0, 0), sigma)
        c = cv2.GaussianBlur(cur.astype(np.float32), (0, 0), sigma)
    h, w = p.shape
    if grads is None:
        gx = cv2.Sobel(c, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
        gy = cv2.Sobel(c, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
        grads = (gx, gy, gx * gx, gx * gy, gy * gy)
    gx, gy, gxx, gxy, gyy = (g.ravel() for g in grads)
    d = np.array(start, np.float64)
    inv_r2 = 1.0 / (LK_ROBUST * LK_ROBUST)
    for _ in range(iterations):
        warp = np.float32([[1, 0, d[0]], [0, 1, d[1]]])
        pw = cv2.warpAffine(p, warp, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                            borderMode=cv2.BORDER_REPLICATE)
        r = cv2.subtract(c, pw).ravel()
        wr = r * r    # wr = 1 / (1 + inv_r2 r^2), in place (frame-size float32 temporaries)
        wr *= inv_r2
        wr += 1.0
        np.divide(1.0, wr, out=wr)
        a, b_, e = float(np.dot(wr, gxx)), float(np.dot(wr, gxy)), float(np.dot(wr, gyy))
        wrr = pw.ravel()   # the warped frame is read no more: its buffer takes wr r
        np.multiply(wr, r, out=wrr)
        bx, by = float(np.dot(wrr, gx)), float(np.dot(wrr, gy))
        det = a * e - b_ * b_
        if not det > 1e-6 * max(a * e, 1e-12):  # no texture to anchor a translation
            break
        step = ((e * bx - b_ * by) / det, (a * by - b_ * bx) / det)
        d += step
        if abs(step[0]) + abs(step[1]) < tol:
            break
    return float(d[0]), float(d[1])


def small_residual(prev: np.ndarray, cur: np.ndarray, d: tuple[float, float]) -> np.ndarray:
    """|cur(x) - prev(x + d)| on slightly blurred grey (the aliasing of 1-spp frames averages out
    at this scale; a region that moves otherwise does not), a 2-px border left out."""
    p = cv2.GaussianBlur(prev.astype(np.float32), (0, 0), 1.0)
    c = cv2.GaussianBlur(cur.astype(np.float32), (0, 0), 1.0)
    h, w = p.shape
    warp = np.float32([[1, 0, d[0]], [0, 1, d[1]]])
    pw = cv2.warpAffine(p, warp, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                        borderMode=cv2.BORDER_REPLICATE)
    r = np.abs(c - pw)
    b = 2 + int(math.ceil(max(abs(d[0]), abs(d[1]))))
    return r[b:h - b, b:w - b] if h > 2 * b and w > 2 * b else r


@dataclass
class Decision:
    """What `choose_model` measured and chose for one frame."""

    model: str                                   # "reset" | "static" | "global" | "dense" ("layers": TSS's record)
    translation: tuple[float, float] = (0.0, 0.0)   # full-frame px, current -> previous
    measures: dict = field(default_factory=dict)


def choose_model(prev: Pyramid, cur: Pyramid, mode: str = "adaptive") -> Decision:
    """The least motion model that explains cur from prev, from cheap measurements (docs/temporal.md)."""
    m: dict = {}
    m["hist_distance"] = hd = histogram_distance(prev.small, cur.small)
    if hd > CUT_HIST:
        return Decision("reset", measures={**m, "cut": True})
    if mode in ("adaptive", "static"):
        m["changed"] = ch = changed_fraction(prev.small, cur.small, STATIC_LEVEL)
        if mode == "static" or ch <= STATIC_FRACTION:
            return Decision("static", measures=m)
    # Start from no motion or the phase-correlation shift of the small frames (large pans), whichever
    # leaves the smaller residual (a periodic texture can fool phase correlation), then refine on
    # the flow frame by global Lucas-Kanade.
    ss, fs = cur.small_scale, cur.flow_scale
    start = (0.0, 0.0)
    hs, ws = prev.small.shape
    if hs >= 16 and ws >= 16:
        win = cv2.createHanningWindow((ws, hs), cv2.CV_32F)
        (sx, sy), _ = cv2.phaseCorrelate(cur.small.astype(np.float32), prev.small.astype(np.float32), win)
        shift = (float(round(sx)), float(round(sy)))
        if shift != (0.0, 0.0) and (small_residual(prev.small, cur.small, shift).mean()
                                    < small_residual(prev.small, cur.small, (0.0, 0.0)).mean()):
            start = (shift[0] * ss, shift[1] * ss)
    # coarse to fine: converge on the small frames (a ninth of the work at 1080p), then refine
    ds = global_translation(prev.blurred("small"), cur.blurred("small"), (start[0] / ss, start[1] / ss),
                            sigma=None)
    d = global_translation(prev.blurred("flow"), cur.blurred("flow"), (ds[0] * ss, ds[1] * ss),
                           iterations=LK_FINE_ITERATIONS, sigma=None, grads=cur.gradients("flow"))
    res = small_residual(prev.small, cur.small, (d[0] / ss, d[1] / ss))
    m["residual_mean"] = rm = float(res.mean()) if res.size else 0.0
    # Outliers that survive a 3x3 erosion: regions the translation does not explain (a mover), not
    # the thin lines that the aliasing of 1-spp edges leaves along every moving edge.
    blobs = cv2.erode((res > GLOBAL_LEVEL).astype(np.uint8), np.ones((3, 3), np.uint8))
    m["global_outliers"] = go = float(np.count_nonzero(blobs)) / max(blobs.size, 1)
    tr = (d[0] * fs, d[1] * fs)
    moves = math.hypot(*tr) >= GLOBAL_MIN_SHIFT
    if rm > CUT_RESIDUAL and hd > 0.5 * CUT_HIST:
        return Decision("reset", measures={**m, "cut": True})
    if mode == "global" or (mode == "adaptive" and go <= GLOBAL_FRACTION and moves):
        return Decision("global", tr, m)
    return Decision("dense", tr, m)


# --- the stage ----------------------------------------------------------------------------------------
class _Buffers:
    """Device memory for one frame format and flow size: allocated once, reused every frame."""

    def __init__(self, context: Context, fmt: FrameFormat, flow_shape: tuple[int, int], linear_input: bool):
        self.fmt, self.flow_shape = fmt, flow_shape
        n, fh, fw = fmt.pixels, *flow_shape
        self.cur = context.buffer(fmt.nbytes)
        self.dst = context.buffer(fmt.nbytes)
        self.hist = [context.buffer(8 * n), context.buffer(8 * n)]      # RGBA half, linear light
        self.conf = context.buffer(n)
        self.gate = context.buffer(n)                                    # where="render": 1 = history allowed
        self.flow = [context.buffer(8 * fh * fw), context.buffer(8 * fh * fw)]  # backward, ping-pong
        self.flow_f = context.buffer(8 * fh * fw)                          # forward (fb check)
        self.params = context.buffer(4 * N_PARAMS)
        table = decode_table(fmt, linear_input)
        self.decode = cl.Buffer(context.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=table)
        self.host_cur = np.empty(fmt.nbytes // fmt.dtype.itemsize, fmt.dtype)
        self.host_dst = np.empty_like(self.host_cur)
        self.host_conf = np.empty((fmt.height, fmt.width), np.uint8)


class TemporalStage:
    """Temporal reprojection blending after the spatial filter: `stage(frame_in, frame_filtered, index)`.

    frame_in is the raw input frame N (motion and cut detection run on it), frame_filtered the
    spatially antialiased frame N; returns the blended frame N (same shape and dtype). `stats`
    gets one dict per frame: index, model, flow_ms, blend_ms, history_weight_mean and measures.
    """

    def __init__(self, device: str | int | None = None, *, strength_k: float = DEFAULT_STRENGTH,
                 mode: str = "adaptive", bgr: bool = True, show: str | None = None,
                 context: Context | None = None, k: float = DEFAULT_K, gamma: float = GAMMA,
                 fb_check: bool = True, linear_input: bool = False, preset: str = "fast",
                 where: str = "everywhere", regions_from=None,
                 motion: Callable[[int], np.ndarray | None] | None = None, auto_exposure: bool = True):
        """where="render": history only on moving pixels of render regions (WHERE); the regions are the
        `regions` argument of each call, or else `regions_from.last_regions` (a Filter(keep_regions=True)
        whose frame was collected just before the call).
        `motion`: known motion instead of DIS on dense frames: motion(index) gives frame `index`'s (H, W, 2)
        offsets to the previous frame in full-size pixels (previous position = pixel + offset: a renderer's
        motion vectors; tss_check's exact-motion oracle), or None for DIS; a known field gets no
        forward-backward check. `auto_exposure`: linear-light float frames are blended at the power of two of
        exposure that puts their key near 1 (spatial/exposure.py), held over the shot, as the spatial filter sees
        them; False: at the exposure they come in (TSSThenBlend hands its blend frames at TSS's scale)."""
        if mode not in MODES:
            raise ValueError(f"mode: expected one of {', '.join(MODES)}, got {mode!r}")
        if show not in SHOWS:
            raise ValueError(f"show: expected None or 'history', got {show!r}")
        if not 0.0 <= float(strength_k) < 1.0:
            raise ValueError(f"strength_k: expected a history weight in [0, 1), got {strength_k!r}")
        if not float(k) >= 0.0 or not float(gamma) > 0.0:
            raise ValueError(f"k, gamma: expected k >= 0 and gamma > 0, got {k!r}, {gamma!r}")
        if preset not in ("ultrafast", "fast"):
            raise ValueError(f"preset: expected 'ultrafast' or 'fast', got {preset!r}")
        if where not in WHERE:
            raise ValueError(f"where: expected one of {', '.join(WHERE)}, got {where!r}")
        self.where, self.regions_from, self.motion = where, regions_from, motion
        self.strength, self.k, self.gamma = float(strength_k), float(k), float(gamma)
        self.mode, self.bgr, self.show = mode, bool(bgr), show
        self.fb_check, self.linear_input = bool(fb_check), bool(linear_input)
        self.exposure = HeldExposure() if auto_exposure else None
        self.stats: list[dict] = []
        self._off = mode == "off" or self.strength == 0.0
        self.context = None if self._off else (context or default_context(device))
        self._dis = None
        self._dis_preset = (cv2.DISOPTICAL_FLOW_PRESET_FAST if preset == "fast"
                            else cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST)
        self._lock = threading.Lock()
        self._buffers: _Buffers | None = None
        if not self._off:
            self.queue = cl.CommandQueue(self.context.ctx, self.context.device)
            self._luts = cl.Buffer(self.context.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                                   hostbuf=device_luts())
        self.reset()

    @property
    def device_name(self) -> str:
        return self.context.name if self.context is not None else "none (temporal stage off)"

    def set_linear_input(self, linear: bool) -> bool:
        """The colour space of the frames from now on (linear light, e.g. EXR, or display-encoded); True when that
        changed it: the history starts again."""
        if bool(linear) == self.linear_input:
            return False
        if self._buffers is not None:
            self.queue.finish()
        self.linear_input, self._buffers = bool(linear), None   # decode table and kernel rebuilt (_prepare)
        self.reset()
        return True

    def reset(self) -> None:
        """Forget the history: the next frame is passed through and starts a new one."""
        self._prev: Pyramid | None = None
        self._prev_index: int | None = None
        self._prev_raw: np.ndarray | None = None   # where="render": the previous raw input
        self._prev_model = PREV_NONE
        self._prev_affine = IDENTITY
        self._prev_flow_scale = 1
        self._slot = 0          # which history/flow buffer holds the previous frame's
        self._last_weight = 0.0

    # -- set-up, once per frame format ---------------------------------------------------------------
    def _prepare(self, fmt: FrameFormat, pyr: Pyramid) -> _Buffers:
        shape = pyr.flow.shape[:2]
        if self._buffers is not None and self._buffers.fmt == fmt and self._buffers.flow_shape == shape:
            return self._buffers
        self.queue.finish()
        self._buffers = _Buffers(self.context, fmt, shape, self.linear_input)
        self._kernel = self.context.kernel("temporal", "temporal_blend", kernel_defines(fmt, self.linear_input))
        self.reset()
        return self._buffers

    def _flow(self, a: np.ndarray, b: np.ndarray, start: tuple[float, float]) -> np.ndarray:
        """DIS optical flow: flow[y, x] such that a(x) ~ b(x + flow), in a's pixels, started from the
        global translation `start` (a flow of a's size passed in is DIS's initial flow): without it
        DIS's coarse levels lock periodic textures onto the wrong period."""
        init = np.empty(a.shape[:2] + (2,), np.float32)
        init[...] = start
        if dis_refuses(a.shape):   # the global translation is all there is to go on
            return init
        if self._dis is None:
            self._dis = cv2.DISOpticalFlow_create(self._dis_preset)
        return self._dis.calc(a, b, init)

    # -- per frame -------------------------------------------------------------------------------------
    def __call__(self, frame_in: np.ndarray, frame_filtered: np.ndarray, index: int,
                 regions: np.ndarray | None = None,
                 measured: tuple[Pyramid, Decision | None] | None = None) -> np.ndarray:
        """`regions`: the spatial filter's render-region flag per tile of frame_in (Filter(keep_regions=True),
        PendingFrame.regions); read with where="render" only, where None means no render region.
        `measured`: frame_in's grey pyramid, and the model choice for this frame after the previous one (or
        None), as another stage measured them (TSSThenBlend): used instead of measuring again."""
        if self._off:
            self.stats.append({"index": int(index), "model": "off", "flow_ms": 0.0, "blend_ms": 0.0,
                               "history_weight_mean": 0.0})
            return frame_filtered
        what = f"frame {index}"
        fmt = frame_format(frame_filtered, self.bgr, what=f"{what} (filtered)")
        fin = frame_format(frame_in, self.bgr, what=f"{what} (input)")
        if (fin.height, fin.width) != (fmt.height, fmt.width):
            raise ValueError(f"{what}: expected the input and filtered frames to be the same size, "
                             f"got {fin.width}x{fin.height} and {fmt.width}x{fmt.height}")
        if regions is None and self.regions_from is not None:
            regions = self.regions_from.last_regions
        scale = 1.0
        with self._lock:
            fi, ff = frame_in, frame_filtered
            if self.exposure is not None:
                scale, changed = self.exposure.scale_for(frame_in, self.linear_input)
                if changed:
                    self.reset()   # the history is another exposure's
            if scale != 1.0:   # copies in float32 (half would overflow): the caller's frames stay as they are
                fi = exposed(np.asarray(frame_in, np.float32), scale)
                ff = exposed(np.asarray(frame_filtered, np.float32), scale)
                fmt = frame_format(ff, self.bgr, what=f"{what} (filtered)")
            # the kernel's 3x3 clamp of the current frame read a NaN or inf as its neighbours' bound and wrote NaN
            # beside it on the pixels the render gate blends (README "Non-finite samples": they never spread):
            # replaced as the spatial filter replaces them, put back below by restore_out_of_range
            fi, ff = _finite(fi), _finite(ff)
            out = self._step(fi, ff, int(index), fmt, regions, measured)
        if self.show is not None:
            return out
        if scale != 1.0:
            out = exposed(out, 1.0 / scale).astype(np.asarray(frame_filtered).dtype)
        # NaN, inf and samples beyond ±1e15 pass through as the spatial filter passes them (spatial/nonfinite.py)
        return restore_out_of_range(frame_in, out)

    def _step(self, frame_in, frame_filtered, index: int, fmt: FrameFormat, regions, measured) -> np.ndarray:
        t0 = time.perf_counter()
        grey = grey8(frame_in, self.bgr, self.linear_input) if measured is None else measured[0].grey
        fresh = self._prev is None or self._prev_index is None or index != self._prev_index + 1
        if (not fresh and self._buffers is not None and self._buffers.fmt == fmt
                and np.array_equal(grey, self._prev.grey)):
            return self._repeat(frame_filtered, index, t0)
        pyr = Pyramid.of(frame_in, self.bgr, grey) if measured is None else measured[0]
        bufs = self._prepare(fmt, pyr)
        fresh = fresh or self._prev is None   # _prepare resets on a new format
        if fresh:
            dec = Decision("reset", measures={"cut": False})
        elif measured is not None and measured[1] is not None:
            dec = measured[1]
        else:
            dec = choose_model(self._prev, pyr, self.mode)
            pyr.drop_gradients()   # kept for TSS's refiner (Pyramid.gradients), which this stage has not
        gate, chosen = None, dec.model
        if self.where == "render":
            gate = (moving_in_regions(frame_in, self._prev_raw, regions, frame_filtered)
                    if dec.model != "reset" and regions is not None else None)
            dec.measures["gate_share"] = 0.0 if gate is None else float(np.count_nonzero(gate)) / gate.size
            if gate is None or not gate.any():   # no history anywhere: the current frame starts it anew
                dec = Decision("reset", dec.translation, dec.measures)
            prev_raw, self._prev_raw = self._prev_raw, np.array(frame_in, copy=True)
        flow_b = flow_f = None
        known = self.motion(index) if self.motion is not None and dec.model == "dense" else None
        if known is not None:
            fh, fw = pyr.flow.shape[:2]
            flow_b = (cv2.resize(known, (fw, fh), interpolation=cv2.INTER_AREA) / np.float32(pyr.flow_scale)
                      if pyr.flow_scale != 1 else np.array(known, np.float32))
        elif dec.model == "dense":
            d = (dec.translation[0] / pyr.flow_scale, dec.translation[1] / pyr.flow_scale)
            flow_b = self._flow(pyr.flow, self._prev.flow, d)                # current -> previous
            if self.fb_check:
                flow_f = self._flow(self._prev.flow, pyr.flow, (-d[0], -d[1]))  # previous -> current
            # Where the input did not change at all (3x3 neighbourhood bit-identical) nothing moved
            # there: DIS spreads a mover's motion over the still background around it, which warps
            # the history of still edges (measured on the mover scene); zero motion there.
            still = cv2.erode((cv2.absdiff(pyr.flow, self._prev.flow) == 0).astype(np.uint8),
                              np.ones((3, 3), np.uint8)).astype(bool)
            flow_b[still] = 0.0
            if flow_f is not None:
                flow_f[still] = 0.0
        if gate is not None and dec.model != "reset":   # nothing near a blob the motion does not explain
            gate &= 1 - unexplained_blobs(frame_in, prev_raw, flow_b, pyr.flow_scale, dec.translation)
            dec.measures["gate_share"] = float(np.count_nonzero(gate)) / gate.size
        t1 = time.perf_counter()

        cur_mode = {"reset": CUR_RESET, "dense": CUR_DENSE}.get(dec.model, CUR_AFFINE)
        affine = (IDENTITY if dec.model != "global" else
                  (1.0, 0.0, dec.translation[0], 0.0, 1.0, dec.translation[1]))
        params = make_params(affine, self._prev_affine, pyr.flow_scale, self._prev_flow_scale,
                             self.strength, self.k, self.gamma, self.fb_check and flow_f is not None)
        prev_slot, new_slot = self._slot, 1 - self._slot
        np.copyto(bufs.host_cur.reshape(frame_filtered.shape), frame_filtered, casting="unsafe")
        q = self.queue
        cl.enqueue_copy(q, bufs.cur, bufs.host_cur, is_blocking=False)
        cl.enqueue_copy(q, bufs.params, params, is_blocking=False)
        if flow_b is not None:
            cl.enqueue_copy(q, bufs.flow[new_slot], flow_b, is_blocking=False)
            if flow_f is not None:
                cl.enqueue_copy(q, bufs.flow_f, flow_f, is_blocking=False)
        if gate is not None:
            cl.enqueue_copy(q, bufs.gate, gate, is_blocking=False)
        fh, fw = bufs.flow_shape
        self._kernel(q, (-(-fmt.width // SEGMENT), fmt.height), None, bufs.cur, bufs.hist[prev_slot],
                     bufs.hist[new_slot], bufs.dst, bufs.conf, bufs.flow[new_slot], bufs.flow_f,
                     bufs.flow[prev_slot], bufs.params, self._luts, bufs.decode, np.int32(fmt.width),
                     np.int32(fmt.height), np.int32(fw), np.int32(fh), np.int32(fw), np.int32(fh),
                     np.int32(cur_mode), np.int32(self._prev_model if cur_mode != CUR_RESET else PREV_NONE),
                     bufs.gate, np.int32(gate is not None))
        if cur_mode == CUR_RESET:
            out = frame_filtered
            cl.enqueue_copy(q, bufs.host_conf, bufs.conf, is_blocking=True) if self.show else q.finish()
        else:
            same = frame_filtered.dtype == fmt.dtype   # download straight into the frame returned
            out = np.empty(frame_filtered.shape, fmt.dtype) if same else bufs.host_dst
            cl.enqueue_copy(q, out, bufs.dst, is_blocking=False)
            cl.enqueue_copy(q, bufs.host_conf, bufs.conf, is_blocking=True)
            out = out if same else out.reshape(frame_filtered.shape).astype(frame_filtered.dtype)
        t2 = time.perf_counter()

        weight = 0.0 if cur_mode == CUR_RESET else cv2.mean(bufs.host_conf)[0] / 255.0
        self._last_weight = weight
        self._prev, self._prev_index, self._slot = pyr, index, new_slot
        self._prev_model = {"reset": PREV_NONE, "dense": PREV_DENSE}.get(dec.model, PREV_AFFINE)
        self._prev_affine, self._prev_flow_scale = affine, pyr.flow_scale
        self.stats.append({"index": index, "model": chosen, "flow_ms": (t1 - t0) * 1e3,
                           "blend_ms": (t2 - t1) * 1e3, "history_weight_mean": weight,
                           "translation": dec.translation, "flow_scale": pyr.flow_scale,
                           **dec.measures})
        if self.show == "history":
            return history_view(bufs.host_conf, out, self.strength, self.bgr)
        return out

    def _repeat(self, frame_filtered: np.ndarray, index: int, t0: float) -> np.ndarray:
        """A frame whose grey levels equal the previous input's (a still shot, a repeated frame):
        nothing moved and nothing new can shimmer, so the previous output (still in the device's
        output buffer) is returned again; no flow, no kernel, the history is kept as it is."""
        bufs = self._buffers
        same = frame_filtered.dtype == bufs.fmt.dtype
        out = np.empty(frame_filtered.shape, bufs.fmt.dtype) if same else bufs.host_dst
        cl.enqueue_copy(self.queue, out, bufs.dst, is_blocking=True)
        out = out if same else out.reshape(frame_filtered.shape).astype(frame_filtered.dtype)
        t1 = time.perf_counter()
        self._prev_index = index
        self._prev_model, self._prev_affine = PREV_AFFINE, IDENTITY   # v_p = 0 for the next frame
        self.stats.append({"index": index, "model": "static", "flow_ms": (t1 - t0) * 1e3,
                           "blend_ms": 0.0, "history_weight_mean": self._last_weight,
                           "translation": (0.0, 0.0), "flow_scale": self._prev.flow_scale,
                           "repeat": True})
        if self.show == "history":
            return history_view(bufs.host_conf, out, self.strength, self.bgr)
        return out

    def finish(self) -> None:
        if not self._off:
            self.queue.finish()

    def close(self) -> None:
        """Wait for work in flight and free the device buffers."""
        try:
            self.finish()
        finally:
            self._buffers = None
            self.reset()

    def __enter__(self) -> "TemporalStage":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


SEGMENT = 64  # pixels of a row per work item (kernels/common.cl)


@functools.lru_cache(maxsize=4)
def _pixel_grid(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """x and y of every pixel centre, (h, w) float32 each (kept: building them costs more than the warp)."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    xs.flags.writeable = ys.flags.writeable = False
    return xs, ys


def _finite(frame: np.ndarray) -> np.ndarray:
    """`frame` itself, or where a float frame holds non-finite or out-of-range samples a copy with each replaced by
    the nearest finite sample of its channel along the row (spatial/nonfinite.py replace_non_finite)."""
    f = np.asarray(frame)
    if f.dtype.kind != "f":
        return frame
    with np.errstate(invalid="ignore"):
        if (np.abs(f) <= SAMPLE_LIMIT).all():
            return frame
    f = f.copy()
    replace_non_finite(f)
    return f


def _one_level(dtype: np.dtype) -> float:
    """One 8-bit level in a frame type's units."""
    return {"f": 1.0 / 255.0}.get(dtype.kind, 257.0 if dtype == np.uint16 else 1.0)


def _largest_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b| per pixel, the largest over the colour channels (alpha left out)."""
    d = cv2.absdiff(a, b)
    if d.ndim == 2:
        return d
    planes = cv2.split(d)[:3]
    out = planes[0]
    for p in planes[1:]:
        out = cv2.max(out, p)
    return out


def moving_in_regions(cur: np.ndarray, prev: np.ndarray | None, regions: np.ndarray | None,
                      filtered: np.ndarray | None = None) -> np.ndarray | None:
    """where="render"'s gate, (h, w) uint8: 1 on pixels of render-region tiles (`regions`: one flag per
    FALLBACK_TILE^2 tile, spatial/fallback.py) where some colour channel of the raw input `cur` differs from
    `prev` by MOVED_LEVELS 8-bit levels or more, at the pixel or one of its 8 neighbours, and (`filtered`
    given) `filtered` differs from `cur` by CHANGED_LEVELS or more in some colour channel. None without a
    previous frame of the same shape and type or without regions."""
    if prev is None or regions is None or prev.shape != cur.shape or prev.dtype != cur.dtype:
        return None
    h, w = cur.shape[:2]
    if not np.any(regions):   # no render region: nothing to gate in (most frames that are not renders)
        return np.zeros((h, w), np.uint8)
    unit = _one_level(cur.dtype)
    moved = cv2.dilate((_largest_difference(cur, prev) >= MOVED_LEVELS * unit).view(np.uint8),
                       np.ones((3, 3), np.uint8))
    if filtered is not None:
        moved &= (_largest_difference(np.asarray(filtered, cur.dtype), cur) >= CHANGED_LEVELS * unit).view(np.uint8)
    th, tw = np.shape(regions)
    inside = cv2.resize((np.asarray(regions) > 0).view(np.uint8), (tw * FALLBACK_TILE, th * FALLBACK_TILE),
                        interpolation=cv2.INTER_NEAREST)[:h, :w]
    return moved & inside


def unexplained_blobs(cur: np.ndarray, prev: np.ndarray, flow_b: np.ndarray | None, flow_scale: int,
                      translation: tuple[float, float]) -> np.ndarray:
    """1 on and around blobs the motion does not explain: where the raw input differs by MOVED_LEVELS or more
    from the previous raw input carried along the motion (bilinear; flow_b at 1/flow_scale of the frame, else
    the translation), what survives a 3x3 erosion (aliasing leaves thin lines along moving edges, which do not;
    a mover the flow missed, or the background it uncovers, does), grown by BLOB_MARGIN pixels."""
    h, w = cur.shape[:2]
    if cur.dtype == np.float16 or prev.dtype == np.float16:
        # OpenCV's remap and warpAffine take no half floats: a half EXR render's frames ended the run with
        # "(-215:Assertion failed) ifunc != 0 in function 'remap'" at its second frame (the default method)
        cur, prev = np.asarray(cur, np.float32), np.asarray(prev, np.float32)
    if flow_b is not None:
        xs, ys = _pixel_grid(h, w)
        f = cv2.resize(flow_b, (w, h), interpolation=cv2.INTER_LINEAR) * np.float32(flow_scale)
        f[..., 0] += xs
        f[..., 1] += ys
        warped = cv2.remap(prev, f, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    else:
        m = np.float32([[1, 0, translation[0]], [0, 1, translation[1]]])
        warped = cv2.warpAffine(prev, m, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                borderMode=cv2.BORDER_REPLICATE)
    off = cv2.erode((_largest_difference(cur, warped) >= MOVED_LEVELS * _one_level(cur.dtype)).view(np.uint8),
                    np.ones((3, 3), np.uint8))
    side = 2 * BLOB_MARGIN + 1
    return cv2.dilate(off, np.ones((side, side), np.uint8))


def make_params(affine, prev_affine, flow_scale: float, prev_flow_scale: float, strength: float,
                k: float, gamma: float, fb_on: bool) -> np.ndarray:
    """The kernel's `params` array (layout in kernels/temporal.cl)."""
    p = np.zeros(N_PARAMS, np.float32)
    p[0:6], p[6:12] = affine, prev_affine
    p[12], p[13] = flow_scale, prev_flow_scale
    p[14], p[15], p[16], p[17], p[18], p[19] = strength, k, gamma, FB_ABS, FB_REL, float(fb_on)
    return p


def history_view(conf: np.ndarray, out: np.ndarray, strength: float, bgr: bool) -> np.ndarray:
    """Debug view: green = history used (weight / strength), red = history rejected, over the
    frame's grey at 40 %; same shape and dtype as `out`."""
    pmax = _PMAX.get(np.dtype(out.dtype), 1.0)
    used = np.clip(conf.astype(np.float32) / (255.0 * max(strength, 1e-6)), 0, 1)
    g = grey8(out, bgr).astype(np.float32) / 255.0 * 0.4
    if out.ndim == 2 or out.shape[2] == 1:
        vis = used.reshape(out.shape)
    else:
        r, gr = g + 0.6 * (1 - used), g + 0.6 * used
        chans = [g, gr, r] if bgr else [r, gr, g]
        if out.shape[2] == 4:
            chans.append(np.ones_like(g))
        vis = np.stack(chans, -1)
    vis = np.clip(vis, 0, 1) * pmax
    if np.issubdtype(out.dtype, np.integer):
        vis = vis + 0.5
    return vis.astype(out.dtype)


# --- numpy reference ----------------------------------------------------------------------------------
def _catmull_rom(t: np.ndarray) -> list[np.ndarray]:
    """The four Catmull-Rom tap weights, as kernels/temporal.cl's catmull_rom (float32)."""
    f32 = np.float32
    t = t.astype(f32)
    return [t * (f32(-0.5) + t * (f32(1.0) - f32(0.5) * t)), f32(1.0) + t * t * (f32(-2.5) + f32(1.5) * t),
            t * (f32(0.5) + t * (f32(2.0) - f32(1.5) * t)), t * t * (f32(-0.5) + f32(0.5) * t)]


def decode_table(fmt: FrameFormat, linear_input: bool = False) -> np.ndarray:
    """The kernel's decode table for integer samples: entry v = the linear value the tables give for
    v / PIXEL_MAX (common.cl's lut_read, the same float32 arithmetic), so one load replaces the
    interpolated read with the same bits; a format with a transfer (HDR video) reads the transfer's decode table
    (device/transfer.py with_transfer_tables: light relative to reference white). Float frames and linear input read
    no table (one entry)."""
    if linear_input or not np.issubdtype(fmt.dtype, np.integer):
        return np.zeros(1, np.float32)
    pmax = np.float32(_PMAX[fmt.dtype])
    codes = np.arange(int(pmax) + 1, dtype=np.float32) * (np.float32(1.0) / pmax)
    # common.cl's lut_read in float32 throughout (colour.lut_read widens the fraction to float64)
    lut = with_transfer_tables(device_luts(), fmt.transfer)
    t = codes * np.float32(LUT_SIZE)
    i = np.minimum(t.astype(np.int32), LUT_SIZE - 1)
    f = t - i.astype(np.float32)
    return np.ascontiguousarray(lut[i] + f * (lut[i + 1] - lut[i]), dtype=np.float32)


def kernel_defines(fmt: FrameFormat, linear_input: bool = False) -> dict:
    """kernels/temporal.cl's build defines for a frame format (the stage's and the tests')."""
    return defines_for(fmt, LINEAR_INPUT=int(linear_input), FLAT_NEAR=1, FLAT_LEVELS=flat_levels(fmt.dtype))


def flat_levels(dtype) -> int | float:
    """How far (stored units) a 3x3 neighbour's sample may be from the centre's for the (near-)flat rule:
    2 levels of 8 bits (codec noise, dithering: the blend could move such a pixel by ~2 levels at most)."""
    dt = np.dtype(dtype)
    return 2 * 257 if dt == np.uint16 else (2 if dt == np.uint8 else 2.0 / 255.0)


def flat_3x3(raw: np.ndarray, levels: float = 0.0) -> np.ndarray:
    """(H, W) bool: all 9 samples of each pixel's 3x3 neighbourhood (edges replicated) within `levels`
    of the centre's in the frame's own type (0: bit-identical) -- where kernels/temporal.cl skips the
    blend (the flat rule, with levels = flat_levels(dtype))."""
    h, w = raw.shape[:2]
    if levels > 0:
        b = np.ascontiguousarray(raw).reshape(h, w, -1).astype(np.float64)
    else:
        b = np.ascontiguousarray(raw).reshape(h, w, -1).view(np.uint8)
    pad = np.pad(b, ((1, 1), (1, 1), (0, 0)), mode="edge")
    flat = np.ones((h, w), bool)
    for dy in range(3):
        for dx in range(3):
            n = pad[dy:dy + h, dx:dx + w]
            flat &= (np.abs(n - b) <= levels).all(-1) if levels > 0 else (n == b).all(-1)
    return flat


def sample_field(fld: np.ndarray, scale: int, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Bilinear read of a (fh, fw, 2) field stored at 1/scale of the frame, at full-size positions."""
    f32 = np.float32
    fh, fw = fld.shape[:2]
    fx = np.clip((xs + f32(0.5)) / f32(scale) - f32(0.5), 0, fw - 1).astype(f32)
    fy = np.clip((ys + f32(0.5)) / f32(scale) - f32(0.5), 0, fh - 1).astype(f32)
    x0, y0 = fx.astype(np.int64), fy.astype(np.int64)
    x1, y1 = np.minimum(x0 + 1, fw - 1), np.minimum(y0 + 1, fh - 1)
    ax, ay = (fx - x0)[..., None], (fy - y0)[..., None]
    top = fld[y0, x0] + (fld[y0, x1] - fld[y0, x0]) * ax
    bot = fld[y1, x0] + (fld[y1, x1] - fld[y1, x0]) * ax
    return (top + (bot - top) * ay).astype(f32)


def temporal_reference(cur: np.ndarray, hist: np.ndarray, params: np.ndarray, cur_mode: int,
                       prev_mode: int, flow_b: np.ndarray | None = None, flow_f: np.ndarray | None = None,
                       flow_prev: np.ndarray | None = None, bgr: bool = False,
                       linear_input: bool = False,
                       gate: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What kernels/temporal.cl computes, in float32 numpy (slow, plain): returns (out frame,
    new history (H, W, 4) float16, weight (H, W) uint8). `hist` is (H, W, 4) float16 linear RGBA;
    `gate` (H, W), when given: no history where it is 0 (where="render")."""
    f32 = np.float32
    fmt = frame_format(cur, bgr)
    h, w = fmt.height, fmt.width
    pmax = f32(_PMAX[fmt.dtype])
    luts = device_luts()
    raw = np.asarray(cur).reshape(h, w, fmt.channels)
    a = raw.astype(f32) * (f32(1.0) / pmax)
    if fmt.channels == 1:
        c = np.concatenate([np.repeat(a, 3, -1), np.ones((h, w, 1), f32)], -1)
    else:
        rgb = a[..., 2::-1] if fmt.bgr else a[..., :3]
        alpha = a[..., 3:4] if fmt.channels == 4 else np.ones((h, w, 1), f32)
        c = np.concatenate([rgb, alpha], -1)
    lin = c.copy()
    if not linear_input:
        lin[..., :3] = lut_read(luts, c[..., :3])
    p = params.astype(f32)
    ys, xs = np.mgrid[0:h, 0:w].astype(f32)

    def sample_flow(f, s, px, py):   # the field is stored in pixels of its own scale
        return (sample_field(f, s, px, py) * f32(s)).astype(f32)

    def affine(m, px, py):
        return np.stack([m[0] * px + m[1] * py + m[2] - px, m[3] * px + m[4] * py + m[5] - py], -1)

    def norm(v):
        return np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1])

    wgt = np.zeros((h, w), f32)
    out_lin = lin.copy()
    if cur_mode != CUR_RESET:
        vc = sample_flow(flow_b, p[12], xs, ys) if cur_mode == CUR_DENSE else affine(p[0:6], xs, ys)
        qx, qy = xs + vc[..., 0], ys + vc[..., 1]
        inside = (qx >= -0.5) & (qx <= w - 0.5) & (qy >= -0.5) & (qy <= h - 0.5)
        fbw = np.ones((h, w), f32)
        if cur_mode == CUR_DENSE and p[19] > 0.5:
            g = sample_flow(flow_f, p[12], qx, qy)
            e, tol = norm(vc + g), p[17] + p[18] * norm(vc)
            fbw = np.clip(f32(2.0) - e / tol, 0, 1)
        if prev_mode == PREV_DENSE:
            vp = sample_flow(flow_prev, p[13], qx, qy)
        elif prev_mode == PREV_AFFINE:
            vp = affine(p[6:12], qx, qy)
        else:
            vp = vc
        # seed 002: w = 0.5 max(0, 1 - K sqrt(|v_c - v_p|)), on vectors, in pixel units
        vw = f32(1.0) - p[15] * np.sqrt(norm(vc - vp))
        wgt = np.where(inside, p[14] * np.maximum(vw, 0) * fbw, 0).astype(f32)
        # history at q, Catmull-Rom over 4x4 taps clamped to the frame
        hf = hist.astype(f32)
        fx, fy = np.clip(qx, 0, w - 1).astype(f32), np.clip(qy, 0, h - 1).astype(f32)
        xi, yi = fx.astype(np.int64), fy.astype(np.int64)
        wx, wy = _catmull_rom(fx - xi), _catmull_rom(fy - yi)
        hs = np.zeros((h, w, 4), f32)
        for j in range(4):
            yy = np.clip(yi - 1 + j, 0, h - 1)
            row = np.zeros((h, w, 4), f32)
            for kk in range(4):
                row = row + hf[yy, np.clip(xi - 1 + kk, 0, w - 1)] * wx[kk][..., None]
            hs = hs + row * wy[j][..., None]
        # variance clip against the current 3x3 neighbourhood (edges replicated)
        pad = np.pad(lin, ((1, 1), (1, 1), (0, 0)), mode="edge")
        taps = [pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dx in (-1, 0, 1) for dy in (-1, 0, 1)]
        cols = [taps[3 * j:3 * j + 3] for j in range(3)]   # the kernel's column sums, left to right
        s = sum(((a + m) + b for a, m, b in cols[1:]), (cols[0][0] + cols[0][1]) + cols[0][2])
        s2 = sum(((a * a + m * m) + b * b for a, m, b in cols[1:]),
                 (cols[0][0] * cols[0][0] + cols[0][1] * cols[0][1]) + cols[0][2] * cols[0][2])
        mn, mx = np.minimum.reduce(taps), np.maximum.reduce(taps)
        mu = s * f32(1.0 / 9.0)
        sd = np.sqrt(np.maximum(s2 * f32(1.0 / 9.0) - mu * mu, 0)).astype(f32)
        lo, hi = np.maximum(mn, mu - p[16] * sd), np.minimum(mx, mu + p[16] * sd)
        ctr, ext = (lo + hi) * f32(0.5), (hi - lo) * f32(0.5) + f32(EXT_FLOOR)
        d = hs - ctr
        t = np.max(np.abs(d[..., :3]) / ext[..., :3], axis=-1)
        clipped = np.where((t > 1)[..., None], ctr + d / np.maximum(t, 1)[..., None], hs)
        keep = (f32(REJECT) - t) * (f32(1.0) / (f32(REJECT) - f32(1.0)))
        wgt = np.where(wgt > 0, wgt * np.clip(keep, 0, 1), wgt).astype(f32)
        # the flat rule (kernels/temporal.cl): a 3x3 neighbourhood bit-identical in the frame's own
        # type bounds the clip box to c +- EXT_FLOOR, so the blend is skipped there: w = 0 gives
        # out = c untouched and history = c in linear light, as on a reset
        wgt = np.where(flat_3x3(raw.astype(fmt.dtype), flat_levels(fmt.dtype)), f32(0), wgt).astype(f32)
        if gate is not None:
            wgt = np.where(np.asarray(gate) == 0, f32(0), wgt).astype(f32)
        blended = lin + (clipped - lin) * wgt[..., None]
        blended[..., 3] = lin[..., 3]
        out_lin = np.where((wgt > 0)[..., None], blended, lin).astype(f32)
    hist_out = out_lin.astype(np.float16)
    conf = (wgt * f32(255.0) + f32(0.5)).astype(np.uint8)
    enc = out_lin.copy()
    if not linear_input:
        enc[..., :3] = lut_read(luts[2 * (LUT_SIZE + 1):], out_lin[..., :3])
    if np.issubdtype(fmt.dtype, np.integer):
        stored = np.floor(np.clip(enc * pmax + f32(0.5), 0, pmax)).astype(fmt.dtype)
    else:
        stored = enc.astype(f32)
    if fmt.channels == 1:
        px = stored[..., :1]
    else:
        px = np.concatenate([stored[..., 2::-1] if fmt.bgr else stored[..., :3],
                             stored[..., 3:4]], -1)[..., :fmt.channels]
    out = np.where((wgt > 0)[..., None], px, raw.astype(fmt.dtype)).reshape(np.shape(cur))
    return out.astype(np.asarray(cur).dtype), hist_out, conf
