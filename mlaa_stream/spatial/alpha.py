"""Alpha as coverage: the alpha of a frame antialiased together with its colour.

A renderer that writes an element over transparency (RGBA PNG, EXR) at one sample per pixel writes a binary alpha:
the silhouette against transparency is as jagged as any edge. Filtering the colour alone blends the element's rim
towards the colour stored in the transparent pixels (black, mostly) while the alpha stays 1 there: the silhouette
stays jagged and a dark fringe appears once the frame is composited (docs/spatial_tuning.md "Alpha").

Here (AlphaSplit):
- the colour is filtered premultiplied by alpha in the filter's mix space (linear light for sRGB frames): the
  transparent pixels hold 0, as a supersampled render's do, and a blend across the silhouette is a coverage mix;
- the alpha is filtered as a grey image of linear samples (coverage), by a filter with the colour filter's options
  (Filter.filter_alpha); where most of the tiles in which the alpha steps by more than HARD_STEP (a 1-spp render's
  coverage is 0 or 1: soft mattes and ramps are no such thing) lie in the colour's render regions, those tiles by
  one whose fallback runs everywhere (preset `rendered`), as the colour of a render is;
- the straight colour is the filtered premultiplied colour divided by the filtered alpha, clamped per channel to
  the range of the input's straight colours with alpha > 0 in the 5x5 window around the pixel (so that a rim pixel
  keeps a colour of the element, never the transparent pixels' own), and premultiplied again for premultiplied
  frames.
A pixel whose colour and alpha the filters both left comes back bit for bit; so do non-finite samples. A frame whose
alpha is one value everywhere (an opaque render) is filtered as before, alpha kept.
"""
from __future__ import annotations

import threading
from functools import lru_cache

import cv2
import numpy as np

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.spatial.nonfinite import SAMPLE_LIMIT
from mlaa_stream.device.transfer import decode_table as transfer_table
from mlaa_stream.device.transfer import encode as transfer_encode

RANGE_RADIUS = 2  # the window of input colours a rim pixel's straight colour is clamped to: 5x5
HARD_STEP = 0.125  # an alpha step (of full scale) between neighbours that marks 1-spp coverage, for render regions
ALPHA_MARGIN = 2  # tiles round the box where the alpha varies that its filter also gets (Filter.filter_alpha)
ALPHA_BOX_STEP = 8  # the box's sides in multiples of this many tiles (64 px): few buffer sizes for a moving element


def _full_scale(dtype: np.dtype) -> float:
    """The sample value of full coverage (alpha 1) and full intensity: an integer type's largest, else 1."""
    return float(np.iinfo(dtype).max) if np.dtype(dtype).kind in "ui" else 1.0


def has_coverage(frame: np.ndarray) -> bool:
    """True when `frame` has an alpha channel (a fourth one) that is not one value everywhere."""
    if frame.ndim != 3 or frame.shape[2] != 4:
        return False
    alpha = frame[..., 3]
    if alpha.dtype.kind == "f":
        alpha = alpha[np.isfinite(alpha)]
    return alpha.size > 0 and bool(alpha.min() != alpha.max())


@lru_cache(maxsize=None)
def _decode_table(top: int) -> np.ndarray:
    """sRGB decode of every integer sample 0 .. top (uint8, uint16), float32: made once."""
    table = srgb_to_linear(np.arange(top + 1) / top).astype(np.float32)
    table.setflags(write=False)
    return table


def _in_range(samples: np.ndarray) -> np.ndarray:
    """Float samples the filter takes (finite, within SAMPLE_LIMIT), compared in float32: 1e15 is inf in half."""
    return np.abs(samples.astype(np.float32, copy=False)) <= np.float32(SAMPLE_LIMIT)


