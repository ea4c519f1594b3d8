"""The spatial MLAA filter of seed 000 §3 as OpenCL passes: edges -> distances -> weights -> blend.

    with Filter() as f:
        out = f.process(frame)                      # same shape and dtype as `frame`
        pending = f.submit(frame); out = pending.result()   # non-blocking: overlap frames

Device buffers are allocated once per frame format and reused; two slots for the frame buffers let
the upload of frame N+1 and the download of frame N-1 overlap the kernels of frame N (out-of-order
queue with explicit events).
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, replace
from fractions import Fraction
from typing import Sequence

import numpy as np
import pyopencl as cl

from mlaa_stream.device.colour import device_luts
from mlaa_stream.device.context import Context, default_context, linear_levels
from mlaa_stream.device.formats import FrameFormat, defines_for, frame_format
from mlaa_stream.device.transfer import check_transfer, with_transfer_tables
from mlaa_stream.spatial.alpha import HARD_STEP, AlphaSplit, MergePass, has_coverage, varied_box, varied_tiles
from mlaa_stream.spatial.exposure import exposure_scale, scale_colour
from mlaa_stream.spatial.keep import KeepRect, kept_patches, keep_rects, restore_patches
from mlaa_stream.spatial.nonfinite import NonFinite, replace_non_finite
from mlaa_stream.spatial.shots import ShotTracker

METRICS = {"lab": 0, "luma": 1, "rgb": 2}
# Default discontinuity thresholds per metric: ΔE76 for lab, fraction of full scale for the others.
DEFAULT_THRESHOLDS = {"lab": 8.0, "luma": 0.06, "rgb": 0.06}
# ΔE76 <= LAB_LIPSCHITZ * max-channel sRGB difference anywhere in the cube: the largest
# infinity-to-2 norm of the sRGB->CIELAB Jacobian (493 on a 129^3 grid), +5%. The cube is convex,
# so the bound holds for finite differences too: pixels closer than threshold / LAB_LIPSCHITZ in
# every channel cannot be an edge and skip the CIELAB conversion.
LAB_LIPSCHITZ = 520.0
AREA_TABLE_L = 64
# Area factor for a line ending in a crossing edge exactly two pixels long (kernels/weights.cl):
# 1 treats it as a jaggy, 0 as a corner; a 2-px crossing is either. How each value below was chosen:
# docs/spatial_tuning.md.
SHORT_CORNER = 0.75
# A 2-px crossing at the end of a line of this many pixels or more, whose far end turns back along the line
# for three pixels, is a 2-px stroke's square end (hinted text stems, UI rules), kept sharp as a corner
# (kernels/weights.cl).
STROKE_END_MIN_L = 8
# Already antialiased edges (kernels/edges.cl `antialiased`): a neighbour along the step whose colour
# projects on p -> q at t in (AA_NEAR, 1 - AA_LO) beside p, (AA_LO, 1 - AA_NEAR) beside q, within AA_OFF
# of the step off the segment, or p (q) between its neighbour across the step and q (p) at t in
# (AA_LO, 1 - AA_LO), marks a rendered coverage ramp, not a 1-spp jaggy. AA_OFF and AA_NEAR keep texture
# and shading beside 1-spp edges out of it (docs/spatial_tuning.md).
AA_LO, AA_OFF, AA_NEAR = 0.1, 0.08, 0.3
# Grain and fine texture (film grain, sensor noise) are not jaggies (kernels/blend.cl `in_grain`): a pixel
# whose 3x3 window holds only pixels that differ from at least GRAIN_MIN of their 8 neighbours, by
# GRAIN_STEP / 255 of full scale or more in some channel, is left as it is.
GRAIN_STEP, GRAIN_MIN = 8, 5
# Sub-pixel features (kernels/blend.cl SUBPIXEL): a pixel bordered by edges on four sides (a dot) moves this
# far from its blended colour to the mean of its 3x3 window, in linear light (docs/spatial_tuning.md).
SUBPIXEL = 0.5
# ... only on one background: the neighbours across its edges spread (luma, linear) by at most SUBPIXEL_BG times
# the feature's contrast to the nearest of them.
SUBPIXEL_BG = 2.0
# A feature with three sides (a line's end, a 1-px bump: the fourth side continues into more of it) moves less.
SUBPIXEL_END = 0.25
# ... and the neighbours across its edges take SUBPIXEL_SHARE of its move, negated, split among them (ink kept).
SUBPIXEL_SHARE = 1.0
FALLBACK_MODES = ("auto", "edges", "everywhere", "off")  # Filter(fallback=...): spatial/fallback.py
ALPHA_MODES = ("coverage", "keep")  # Filter(alpha=...): spatial/alpha.py
SHOWS = (None, "regions")  # Filter(show=...): debug views
# A U shape (a bump) of STEM_MIN_L or more pixels on a 1-px line is a 1-px stroke -- small text's stems, rules --
# with square ends, not a curve's bump: its areas are scaled by STEM_K (kernels/weights.cl, docs/spatial_tuning.md).
STEM_MIN_L, STEM_K = 8, 0.25
SEGMENT = 64  # pixels of a row per work item in the per-pixel passes (kernels/common.cl)
VCHUNK = 32   # rows per work item of vline_distances_columns (kernels/distances.cl; GPUs)
EDGE_ROWS = 4  # rows per work item in detect_edges (kernels/edges.cl): each row's CIELAB and samples shared

# Named quality presets -> Filter keyword arguments (the CLI's --preset).
PRESETS: dict[str, dict] = {
    "default": {},                        # corners kept sharp, CIELAB edges, linear-light blending, wires bridged
    # corners rounded by seed 002's factor r: smoother text and wires; without the FXAA fallback, whose evidence
    # gate counts on MLAA leaving photographs alone (rounded corners blend inside them: photo damage 1.0 -> 2.1)
    "soft": {"rounding": 0.25, "fallback": "off"},
    "luma": {"metric": "luma"},           # luma edges (SMAA/FXAA-like), for comparison
    "reconstruct": {"reconstruct": True},  # + topological reconstruction of thin features (seed 000 §4)
    "no_bridge": {"bridge": False},        # without bridging the dash chains of sub-pixel wires (on by default)
    "fast": {"fast": True},               # seed 004's three passes, lines up to 31 px: live loops, previews
    "rendered": {"fallback": "everywhere"},  # 1-spp 3D renders only: the FXAA fallback on every pixel MLAA leaves
    # screen captures and UI through a lossy codec: the fallback's local gates without render regions (their
    # two-tone test can take three-tone flat-colour art through JPEG for a render: docs/spatial_tuning.md)
    "screen": {"fallback": "edges"},
}
# One line per preset for --help: what it is for.
PRESET_USES: dict[str, str] = {
    "default": "anything: renders, video games, vector art, text; photographs left alone",
    "screen": "screen captures and UI recordings through a lossy codec (no render regions)",
    "rendered": "frames known to be 1-spp 3D renders only (blurs text and photographs)",
    "soft": "rounder corners on text and wires",
    "luma": "luma edges, as SMAA and FXAA find them (for comparison)",
    "no_bridge": "without reconnecting dashed sub-pixel wires",
    "reconstruct": "+ topological reconstruction of thin features (slow)",
    "fast": "seed 004's three passes: live loops and previews, no guards",
}


def area_table(max_len: int = AREA_TABLE_L) -> np.ndarray:
    """Coverage areas of seed 000 eq. (2): table[L, p] for lines of length L and position p.

    The rebuilt silhouette falls from 1/2 at the line's end to 0 at its middle L/2; a pixel
    p..p+1 wholly before the middle gets the trapezoid 1/2 (1 - (2p+1)/L), the middle pixel of an
    odd line the triangle 1/(8L), pixels past the middle nothing.
    """
    t = np.zeros((max_len + 1, max_len), dtype=np.float32)
    for L in range(1, max_len + 1):
        for p in range(L):
            t[L, p] = trapezoid_area(p, L)
    return t


def ramp_fraction(ramp: float) -> tuple[int, int]:
    """The ramp factor as a fraction (numerator, denominator <= 1000): integer frames run the ramp
    test exactly on stored samples (kernels/edges.cl is_ramp_int, reference.edges_reference)."""
    f = Fraction(float(ramp)).limit_denominator(1000)
    return f.numerator, f.denominator


def quiet_levels(options: "FilterOptions", fmt: FrameFormat) -> int:
    """The largest max-channel difference in stored levels that cannot be an edge by the metric's
    cheap bound (edges.cl skips groups of pixels whose neighbours all differ by no more); -1 for
    float frames and linear input, whose stored values are not what the metric compares."""
    if options.linear_input or np.dtype(fmt.dtype).kind == "f":
        return -1
    pmax = float(np.iinfo(fmt.dtype).max)
    # lab: no edge below CHEAP_BOUND (ΔE <= LAB_LIPSCHITZ * difference); luma and weighted RGB: no
    # edge at or below the threshold (their weights sum to 1). A relative margin absorbs float rounding.
    bound = options.threshold / LAB_LIPSCHITZ if options.metric == "lab" else options.threshold
    return max(int(np.ceil(bound * pmax * (1.0 - 1e-4))) - 1, -1)


def trapezoid_area(p: int, L: int) -> float:
    if 2 * p + 2 <= L:
        return 0.5 * (1.0 - (2 * p + 1) / L)
    if 2 * p + 1 == L:
        return 1.0 / (8.0 * L)
    return 0.0


@dataclass(frozen=True)
class FilterOptions:
    threshold: float
    metric: str
    linear: bool
    linear_input: bool
    rounding: float
    blend_u: bool
    ramp: float
    short_corner: float = SHORT_CORNER
    aa_guard: bool = True
    grain_guard: bool = True
    subpixel: float = SUBPIXEL

    def pass_defines(self) -> dict[str, object]:
        return {
            "METRIC": METRICS[self.metric],
            "CHEAP_BOUND": float(self.threshold / LAB_LIPSCHITZ),
            "LINEAR_INPUT": int(self.linear_input),
            "BLEND_LINEAR": int(self.linear),
            "AREA_TABLE_L": AREA_TABLE_L,
            "ROUNDING": float(self.rounding),
            "BLEND_U": int(self.blend_u),
            "SHORT_CORNER": float(self.short_corner), "CAP_MIN_L": STROKE_END_MIN_L,
            "STEM_MIN_L": STEM_MIN_L, "STEM_K": float(STEM_K),
            "AA_GUARD": int(self.aa_guard), "AA_LO": float(AA_LO), "AA_OFF": float(AA_OFF), "AA_NEAR": float(AA_NEAR),
            "SUBPIXEL": float(self.subpixel), "SUBPIXEL_ON": int(self.subpixel > 0), "SUBPIXEL_BG": float(SUBPIXEL_BG),
            "SUBPIXEL_SHARE": float(SUBPIXEL_SHARE),
            "SUBPIXEL_END": float(self.subpixel * SUBPIXEL_END / SUBPIXEL) if SUBPIXEL > 0 else 0.0,
            "GRAIN_GUARD": int(self.grain_guard), "GRAIN_STEP": GRAIN_STEP, "GRAIN_MIN": GRAIN_MIN,
            "SEGMENT": SEGMENT, "EDGE_ROWS": EDGE_ROWS, "VCHUNK": VCHUNK,
            "RAMP_TEST": int(self.ramp > 0),
            "RAMP": float(self.ramp),
            "RAMP_NUM": ramp_fraction(self.ramp)[0], "RAMP_DEN": ramp_fraction(self.ramp)[1],
        }


HALF_MAX = float(np.finfo(np.float16).max)


class PendingFrame:
    """A frame in flight; `result()` waits for its download and returns it in the input's dtype, as an array the
    caller owns: the first call the download itself, each later call a new copy of what the first returned."""

    def __init__(self, host_out: np.ndarray, event, out_dtype: np.dtype, shape: tuple, keep=(),
                 non_finite: NonFinite | None = None, regions: tuple | None = None, dim: bool = False,
                 owner: "Filter | None" = None, patches: list | None = None, scale: float = 1.0):
        self._scale = scale  # the exposure the frame was filtered at (spatial/exposure.py): divided out here
        self._out, self._event, self._dtype, self._shape = host_out, event, out_dtype, shape
        self._patches = patches or []  # the input inside the filter's keep rectangles (spatial/keep.py)
        self._keep = keep  # host arrays that must outlive the non-blocking copies
        self._non_finite = non_finite
        self._regions = regions  # (per-tile flags or None, the event of their copy or None), or None
        self._dim = dim          # show="regions": dim everything outside the regions
        self._owner = owner      # its last_regions is set on result()
        self.regions: np.ndarray | None = None
        self._result: np.ndarray | None = None   # what the first result() returned

    def result(self) -> np.ndarray:
        """The filtered frame; afterwards `regions` holds its render-region flag per tile when the filter
        was made with keep_regions=True or show="regions" (None where it has no render regions), and so
        does the filter's `last_regions`: a temporal stage called right after result() reads its frame's.
        Each call returns an array of its own: the first the downloaded frame (no copy), a later one a copy of
        the first call's array as it is then (changes the caller made to it included)."""
        if self._result is not None:
            # two calls returned views of one buffer: drawing on one frame changed the other
            self.publish_regions()
            return self._result.copy()
        self._event.wait()
        self._keep = ()
        out = self._out.reshape(self._shape)
        if self._scale != 1.0:
            scale_colour(out, 1.0 / self._scale)
            if self._dtype == np.float16:  # a blend near half's largest value must not round to infinity
                np.clip(out, -HALF_MAX, HALF_MAX, out=out)
        if self._non_finite is not None:
            out = self._non_finite.restore(out)
        if self._regions is not None:
            flags, copied = self._regions
            if copied is not None:
                copied.wait()
            self.regions = flags
            self.publish_regions()
            if self._dim:
                from mlaa_stream.spatial.fallback import dim_outside_regions
                out = dim_outside_regions(out, flags)
        out = out if out.dtype == self._dtype else out.astype(self._dtype)
        self._result = restore_patches(out, self._patches)
        self._out = None   # the download buffer is the result now (or was copied into it)
        return self._result

    def publish_regions(self) -> None:
        """Make this frame's region flags (after result()) its filter's `last_regions` again: a pipeline that
        collects the frames after it before its temporal stage runs (look-ahead) calls this first."""
        if self._owner is not None and self._regions is not None:
            self._owner.last_regions = self.regions


