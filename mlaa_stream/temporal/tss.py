"""Temporal supersampling (issue 16): accumulate the input's point samples along the scene's motion.

Each input pixel of frame t is a point sample of the scene at a known sub-pixel position once the
motion is known; a moving camera puts the samples of past frames at new positions inside the current
frame's pixels (the jitter a renderer's TAA adds on purpose; seed 002's T2x). The stage keeps a ring
of the last K *input* frames (linear light in 16-bit fixed point, L = floor(clamp(lin, 0, 1) 65535 + 0.5):
`ring_of`; linear-light float frames, `linear_input`, and the codes of HDR video, `transfer` (their light relative
to reference white, device/transfer.py): lin / LINEAR_RANGE; a sample over the range is marked OVER and never
averaged, and a pixel near one keeps the spatial output) with a map from the current
frame's pixels into each of them, and resolves each output pixel from the samples that land inside its
footprint:

    stage = TSSStage(bgr=True, frames=16)
    out = stage(frame_in, frame_filtered, index)     # per frame, in order; ring kept inside

The resolve's plain statement and the ring's codes: mlaa_stream.temporal.resolve (tss_reference; kernels/tss.cl
is its device twin). The motion of every ring frame: mlaa_stream.temporal.motion_ring (MotionRing). Look-ahead
(files: `TSSStage(lookahead=N)`, called with `future=` the next N raw frames, which mlaa_stream.pipeline hands
in): the frames after the current one are ring entries too, in K + N device slots; FULL_CELLS grows by
FULL_CELLS_AHEAD per frame ahead (docs/temporal.md, "Look-ahead").
"""
from __future__ import annotations

import threading
import time

import cv2
import numpy as np

from mlaa_stream.device.colour import device_luts
from mlaa_stream.device.formats import frame_format, with_transfer
from mlaa_stream.device.transfer import check_transfer, with_transfer_tables
from mlaa_stream.spatial.exposure import HeldExposure, exposed
from mlaa_stream.spatial.noise import level_of, luma256, quiet_pixels
from mlaa_stream.spatial.nonfinite import restore_out_of_range
from mlaa_stream.temporal.motion_ring import DEFAULT_FRAMES, Ahead, FrameMotion, MotionRing, RingEntry
from mlaa_stream.temporal.resolve import (EPS, FULL_CELLS, GRID, LANES, MIN_CELLS, TILE_ROWS, dead_codes,
                                          encode_table, eps_q, level_table, ring_range, tile_shifts,
                                          tss_frame_reference)
from mlaa_stream.temporal.stage import _PMAX, Decision, Pyramid, choose_model, grey8


NOISE_EVERY = 8       # frames between measurements of the input's grain level (spatial/noise.py) in a shot
FULL_CELLS_AHEAD = 1.25   # FULL_CELLS (resolve.py) plus this many per look-ahead frame (rounded): more frames fill
                          # more cells with samples of sub-pixel detail that the spatial output renders better
                          # (docs/temporal.md, "Look-ahead")
FULL_CELLS_FIELDS = 16  # FULL_CELLS where the maps are fields (moving layers): a layer's samples fill the cells along
                        # its local motion (a turning object's edge moves along one direction), so their mean is
                        # trusted less (docs/temporal.md, "Moving layers")
TSS_LOCAL = 8         # CPU work-group of tss_resolve_shift along the row (docs/temporal.md: speed)


def set_constant(name: str, text: str) -> None:
    """Sets the module constant `name` of temporal supersampling (this module, motion_ring or resolve) to `text` read
    as its type, in each of those modules that holds it (a constant imported from another is a copy): the tuning runs
    of docs/temporal.md, by command (the benches' --tss-set)."""
    import sys

    from mlaa_stream.temporal import motion_ring, resolve
    holders = [m for m in (sys.modules[__name__], motion_ring, resolve) if hasattr(m, name)]
    if not holders or not name.isupper():
        raise KeyError(f"{name!r} is no constant of mlaa_stream.temporal.tss, motion_ring or resolve")
    kind = type(getattr(holders[0], name))
    value = text.lower() in ("1", "true") if kind is bool else kind(float(text)) if kind is int else kind(text)
    for m in holders:
        setattr(m, name, value)