def _every_channel(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the (H, W, C) `mask` holds in every channel (channel by channel: numpy's reduction over a short
    last axis is ~4x slower)."""
    out = mask[..., 0].copy()
    for c in range(1, mask.shape[2]):
        out &= mask[..., c]
    return out


def _rgb(frame: np.ndarray) -> np.ndarray:
    """The colour channels of an (H, W, 4) frame as a new contiguous array (cv2 where it takes the type: ~5x
    numpy's strided copy)."""
    if frame.dtype in (np.uint8, np.uint16, np.float32) and frame.flags.c_contiguous:
        return cv2.cvtColor(frame, cv2.COLOR_RGBA2RGB)
    return np.ascontiguousarray(frame[..., :3])


def _any_channel_differs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(H, W) bool: some channel of the (H, W, 3) arrays differs."""
    if a.dtype in (np.uint8, np.uint16):
        d = cv2.split(cv2.absdiff(a, b))
        return cv2.max(cv2.max(d[0], d[1]), d[2]) > 0
    return (a != b).any(axis=2)


def varied_tiles(plane: np.ndarray, tile: int, step: float = 0.0) -> np.ndarray:
    """Per tile x tile block of the (H, W) `plane`, whether a pixel of it lies within 2 px (the reach of the widest
    pass, the footprint table's 5 x 5 window) of two 4-neighbours differing by more than `step` of full scale:
    (tiles_y, tiles_x) bool. A block without one (step 0) is left as it is by every filter."""
    top = _full_scale(plane.dtype)
    work = plane.astype(np.float32) if plane.dtype not in (np.uint8, np.uint16, np.float32) else plane
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    # a pixel and its 4-neighbours span more than `step`: it is one end of such a pair (or between two)
    with np.errstate(invalid="ignore", over="ignore"):  # inf - inf: no step; max - -max: a step
        span = cv2.dilate(work, cross).astype(np.float32) - cv2.erode(work, cross).astype(np.float32)
        jump = span > step * top
    near = cv2.dilate(jump.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    h, w = near.shape
    ty, tx = -(-h // tile), -(-w // tile)
    padded = np.zeros((ty * tile, tx * tile), bool)
    padded[:h, :w] = near
    return padded.reshape(ty, tile, tx, tile).any(axis=(1, 3))


def varied_box(varied: np.ndarray) -> tuple[int, int, int, int] | None:
    """The tiles (ty0, ty1, tx0, tx1) of the box round the `varied` ones (varied_tiles) with ALPHA_MARGIN more each
    side, its sides grown to multiples of ALPHA_BOX_STEP tiles within the frame (a moving element's box takes few
    sizes, so its filter seldom makes new buffers); None where no tile varies."""
    rows, cols = np.flatnonzero(varied.any(axis=1)), np.flatnonzero(varied.any(axis=0))
    if rows.size == 0:
        return None

    def span(lo: int, hi: int, n: int) -> tuple[int, int]:
        lo, hi = max(lo - ALPHA_MARGIN, 0), min(hi + ALPHA_MARGIN, n)
        size = min(-(-(hi - lo) // ALPHA_BOX_STEP) * ALPHA_BOX_STEP, n)
        lo = min(lo, n - size)
        return lo, lo + size

    return (*span(int(rows[0]), int(rows[-1]) + 1, varied.shape[0]),
            *span(int(cols[0]), int(cols[-1]) + 1, varied.shape[1]))


class AlphaSplit:
    """One RGBA frame split into the premultiplied colour and the alpha that the filters see (`colour`, `alpha`),
    and merged back (`merge`). `premultiplied`: the frame's colour is premultiplied by its alpha already (EXR);
    `decode`: the filter mixes in linear light and the samples are sRGB-encoded (integer or float). Work on the host
    is per pixel only where alpha is fractional (splitting) or where a filter changed something (merging)."""

    def __init__(self, frame: np.ndarray, premultiplied: bool, decode: bool, transfer: str | None = None):
        self.frame, self.premultiplied, self.decode = frame, bool(premultiplied), bool(decode)
        self.transfer = transfer if decode else None  # HDR codes (device/transfer.py): mixed in the light they code
        self.dtype = frame.dtype
        self.integer = frame.dtype.kind in "ui"
        self.top = _full_scale(frame.dtype)
        self._lut = None
        if self.integer and self.decode:
            self._lut = _decode_table(int(self.top)) if self.transfer is None else \
                transfer_table(self.transfer, int(self.top))
        self.alpha = np.ascontiguousarray(frame[..., 3])
        # samples the filter passes through (non-finite, out of range: spatial/nonfinite.py) pass through here too
        self.finite = None if self.integer else _every_channel(_in_range(frame))
        a = np.asarray(self.alpha, np.float32) / np.float32(self.top)
        if self.finite is not None:
            a = np.clip(np.where(self.finite, a, 0.0), 0.0, 1.0).astype(np.float32)
        self.cover = a
        if self.premultiplied:
            self.colour = _rgb(frame)
            return
        # straight colour premultiplied in mix space: 0 where alpha is 0, as it is where alpha is 1
        self.colour = _rgb(frame)
        clear = self.cover <= 0
        part = (self.cover > 0) & (self.cover < 1)
        if self.finite is not None:  # samples passed through stay as they are, for the filter to pass them
            clear &= self.finite
            part &= self.finite
        self.colour[clear] = 0
        if part.any():
            self.colour[part] = self._from_mix(self._to_mix(frame[..., :3][part]) * self.cover[part][:, None])

    def _to_mix(self, stored: np.ndarray) -> np.ndarray:
        """Stored samples -> mix space, float32."""
        if self._lut is not None:
            return self._lut[stored]
        v = stored.astype(np.float32) / np.float32(self.top)
        return srgb_to_linear(v).astype(np.float32) if self.decode else v

    def _from_mix(self, mix: np.ndarray) -> np.ndarray:
        if self.transfer is not None:
            v = transfer_encode(np.asarray(mix, np.float64), self.transfer)
        else:
            v = linear_to_srgb(mix) if self.decode else mix
        if self.integer:
            return np.clip(np.rint(v * self.top), 0, self.top).astype(self.dtype)
        return np.asarray(v).astype(self.dtype)

    def _colour_range(self, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """At the pixels `rest` (flat indices), per channel, the smallest and largest straight colour (mix space)
        with alpha > 0 in the pixel's (2 RANGE_RADIUS + 1)^2 window; lo > hi where the window has none. Straight
        samples are compared as stored (the decode is monotonic), premultiplied ones divided by alpha first."""
        k = 2 * RANGE_RADIUS + 1
        kernel = np.ones((k, k), np.uint8)
        covered = self.cover > 0
        if self.finite is not None:
            covered &= self.finite
        if self.premultiplied:  # straight = premultiplied / alpha, in mix space
            with np.errstate(divide="ignore", invalid="ignore"):
                straight = (self._to_mix(self.frame[..., :3]) / self.cover[..., None]).astype(np.float32)
            covered &= np.isfinite(straight).all(axis=2)
        else:
            straight = _rgb(self.frame) if self.integer else _rgb(self.frame).astype(np.float32)
        if straight.dtype.kind == "f":
            low, high = float(np.finfo(np.float32).max), float(-np.finfo(np.float32).max)
            uncovered = ~covered
            lo_in, hi_in = straight.copy(), straight.copy()
            lo_in[uncovered], hi_in[uncovered] = low, high
        else:  # integers: the uncovered pixels to the top / to 0 by a mask of the type's top (cv2: fast)
            low, high = self.top, 0.0
            top = cv2.cvtColor(covered.astype(straight.dtype) * straight.dtype.type(self.top), cv2.COLOR_GRAY2RGB)
            lo_in, hi_in = cv2.max(straight, cv2.bitwise_not(top)), cv2.min(straight, top)
        # a border value per channel: cv2 pads the second and third channels with 0 given one number
        lo = cv2.erode(lo_in, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=(low,) * 3).reshape(-1, 3)[rest]
        hi = cv2.dilate(hi_in, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=(high,) * 3).reshape(-1, 3)[rest]
        none = cv2.dilate(covered.astype(np.uint8), kernel).reshape(-1)[rest] == 0
        if not self.premultiplied:
            lo, hi = self._to_mix(lo), self._to_mix(hi)
        lo[none], hi[none] = 1.0, 0.0
        return lo, hi

    def merge(self, colour_out: np.ndarray, alpha_out: np.ndarray) -> np.ndarray:
        """The output frame from the filtered premultiplied colour (`colour_out`, as `colour`) and the filtered
        alpha (`alpha_out`, as `alpha`)."""
        out = self.frame.copy()
        same_alpha = alpha_out == self.alpha
        moved = ~same_alpha | _any_channel_differs(colour_out, self.colour)
        if self.finite is not None:
            moved &= self.finite & _in_range(alpha_out)
        # where the alpha filter left the pixel, the colour filter's result as it is inside the element (alpha 1: the
        # colour filter alone, bit for bit) and, premultiplied, on light with no coverage (emission: alpha 0, colour
        # not 0); a pixel of nothing (alpha 0, colour 0) gains no light while its alpha stays 0
        inside = self.cover >= 1
        if self.premultiplied:
            inside |= (self.cover <= 0) & (self.frame[..., :3] != 0).any(axis=2)
        direct = moved & same_alpha & inside
        np.copyto(out[..., :3], colour_out, where=direct[..., None])
        np.copyto(out[..., 3], alpha_out, where=moved)
        rest = np.flatnonzero(moved & ~direct)
        if rest.size == 0:
            return out
        cover = np.clip(np.asarray(alpha_out.reshape(-1)[rest], np.float32) / np.float32(self.top), 0, 1)[:, None]
        lo, hi = self._colour_range(rest)
        with np.errstate(divide="ignore", invalid="ignore"):
            straight = self._to_mix(colour_out.reshape(-1, 3)[rest]) / cover
        straight = np.where(lo <= hi, np.clip(straight, lo, hi), straight)  # windows with covered pixels
        flat = out.reshape(-1, 4)
        straight = np.where(cover > 0, straight, self._to_mix(flat[rest, :3]))  # alpha 0: as it was
        flat[rest, :3] = self._from_mix(straight * cover if self.premultiplied else straight)
        return out


class MergePass:
    """AlphaSplit.merge on the device (kernels/alpha.cl; merge itself is the numpy reference): the frame, the colour
    the colour filter got and returned and the filtered alpha uploaded, the merged frame downloaded (~10x faster than
    the host's merge on a 1080p frame). `luts` and `pass_defines`: the colour filter's tables and defines (its mix
    space: DECODE, a transfer's tables). Half and double frames are merged in float32 and returned in their type."""

    def __init__(self, context, luts, pass_defines: dict):
        import pyopencl as cl

        self.context, self.luts, self.pass_defines = context, luts, dict(pass_defines)
        self.queue = cl.CommandQueue(context.ctx, context.device)   # in order: upload, merge, download
        self._buffers: dict[tuple, list] = {}   # (h, w, dtype) -> [frame, colour in, colour out, alpha, out]
        self._lock = threading.Lock()   # frames collected in two threads share the buffers

    def merge(self, split: AlphaSplit, colour_out: np.ndarray, alpha_out: np.ndarray) -> np.ndarray:
        import pyopencl as cl

        from mlaa_stream.device.formats import FrameFormat, defines_for
        from mlaa_stream.spatial.nonfinite import SAMPLE_LIMIT

        work = np.dtype(np.float32) if split.dtype.kind == "f" else split.dtype
        h, w = split.frame.shape[:2]
        fmt = FrameFormat(h, w, 4, work, transfer=split.transfer)
        defs = defines_for(fmt, **self.pass_defines, PREMULTIPLIED=int(split.premultiplied),
                           RANGE_RADIUS=RANGE_RADIUS, SAMPLE_LIMIT=float(SAMPLE_LIMIT))
        kernel = self.context.kernel("alpha", "alpha_merge", defs)
        arrays = [np.ascontiguousarray(a, work) for a in (split.frame, split.colour, colour_out, alpha_out)]
        key = (h, w, work)
        out = np.empty((h, w, 4), work)
        with self._lock:
            if key not in self._buffers:
                self._buffers = {key: [self.context.buffer(a.nbytes) for a in (*arrays, arrays[0])]}  # last: out
            bufs = self._buffers[key]
            for buf, a in zip(bufs, arrays):
                cl.enqueue_copy(self.queue, buf, a, is_blocking=False)
            kernel(self.queue, (w, h), None, *bufs[:4], self.luts, bufs[4], np.int32(w), np.int32(h))
            cl.enqueue_copy(self.queue, out, bufs[4], is_blocking=True)
        return out if work == split.dtype else out.astype(split.dtype)


def spatial_at_rims(spatial: np.ndarray, temporal: np.ndarray) -> np.ndarray:
    """After a temporal stage: the spatial output wherever its alpha, or a neighbour's, is below full coverage. The
    temporal stages resolve colour from the input frames' straight samples, which hold the transparent pixels'
    colour (black) where the element's rim was: their mean there is a dark fringe under the spatial alpha."""
    if not has_coverage(spatial):
        return temporal
    alpha = spatial[..., 3]
    rim = cv2.dilate((alpha < _full_scale(alpha.dtype)).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    out = temporal.copy()
    out[rim] = spatial[rim]
    return out