class DerivedPendingFrame:
    """A frame in flight whose result is made on the host from another pending frame's (`inner`) by `finish` (the
    alpha as coverage, spatial/alpha.py: the alpha plane filtered and merged with the colour). The same interface
    as PendingFrame."""

    def __init__(self, inner: "PendingFrame | DerivedPendingFrame", finish):
        self._inner, self._finish = inner, finish
        self._result: np.ndarray | None = None

    @property
    def regions(self) -> np.ndarray | None:
        return self._inner.regions

    def publish_regions(self) -> None:
        self._inner.publish_regions()

    def result(self) -> np.ndarray:
        """The filtered frame (see PendingFrame.result: each call returns an array of its own)."""
        if self._result is not None:
            self.publish_regions()
            return self._result.copy()
        self._result = self._finish(self._inner)
        self._finish = None  # what it holds (the split frame) is not needed again
        return self._result


class _FrameBuffers:
    """All device memory for one frame format: allocated once, reused for every frame."""

    SLOTS = 2

    def __init__(self, context: Context, fmt: FrameFormat):
        n = fmt.pixels
        self.fmt = fmt
        self.src = [context.buffer(fmt.nbytes) for _ in range(self.SLOTS)]
        self.dst = [context.buffer(fmt.nbytes) for _ in range(self.SLOTS)]
        self.edges = context.buffer(n)
        self.hdist = context.buffer(4 * n)
        self.vdist = context.buffer(4 * n)
        self.weights = context.buffer(8 * n)
        self.moved_features = context.buffer(n)   # blend.cl feature_shares: 1 where a feature moves
        self.shares = context.buffer(16 * n)      # ... and what its neighbours take (float4, only there)
        self.staging = [np.empty(fmt.nbytes // fmt.dtype.itemsize, fmt.dtype) for _ in range(self.SLOTS)]
        self.last_use = [None] * self.SLOTS  # event after which slot k's src/dst/staging are free

    def device_bytes(self) -> int:
        return sum(b.size for b in [*self.src, *self.dst, self.edges, self.hdist, self.vdist, self.weights,
                                    self.moved_features, self.shares])


class Filter:
    """Spatial MLAA (seed 000 §3) on an OpenCL device, for numpy frames one after another."""

    def __init__(self, device: str | int | None = None, *, threshold: float | None = None,
                 metric: str = "lab", linear: bool = True, reconstruct: bool = False,
                 bgr: bool = False, linear_input: bool = False, rounding: float = 0.0,
                 blend_u: bool = True, ramp: float = 0.35, short_corner: float = SHORT_CORNER,
                 aa_guard: bool = True, bridge: bool = True, grain_guard: bool = True,
                 subpixel: float = SUBPIXEL, fallback: str | bool = "auto", fast: bool = False,
                 preset: str | None = None, context: Context | None = None, show: str | None = None,
                 keep_regions: bool = False, footprint_table: np.ndarray | None | str = "default",
                 refine_table: np.ndarray | None | str = "default", moire: bool = True,
                 keep: Sequence[KeepRect | str] | str | None = None, auto_exposure: bool = True,
                 alpha: str = "coverage", transfer: str | None = None, hold_render: bool = True):
        """`preset`: one of PRESETS; its options replace the keywords of the same names. `fallback`: FXAA
        for the pixels MLAA leaves (spatial/fallback.py): "auto" where the neighbourhood shows 1-spp
        aliasing and is no flat-colour art, with the footprint table in render regions; "edges" the same
        without render regions (screen captures); "everywhere" (frames known to be 1-spp renders); "off".
        `show="regions"`: a debug view, the output with every pixel outside render regions dimmed.
        `keep_regions`: read every frame's render-region flags back (PendingFrame.regions, `last_regions`)
        for a temporal stage with where="render". `footprint_table`: the fallback's filter table for render
        regions (spatial/footprint.py): "default" the shipped one, None none (render regions then get FXAA
        only), or a (BUCKETS, WEIGHTS) float32 array. `refine_table`: the second table after it
        (spatial/refine.py): "default", None or a (BUCKETS, REFINE_WEIGHTS) array; only with a footprint table.
        `moire`: the last pass, point-sampled moire in two-colour art low-passed (a 3 x 3 binomial)
        (spatial/moire.py). `keep`: rectangles left exactly as they are in every frame (subtitles, a HUD over a
        render; spatial/keep.py): KeepRect or 'X,Y,W,H' strings in pixels or % of the frame. `auto_exposure`: a
        float frame with `linear_input` is filtered at the power of two of exposure that puts its key near display
        white and multiplied back (spatial/exposure.py); False filters it as its samples are. `alpha`: "coverage"
        antialiases the alpha of an RGBA frame with its colour where the alpha is not one value (an element over
        transparency; spatial/alpha.py), "keep" leaves it as it is and filters the colour alone. `transfer`: "pq" or
        "hlg": the frames' integer samples code light by SMPTE ST 2084 or ARIB STD-B67 (HDR video): the passes mix the
        light they code and code the mix back (device/transfer.py). `hold_render`: frames submitted one after another
        form shots; a frame judged a render holds that verdict for the frames after it until a cut (spatial/shots.py:
        a codec's P- and B-frames fall under the share their keyframe passes); False judges every frame alone, as
        does a frame after new_shot()."""
        if show not in SHOWS:
            raise ValueError(f"show: expected None or 'regions', got {show!r}")
        self.show = show
        self.keep = keep_rects(keep)
        self.keep_regions = bool(keep_regions) or show == "regions"
        self.last_regions: np.ndarray | None = None  # the flags of the frame collected last (keep_regions)
        self.regions_owner: "Filter" = self  # whose last_regions this filter's frames set (io.sequence.FilterSet)
        self._shots = ShotTracker() if hold_render else None
        if preset is not None:
            if preset not in PRESETS:
                raise ValueError(f"preset: expected one of {', '.join(sorted(PRESETS))}, got {preset!r}")
            opts = PRESETS[preset]
            metric, rounding = opts.get("metric", metric), opts.get("rounding", rounding)
            reconstruct, bridge = opts.get("reconstruct", reconstruct), opts.get("bridge", bridge)
            fast, fallback = opts.get("fast", fast), opts.get("fallback", fallback)
        if metric not in METRICS:
            raise ValueError(f"metric: expected one of {', '.join(METRICS)}, got {metric!r}")
        thr = DEFAULT_THRESHOLDS[metric] if threshold is None else float(threshold)
        if not thr > 0:
            raise ValueError(f"threshold: expected a positive number, got {threshold!r}")
        if not 0.0 <= float(short_corner) <= 1.0:
            raise ValueError(f"short_corner: expected a factor in [0, 1], got {short_corner!r}")
        if not 0.0 <= float(subpixel) <= 1.0:
            raise ValueError(f"subpixel: expected a factor in [0, 1], got {subpixel!r}")
        self.transfer = check_transfer(transfer)
        if self.transfer is not None and linear_input:
            raise ValueError("transfer and linear_input exclude each other: a transfer's frames hold codes, "
                             "linear_input's linear light")
        self.options = FilterOptions(thr, metric, bool(linear), bool(linear_input),
                                     float(rounding), bool(blend_u), float(ramp), float(short_corner),
                                     bool(aa_guard), bool(grain_guard), float(subpixel))
        self.bgr = bool(bgr)
        self.auto_exposure = bool(auto_exposure)
        if alpha not in ALPHA_MODES:
            raise ValueError(f"alpha: expected one of {', '.join(ALPHA_MODES)}, got {alpha!r}")
        self.alpha = alpha
        self._alpha_filters: dict[str, "Filter"] = {}  # fallback mode -> the filter of alpha planes (_alpha_filter)
        self._alpha_lock = threading.Lock()
        self._merger: MergePass | None = None
        self.fast = bool(fast)  # spatial/fast.py: seed 004's passes instead of the default chain
        self.reconstruct = bool(reconstruct) and not self.fast
        self.bridge = bool(bridge) and not self.fast
        fallback = {True: "auto", False: "off"}.get(fallback, fallback) if isinstance(fallback, bool) else fallback
        if fallback not in FALLBACK_MODES:
            raise ValueError(f"fallback: expected one of {', '.join(FALLBACK_MODES)}, got {fallback!r}")
        self.fallback = "off" if self.fast else fallback
        self.moire = bool(moire) and not self.fast
        from mlaa_stream.spatial.footprint import table_of
        from mlaa_stream.spatial.refine import refine_table_of
        self.footprint_table = table_of(footprint_table)
        self.refine_table = refine_table_of(refine_table)   # FallbackPass runs it only after a footprint table
        self.context = context or default_context(device)
        dev = self.context.device
        props = cl.command_queue_properties.OUT_OF_ORDER_EXEC_MODE_ENABLE
        self.queue = cl.CommandQueue(self.context.ctx, dev,
                                     properties=props if dev.queue_properties & props else 0)
        self._luts = cl.Buffer(self.context.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                               hostbuf=with_transfer_tables(device_luts(), self.transfer))
        # the edge tests' CIELAB: of the codes through the sRGB decode (device/transfer.py), as for any integer frame
        self._lab_luts = self._luts if self.transfer is None else cl.Buffer(
            self.context.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=device_luts())
        self._table = cl.Buffer(self.context.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                                hostbuf=area_table())
        self._buffers: _FrameBuffers | None = None
        self._reconstructor = None
        self._recon_buf = None
        self._bridger = None
        self._fallback = None
        self._moire = None
        self._fast = None
        self._frame_no = 0
        self._lock = threading.Lock()
        self._last_event = None

    @property
    def device_name(self) -> str:
        return self.context.name

    # -- set-up, once per frame format -------------------------------------------------------
    def _prepare(self, fmt: FrameFormat) -> _FrameBuffers:
        if self._buffers is not None and self._buffers.fmt == fmt:
            return self._buffers
        self.finish()
        self._buffers = bufs = _FrameBuffers(self.context, fmt)
        defs = defines_for(fmt, **self.options.pass_defines(), QUIET_LEVELS=quiet_levels(self.options, fmt))
        if self.fast:
            from mlaa_stream.spatial.fast import FastPasses
            self._fast = FastPasses(self.context, fmt, defs, self._luts)
            return bufs
        k = self.context.kernel
        self._k_edges = k("edges", "detect_edges", defs)
        self._lin = linear_levels(self.context, "edges", defs, fmt, self._luts)
        self._lin_lab = self._lin if self.transfer is None else linear_levels(self.context, "edges", defs, fmt,
                                                                              self._lab_luts)
        self._k_hdist = k("distances", "hline_distances", defs)
        self._k_vdist = k("distances", "vline_distances_columns" if self.context.column_sweeps else "vline_distances",
                          defs)
        self._k_weights = k("weights", "blend_weights", defs)
        self._k_blend = k("blend", "blend_neighbours", defs)
        self._k_shares = k("blend", "feature_shares", defs)
        if self.reconstruct:
            from mlaa_stream.spatial.reconstruct import Reconstructor
            self._reconstructor = Reconstructor(self.context, fmt)
            self._recon_buf = self.context.buffer(fmt.nbytes)
        if self.bridge:
            from mlaa_stream.spatial.bridge import BridgeOptions, Bridger
            self._bridger = Bridger(self.context, fmt, BridgeOptions(linear=self.options.linear,
                                                                     linear_input=self.options.linear_input))
        if self.fallback != "off":
            from mlaa_stream.spatial.fallback import FallbackPass
            self._fallback = FallbackPass(self.context, fmt, self.options.linear, self.options.linear_input,
                                          everywhere=self.fallback == "everywhere",
                                          regions=self.fallback != "edges", table=self.footprint_table,
                                          refine=self.refine_table)
        if self.moire:
            from mlaa_stream.spatial.moire import MoirePass
            self._moire = MoirePass(self.context, fmt, self.options.linear, self.options.linear_input)
        return bufs

    # -- per frame ---------------------------------------------------------------------------
    def submit(self, frame: np.ndarray, premultiplied: bool = False) -> "PendingFrame | DerivedPendingFrame":
        """Enqueue upload, passes and download of `frame` without waiting; see PendingFrame. `premultiplied`: the
        colour of an RGBA frame is premultiplied by its alpha (EXR's convention), for alpha="coverage"."""
        if self._wants_alpha(frame):
            split = AlphaSplit(frame, premultiplied, decode=self.options.linear and not self.options.linear_input,
                               transfer=self.transfer)
            patches = kept_patches(frame, self.keep)

            def merged(colour: PendingFrame) -> np.ndarray:
                filtered = colour.result()  # sets colour.regions
                alpha = self.filter_alpha(split.alpha, colour.regions)
                return restore_patches(self._merge_pass().merge(split, filtered, alpha), patches)

            return DerivedPendingFrame(self._submit(split.colour, want_regions=self.fallback == "auto"), merged)
        return self._submit(frame)

    def _format(self, frame: np.ndarray) -> FrameFormat:
        """frame_format with this filter's transfer: the passes read the samples through it (device/transfer.py)."""
        fmt = frame_format(frame, self.bgr)
        return fmt if self.transfer is None else replace(fmt, transfer=self.transfer)

    def _wants_alpha(self, frame: np.ndarray) -> bool:
        """True when `frame`'s alpha is filtered as coverage (alpha="coverage" and an alpha that varies)."""
        frame_format(frame, self.bgr)  # a frame the filter cannot take is named as such first
        if self.transfer is not None and frame.dtype.kind == "f":
            raise ValueError(f"transfer={self.transfer!r}: expected a frame of 8- or 16-bit codes (a decoded HDR video "
                             f"frame), got {frame.dtype}; float frames of linear light take linear_input=True")
        return self.alpha == "coverage" and has_coverage(frame)

    def _submit(self, frame: np.ndarray, want_regions: bool = False) -> PendingFrame:
        """submit without the alpha split; `want_regions`: read the frame's render-region flags back
        (PendingFrame.regions) even without keep_regions."""
        fmt = self._format(frame)
        with self._lock:
            bufs = self._prepare(fmt)
            slot = self._frame_no % bufs.SLOTS
            self._frame_no += 1
            if bufs.last_use[slot] is not None:
                bufs.last_use[slot].wait()  # the frame that used this slot two frames ago is out
            staging = bufs.staging[slot]
            with np.errstate(over="ignore"):  # float64 beyond float32's range: inf here, restored from `frame`
                np.copyto(staging.reshape(frame.shape), frame, casting="unsafe")
            non_finite = replace_non_finite(staging.reshape(frame.shape), frame)  # float frames only
            scale = 1.0
            if self.auto_exposure and self.options.linear_input and fmt.dtype.kind == "f":
                scale = exposure_scale(staging.reshape(frame.shape))
                scale_colour(staging.reshape(frame.shape), scale)
            up = cl.enqueue_copy(self.queue, bufs.src[slot], staging, is_blocking=False)
            after = [up] + ([self._last_event] if self._last_event is not None else [])
            cut = self._shots is None or self._fallback is None or self._shots.cut(frame)
            done = self._enqueue_passes(bufs, bufs.src[slot], bufs.dst[slot], after, cut=cut)
            host_out = np.empty_like(staging)
            down = cl.enqueue_copy(self.queue, host_out, bufs.dst[slot], wait_for=[done],
                                   is_blocking=False)
            bufs.last_use[slot] = down
            self._last_event = done
            regions = None
            if self.keep_regions or want_regions:  # without the fallback pass: no regions
                regions = (self._fallback.read_regions(self.queue, [done]) if self._fallback is not None else
                           (None, None))
                if regions[1] is not None:  # the next frame's passes rewrite the flags after the copy
                    self._last_event = regions[1]
            self.queue.flush()
        return PendingFrame(host_out, down, np.dtype(frame.dtype), frame.shape, keep=(staging,),
                            non_finite=non_finite, regions=regions, dim=self.show == "regions", scale=scale,
                            owner=self.regions_owner, patches=kept_patches(frame, self.keep))

    def _enqueue_passes(self, bufs: _FrameBuffers, src, dst, after: list, queue=None,
                        events: dict | None = None, cut: bool = True):
        """Enqueue every pass of one frame after the events `after`; returns the last event.
        `events`, when given, receives each pass's event (for profiling); `cut`: the frame starts a shot (no held
        render verdict; spatial/shots.py)."""
        w, h = bufs.fmt.width, bufs.fmt.height
        W, H = np.int32(w), np.int32(h)
        q, g2 = queue or self.queue, (-(-w // SEGMENT), h)  # one work item per SEGMENT pixels of a row
        ev: dict = {} if events is None else events
        if self._fast is not None:
            return self._fast.enqueue(q, src, dst, self._luts, after, SEGMENT, ev)
        if self._reconstructor is not None:
            ev["reconstruct"] = self._reconstructor.enqueue(q, src, self._recon_buf, self._luts, wait_for=after)
            src, after = self._recon_buf, [ev["reconstruct"]]
        # detect_edges: EDGE_ROWS rows per work item; on a CPU (PoCL) one per work group, faster than
        # PoCL's own choice (docs/spatial_tuning.md)
        g_edges = (g2[0], -(-h // EDGE_ROWS))
        l_edges = (1, 1) if self.context.device.type & cl.device_type.CPU else None
        ev["edges"] = self._k_edges(q, g_edges, l_edges, src, self._luts, self._lin_lab, bufs.edges, W, H,
                                    np.float32(self.options.threshold), wait_for=after)
        ev["hlines"] = self._k_hdist(q, (max(h - 1, 1),), None, bufs.edges, bufs.hdist, W, H,
                                     wait_for=[ev["edges"]])
        g_vlines = (w, -(-h // VCHUNK)) if self.context.column_sweeps else (-(-w // SEGMENT),)
        ev["vlines"] = self._k_vdist(q, g_vlines, None, bufs.edges, bufs.vdist, W, H, wait_for=[ev["edges"]])
        ev["weights"] = self._k_weights(q, g2, None, src, bufs.edges, bufs.hdist, bufs.vdist, self._table,
                                        bufs.weights, W, H, wait_for=[ev["hlines"], ev["vlines"]])
        ev["copy"] = cl.enqueue_copy(q, dst, src, byte_count=bufs.fmt.nbytes, wait_for=after)
        ev["shares"] = self._k_shares(q, g2, None, src, bufs.edges, bufs.weights, self._luts, bufs.moved_features,
                                      bufs.shares, W, H, wait_for=[ev["weights"]])
        ev["blend"] = self._k_blend(q, g2, None, src, bufs.edges, bufs.weights, self._luts, bufs.moved_features,
                                    bufs.shares, dst, W, H, wait_for=[ev["shares"], ev["copy"]])
        last = ev["blend"]
        if self._bridger is not None:  # dash chains found in src, drawn over the blended frame
            last = self._bridger.enqueue(q, src, dst, self._luts, wait_for=[last], events=ev)
        if self._fallback is not None:  # FXAA where MLAA left pixels of an aliased neighbourhood
            last = self._fallback.enqueue(q, src, dst, bufs.edges, bufs.hdist, bufs.vdist, self._luts, self._lin,
                                          wait_for=[last], events=ev, cut=cut)
        if self._moire is not None:  # moire in two-colour art; the blend's feature shares are free by now
            last = self._moire.enqueue(q, src, dst, bufs.edges, self._luts, bufs.shares, wait_for=[last], events=ev)
        return last

    def profile(self, frame: np.ndarray, runs: int = 20, warmup: int = 3) -> dict[str, float]:
        """Median device milliseconds of each pass (and of upload/download) over `runs` frames,
        serialised on a profiling queue: for the benchmark, never for unit tests."""
        fmt = self._format(frame)
        self.finish()
        bufs = self._prepare(fmt)
        q = cl.CommandQueue(self.context.ctx, self.context.device,
                            properties=cl.command_queue_properties.PROFILING_ENABLE)
        host = np.ascontiguousarray(frame, dtype=fmt.dtype)
        out = np.empty_like(host)
        times: dict[str, list[float]] = {}
        for k in range(warmup + runs):
            ev = {"upload": cl.enqueue_copy(q, bufs.src[0], host)}
            self._enqueue_passes(bufs, bufs.src[0], bufs.dst[0], [ev["upload"]], queue=q, events=ev)
            ev["download"] = cl.enqueue_copy(q, out, bufs.dst[0])
            q.finish()
            if k >= warmup:
                for name, e in ev.items():
                    times.setdefault(name, []).append((e.profile.end - e.profile.start) * 1e-6)
        return {name: float(np.median(v)) for name, v in times.items()}

    def new_shot(self) -> None:
        """The next frame starts a shot: no render verdict of the frames before it is held (hold_render)."""
        if self._shots is not None:
            self._shots.reset()

    def process(self, frame: np.ndarray, premultiplied: bool = False) -> np.ndarray:
        """Filter one frame and return it (same shape and dtype); `premultiplied` as for submit."""
        return self.submit(frame, premultiplied).result()

    # -- inspection, for tests and the benchmark ---------------------------------------------
    def intermediates(self, frame: np.ndarray) -> dict[str, np.ndarray]:
        """Run one frame and return every pass's output (edges, hdist, vdist, weights, out)."""
        out = self.process(frame)
        bufs = self._buffers
        h, w = bufs.fmt.height, bufs.fmt.width
        res = {"out": out}
        for name, dtype, shape in [("edges", np.uint8, (h, w)), ("hdist", np.uint16, (h, w, 2)),
                                   ("vdist", np.uint16, (h, w, 2)), ("weights", np.uint16, (h, w, 4))]:
            arr = np.empty(shape, dtype)
            cl.enqueue_copy(self.queue, arr, getattr(bufs, name), is_blocking=True)
            res[name] = arr
        return res

    def device_bytes_per_pixel(self) -> float:
        if self._buffers is None:
            return 0.0
        extra = self._recon_buf.size if self._recon_buf is not None else 0
        extra += self._bridger.device_bytes() if self._bridger is not None else 0
        extra += self._fast.device_bytes() if self._fast is not None else 0
        extra += self._fallback.device_bytes() if self._fallback is not None else 0
        return (self._buffers.device_bytes() + extra) / self._buffers.fmt.pixels

    def finish(self) -> None:
        self.queue.finish()

    # -- alpha as coverage (spatial/alpha.py) ------------------------------------------------------
    def _alpha_filter(self, fallback: str) -> "Filter":
        """The filter of alpha planes: this one's options, samples taken as linear (coverage), `fallback`."""
        with self._alpha_lock:
            if fallback not in self._alpha_filters:
                o = self.options
                self._alpha_filters[fallback] = Filter(
                    context=self.context, threshold=o.threshold, metric=o.metric, linear=o.linear, linear_input=True,
                    rounding=o.rounding, blend_u=o.blend_u, ramp=o.ramp, short_corner=o.short_corner,
                    aa_guard=o.aa_guard, bridge=self.bridge, grain_guard=o.grain_guard, subpixel=o.subpixel,
                    fallback=fallback, fast=self.fast, reconstruct=self.reconstruct,
                    footprint_table=self.footprint_table, refine_table=self.refine_table, moire=self.moire,
                    auto_exposure=False, alpha="keep")
            return self._alpha_filters[fallback]

    def _merge_pass(self) -> MergePass:
        """The device merge of alpha as coverage (spatial/alpha.py), made on first need."""
        with self._alpha_lock:
            if self._merger is None:
                self._merger = MergePass(self.context, self._luts, self.options.pass_defines())
            return self._merger

    def filter_alpha(self, plane: np.ndarray, regions: np.ndarray | None) -> np.ndarray:
        """An alpha plane (H, W) filtered as coverage: with this filter's fallback; where the colour is mostly a
        render (`regions`: its render-region flags per tile, or None; the tiles where the alpha steps by HARD_STEP
        or more lie mostly in them), those tiles with the fallback on every pixel, as a 1-spp render's coverage.
        Only the box of tiles where the alpha varies (and ALPHA_MARGIN tiles round it) is filtered: outside it the
        alpha is one value over every pass's reach, which no filter changes (an element over transparency is
        often a part of the frame)."""
        from mlaa_stream.spatial.fallback import FALLBACK_TILE
        varied = varied_tiles(plane, FALLBACK_TILE)
        out = plane.copy()
        tiles = varied_box(varied)
        if tiles is None:
            return out
        ty0, ty1, tx0, tx1 = tiles
        box = (slice(ty0 * FALLBACK_TILE, ty1 * FALLBACK_TILE), slice(tx0 * FALLBACK_TILE, tx1 * FALLBACK_TILE))
        crop = np.ascontiguousarray(plane[box])
        out[box] = self._filter_alpha_box(crop, None if regions is None else np.asarray(regions)[ty0:ty1, tx0:tx1],
                                          varied[ty0:ty1, tx0:tx1])
        return out

    def _filter_alpha_box(self, plane: np.ndarray, regions: np.ndarray | None, varied: np.ndarray) -> np.ndarray:
        """filter_alpha on a box of whole tiles (`regions`, `varied`: its tiles' flags)."""
        if regions is None or self.fallback != "auto" or not np.any(regions):
            return self._alpha_filter(self.fallback).process(plane)
        from mlaa_stream.spatial.fallback import FALLBACK_TILE, region_pixels
        hard = varied_tiles(plane, FALLBACK_TILE, HARD_STEP)
        if 2 * np.count_nonzero(hard & (regions > 0)) <= np.count_nonzero(hard):
            return self._alpha_filter(self.fallback).process(plane)
        rendered = self._alpha_filter("everywhere").process(plane)
        if not (varied & ~hard).any():  # no soft alpha (a matte, a ramp) to leave
            return rendered
        out = self._alpha_filter(self.fallback).process(plane)
        return np.where(region_pixels(hard, *plane.shape[:2]), rendered, out)

    def close(self) -> None:
        """Wait for work in flight and free the device buffers."""
        try:
            self.finish()
        finally:
            self._buffers = None
            self._recon_buf = None
            self._reconstructor = None
            self._bridger = None
            self._fallback = None
            self._fast = None
            self._merger = None
            children, self._alpha_filters = list(self._alpha_filters.values()), {}
            for child in children:
                child.close()

    def __getstate__(self) -> None:
        # pickle named pyopencl's Device ("cannot pickle 'Device' object"): say what cannot travel and what to do
        raise TypeError(f"a {type(self).__name__} holds OpenCL device state and cannot be pickled or copied; make one "
                        f"in each process that filters (the cluster's workers do: mlaa_stream.cluster)")

    def __enter__(self) -> "Filter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