def shift_launch(width: int, height: int, context) -> tuple[tuple[int, int], tuple[int, int] | None]:
    """(global, local) of tss_resolve_shift and tss_ingest: one work item per LANES pixels of a row; on CPU devices
    work-groups of TSS_LOCAL work items along the row (kernels/tss.cl), elsewhere the driver's choice."""
    gx = -(-width // LANES)
    import pyopencl as cl
    if context.device.type & cl.device_type.CPU:
        return (-(-gx // TSS_LOCAL) * TSS_LOCAL, height), (TSS_LOCAL, 1)
    return (gx, height), None


def vrows_of(valid: np.ndarray, flow_scale: int, width: int) -> np.ndarray:
    """A flow-size valid mask with each column repeated flow_scale times, cut to the frame's width: the
    form tss_resolve_shift reads (a pixel's mask byte at its own column, no division)."""
    v = np.asarray(valid, np.uint8)
    if flow_scale not in (1, 2, 4, 8):
        return np.ascontiguousarray(np.repeat(v, flow_scale, 1)[:, :width])
    # each byte copied into every byte of a wider integer (its bytes all equal: no byte order), viewed as bytes:
    # ~2x faster than np.repeat along a row at 1080p
    wide = np.dtype(f"u{flow_scale}").type
    rep = v.astype(wide) * wide(int.from_bytes(b"\x01" * flow_scale, "little"))
    return np.ascontiguousarray(rep.view(np.uint8).reshape(v.shape[0], -1)[:, :width])


def kernel_defines(fmt, grid: int = GRID, eps: float = EPS, min_cells: int = MIN_CELLS,
                   full_cells: int | None = None, linear_input: bool = False) -> dict:
    """kernels/tss.cl's build defines."""
    from mlaa_stream.device.formats import defines_for
    full = FULL_CELLS if full_cells is None else int(full_cells)
    dead = dead_codes(fmt.dtype) if np.issubdtype(fmt.dtype, np.integer) else 0
    rng = ring_range(fmt.dtype, linear_input, fmt.transfer)   # fmt.transfer: defines_for adds ENCODE_WARP too
    return defines_for(fmt, GRID=int(grid), MIN_CELLS=int(min_cells), FULL_CELLS=full, EPSQ=eps_q(eps, rng),
                       LINEAR_INPUT=int(linear_input), DEAD_CODES=dead, TSS_RANGE=rng)


def cells_view(cells: np.ndarray, out: np.ndarray, grid: int, bgr: bool) -> np.ndarray:
    """Debug view (--show history): green = share of the footprint's cells filled by samples, red =
    the spatial output stands (fewer than MIN_CELLS), over the frame's grey at 40 %."""
    pmax = _PMAX.get(np.dtype(out.dtype), 1.0)
    used = np.clip(cells.astype(np.float32) / float(grid * grid), 0, 1)
    g = grey8(out, bgr).astype(np.float32) / 255.0 * 0.4
    if out.ndim == 2 or out.shape[2] == 1:
        vis = used.reshape(out.shape)
    else:
        r, gr = g + 0.6 * (used <= 0), g + 0.6 * used
        chans = [g, gr, r] if bgr else [r, gr, g]
        if out.shape[2] == 4:
            chans.append(np.ones_like(g))
        vis = np.stack(chans, -1)
    vis = np.clip(vis, 0, 1) * pmax
    if np.issubdtype(out.dtype, np.integer):
        vis = vis + 0.5
    return vis.astype(out.dtype)


class _Buffers:
    """Device memory for one frame format and flow size: the ring of K input frames, the maps."""

    def __init__(self, context, fmt, flow_shape: tuple[int, int], frames: int, dense: bool = False):
        import pyopencl as cl
        self.fmt, self.flow_shape = fmt, flow_shape
        fh, fw = flow_shape
        self.planes = 1 if fmt.channels == 1 else 3
        self.slot_bytes = 2 * self.planes * fmt.pixels       # one ring slot: 16-bit linear planes
        limit = context.device.max_mem_alloc_size
        if frames * self.slot_bytes > limit:   # else OpenCL's INVALID_BUFFER_SIZE (or an out-of-memory) at frame 0
            raise ValueError(f"frames: a ring of {frames} frames (K and the look-ahead) of {fmt.width}x{fmt.height} "
                             f"takes {frames * self.slot_bytes / 2**20:.0f} MiB in one buffer, more than the device "
                             f"allows ({limit / 2**20:.0f} MiB); keep fewer frames")
        self.ring = context.buffer(frames * self.slot_bytes)
        self.src = context.buffer(fmt.nbytes)                # the current input, before tss_ingest
        self.spatial = context.buffer(fmt.nbytes)
        self.dst = context.buffer(fmt.nbytes)
        self.cells = context.buffer(fmt.pixels)
        self.info = context.buffer(4 * 4 * frames)
        self.shift = context.buffer(4 * 2 * frames)
        # tss_resolve_shift's tables (one, or one per tile of projective maps: grown when needed)
        self.tables, self.table_vslots = context.buffer(4 * 4 * frames), context.buffer(4 * frames)
        # dense maps only with dense_samples (66 MB at 1080p, K = 16): the default path reads none
        self.fields = context.buffer(8 * fh * fw * frames if dense else 8)
        self.valids = context.buffer(fh * fw * frames)
        self.vrows = context.buffer(fh * fmt.width * frames)   # the same masks widened (vrows_of)
        ro = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
        self.ltab = cl.Buffer(context.ctx, ro, hostbuf=level_table(fmt))
        self.etab = cl.Buffer(context.ctx, ro, hostbuf=encode_table(fmt))
        self.host_cells = np.empty((fmt.height, fmt.width), np.uint8)


class TSSStage:
    """Temporal supersampling after the spatial filter: `stage(frame_in, frame_filtered, index)`.

    frame_in is the raw input frame (its samples are accumulated; motion and cuts are measured on
    it), frame_filtered the spatial output of the same frame (it stands where samples are few);
    returns frame `index`'s output (same shape and dtype as frame_filtered). Frames must come in
    order; a jump in `index`, a new size, a cut or reset() start a new ring. With `lookahead` N, pass the raw
    frames index + 1 .. index + N as `future` (fewer at the end). `stats` gets one dict
    per frame (index, model, ring, lookahead, flow_ms, resolve_ms, cells_mean, ...). backend "device"
    (kernels/tss.cl) or "numpy" (tss_frame_reference, slow). `transfer`: "pq" or "hlg" (HDR video,
    device/transfer.py): integer frames are codes of it; the ring holds the light they stand for over [0, LINEAR_RANGE]
    (level_table) and the resolve's mix is coded back by the transfer (encode_table), as the spatial
    Filter(transfer=...) mixes light."""

    def __init__(self, device: str | int | None = None, *, frames: int = DEFAULT_FRAMES, bgr: bool = True,
                 mode: str = "adaptive", grid: int = GRID, eps: float = EPS, min_cells: int = MIN_CELLS,
                 full_cells: int | None = None, refine: bool = True, fb_check: bool = True, show: str | None = None,
                 context=None, backend: str = "device", dense_samples: bool = False, lookahead: int = 0,
                 linear_input: bool = False, auto_exposure: bool = True, transfer: str | None = None):
        if int(frames) < 1:
            raise ValueError(f"frames: expected K >= 1, got {frames!r}")
        if int(lookahead) < 0:
            raise ValueError(f"lookahead: expected N >= 0 frames, got {lookahead!r}")
        if backend not in ("device", "numpy"):
            raise ValueError(f"backend: expected 'device' or 'numpy', got {backend!r}")
        if show not in (None, "history"):
            raise ValueError(f"show: expected None or 'history', got {show!r}")
        if not 1 <= int(grid) <= 8:   # kernels/tss.cl keeps one bit per footprint cell in a 64-bit word
            raise ValueError(f"grid: expected 1 to 8 footprint cells per side, got {grid!r}")
        if mode not in ("adaptive", "dense", "global", "static"):
            raise ValueError(f"mode: expected adaptive, dense, global or static, got {mode!r}")
        self.frames, self.bgr, self.mode, self.show = int(frames), bool(bgr), mode, show
        self.linear_input = bool(linear_input)   # frames are linear light (EXR): no sRGB decode, grey encoded
        self.transfer = check_transfer(transfer)
        if self.transfer is not None and self.linear_input:
            raise ValueError("transfer and linear_input exclude each other: a transfer's frames hold codes, "
                             "linear input holds light")
        # linear-light float frames are resolved at the power of two of exposure that puts their key near 1, as the
        # spatial filter sees them (spatial/exposure.py), held over the shot; False: at the exposure they come in
        self.exposure = HeldExposure() if auto_exposure else None
        self.last_scale = 1.0   # the scale the latest frame was resolved at
        self.lookahead = int(lookahead)   # N: frames after the current one the caller hands in (`future`)
        self.grid, self.eps, self.min_cells = int(grid), float(eps), int(min_cells)
        ahead = int(FULL_CELLS_AHEAD * self.lookahead + 0.5)
        self.full_cells = FULL_CELLS + ahead if full_cells is None else int(full_cells)
        self.field_full_cells = FULL_CELLS_FIELDS + ahead if full_cells is None else int(full_cells)   # tss_resolve
        self.backend = backend
        self.motion = MotionRing(self.frames, mode, refine, fb_check, dense_samples)
        self.stats: list[dict] = []
        self._noise: tuple | None = None   # (frame shape, index measured, level): _grain_stands
        self._lock = threading.Lock()
        self._buffers: _Buffers | None = None
        self.context = None
        if backend == "device":
            import pyopencl as cl
            from mlaa_stream.device.context import default_context
            self.context = context or default_context(device)
            self.queue = cl.CommandQueue(self.context.ctx, self.context.device)
            self._luts = cl.Buffer(self.context.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                                   hostbuf=with_transfer_tables(device_luts(), self.transfer))
        self._frames: dict[int, np.ndarray] = {}     # numpy backend: ring slot -> input frame
        self.reset()

    @property
    def device_name(self) -> str:
        return self.context.name if self.context is not None else "numpy reference"

    def reset(self) -> None:
        """Forget the ring: the next frame starts a new one (and returns the spatial output)."""
        self.motion.reset()
        self._pending: dict[int, tuple[int, np.ndarray]] = {}   # ring slot -> (index, input frame) not yet ingested
        self._resident: dict[int, int] = {}         # ring slot -> index of the frame the device holds there
        self._slot_of: dict[int, int] = {}          # frame index -> ring slot, for the frames kept (past, current, future)
        self._seen: dict[int, Ahead] = {}           # look-ahead frames measured already, by index
        self._vrows_sent: dict[int, np.ndarray] = {}   # ring slot -> the valid mask on the device
        self._prev_index: int | None = None
        self._shape = None   # (shape, dtype) of the previous frame: a change of either starts a new ring
        self._last: tuple[np.ndarray, np.ndarray] | None = None   # (grey, output) of the previous frame
        self._cells: np.ndarray | None = None   # the latest resolve's filled cells per pixel (None: none ran)
        # the latest frame's grey pyramid and motion decision (None after a repeated frame): TSSThenBlend
        # hands them to the blend, which would measure the same frame pair again
        self.last_motion: tuple[Pyramid, Decision] | None = None

    def set_linear_input(self, linear: bool) -> bool:
        """The colour space of the frames from now on (linear light, e.g. EXR, or display-encoded); True when that
        changed it: the ring starts again (its samples are in the other space)."""
        if bool(linear) == self.linear_input:
            return False
        if self.backend == "device":
            self.queue.finish()
        self.linear_input, self._buffers = bool(linear), None   # the kernels are rebuilt with the new define
        self.reset()
        return True

    def __call__(self, frame_in: np.ndarray, frame_filtered: np.ndarray, index: int,
                 regions: np.ndarray | None = None, future: list[np.ndarray] = ()) -> np.ndarray:
        """`regions` is accepted for the stages' common call (temporal.methods) and not read: TSS takes samples
        wherever the motion checks pass. `future`: the raw input frames index + 1, index + 2, ... (at most
        `lookahead` are read; fewer at the end of a stream): their samples count as the ring's do."""
        fin, fout = np.asarray(frame_in), np.asarray(frame_filtered)
        if fin.shape != fout.shape or fin.dtype != fout.dtype:
            raise ValueError(f"frame {index}: expected the input and filtered frames to have the same shape "
                             f"and type, got {fin.shape} {fin.dtype} and {fout.shape} {fout.dtype}")
        ahead = []
        for f in list(future)[:self.lookahead]:
            f = np.asarray(f)
            if f.shape != fin.shape or f.dtype != fin.dtype:
                break   # a new size or type starts a new ring there: the window ends before it
            ahead.append(f)
        wide = fin.dtype in (np.float16, np.float64)   # half (EXR) and double: the kernels read float32
        if wide:
            fin, fout = fin.astype(np.float32), fout.astype(np.float32)
            ahead = [f.astype(np.float32) for f in ahead]
        with self._lock:
            scale, changed = self.exposure.scale_for(fin, self.linear_input) if self.exposure else (1.0, False)
            if changed:
                self.reset()   # the ring's samples are another exposure's
            self.last_scale = scale
            if scale != 1.0:   # copies: the caller's frames stay as they are
                fin, fout, ahead = exposed(fin, scale), exposed(fout, scale), [exposed(f, scale) for f in ahead]
            out = self._step(fin, fout, int(index), ahead)
        if self.show is not None:
            return out
        out = self._grain_stands(fin, fout, out, int(index))
        if scale != 1.0:
            out = exposed(out, 1.0 / scale)
        # NaN, inf and samples beyond ±1e15 pass through as the spatial filter passes them (spatial/nonfinite.py)
        return restore_out_of_range(frame_in, out.astype(frame_filtered.dtype) if wide else out)

    def _grain_stands(self, fin: np.ndarray, fout: np.ndarray, out: np.ndarray, index: int) -> np.ndarray:
        """`out` with the spatial pixel back where the input's 3x3 window spans no more than its grain (quiet
        pixels, spatial/noise.py, as the spatial filter's render regions leave them): grain added after rendering
        is new every frame and part of the truth, and the ring's samples of other frames would average it away
        (docs/temporal.md, "Grain"). The frame's level is measured every NOISE_EVERY frames of a shot (grain keeps
        its strength), and where it is 0 (a clean render) nothing is computed."""
        if self._noise is None or self._noise[0] != fin.shape or index - self._noise[1] >= NOISE_EVERY \
                or index < self._noise[1]:
            self._noise = (fin.shape, index, level_of(luma256(fin, self.bgr)))
        level = self._noise[2]
        if self.stats:
            self.stats[-1]["noise_level"] = level
        if level <= 0:
            return out
        quiet = quiet_pixels(fin, self.bgr, level)
        return np.where(quiet.reshape(quiet.shape + (1,) * (out.ndim - 2)), fout, out)

    def _look_ahead(self, pyr: Pyramid, index: int, future: list[np.ndarray]) -> list[Ahead]:
        """The look-ahead frames' pyramids and frame-to-frame decisions, each measured once (kept by index
        until the frame is current)."""
        self._seen = {i: a for i, a in self._seen.items() if index < i <= index + len(future)}
        out, prev = [], pyr
        for k, f in enumerate(future):
            i = index + 1 + k
            a = self._seen.get(i)
            if a is None:
                fp = Pyramid.of(f, self.bgr, linear=self.linear_input)
                a = self._seen[i] = Ahead(i, fp, choose_model(prev, fp, self.mode))
            out.append(a)
            prev = a.pyr
        return out

    def _step(self, frame_in: np.ndarray, frame_filtered: np.ndarray, index: int,
              future: list[np.ndarray] = ()) -> np.ndarray:
        t0 = time.perf_counter()
        self.last_motion = None
        grey = grey8(frame_in, self.bgr, self.linear_input)
        # a new size or sample type starts a new ring: the ring's frames and the repeat test hold the old one
        fmt_key = (frame_in.shape, frame_in.dtype)
        fresh = self._prev_index is None or index != self._prev_index + 1 or fmt_key != self._shape
        if fresh:   # a new ring: nothing kept from before a jump back or forward is trusted
            self._seen, self._pending, self._resident = {}, {}, {}
        seen = self._seen.pop(index, None)   # this frame came as a look-ahead frame: measured already
        if seen is not None and not np.array_equal(seen.pyr.grey, grey):
            seen, self._seen = None, {}
        if not fresh and self._last is not None and np.array_equal(grey, self._last[0]):
            # a repeated frame (a still shot from a renderer, a duplicated frame): no new samples, no
            # new motion; the previous output stands and the ring is kept as it is
            self._prev_index = index
            self.stats.append({"index": index, "model": "static", "repeat": True, "ring": len(self.motion.entries),
                               "flow_ms": (time.perf_counter() - t0) * 1e3, "resolve_ms": 0.0,
                               "cells_mean": self.stats[-1]["cells_mean"] if self.stats else 0.0})
            return self.history_view(self._last[1]) if self.show == "history" else self._last[1].copy()
        pyr = seen.pyr if seen is not None else Pyramid.of(frame_in, self.bgr, grey)
        fm = self.motion.push(pyr, index, fresh, seen.decision if seen is not None else None,
                              self._look_ahead(pyr, index, future) if future else [])
        self.last_motion = (pyr, fm.decision)
        self._assign_slots(fm)
        future = future[:len(fm.future)]
        t1 = time.perf_counter()
        self._prev_index, self._shape = index, fmt_key
        # Every sample in one cell (static shot, whole-pixel motion, a single frame): nothing to
        # resolve, the spatial output stands without a kernel.
        taps = fm.entries + fm.future
        trivial = all(e.translated and not e.projective and e.valid is None for e in taps) and len(
            {self._cell_of(e.shift) for e in taps}) < self.min_cells or "aperture" in fm.decision.measures
        cells = None
        if self.backend == "numpy":
            self._frames = {e.slot: self._frames[e.slot] for e in fm.entries[:-1]}
            self._frames[fm.entries[-1].slot] = frame_in
            self._frames.update({e.slot: np.array(f, copy=True) for e, f in zip(fm.future, future)})
        if trivial:
            out = frame_filtered
            if self.backend != "numpy":
                self._upload_only(frame_in, pyr, fm, future)
        elif self.backend == "numpy":
            h, w = frame_in.shape[:2]

            def reference(entries, full_cells):
                ring = [(self._frames[e.slot], tile_shifts(e.homography, w, h, pyr.flow_scale) if e.projective
                         else e.shift if e.translated else e.field, e.valid) for e in entries]
                return tss_frame_reference(frame_filtered, frame_in, ring, self.bgr, pyr.flow_scale, self.grid,
                                           self.eps, self.min_cells, full_cells, self.linear_input, self.transfer)
            rect = self._layer_rect(fm, pyr, w, h)
            if rect is not None:   # as the device: background translations, then the layers' rectangle
                out, cells = reference(self._background_entries(taps), self.full_cells)
                fout, fcells = reference(taps, self.field_full_cells)
                x0, y0, x1, y1 = rect
                out[y0:y1, x0:x1], cells[y0:y1, x0:x1] = fout[y0:y1, x0:x1], fcells[y0:y1, x0:x1]
            else:
                translated = all(e.translated for e in taps)
                out, cells = reference(taps, self.full_cells if translated else self.field_full_cells)
        else:
            out, cells = self._resolve(frame_in, frame_filtered, pyr, fm, future)
        t2 = time.perf_counter()
        self._last = (grey, out)
        self.stats.append({"index": index, "model": fm.decision.model, "ring": len(fm.entries),
                           "lookahead": len(fm.future),
                           "flow_ms": (t1 - t0) * 1e3, "resolve_ms": (t2 - t1) * 1e3,
                           # filled cells per pixel outside flat neighbourhoods (those have 0), and the
                           # share of all pixels that took samples (n >= min_cells)
                           "cells_mean": 1.0 if cells is None else float(cv2.mean(cells, (cells > 0).astype(np.uint8))[0]),
                           "samples_share": 0.0 if cells is None else float(np.count_nonzero(cells >= self.min_cells)) / cells.size,
                           "translation": fm.decision.translation,
                           "projective": any(e.projective for e in taps), **fm.decision.measures})
        self._cells = cells
        if self.show == "history":
            return self.history_view(out)
        return out

    def history_view(self, out: np.ndarray) -> np.ndarray:
        """The debug view (--show history) of the latest frame resolved (a repeated frame: the one it repeats): its
        samples per pixel (cells_view) over `out`'s grey."""
        c = np.ones(out.shape[:2], np.uint8) if self._cells is None else self._cells
        return cells_view(c, out, self.grid, self.bgr)

    def _assign_slots(self, fm: FrameMotion) -> None:
        """Ring slots for the current and the look-ahead frames: a frame keeps its slot from when it first came
        (a look-ahead frame is ingested once for the frames before it; as the current frame it is ingested again,
        _resolve); K + N slots in all."""
        live = {e.index for e in fm.entries + fm.future}
        self._slot_of = {i: sl for i, sl in self._slot_of.items() if i in live}
        for e in fm.entries[:-1]:
            self._slot_of[e.index] = e.slot
        for e in [fm.entries[-1]] + fm.future:
            sl = self._slot_of.get(e.index)
            if sl is None:
                sl = self._slot_of[e.index] = min(set(range(self.frames + self.lookahead)) - set(self._slot_of.values()))
            e.slot = sl

    def _layer_rect(self, fm: FrameMotion, pyr: Pyramid, width: int, height: int) -> tuple[int, int, int, int] | None:
        """A layers frame's maps are the background's translation outside its layers and unexplained texels: the
        full-size rectangle (x0, y0, x1, y1) holding every pixel whose field read (bilinear) touches one of them,
        where the general resolve runs with FULL_CELLS_FIELDS; the translations' resolve (FULL_CELLS) does the rest
        of the frame. None: not a layers frame (fields everywhere: the general resolve)."""
        if fm.decision.model != "layers" or self.motion.frame_layers is None:
            return None
        layers, unexplained = self.motion.frame_layers
        mask = unexplained.copy()
        for layer in layers:
            mask |= layer.texels
        ys, xs = np.nonzero(mask)
        if not ys.size:
            return (0, 0, 0, 0)
        fs, (fh, fw) = pyr.flow_scale, mask.shape
        # texel t is read by the pixels whose position falls in texels t - 1 .. t + 1
        y0, y1 = max(int(ys.min()) - 1, 0), min(int(ys.max()) + 2, fh)
        x0, x1 = max(int(xs.min()) - 1, 0), min(int(xs.max()) + 2, fw)
        return (x0 * fs, y0 * fs, width if x1 == fw else x1 * fs, height if y1 == fh else y1 * fs)

    @staticmethod
    def _background_entries(entries: list[RingEntry]) -> list[RingEntry]:
        """The ring with each field replaced by its background translation (valid masks kept)."""
        return [e if e.translated else RingEntry(e.index, None, e.pyr, shift=e.bg, slot=e.slot, valid=e.valid)
                for e in entries]

    def _cell_of(self, shift: tuple[float, float]) -> tuple[int, int]:
        """The footprint cell every sample of a translated frame lands in (the same for all pixels)."""
        out = []
        for d in shift:
            p = np.float32(d)
            o = np.floor(p + np.float32(0.5)) - p
            out.append(int(min(max(np.floor((o + np.float32(0.5)) * np.float32(self.grid)), 0), self.grid - 1)))
        return tuple(out)

    # -- device ------------------------------------------------------------------------------------------
    def _prepare(self, frame: np.ndarray, pyr: Pyramid) -> _Buffers:
        fmt = with_transfer(frame_format(frame, self.bgr), self.transfer)   # tables and ENCODE_WARP of a transfer
        shape = pyr.flow.shape[:2]
        if self._buffers is not None and self._buffers.fmt == fmt and self._buffers.flow_shape == shape:
            return self._buffers
        self.queue.finish()
        self._buffers = _Buffers(self.context, fmt, shape, self.frames + self.lookahead, self.motion.dense_samples)
        self._vrows_sent, self._resident = {}, {}
        defines = kernel_defines(fmt, self.grid, self.eps, self.min_cells, self.full_cells, self.linear_input)
        field_defines = kernel_defines(fmt, self.grid, self.eps, self.min_cells, self.field_full_cells,
                                       self.linear_input)
        self._kernel = self.context.kernel("tss", "tss_resolve", field_defines)
        self._kernel_shift = self.context.kernel("tss", "tss_resolve_shift", defines)
        self._kernel_ingest = self.context.kernel("tss", "tss_ingest", defines)
        return self._buffers

    def _ingest(self, frame_in: np.ndarray, pyr: Pyramid, slot: int, index: int) -> _Buffers:
        """Input frame `index` into ring slot `slot` (tss_ingest: 16-bit linear planes)."""
        import pyopencl as cl
        bufs = self._prepare(frame_in, pyr)
        self._resident[slot] = index
        fmt = bufs.fmt
        cl.enqueue_copy(self.queue, bufs.src, np.ascontiguousarray(frame_in), is_blocking=False)
        self._kernel_ingest(self.queue, *shift_launch(fmt.width, fmt.height, self.context), bufs.src, bufs.ring,
                            self._luts,
                            bufs.ltab,
                            np.int32(fmt.width), np.int32(fmt.height), np.int32(slot))
        return bufs

    def _keep_pending(self, fm: FrameMotion, frames: list[tuple[RingEntry, np.ndarray]]) -> None:
        """Host copies of the frames the device does not hold yet (the look-ahead frames; the current one when
        its resolve is trivial); copies of frames no longer kept are dropped."""
        live = {e.slot: e.index for e in fm.entries + fm.future}
        self._pending = {sl: v for sl, v in self._pending.items() if live.get(sl) == v[0]}
        for e, f in frames:
            if self._resident.get(e.slot) != e.index and self._pending.get(e.slot, (None,))[0] != e.index:
                self._pending[e.slot] = (e.index, np.array(f, copy=True))

    def _upload_only(self, frame_in: np.ndarray, pyr: Pyramid, fm: FrameMotion, future: list[np.ndarray]) -> None:
        """A frame whose resolve is trivial (static shot): kept on the host until a resolve reads it
        (a still shot with codec noise then costs a copy, not an ingest, per frame)."""
        self._prepare(frame_in, pyr)
        self._keep_pending(fm, [(fm.entries[-1], frame_in)] + list(zip(fm.future, future)))

    def _resolve(self, frame_in, frame_filtered, pyr: Pyramid, fm: FrameMotion, future: list[np.ndarray]):
        import pyopencl as cl
        self._prepare(frame_in, pyr)
        self._keep_pending(fm, list(zip(fm.future, future)))
        for e in fm.entries[:-1] + fm.future:
            if self._resident.get(e.slot) != e.index:
                self._ingest(self._pending.pop(e.slot)[1], pyr, e.slot, e.index)
        self._pending = {}
        # the current frame always (a look-ahead frame is in its slot already, but the caller's frame is the one
        # this output answers for: the same index after a jump or reset is another frame)
        bufs = self._ingest(frame_in, pyr, fm.entries[-1].slot, index=fm.entries[-1].index)
        q, fmt = self.queue, bufs.fmt
        ring = fm.entries + fm.future
        fh, fw = bufs.flow_shape
        n = len(ring)
        if not all(e.translated for e in ring) and bufs.fields.size < 8 * fh * fw * (self.frames + self.lookahead):
            bufs.fields = self.context.buffer(8 * fh * fw * (self.frames + self.lookahead))   # fields: layers, dense
        for e in ring:
            if not e.translated:
                cl.enqueue_copy(q, bufs.fields, np.ascontiguousarray(e.field, np.float32),
                                dst_offset=e.slot * fh * fw * 8, is_blocking=False)
        rect = self._layer_rect(fm, pyr, fmt.width, fmt.height)
        shift_path = all(e.translated for e in ring)
        for e in ring:
            if e.valid is not None and (shift_path or rect is not None):
                if not (e.slot in self._vrows_sent and np.array_equal(self._vrows_sent[e.slot], e.valid)):
                    # masks change rarely (a tile's verdict): upload only a changed one
                    cl.enqueue_copy(q, bufs.vrows, vrows_of(e.valid, pyr.flow_scale, fmt.width),
                                    dst_offset=e.slot * fh * fmt.width, is_blocking=False)
                    self._vrows_sent[e.slot] = e.valid
            if e.valid is not None and not shift_path:
                cl.enqueue_copy(q, bufs.valids, np.ascontiguousarray(e.valid, np.uint8),
                                dst_offset=e.slot * fh * fw, is_blocking=False)
        cl.enqueue_copy(q, bufs.spatial, np.ascontiguousarray(frame_filtered), is_blocking=False)
        if shift_path or rect is not None:
            shifted = ring if shift_path else self._background_entries(ring)
            taps, vslots, (tile_rows, tiles_x) = self._taps(shifted, fmt.width, fmt.height, pyr.flow_scale)
            if bufs.tables.size < taps.nbytes:
                bufs.tables, bufs.table_vslots = self.context.buffer(taps.nbytes), self.context.buffer(vslots.nbytes)
            cl.enqueue_copy(q, bufs.tables, taps, is_blocking=False)
            cl.enqueue_copy(q, bufs.table_vslots, vslots, is_blocking=False)
            self._kernel_shift(q, *shift_launch(fmt.width, fmt.height, self.context), bufs.ring, bufs.spatial, bufs.dst,
                               bufs.cells, bufs.tables, bufs.table_vslots, bufs.vrows, self._luts, bufs.ltab,
                               bufs.etab, np.int32(fmt.width), np.int32(fmt.height), np.int32(fw), np.int32(fh),
                               np.int32(pyr.flow_scale), np.int32(n), np.int32(fm.entries[-1].slot),
                               np.int32(tile_rows), np.int32(tiles_x))
        if not shift_path:
            x0, y0, x1, y1 = rect if rect is not None else (0, 0, fmt.width, fmt.height)
            info = np.zeros((n, 4), np.int32)
            shift = np.zeros((n, 2), np.float32)
            for j, e in enumerate(ring):
                info[j] = (e.slot, 0 if e.translated else 1, e.slot, int(e.valid is not None))
                if e.translated:
                    shift[j] = e.shift
            cl.enqueue_copy(q, bufs.info, info, is_blocking=False)
            cl.enqueue_copy(q, bufs.shift, shift, is_blocking=False)
            if x1 > x0 and y1 > y0:   # the layers' rectangle (get_global_id counts from the offset)
                self._kernel(q, (x1 - x0, y1 - y0), None, bufs.ring, bufs.spatial, bufs.dst, bufs.cells,
                             bufs.info, bufs.shift, bufs.fields, bufs.valids, self._luts, bufs.ltab, bufs.etab,
                             np.int32(fmt.width), np.int32(fmt.height), np.int32(fw), np.int32(fh),
                             np.int32(pyr.flow_scale), np.int32(n), np.int32(fm.entries[-1].slot),
                             global_offset=(x0, y0))
        out = np.empty(frame_filtered.shape, frame_filtered.dtype)
        cl.enqueue_copy(q, out, bufs.dst, is_blocking=False)
        cl.enqueue_copy(q, bufs.host_cells, bufs.cells, is_blocking=True)
        return out, bufs.host_cells

    def _taps(self, entries: list[RingEntry], width: int, height: int,
              fs: int) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
        """tss_resolve_shift's tables: per ring frame (slot, dx, dy, close) with (dx, dy) its whole-pixel offset,
        frames ordered by footprint cell (stable: ring order inside a cell), close = the cell's frame count on
        its last frame, else 0; and each frame's valid-mask slot (-1: none). One table for the frame when every
        map is a translation; with projective maps one per tile of TILE_ROWS x LANES pixels (tiles in row order),
        from the per-tile translations (tile_shifts) as tss_reference takes them. Returns the tables, the mask
        slots and the kernel's (tile_rows, tiles_x)."""
        f32 = np.float32
        projective = any(e.projective for e in entries)
        ty, tx = (-(-height // TILE_ROWS), -(-width // LANES)) if projective else (1, 1)
        d = np.stack([tile_shifts(e.homography, width, height, fs).shifts if e.projective
                      else np.broadcast_to(np.asarray(e.shift, f32), (ty, tx, 2)) for e in entries], 2)
        whole = np.floor(d + f32(0.5))
        c = np.clip(np.floor((whole - d + f32(0.5)) * f32(self.grid)), 0, self.grid - 1).astype(np.int32)
        cell = c[..., 1] * self.grid + c[..., 0]                                   # (ty, tx, K)
        order = np.argsort(cell, axis=-1, kind="stable")
        cell = np.take_along_axis(cell, order, -1)
        taps = np.zeros((ty, tx, len(entries), 4), np.int32)
        taps[..., 0] = np.array([e.slot for e in entries], np.int32)[order]
        taps[..., 1] = np.take_along_axis(whole[..., 0].astype(np.int32), order, -1)
        taps[..., 2] = np.take_along_axis(whole[..., 1].astype(np.int32), order, -1)
        last = np.ones(cell.shape, bool)
        last[..., :-1] = cell[..., 1:] != cell[..., :-1]
        # a cell's frame count on its last frame: the run's length in the sorted cells (position - run start + 1)
        pos = np.arange(cell.shape[-1], dtype=np.int32)
        first = np.ones(cell.shape, bool)
        first[..., 1:] = last[..., :-1]
        start = np.maximum.accumulate(np.where(first, pos, 0), axis=-1)
        taps[..., 3] = np.where(last, pos - start + 1, 0)
        vslots = np.array([e.slot if e.valid is not None else -1 for e in entries], np.int32)[order]
        return (np.ascontiguousarray(taps), np.ascontiguousarray(vslots),
                (TILE_ROWS, tx) if projective else (height, 1))

    def finish(self) -> None:
        if self.context is not None:
            self.queue.finish()

    def close(self) -> None:
        """Wait for work in flight and free the device buffers."""
        try:
            self.finish()
        finally:
            self._buffers = None
            self._frames = {}
            self.reset()

    def __enter__(self) -> "TSSStage":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class TSSThenBlend:
    """Temporal supersampling, then the older reprojection blending on its output (methods "tss+blend" and,
    with the blend's where="render", "auto": mlaa_stream.temporal.methods).

    Measured (docs/temporal_bench.md): TSS alone gains only where one global motion holds and needs a
    few frames to fill its cells; the blend (mlaa_stream.temporal.stage.TemporalStage, seed 002)
    helps from the second frame and on dense motion. Chained, the rendered pan goes to 0.49 of the
    input's temporal error (TSS 0.64, blend 0.54), the bench pan to 0.39 (0.42, 0.53)."""

    def __init__(self, device: str | int | None = None, *, frames: int = DEFAULT_FRAMES, bgr: bool = True,
                 mode: str = "adaptive", show: str | None = None, context=None, blend_mode: str | None = None,
                 lookahead: int = 0, linear_input: bool = False, dense_samples: bool = False,
                 transfer: str | None = None, **blend_kwargs):
        """`blend_mode`: the blend's motion model when not `mode` ("auto": "dense"); `lookahead`, `dense_samples`:
        TSS's (the blend reads the past only); `linear_input`: both stages' (linear-light frames); `transfer`: TSS's
        (codes of HDR video, averaged as light; the blend keeps blending the codes: make_stage). `show="history"`:
        the blend's weights where it runs everywhere ("tss+blend"); with the blend only in render regions ("auto")
        TSS's samples per pixel, as the blend's view would be rejection everywhere else."""
        from mlaa_stream.temporal.stage import TemporalStage
        self.tss = TSSStage(device, frames=frames, bgr=bgr, mode=mode, context=context, lookahead=lookahead,
                            linear_input=linear_input, dense_samples=dense_samples, transfer=transfer)
        self._tss_view = show == "history" and blend_kwargs.get("where") == "render"
        self.blend = TemporalStage(device, bgr=bgr, mode=blend_mode or mode, show=None if self._tss_view else show,
                                   context=self.tss.context, linear_input=linear_input, auto_exposure=False,
                                   **blend_kwargs)
        self._scale = 1.0   # the exposure the blend's history is at (TSS's, spatial/exposure.py)

    @property
    def stats(self) -> list[dict]:
        """TSS's per-frame rows with the blend's history weight added."""
        return [{**b, **t, "history_weight_mean": b.get("history_weight_mean", 0.0),
                 "blend_model": b.get("model")} for t, b in zip(self.tss.stats, self.blend.stats)]

    @property
    def lookahead(self) -> int:
        return self.tss.lookahead

    def set_linear_input(self, linear: bool) -> bool:
        """Both stages' colour space (TSSStage.set_linear_input); True when it changed."""
        changed = self.tss.set_linear_input(linear)
        return self.blend.set_linear_input(linear) or changed

    def __call__(self, frame_in: np.ndarray, frame_filtered: np.ndarray, index: int,
                 regions: np.ndarray | None = None, future: list[np.ndarray] = ()) -> np.ndarray:
        out = self.tss(frame_in, frame_filtered, index, future=future)
        scale = self.tss.last_scale
        if scale != self._scale:   # the blend's history is another exposure's
            self.blend.reset()
            self._scale = scale
        if scale == 1.0 or self.blend.show is not None:   # (a debug view is no frame to scale back)
            out = self.blend(frame_in, out, index, regions=regions, measured=self._measured())
        else:   # at TSS's exposure, whose pyramid it reads (float32: half would overflow)
            f32 = np.float32
            blended = self.blend(exposed(np.asarray(frame_in, f32), scale), exposed(np.asarray(out, f32), scale), index,
                                 regions=regions, measured=self._measured())
            out = restore_out_of_range(frame_in, exposed(blended, 1.0 / scale).astype(np.asarray(out).dtype))
        return self.tss.history_view(out) if self._tss_view else out

    def _measured(self) -> tuple[Pyramid, Decision | None] | None:
        """TSS's pyramid of this frame and, where the blend's model choice would reach the same, its decision:
        the same choice in the same mode, or a translation measured in adaptive mode handed to a dense blend
        (choose_model measures it the same way in both modes before it decides)."""
        if self.tss.last_motion is None:
            return None
        pyr, dec = self.tss.last_motion
        if dec.model == "layers":   # TSS's own model for what choose_model classed dense
            dec = Decision("dense", dec.translation, dec.measures)
        if self.blend.mode == self.tss.motion.mode:
            return pyr, Decision(dec.model, dec.translation, dict(dec.measures))
        if self.blend.mode == "dense" and dec.model in ("global", "dense"):
            return pyr, Decision("dense", dec.translation, dict(dec.measures))
        return pyr, None

    def reset(self) -> None:
        self.tss.reset()
        self.blend.reset()

    def close(self) -> None:
        try:
            self.tss.close()
        finally:
            self.blend.close()

    def __enter__(self) -> "TSSThenBlend":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
