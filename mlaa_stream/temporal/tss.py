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

Resolve (per output pixel x; `tss_reference` is the plain statement, kernels/tss.cl the device twin):
  - ring frame j (the current frame is j = 0, identity map) maps x to p = M_j(x) in its own pixels;
    its sample nearest p, at s = round(p), lies at o = s - p inside x's footprint ([-0.5, 0.5)^2:
    the box filter the truth is defined with): one tap per ring frame, a gather, no atomics;
  - rejection: a sample outside the current input's 3x3 per-channel min/max box of L widened by EPS
    (linear light; EPSQ in L units) is another surface (disocclusion, a mover, a flow error) and is dropped; a
    position outside ring frame j, or a map marked invalid (NaN: forward-backward flow
    inconsistency), drops the tap;
  - stratification (seed 002: each sample's offset inside its pixel decides its coverage area): the
    footprint is split into GRID x GRID cells; samples are averaged per cell (integer sum times
    1 / count) and the filled cells are averaged (in ascending cell order), so 10 frames that repeat one
    phase count once, not ten times;
  - combination with the spatial estimate: the empty cells are the part of the footprint the samples
    do not cover; the spatial (MLAA) output S stands for them:
        out = S + min(1, n / FULL_CELLS) (mean of filled cells - S)   when n >= MIN_CELLS
        out = S (the spatial pixel, bit for bit)                         otherwise
    with S the spatial output's L, rounded to L and encoded by table (`encode_table`); so static
    content and integer-pixel motion (every sample in one cell) return the spatial output exactly, and
    a pan that fills the cells converges toward the box-filtered truth;
  - the spatial pixel also stands where the current frame's 3x3 is flat in every plane (n = 0: no
    aliasing to resolve; the kernels read no ring there) and where the result is within one 8-bit level
    of it in every channel (`within_dead_zone`: rounding-size moves only added damage).

Motion (host, per frame; `MotionRing`): the per-frame decision of stage.choose_model (reset at a cut or
an index jump or a size change, static, global translation, dense DIS flow). Global: each ring frame's
translation is the previous one composed with this frame's, then refined *directly* against the
current frame by sparse Gauss-Newton (`_Refiner`: the current frame's largest gradients on the flow-size
grey, the ring frame's blurred grey kept): chaining alone drifts (issue 16: 0.09 px after 16 frames
against 0.016 direct). Row and column bands test the translation along long edges (`_Refiner._band_deviations`:
a band whose own 1-D step departs from the frame's takes no samples from that ring frame) and still
bands leave the estimate (`_Refiner._band_weights`): docs/temporal.md, "Never worse". A turning camera moves
the image by a homography, far from one translation with a wide lens: each translated ring frame also keeps a
homography (`MotionRing._projective`, 8-parameter steps of `_Refiner.homography`), and where it departs from the
translation at the frame's corners the frame's maps are projective, resolved as one translation per tile of
TILE_ROWS x LANES pixels (`tile_shifts`, per-tile tables of tss_resolve_shift) and checked per region
(`MotionRing._alignment`): docs/temporal.md, "Pans are not translations". Frames choose_model classes dense:
moving layers (mlaa_stream.temporal.layers: a background translation and a few affine layers, each ring frame's
map a field, refined directly, checked per region; resolved by tss_resolve with FULL_CELLS_FIELDS) where they
explain the frame (docs/temporal.md, "Moving layers"), else the ring restarts; with dense_samples (off by
default: ~20 ms per ring frame at 1080p) every ring frame's map becomes a field of per-tile translations tracked
directly from the current frame (`MotionRing._tracked_tiles`; docs/temporal.md, "Dense camera motion").

Look-ahead (files: `TSSStage(lookahead=N)`, called with `future=` the next N raw frames, which
mlaa_stream.pipeline hands in): the frames after the current one are ring entries too, each one's translation
chained from the frame-to-frame decisions and refined directly against the current frame (`MotionRing._ahead`),
in K + N device slots; FULL_CELLS grows by FULL_CELLS_AHEAD per frame ahead (docs/temporal.md, "Look-ahead").
"""
from __future__ import annotations

import functools
import math
import threading
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from mlaa_stream.device.colour import device_luts, lut_read
from mlaa_stream.device.formats import LUT_SIZE, frame_format, with_transfer
from mlaa_stream.device.transfer import check_transfer, encode_arg, with_transfer_tables
from mlaa_stream.spatial.exposure import HeldExposure, exposed
from mlaa_stream.spatial.noise import level_of, luma256, quiet_pixels
from mlaa_stream.spatial.nonfinite import restore_out_of_range
from mlaa_stream.temporal.layers import (STILL_AGE, STILL_SHIFT, CompositionalPoints, ahead_fields, background_of,
                                         find_layers, inverse_compositional, layer_fields, layers_decision,
                                         sample_bilinear, still_background, translation_map)
from mlaa_stream.temporal.stage import (LK_ROBUST, Decision, Pyramid, _PMAX, choose_model, sample_field,
                                        decode_table, dis_refuses, grey8)

DEFAULT_FRAMES = 16   # K: ring frames (the current one included)
GRID = 4              # footprint cells per side (GRID^2 strata)
EPS = 0.03            # linear-light widening of the current 3x3 colour box (issue 16: 0.02-0.05)
MIN_CELLS = 2         # fewer filled cells: the spatial output stands
NOISE_EVERY = 8       # frames between measurements of the input's grain level (spatial/noise.py) in a shot
FULL_CELLS = 9        # filled cells at which the samples alone resolve the pixel (below: n / 9 of it)
FULL_CELLS_AHEAD = 1.25   # ... plus this many per look-ahead frame (rounded): more frames fill more cells with
                          # samples of sub-pixel detail that the spatial output renders better (docs/temporal.md,
                          # "Look-ahead")
FULL_CELLS_FIELDS = 16  # ... where the maps are fields (moving layers): a layer's samples fill the cells along its
                        # local motion (a turning object's edge moves along one direction), so their mean is trusted
                        # less (docs/temporal.md, "Moving layers")
NEWEST_STEPS = 2      # Gauss-Newton steps per frame for the newest ring frame (MotionRing._refine)
REFINE_STEPS = 2      # ... and for each older ring frame refined in that frame
REFINE_EVERY = 3      # older ring frames refined directly at ages 1 + a multiple of this (docs/temporal.md)
ONE = 65535           # ring samples: linear light in 16-bit fixed point (kernels/tss.cl, ring_of)
OVER = 65535          # a float frame's sample over the ring's range: never averaged; in-range ones top out at ONE - 1
LINEAR_RANGE = 16     # linear-light float frames (EXR): the ring holds [0, 16] (highlights 4 stops over white; one
                      # step 2.4e-4: 0.8 of an 8-bit level of the sRGB-encoded value at black, 0.07 at mid-grey)
LANES = 16            # pixels of a row per work item of tss_resolve_shift (int16 / float16 vectors)
TILE_ROWS = 16        # rows of a tile of projective maps (tss_resolve_shift: one translation per tile and ring frame)
TSS_LOCAL = 8         # CPU work-group of tss_resolve_shift along the row (docs/temporal.md: speed)
DENSE_TILE, DENSE_WIN, DENSE_FB = 16, 21, 0.3   # dense_samples: tile centres' spacing and LK window (flow px), the
                      # forward-backward tolerance (full-size px); docs/temporal.md, "Dense camera motion"
PARALLAX_SHARE = 0.5   # dense_samples: a global frame whose ring frames fail the tile check (TILE_TOL) on over this
                      # share of the textured tiles at every age checked is a camera moving with parallax (dollies:
                      # 0.58-1.0; rendered pans 0.02-0.27; a flat-colour pan's few textured tiles 0.36-0.50): its maps
                      # are tracked per tile (MotionRing._tracked_tiles) instead of one translation ...
PARALLAX_TILES = 24   # ... judged on at least this many textured tiles (docs/temporal.md, "Dollies through tracked
                      # tiles")
TRACKED_AGE = 7       # dense_samples: ring frames up to this many frames old are tracked; older ones leave the ring
                      # (16-frame dollies: never worse than spatial only with 7, damage over it with all 15; a dolly's
                      # field departs further from a tile's translation with age)
ALIGN_LEVEL, ALIGN_PX, ALIGN_SIGMA, ALIGN_GROW = 10.0, 0.35, 2.0, 3   # MotionRing._alignment
PROJECTIVE_MIN = 0.25 # px (full size): a global frame uses projective maps where some ring frame's homography departs
                      # from its translation by this much at a corner of the frame (MotionRing._projective)
HOMOGRAPHY_STEPS = 3  # inverse-compositional Gauss-Newton steps for the newest ring frame's homography
PROJECTIVE_RATIO = 1.0  # ... and no ring frame departs by more than this times its translation (plus PROJECTIVE_MIN)
APERTURE_RATIO = 0.02  # a frame whose refinement points' structure tensor has eigenvalues further apart than this
                      # ratio (every gradient of one direction: straight stripes) keeps the spatial output: the motion
                      # along the stripes is a guess, the samples placed by it line up in the footprint and pull
                      # MLAA's blend back towards the aliased steps (docs/temporal.md, "Stripes")
TILE, TILE_TOL, TILE_TEXTURE = 48, 0.4, 1.0   # _Refiner's tile check: flow px, px, mean squared gradient
BAND, BAND_TOL, BAND_TEXTURE = 32, 0.25, 0.05   # _Refiner._band_deviations: flow px, px, mean squared gradient
STATIC_TOL = 0.05     # px (flow): a band whose own motion is under this while the frame's is over twice it is
                      # still content (_Refiner._band_weights): left out of the estimate; 0 = off
BAND_GROWTH = 0.2     # with 3 ring ages or more checked in a frame, a band is off only where its deviation also grows
                      # with age by this share of BAND_TOL per age (_bands_growing; docs/temporal.md, "The band
                      # check on a pure pan"); 0 = every band over BAND_TOL is off
BAND_FAR = 0.75       # px (flow): a band departing this much is off at any age
TRAJECTORY_MIN = 10   # ring frames (look-ahead ones included) for MotionRing._fit_trajectory: fewer are too noisy
TRAJECTORY_DEGREE = 2  # the fit's degree in age: 2 follows a camera easing in or out (0.005-0.02 px / frame^2)
TRAJECTORY_AHEAD = True   # look-ahead frames join the fit (look-ahead 2: damage 0.65 -> 0.54 on the bench pan)
TRAJECTORY_TOL = 0.1  # px (full size): residual RMS per axis up to which the fit replaces the ring's estimates
REFINE_POINTS = 16384 # _Refiner: points in all (the largest gradients of each tile, at most a whole tile)


# --- motion of every ring frame relative to the current one ------------------------------------------
@dataclass
class RingEntry:
    """One past input frame: its linear samples, grey pyramid and map from the current frame's pixels."""

    index: int
    lin: np.ndarray | None            # (H, W, 3) float32 linear RGB (host reference path)
    pyr: Pyramid
    shift: tuple[float, float] | None = (0.0, 0.0)   # p = x + shift (translation map), or None: dense
    field: np.ndarray | None = None   # (fh, fw, 2) float32 offsets in full-size px (dense map), NaN = invalid
    slot: int = -1                    # device ring slot
    valid: np.ndarray | None = None   # (fh, fw) uint8 at flow size: 1 where the map explains the frame
    homography: np.ndarray | None = None   # 3x3, current frame's flow px -> this frame's (global frames)
    projective: bool = False          # this frame's map is the homography (per-tile translations), not shift
    bg: tuple[float, float] = (0.0, 0.0)   # the background's translation where the map is a field of layers
    field_box: tuple[slice, slice] | None = None   # where a field of layers departs from `bg` (NaN aside);
                                                   # None: anywhere
    estimate: tuple[float, float] | None = None   # the measured translation where `shift` is the fitted camera
                                                   # path's (MotionRing._fit_trajectory); None: `shift` is measured

    @property
    def translated(self) -> bool:
        """True when the map is one translation for every pixel (`shift`, the fast resolve path)."""
        return self.field is None


@dataclass
class FrameMotion:
    """What the ring knows for the current frame: the decision and each ring frame's map."""

    decision: Decision
    entries: list[RingEntry] = field(default_factory=list)   # oldest first, current last
    future: list[RingEntry] = field(default_factory=list)    # look-ahead frames after the current one, in order


@dataclass
class Ahead:
    """A frame after the current one (look-ahead): its index, grey pyramid and the decision of its motion from
    the frame before it (choose_model, made once: the same decision is the ring's when the frame is current)."""

    index: int
    pyr: Pyramid
    decision: Decision


class MotionRing:
    """The ring's motion bookkeeping: which frames are kept and how the current frame maps into them."""

    def __init__(self, frames: int = DEFAULT_FRAMES, mode: str = "adaptive", refine: bool = True,
                 fb_check: bool = True, dense_samples: bool = False, layers: bool = True):
        self.frames, self.mode, self.refine, self.fb_check = int(frames), mode, bool(refine), bool(fb_check)
        self.dense_samples, self.layers = bool(dense_samples), bool(layers)
        self.entries: list[RingEntry] = []
        self._dis = None
        self._last_refiner: _Refiner | None = None   # this frame's, made by _refine, used by _projective
        self._refiner_pyr: Pyramid | None = None     # the frame _last_refiner was made for
        self.band_slopes = None                      # each band's deviation per frame of age (_refine, _band_slopes)
        self.tiles_off = None                        # the share of textured tiles off at every checked age (_refine)
        self.frame_layers = None                    # this frame's (layers, unexplained texels) where it has layers

    def reset(self) -> None:
        self.entries = []

    def _flow(self, a: np.ndarray, b: np.ndarray, start: tuple[float, float]) -> np.ndarray:
        """DIS flow (FAST) with a(x) ~ b(x + flow), started from the global translation (stage.py)."""
        init = np.empty(a.shape[:2] + (2,), np.float32)
        init[...] = start
        if dis_refuses(a.shape):   # too small for DIS (stage.py): the global translation as the flow
            return init
        if self._dis is None:
            self._dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_FAST)
        return self._dis.calc(a, b, init)

    def push(self, pyr: Pyramid, index: int, fresh: bool, decision: Decision | None = None,
             future: list[Ahead] = ()) -> FrameMotion:
        """Add the current frame; returns its decision and the maps of all kept frames (current last), and of the
        look-ahead frames `future` (frames index + 1, index + 2, ...). `decision`: the current frame's motion
        from the previous one when already measured (it came as a look-ahead frame), else measured here."""
        prev = self.entries[-1] if self.entries else None
        for e in self.entries:   # every frame starts from the measured maps: the fitted path never feeds itself
            if e.estimate is not None:
                e.shift, e.estimate = e.estimate, None
        self.band_slopes = None   # set by _refine where it fits them this frame (_ahead reads them)
        self.tiles_off = None     # set by _refine: the share of textured tiles off at every checked age (parallax)
        self.frame_layers = None
        if fresh or prev is None:
            dec = Decision("reset", measures={"cut": False})
        else:
            dec = decision if decision is not None else choose_model(prev.pyr, pyr, self.mode)
            if dec.model == "global" and self.layers and self.mode == "adaptive" and self._still_background(pyr, dec):
                dec = Decision("dense", dec.translation, {**dec.measures, "still_background": True})
        if dec.model == "reset":
            self.entries = []
        elif dec.model == "global" and (aperture := self._aperture(pyr)) is not None:
            # one edge direction: the motion along it is a guess (the samples would line up in every footprint),
            # so no samples and nothing to refine; the ring starts anew
            self.entries = []
            dec = Decision("global", dec.translation, {**dec.measures, "aperture": aperture})
        elif dec.model == "global":
            d = dec.translation
            for e in self.entries:
                if e.shift is not None:
                    e.shift = (e.shift[0] + d[0], e.shift[1] + d[1])
                    e.projective = False   # decided anew below
                else:
                    e.field, e.field_box = self._compose_const(e.field, d, pyr), None
                    e.bg = (e.bg[0] + d[0], e.bg[1] + d[1])
            if self.refine:
                self._refine(pyr, index, d)
                if self._parallax():
                    self._tracked_tiles(pyr, self.entries)
                    dec = Decision("global", dec.translation, {**dec.measures, "tracked": True})
                else:
                    self._fit_trajectory(index)
                    self._projective(pyr, index)
        elif dec.model == "dense" and self.layers and (found := self._layers(prev, pyr, dec)) is not None:
            dec = found
        elif dec.model == "dense" and self.dense_samples:
            self._tracked_tiles(pyr, self.entries)
        elif dec.model == "dense":
            # No layers explain the frame (a camera move with parallax, a mover they cannot fit). Measured
            # (docs/temporal.md, TSS section): DIS flow on 1-spp frames is ~0.1-0.2 px off and composing it
            # over the ring puts samples on the wrong side of edges: rotation, orbit, dolly and the fast mover
            # all came out worse than the spatial output. Without sub-pixel-accurate local motion the spatial
            # output stands and the ring starts anew.
            self.entries = []
        # static: every map stays as it is (nothing moved)
        future = list(future)
        first = self._first_layers(pyr, index, future) if future and dec.model == "reset" else None
        if not future or "aperture" in dec.measures:
            ahead = []
        elif dec.model == "layers" or first is not None:
            ahead = ahead_fields(pyr, index, future, *(first or self.frame_layers),
                                 lambda i, p, fld, bg, box: RingEntry(i, None, p, shift=None, field=fld, bg=bg,
                                                                      field_box=box),
                                 still=bool(dec.measures.get("still_background")), forward=first is not None)
        else:
            ahead = self._ahead(pyr, index, future)
            if dec.measures.get("tracked"):
                self._tracked_tiles(pyr, ahead)
            elif ahead and dec.model == "global" and self.refine and TRAJECTORY_AHEAD:
                self._fit_trajectory(index, ahead)
        if "aperture" not in dec.measures and any(e.translated for e in ahead) and \
                (aperture := self._aperture(pyr)) is not None:   # a shot's first frame reading frames ahead
            dec = Decision(dec.model, dec.translation, {**dec.measures, "aperture": aperture})
        for e in self.entries + ahead:
            # translations are checked per tile (global branch above); dense and projective maps per region
            if not e.translated or e.projective:
                e.valid = self._alignment(e, pyr)
        self.entries.append(RingEntry(index, None, pyr))
        if len(self.entries) > self.frames:
            del self.entries[0]
        pyr.drop_gradients()   # choose_model's and the refiner's: this frame's motion is measured
        return FrameMotion(dec, list(self.entries), ahead)

    def _layers(self, prev: RingEntry, pyr: Pyramid, dec: Decision) -> Decision | None:
        """Moving layers (temporal.layers): the ring's maps become fields of a background translation and each
        layer's affine map; None (the ring untouched) where layers do not explain the frame."""
        bg = background_of(dec, prev.pyr, pyr)
        found = find_layers(prev.pyr, pyr, bg, self._flow)
        if found is None:
            return None
        if dec.measures.get("still_background"):   # the ring's translations were the pulled estimate's
            for e in self.entries:
                e.shift, e.bg = ((0.0, 0.0) if e.shift is not None else None), (0.0, 0.0)
        layer_fields(self.entries, *found, bg, pyr.flow_scale)
        self.frame_layers = found
        return layers_decision(dec, found[0])

    def _first_layers(self, pyr: Pyramid, index: int, future: list[Ahead]):
        """A shot's first frame with frames ahead: the moving layers from it to the next frame (the maps run forward,
        layers.ahead_fields), where that frame moved densely; else None."""
        a = future[0]
        if not self.layers or a.index != index + 1 or a.decision.model != "dense" or a.pyr.flow.shape != pyr.flow.shape:
            return None
        d = background_of(a.decision, pyr, a.pyr)   # the next frame's pixels into this one
        return find_layers(a.pyr, pyr, (-d[0], -d[1]), self._flow)

    def _still_background(self, pyr: Pyramid, dec: Decision) -> bool:
        """One small translation (under STILL_SHIFT px) fitted to a still background and an object moving over it
        (a turning wheel pulls it to ~0.26 px per frame)? Judged over the ring's whole baseline, at least STILL_AGE
        frames: layers.still_background between the oldest ring frame and the current one (1-spp frames of a slow
        pan can match better unmoved frame to frame: near-horizontal edges jump a row now and then; over several
        frames the pan shows). docs/temporal.md, "Moving layers"."""
        d = dec.translation
        far = self.entries[0] if self.entries else None
        age = self.entries[-1].index - far.index + 1 if far is not None else 0
        if math.hypot(*d) >= STILL_SHIFT or age < STILL_AGE:
            return False
        # the moving background's hypothesis: the ring's translation (global frames), or this frame's for every frame
        # of the baseline (after a still background was found, the ring's background is still)
        moved = (far.shift[0] + d[0], far.shift[1] + d[1]) if far.shift is not None else (d[0] * age, d[1] * age)
        return still_background(far.pyr, pyr, moved)

    def _aperture(self, pyr: Pyramid) -> float | None:
        """The current frame's structure-tensor ratio (_Refiner.aperture) where it is under APERTURE_RATIO -- one edge
        direction, whose motion along it is not measured -- else None (or without refinement)."""
        if not self.refine:
            return None
        ratio = self._refiner(pyr).aperture
        return ratio if ratio < APERTURE_RATIO else None

    def _refiner(self, pyr: Pyramid) -> _Refiner:
        """The direct refiner of the current frame (made once per frame)."""
        if self._refiner_pyr is not pyr or self._last_refiner is None:
            self._last_refiner, self._refiner_pyr = _Refiner(pyr.blurred("flow"), grads=pyr.gradients("flow")), pyr
        return self._last_refiner

    def _ahead(self, pyr: Pyramid, index: int, future: list[Ahead]) -> list[RingEntry]:
        """Maps of the look-ahead frames (issue 16: a window that also reads later frames removes the warm-up
        cost): each one's translation chained from the frame-to-frame decisions (frame f's translation d_f
        maps f's pixels into f - 1, so the current frame's pixels land in f at x - d_(t+1) - ... - d_f), then
        refined *directly* against the current frame as the newest ring frame is (NEWEST_STEPS steps, the last
        with the tile and band checks: its valid mask). The window ends before the first frame that is not
        the next one, is a cut, or moves by more than one translation (dense). Projective when the ring's maps
        are this frame (each future frame's homography then refined from its translation)."""
        out: list[RingEntry] = []
        fs = pyr.flow_scale
        d = (0.0, 0.0)
        moved = False
        for k, a in enumerate(future):
            if a.index != index + 1 + k or a.decision.model not in ("global", "static") or a.pyr.flow.shape != pyr.flow.shape:
                break
            if a.decision.model == "global":
                t = a.decision.translation
                d = (d[0] - t[0], d[1] - t[1])
                moved = True
            e = RingEntry(a.index, None, a.pyr, shift=d)
            if self.refine and moved:
                ref = self._refiner(pyr)
                # with band slopes the mask is made below from the check: none from the refinement
                s, e.valid, check = ref.refine(a.pyr.blurred("flow"), (d[0] / fs, d[1] / fs), NEWEST_STEPS,
                                               mask=self.band_slopes is None)
                e.shift = (s[0] * fs, s[1] * fs)
                if self.band_slopes is not None and check is not None:   # a frame ahead's age is negative
                    bad, dy, ty, dx, tx = check
                    e.valid = ref.valid_of(bad, *_bands_growing(self.band_slopes, index - a.index, dy, ty, dx, tx))
            out.append(e)
        if self.refine and any(e.projective for e in self.entries):
            ref = self._refiner(pyr)
            for e in out:
                e.homography = ref.homography(e.pyr.blurred("flow"), _translation(e.shift, fs), HOMOGRAPHY_STEPS)
                e.projective = True
        return out

    def _refine(self, pyr: Pyramid, index: int, d: tuple[float, float]) -> None:
        """Direct Gauss-Newton refinement of the translated ring frames against the current frame (chaining
        alone drifts: issue 16). The newest ring frame (the previous input) gets NEWEST_STEPS steps; what
        they change is this frame's chaining error, the same for every older frame, so it is added to them
        all; then the older frames of age 1 + a multiple of REFINE_EVERY get REFINE_STEPS steps each (a
        frame is refined on every REFINE_EVERY-th of the K frames it stays in the ring, so its estimate
        converges; refining all of them every frame made the output less steady).
        The last step of each refined frame also runs the per-tile check (its valid mask)."""
        fs = pyr.flow_scale
        ref = self._refiner(pyr)
        todo = [e for e in self.entries if e.shift is not None]
        if not todo:
            return

        checks = []
        newest, older = todo[-1], todo[:-1]
        # by age alone, not by what was refined before: the state after K frames is then the same
        # however the run started (--resume's warm-up, a cluster chunk's: docs/cluster.md)
        due = [e for e in older if (index - e.index - 1) % REFINE_EVERY == 0]
        # frames checked at three ages or more get their masks from the bands' growth below, not from refine
        growing = BAND_GROWTH > 0 and (NEWEST_STEPS > 0) + (REFINE_STEPS > 0) * len(due) >= 3

        def refine(e: RingEntry, steps: int) -> None:
            s, e.valid, check = ref.refine(e.pyr.blurred("flow"), (e.shift[0] / fs, e.shift[1] / fs), steps,
                                           mask=not growing)
            e.shift = (s[0] * fs, s[1] * fs)
            if check is not None:
                checks.append((e, index - e.index, check))

        before = newest.shift
        refine(newest, NEWEST_STEPS)
        corr = (newest.shift[0] - before[0], newest.shift[1] - before[1])
        for e in older:
            e.shift = (e.shift[0] + corr[0], e.shift[1] + corr[1])
        for e in due:
            refine(e, REFINE_STEPS)
        textured = int(ref.textured.sum()) if checks else 0
        if textured >= PARALLAX_TILES:   # the share of textured tiles off, at the checked age where it is least
            self.tiles_off = min(float(bad.sum()) for _, _, (bad, *_rest) in checks) / textured
        if BAND_GROWTH > 0 and len({a for _, a, _ in checks}) >= 3:
            self.band_slopes = _band_slopes(checks)
            for e, age, (bad, dy, ty, dx, tx) in checks:
                e.valid = ref.valid_of(bad, *_bands_growing(self.band_slopes, age, dy, ty, dx, tx))

    def _fit_trajectory(self, index: int, ahead: list[RingEntry] = ()) -> None:
        """A smooth camera path through the ring's translations: each direct estimate of a 1-spp frame is off by how
        its edges' quantised positions happen to match (0.05-0.1 px, independent of age), and the current frame's
        own quantisation offsets all of them alike. shift(age) = c + v age + w age^2 (TRAJECTORY_DEGREE) by least
        squares; c is that common offset (the current frame's pixel centres are where its samples are, by
        definition), so the maps become v age + w age^2. Only where the fit explains the estimates (residual RMS
        per axis at most TRAJECTORY_TOL); the measured estimates are kept in `estimate` and the next frame starts
        from them (push), so the fit never feeds itself. `ahead`: look-ahead frames (negative ages), fitted with
        the ring once their own direct estimates are in. docs/temporal.md, "The ring's trajectory"."""
        entries = self.entries + list(ahead)
        if len(entries) < TRAJECTORY_MIN or any(e.shift is None for e in entries):
            return
        measured = [e.shift if e.estimate is None else e.estimate for e in entries]
        ages = np.array([index - e.index for e in entries], np.float64)
        xy = np.array(measured, np.float64)
        a = np.stack([ages ** p for p in range(TRAJECTORY_DEGREE + 1)], 1)
        coef = np.linalg.lstsq(a, xy, rcond=None)[0]
        if np.sqrt(((xy - a @ coef) ** 2).mean(0)).max() > TRAJECTORY_TOL:
            return
        path = a[:, 1:] @ coef[1:]   # the offset c dropped
        for e, m, s in zip(entries, measured, path):
            e.estimate, e.shift = m, (float(s[0]), float(s[1]))

    def _projective(self, pyr: Pyramid, index: int) -> None:
        """A camera that turns about its eye moves the image by a homography, which one translation fits only
        near the frame's centre (docs/temporal.md, "Pans are not translations"). Each translated ring frame
        keeps a homography from the current frame: the newest gets HOMOGRAPHY_STEPS direct steps from its
        translation, older ones are chained through it (last frame's map after the newest's) and refined
        directly on the translation's schedule. Where one departs from its translation by PROJECTIVE_MIN px at a
        corner (and none by more than a turning camera can: PROJECTIVE_RATIO), every ring frame's map is its
        homography this frame (`projective`: resolved as per-tile translations, checked per region by _alignment,
        since the band and tile checks measure translations)."""
        todo = [e for e in self.entries if e.shift is not None]
        if not todo or PROJECTIVE_MIN <= 0:
            return
        fs = pyr.flow_scale
        ref = self._last_refiner
        newest = todo[-1]
        step = ref.homography(newest.pyr.blurred("flow"), _translation(newest.shift, fs), HOMOGRAPHY_STEPS)
        newest.homography = step
        for e in todo[:-1]:
            e.homography = (e.homography @ step if e.homography is not None
                            else _translation(e.shift, fs))
            if (index - e.index - 1) % REFINE_EVERY == 0:
                e.homography = ref.homography(e.pyr.blurred("flow"), e.homography, REFINE_STEPS)
        fh, fw = pyr.flow.shape
        corners = np.array([[0, 0, 1], [fw - 1, 0, 1], [0, fh - 1, 1], [fw - 1, fh - 1, 1]], np.float64)
        gap, wild = 0.0, False
        for e in todo:
            q = corners @ e.homography.T
            q = q[:, :2] / q[:, 2:3] - corners[:, :2]
            g = float(np.abs(q - np.array(e.shift) / fs).max()) * fs
            gap = max(gap, g)
            # a turning camera's image moves at most ~2x as fast at the corners as at the centre (a 90-degree
            # lens): a homography departing more from the translation fits something else
            wild |= g > PROJECTIVE_MIN + PROJECTIVE_RATIO * math.hypot(*e.shift)
        if gap < PROJECTIVE_MIN or wild:
            return
        for e in todo:
            e.projective = True

    def _alignment(self, e: RingEntry, pyr: Pyramid) -> np.ndarray:
        """1 where ring frame e, moved by its map, matches the current frame (flow size): a map that is
        wrong over a region (a second motion that the global model averages away, a flow error) puts
        that region's samples in the wrong place, which the colour box cannot always see. Residuals
        of grey blurred by ALIGN_SIGMA above ALIGN_LEVEL that survive a 3x3 erosion (blobs, not the
        thin lines that 1-spp aliasing and sub-pixel wires leave along edges under a right map),
        grown by ALIGN_GROW texels."""
        fh, fw = pyr.flow.shape
        fs = pyr.flow_scale
        nan = None
        if e.projective:   # every texel has a position
            warped = cv2.warpPerspective(_blur_align(e.pyr), e.homography, (fw, fh),
                                         flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
        else:
            gx, gy = _texel_grid(fh, fw)
            ring = _blur_align(e.pyr)
            if e.field is not None and e.field_box is not None:
                # a field of layers: the background's translation everywhere (one affine warp), the field's
                # own positions only in the layers' box (a full-frame remap cost ~4x as much)
                ys, xs = e.field_box
                warped = cv2.warpAffine(ring, _translation(e.bg, fs)[:2], (fw, fh),
                                        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
                box = e.field[ys, xs]
                warped[ys, xs] = cv2.remap(ring, gx[ys, xs] + box[..., 0] / np.float32(fs),
                                           gy[ys, xs] + box[..., 1] / np.float32(fs), cv2.INTER_LINEAR,
                                           borderMode=cv2.BORDER_REPLICATE)
                nan = np.isnan(e.field[..., 0])   # _field writes NaN to both components
                warped[nan] = np.nan
            else:
                if e.field is None:
                    mx, my = gx + np.float32(e.shift[0] / fs), gy + np.float32(e.shift[1] / fs)
                else:
                    mx, my = gx + e.field[..., 0] / np.float32(fs), gy + e.field[..., 1] / np.float32(fs)
                warped = cv2.remap(ring, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                nan = ~np.isfinite(mx) | ~np.isfinite(my)
        cur = _blur_align(pyr)
        if "align_level" not in pyr._blur:   # the current frame's, once for every ring frame
            grad = cv2.magnitude(cv2.Sobel(cur, cv2.CV_32F, 1, 0, ksize=3, scale=0.125),
                                 cv2.Sobel(cur, cv2.CV_32F, 0, 1, ksize=3, scale=0.125))
            # a residual a misplacement of under ALIGN_PX explains is motion error the cells tolerate
            pyr._blur["align_level"] = np.float32(ALIGN_LEVEL) + np.float32(ALIGN_PX) * grad
        np.subtract(warped, cur, out=warped)   # |warped - cur|, in place (a frame-size temporary)
        np.abs(warped, out=warped)
        bad = np.less_equal(warped, pyr._blur["align_level"])
        np.logical_not(bad, out=bad)   # NaN maps are bad too
        bad = cv2.erode(bad.view(np.uint8), np.ones((3, 3), np.uint8))
        bad = cv2.dilate(bad, np.ones((2 * ALIGN_GROW + 1,) * 2, np.uint8))
        good = bad == 0
        if nan is not None:
            good &= ~nan
        return good.view(np.uint8)

    def _compose_const(self, fld: np.ndarray, d: tuple[float, float], pyr: Pyramid) -> np.ndarray:
        """field_new(x) = d + field(x + d), at the field's resolution."""
        fh, fw = fld.shape[:2]
        fs = pyr.flow_scale
        gx, gy = np.meshgrid(np.arange(fw, dtype=np.float32), np.arange(fh, dtype=np.float32))
        out = cv2.remap(fld, gx + d[0] / fs, gy + d[1] / fs, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        out += np.float32(d)
        return out

    def _parallax(self) -> bool:
        """dense_samples: does this global frame's translation fail over most of the frame (over PARALLAX_SHARE of
        the textured tiles off at every ring age checked, PARALLAX_TILES of them at least)? A camera moving forward
        or sideways past near and far content (a dolly) moves the image by a field, not one translation: the tile
        check then keeps samples only where the field happens to be near the translation, and those pass with up to
        TILE_TOL of error. A projective pan's older frames fail the translation's check too, but its newest does
        not; a few textured tiles of flat-colour art fail at random (1-spp edges move in jumps)."""
        return self.dense_samples and self.tiles_off is not None and self.tiles_off > PARALLAX_SHARE

    def _tracked_tiles(self, pyr: Pyramid, entries: list[RingEntry]) -> None:
        """dense_samples: each of `entries` (ring or look-ahead frames) gets as its map a field of per-tile
        translations, each tracked *directly* from the current frame into that frame (cv2's pyramidal Lucas-Kanade
        at tile centres DENSE_TILE flow px apart), forward-backward checked (fb_check; over DENSE_FB full-size px:
        NaN, no samples), bilinear between the centres: the parallax of a dolly or an orbit, which one translation
        and moving layers do not explain (docs/temporal.md, "Dense camera motion"). On a dense frame each tile
        starts from the ring frame's map before this frame, not composed with this frame's translation: a fast mover
        pulls that translation and the still background's tiles would lock to its texture's period. On a global
        frame with parallax (_parallax) the maps are the ring's composed and refined ones. Ring frames over
        TRACKED_AGE frames old leave the ring."""
        if entries is self.entries and len(self.entries) > TRACKED_AGE:   # the newest past frame is 1 frame old
            del self.entries[:len(self.entries) - TRACKED_AGE]
            entries = self.entries
        fs = pyr.flow_scale
        gx, gy, pts, grid_at = _tile_grid(*pyr.flow.shape[:2])
        crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
        lk = dict(winSize=(DENSE_WIN, DENSE_WIN), maxLevel=2, criteria=crit, flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
        for e in entries:
            if e.translated:
                prior = pts + np.float32([e.shift[0] / fs, e.shift[1] / fs])
            else:   # the field at the tile centres (NaN: no motion known there, start from none)
                old = e.field[gy.astype(np.int64), gx.astype(np.int64)]
                prior = pts + (np.where(np.isfinite(old), old, np.float32(0.0)) / np.float32(fs)).reshape(-1, 1, 2)
            found, ok, _ = cv2.calcOpticalFlowPyrLK(pyr.flow, e.pyr.flow, pts, prior.astype(np.float32), **lk)
            off = ((found - pts)[:, 0] * np.float32(fs)).reshape(gx.shape + (2,))
            bad = ok[:, 0] == 0
            if self.fb_check:
                back, ok2, _ = cv2.calcOpticalFlowPyrLK(e.pyr.flow, pyr.flow, found, pts.copy(), **lk)
                bad |= (ok2[:, 0] == 0) | (np.hypot(*(back - pts)[:, 0].T) * fs > DENSE_FB)
            bad = bad.reshape(gx.shape)
            off[bad] = np.nan
            # bilinear between the tile centres (each texel's grid position), extrapolated one tile past the outer
            # centres and constant beyond; NaN spreads to every texel whose read touches a bad tile
            e.field = cv2.remap(_extrapolated(off), *grid_at, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            e.shift, e.field_box, e.projective = None, None, False


@functools.lru_cache(maxsize=4)
def _tile_grid(fh: int, fw: int):
    """_tracked_tiles' tile centres on a flow-size frame (made once per size): their x and y (gh, gw), as LK points
    (n, 1, 2), and each texel's position in the grid padded by one tile each side (cv2.remap maps)."""
    half = DENSE_TILE // 2
    gy, gx = np.mgrid[half:max(fh, half + 1):DENSE_TILE, half:max(fw, half + 1):DENSE_TILE].astype(np.float32)
    # a frame under half a tile across (3x4097, 16x5) has its one centre on its last texel, not past it
    gy, gx = np.minimum(gy, np.float32(fh - 1)), np.minimum(gx, np.float32(fw - 1))
    pts = np.stack([gx.ravel(), gy.ravel()], -1)[:, None, :]
    tx, ty = np.meshgrid((np.arange(fw, dtype=np.float32) - half) / DENSE_TILE,
                         (np.arange(fh, dtype=np.float32) - half) / DENSE_TILE)
    # linear extrapolation one tile past the outer centres (a zoom's map grows to the borders), constant beyond
    grid_at = (np.clip(tx, -1, gx.shape[1]) + 1, np.clip(ty, -1, gx.shape[0]) + 1)
    for a in (gx, gy, pts, *grid_at):
        a.flags.writeable = False
    return gx, gy, pts, grid_at


def _extrapolated(grid: np.ndarray) -> np.ndarray:
    """A (gh, gw, c) grid padded by one row / column each side, linearly extrapolated (2 edge - next; a grid one
    wide repeats its edge)."""
    def pad(a: np.ndarray, axis: int) -> np.ndarray:
        n = a.shape[axis]
        first, last = np.take(a, [0], axis), np.take(a, [n - 1], axis)
        if n > 1:
            first, last = 2 * first - np.take(a, [1], axis), 2 * last - np.take(a, [n - 2], axis)
        return np.concatenate([first, a, last], axis)
    return np.ascontiguousarray(pad(pad(grid, 0), 1), dtype=np.float32)


class _Refiner:
    """Direct Gauss-Newton refinement of ring frames' translations against one current frame, and the
    per-tile check that the translation holds everywhere (flow-size grey blurred by LK_SIGMA).

    Sparse: the current frame's gradients, once per frame, pick in every TILE x TILE tile its pixels of
    largest squared gradient, REFINE_POINTS in all (flat pixels add nothing to a Gauss-Newton step; at
    1080p 16k of the 518k flow-size pixels, 68 per tile); a step samples the ring frame at those points
    only, by exact bilinear interpolation (cv2's warps quantise positions to 1/32 px), so it costs
    ~1 ms instead of a whole-frame warp (inverse-additive, as stage.global_translation).
    Tile check: one Gauss-Newton step per tile from the same residuals; where a textured tile (the
    whole tile's gradients) would move by more than TILE_TOL px from the whole frame's solution,
    another motion is there (the cut scene's second shot: a bar and a disc 0.3 px per frame apart pass
    the frame-to-frame test of choose_model and drift apart over the ring) and that tile takes no samples
    from that frame."""

    def __init__(self, cur_b: np.ndarray, points: int | None = None, grads: tuple[np.ndarray, ...] | None = None):
        """`grads`: cur_b's (gx, gy, gx gx, gx gy, gy gy) where the caller has them (Pyramid.gradients)."""
        self.last_check = None   # (bad tiles, row deviations, textured rows, column deviations, textured columns)
        points = REFINE_POINTS if points is None else int(points)
        self.h, self.w = h, w = cur_b.shape
        points = -(-points // max(-(-h // TILE) * -(-w // TILE), 1))    # per tile
        if grads is None:
            gx = cv2.Sobel(cur_b, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
            gy = cv2.Sobel(cur_b, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
            grads = (gx, gy, gx * gx, gx * gy, gy * gy)
        gx, gy, gxx, gxy, gyy = grads   # each product once: the energy and the tiles' Hessians read them
        self.ty, self.tx = h // TILE, w // TILE
        # the points: each tile's largest gradients (partial tiles at the right and bottom count too), picked by
        # argpartition of the negated energy, written negated into the padded frame (one pass less than negating
        # the tile blocks; the padding's 0 and -0 compare equal)
        t = TILE
        ny, nx = -(-h // t), -(-w // t)
        pad = np.zeros((ny * t, nx * t), np.float32)
        neg = pad[:h, :w]
        np.add(gxx, gyy, out=neg)   # the energy
        np.negative(neg, out=neg)
        neg_blocks = pad.reshape(ny, t, nx, t).transpose(0, 2, 1, 3).reshape(ny, nx, t * t)
        k = min(points, t * t)
        top = np.argpartition(neg_blocks, k - 1, axis=-1)[..., :k] if k < t * t else np.broadcast_to(
            np.arange(t * t), neg_blocks.shape)
        by, bx = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
        row, col = np.divmod(top, t)
        ys = (by[..., None] * t + row).ravel()
        xs = (bx[..., None] * t + col).ravel()
        keep = (ys < h) & (xs < w)
        ys, xs = ys[keep], xs[keep]
        keep = neg[ys, xs] < 0   # energy > 0
        ys, xs = ys[keep], xs[keep]
        self.ys, self.xs = ys.astype(np.float64), xs.astype(np.float64)
        self.iy, self.ix = ys, xs
        at = ys * w + xs   # flat indices
        self.c = cur_b.ravel().take(at).astype(np.float64)
        # the gradients and their products at the points, written into the stacks the steps' matrix products read
        self.gradients, self.products = np.empty((2, ys.size)), np.empty((3, ys.size))
        self.gx, self.gy = self.gradients
        self.gx[:], self.gy[:] = gx.ravel().take(at), gy.ravel().take(at)
        self.gxx, self.gxy, self.gyy = self.products
        np.multiply(self.gx, self.gx, out=self.gxx)
        np.multiply(self.gx, self.gy, out=self.gxy)
        np.multiply(self.gy, self.gy, out=self.gyy)
        # the points' structure tensor (the Gauss-Newton matrix but for the robust weights): its smaller eigenvalue
        # over its larger is ~0 where every gradient has one direction (straight stripes: the motion along them is
        # not measured; APERTURE_RATIO)
        a, b, e = (float(v) for v in self.products.sum(axis=1))
        half, root = (a + e) / 2, float(np.hypot((a - e) / 2, b))
        self.aperture = (half - root) / (half + root) if half + root > 0 else 1.0
        # the bands' indices and texture (the same for every step), and homography()'s steepest-descent matrix
        self.nr, self.nc = -(-h // BAND), -(-w // BAND)
        self.ry, self.cx = ys // BAND, xs // BAND
        self.band_gyy, self.band_gxx = np.bincount(self.ry, self.gyy, self.nr), np.bincount(self.cx, self.gxx, self.nc)
        self._ic: CompositionalPoints | None = None
        if self.ty and self.tx:
            # per-tile Hessians: the whole tile's for the texture test, the points' for the tile's step
            def tiles(a):
                return a[:self.ty * t, :self.tx * t].reshape(self.ty, t, self.tx, t).sum((1, 3), dtype=np.float64)
            fa, fb, fc = tiles(gxx), tiles(gxy), tiles(gyy)
            self.textured = (fa * fc - fb * fb > 1e-3 * np.maximum(fa * fc, 1e-12)) & (
                np.minimum(fa, fc) > TILE_TEXTURE * t * t)
            self.tile = (np.minimum(ys // t, self.ty - 1) * self.tx + np.minimum(xs // t, self.tx - 1))
            nt = self.ty * self.tx
            self.ta = np.bincount(self.tile, self.gxx, nt).reshape(self.ty, self.tx)
            self.tb = np.bincount(self.tile, self.gxy, nt).reshape(self.ty, self.tx)
            self.tc = np.bincount(self.tile, self.gyy, nt).reshape(self.ty, self.tx)
            self.tdet = self.ta * self.tc - self.tb * self.tb

    def _sample(self, img: np.ndarray, d: tuple[float, float]) -> np.ndarray:
        """img at the points moved by d, bilinear, positions clamped to the frame (replicated border)."""
        return self._sample_at(img, self.xs + d[0], self.ys + d[1])

    def _sample_at(self, img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """img at per-point positions (x, y), bilinear, clamped to the frame."""
        return sample_bilinear(img, x, y)

    def homography(self, ring_b: np.ndarray, m: np.ndarray, steps: int) -> np.ndarray:
        """`steps` inverse-compositional Gauss-Newton steps of the homography m with cur(x) ~ ring(m x) (flow px),
        at the points, robust weights as step() (layers.inverse_compositional)."""
        if self._ic is None:   # made on the first call: every homography of this frame reuses it
            self._ic = CompositionalPoints(self.xs, self.ys, self.gx, self.gy, (self.h, self.w), 8)
        return inverse_compositional(ring_b, m, steps, self.xs, self.ys, self.c, self.gx, self.gy, (self.h, self.w),
                                     8, LK_ROBUST, self._ic)

    def _band_steps(self, rgx: np.ndarray, rgy: np.ndarray):
        """Each row band's 1-D vertical step and each column band's horizontal step from the residuals times the
        gradients at the points (rgx = r gx, rgy = r gy), with whether the band has the texture to measure it."""
        gyy, gxx = self.band_gyy, self.band_gxx
        with np.errstate(divide="ignore", invalid="ignore"):
            dy = np.bincount(self.ry, rgy, self.nr) / gyy
            dx = np.bincount(self.cx, rgx, self.nc) / gxx
        return (dy, gyy > BAND_TEXTURE * BAND * self.w), (dx, gxx > BAND_TEXTURE * BAND * self.h)

    def _band_deviations(self, bands, step: tuple[float, float]):
        """How far each row band's own 1-D step across its edges (vertical; column bands: horizontal) departs
        from the frame's, with whether the band has the texture to measure it: (dy, ty, dx, tx). A band
        departing by over BAND_TOL px holds a second motion along long, near-horizontal or near-vertical edges,
        which a tile cannot measure (an aliased edge of slope 1/L moves in 1-px jumps every L px; a band spans
        several); but 1-spp aliasing alone makes some depart by 0.4-0.6 px at any age, so MotionRing._refine
        keeps only those whose deviation grows with age (_bands_growing). `bands`: _band_steps of the residuals."""
        (dy, ty), (dx, tx) = bands
        return dy - step[1], ty, dx - step[0], tx

    def _band_weights(self, d: tuple[float, float], bands, step: tuple[float, float]) -> np.ndarray | None:
        """Per point weights for the next step: 0 in a band of still content, 1 elsewhere. Still content
        is the one other motion that is common and known in advance (titles, borders, letterboxing over
        a pan); a band whose own motion (d + its step) is under STATIC_TOL while the frame's is over
        twice that holds it, and averaging it in biases the translation (the bench pan: (-0.33, -0.06)
        px per frame against (-0.35, -0.15) for what moves: its static strip borders). The band check
        then masks those bands too (their deviation from the frame grows with the ring frame's age)."""
        if STATIC_TOL <= 0:
            return None
        (dy, ty), (dx, tx) = bands
        fy, fx = d[1] + step[1], d[0] + step[0]
        with np.errstate(invalid="ignore"):
            sy = ty & (np.abs(d[1] + dy) < STATIC_TOL) & (abs(fy) > 2 * STATIC_TOL)
            sx = tx & (np.abs(d[0] + dx) < STATIC_TOL) & (abs(fx) > 2 * STATIC_TOL)
        if not sy.any() and not sx.any():
            return None
        return (~sy[self.ry] & ~sx[self.cx]).astype(np.float64)

    def step(self, ring_b: np.ndarray, d: tuple[float, float], check: bool = True,
             weights: np.ndarray | None = None, mask: bool = True):
        """One step from d (flow px, cur(x) ~ ring(x + d)): returns (new d, valid mask or None).
        weights: per point (the previous step's band_weights); self.band_weights: this step's. mask=False: the
        check's valid mask is not made (None; the caller makes its own from last_check)."""
        h, w = self.h, self.w
        r = self._sample(ring_b, d)
        np.subtract(self.c, r, out=r)
        wr = r * r   # 1 / (1 + (r / LK_ROBUST)^2), in place
        wr *= 1.0 / (LK_ROBUST * LK_ROBUST)
        wr += 1.0
        np.divide(1.0, wr, out=wr)
        if weights is not None:
            wr *= weights
        a, b_, e = (float(v) for v in self.products @ wr)   # matrix-vector products: faster than five reductions
        bx, by = (float(v) for v in self.gradients @ (wr * r))
        det = a * e - b_ * b_
        step = (0.0, 0.0)
        if det > 1e-6 * max(a * e, 1e-12):
            step = ((e * bx - b_ * by) / det, (a * by - b_ * bx) / det)
        new = (d[0] + step[0], d[1] + step[1])
        rgx, rgy = r * self.gx, r * self.gy   # the bands' and the tiles' right-hand sides
        bands = self._band_steps(rgx, rgy) if STATIC_TOL > 0 or check else None   # once for the weights and the check
        self.band_weights = self._band_weights(d, bands, step)
        if not check or not (self.ty and self.tx):
            return new, None
        nt = self.ty * self.tx
        tbx = np.bincount(self.tile, rgx, nt).reshape(self.ty, self.tx)
        tby = np.bincount(self.tile, rgy, nt).reshape(self.ty, self.tx)
        with np.errstate(divide="ignore", invalid="ignore"):
            sx = (self.tc * tbx - self.tb * tby) / self.tdet
            sy = (self.ta * tby - self.tb * tbx) / self.tdet
        bad = self.textured & (np.hypot(sx - step[0], sy - step[1]) > TILE_TOL)
        dy, ty, dx, tx = self._band_deviations(bands, step)
        self.last_check = (bad, dy, ty, dx, tx)   # the tiles and bands of this check (MotionRing._refine)
        if not mask:
            return new, None
        return new, self.valid_of(bad, ty & (np.abs(dy) > BAND_TOL), tx & (np.abs(dx) > BAND_TOL))

    def refine(self, ring_b: np.ndarray, d: tuple[float, float], steps: int, mask: bool = True):
        """`steps` steps from d (flow px), each with the previous one's band weights, the last with the checks:
        returns (d, valid mask or None, the last check's (bad tiles, dy, ty, dx, tx) or None). mask=False: no
        valid mask (None) where the caller makes its own from the check (step)."""
        weights, valid, self.last_check = None, None, None
        for k in range(steps):
            d, valid = self.step(ring_b, d, check=k == steps - 1, weights=weights, mask=mask)
            weights = self.band_weights
        check, self.last_check = self.last_check, None
        return d, valid, check

    def valid_of(self, bad: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray | None:
        """The valid mask (flow size) without the bad tiles, row bands and column bands; None: all valid."""
        h, w = self.h, self.w
        if not bad.any() and not rows.any() and not cols.any():
            return None
        # rows and columns outside the bad bands, then the bad tiles cleared through a (tiles, TILE, tiles, TILE)
        # view of the frame's whole tiles (no full-size index masks)
        ok = ~np.repeat(rows, BAND)[:h, None] & ~np.repeat(cols, BAND)[:w]
        tiles = ok[:self.ty * TILE, :self.tx * TILE].reshape(self.ty, TILE, self.tx, TILE)   # a view
        tiles &= ~bad[:, None, :, None]
        valid = ok.view(np.uint8)
        # the last partial row/column of tiles follows its neighbour (band masks included: measured so,
        # bench pan error removed 0.732; masking the bands after this copy gave 0.721)
        if self.ty * TILE < h:
            valid[self.ty * TILE:, :] = valid[self.ty * TILE - 1:self.ty * TILE, :]
        if self.tx * TILE < w:
            valid[:, self.tx * TILE:] = valid[:, self.tx * TILE - 1:self.tx * TILE]
        return valid


def _band_slopes(checks: list) -> tuple[np.ndarray, np.ndarray]:
    """Each band's deviation per frame of age: the least-squares slope, with an intercept, of its deviations from
    the frame's motion against the ages of the ring frames checked this frame (row bands vertical, column bands
    horizontal)."""
    def fit(pairs):
        ages = np.array([a for a, _, _ in pairs], np.float64)[:, None]
        dev = np.stack([np.nan_to_num(d) for _, d, _ in pairs])
        w = np.stack([t for _, _, t in pairs]).astype(np.float64)
        sw, sa, saa = w.sum(0), (w * ages).sum(0), (w * ages * ages).sum(0)
        sd, sad = (w * dev).sum(0), (w * ages * dev).sum(0)
        with np.errstate(divide="ignore", invalid="ignore"):
            v = (sad * sw - sa * sd) / (sw * saa - sa * sa)
        return np.where(np.isfinite(v), v, 0.0)
    return (fit([(a, dy, ty) for _, a, (_, dy, ty, _, _) in checks]),
            fit([(a, dx, tx) for _, a, (_, _, _, dx, tx) in checks]))


def _bands_growing(slopes, age: int, dy, ty, dx, tx) -> tuple[np.ndarray, np.ndarray]:
    """Bands off for a ring frame of this age: its deviation over BAND_TOL *and* growing with age (slope x age over
    BAND_GROWTH x BAND_TOL), or its deviation over BAND_FAR."""
    vr, vc = slopes
    def off(v, d, t):
        d = np.abs(np.nan_to_num(d))
        return t & (((d > BAND_TOL) & (np.abs(v * age) > BAND_GROWTH * BAND_TOL)) | (d > BAND_FAR))
    return off(vr, dy, ty), off(vc, dx, tx)


@dataclass
class TileShifts:
    """A ring frame's map as one translation per tile of TILE_ROWS x LANES pixels (projective maps: the homography
    at each tile's centre): shifts (tiles down, tiles across, 2) float32, full-size px."""

    shifts: np.ndarray


def tile_shifts(m: np.ndarray | None, width: int, height: int, fs: int) -> TileShifts:
    """The per-tile translations of the homography m (flow px, current -> ring frame; None: identity)."""
    ty, tx = -(-height // TILE_ROWS), -(-width // LANES)
    cy = np.minimum(np.arange(ty) * TILE_ROWS + (TILE_ROWS - 1) / 2.0, height - 1)
    cx = np.minimum(np.arange(tx) * LANES + (LANES - 1) / 2.0, width - 1)
    gx, gy = np.meshgrid(cx, cy)
    if m is None:
        return TileShifts(np.zeros((ty, tx, 2), np.float32))
    fx, fy = (gx + 0.5) / fs - 0.5, (gy + 0.5) / fs - 0.5
    den = m[2, 0] * fx + m[2, 1] * fy + m[2, 2]
    px = ((m[0, 0] * fx + m[0, 1] * fy + m[0, 2]) / den + 0.5) * fs - 0.5
    py = ((m[1, 0] * fx + m[1, 1] * fy + m[1, 2]) / den + 0.5) * fs - 0.5
    return TileShifts(np.stack([px - gx, py - gy], -1).astype(np.float32))


@functools.lru_cache(maxsize=4)
def _texel_grid(fh: int, fw: int) -> tuple[np.ndarray, np.ndarray]:
    """Each texel's x and y (float32, read-only), made once per flow size."""
    gx, gy = np.meshgrid(np.arange(fw, dtype=np.float32), np.arange(fh, dtype=np.float32))
    gx.flags.writeable = gy.flags.writeable = False
    return gx, gy


def _translation(shift: tuple[float, float], fs: int) -> np.ndarray:
    """The homography of a translation by `shift` full-size px, in flow px."""
    return translation_map((shift[0] / fs, shift[1] / fs))


def _blur_align(pyr: Pyramid) -> np.ndarray:
    """The flow-size grey blurred by ALIGN_SIGMA, computed once per frame."""
    if "align" not in pyr._blur:
        pyr._blur["align"] = cv2.GaussianBlur(pyr.flow.astype(np.float32), (0, 0), ALIGN_SIGMA)
    return pyr._blur["align"]


# --- numpy reference of the resolve --------------------------------------------------------------------
def linear_of(frame: np.ndarray, bgr: bool, linear_input: bool = False, transfer: str | None = None) -> np.ndarray:
    """(H, W, 3) float32 linear RGB of a frame, by the kernel's arithmetic (decode table / tables; integer codes of
    a `transfer`: its decode, light relative to reference white)."""
    fmt = with_transfer(frame_format(frame, bgr), transfer)
    h, w = fmt.height, fmt.width
    raw = np.asarray(frame).reshape(h, w, fmt.channels)
    if np.issubdtype(fmt.dtype, np.integer) and not linear_input:
        lin = decode_table(fmt)[raw.astype(np.int64)]   # the transfer's decode where fmt carries one
    else:
        a = raw.astype(np.float32) * np.float32(1.0 / _PMAX[fmt.dtype])   # load_px's normalisation
        lin = a if linear_input else lut_read(device_luts(), a).astype(np.float32)
    if fmt.channels == 1:
        return np.repeat(lin, 3, -1).astype(np.float32)
    rgb = lin[..., 2::-1] if fmt.bgr else lin[..., :3]
    return np.ascontiguousarray(rgb, dtype=np.float32)


def level_table(fmt) -> np.ndarray:
    """ltab: the ring sample L of every stored code of an integer format (one entry for float frames):
    linear light (the decode table) in 16-bit fixed point, L = floor(clamp(lin, 0, 1) 65535 + 0.5). Codes of a
    transfer (HDR video: light up to 49 times reference white, which a clip at 1 would flatten) are held as
    linear float frames are: L = lin / LINEAR_RANGE rounded as ring_of rounds them, at most ONE - 1, OVER over the
    range (PQ above 3250 cd/m2)."""
    if not np.issubdtype(fmt.dtype, np.integer):
        return np.zeros(1, np.uint16)
    lin = decode_table(fmt)
    if fmt.transfer is None:
        return np.floor(np.clip(lin, 0, 1) * np.float32(ONE) + np.float32(0.5)).astype(np.uint16)
    f32 = np.float32
    x = (lin * f32(1.0 / LINEAR_RANGE)).astype(f32)
    q = np.where(x > 0, np.minimum(x * f32(ONE) + f32(0.5), f32(ONE - 1)), f32(0)).astype(np.uint16)
    return np.where(lin > LINEAR_RANGE, OVER, q).astype(np.uint16)


def encode_table(fmt) -> np.ndarray:
    """etab: the stored code of every L (65536 entries) for an integer format (one entry for float frames):
    the encode table read at L / 65535 (colour.lut_read), rounded as store_px does; codes of a transfer: the light
    L / 65535 x LINEAR_RANGE (level_table) through the transfer's encode as the spatial passes read it
    (common.cl encode_mix: encode_arg, then the table)."""
    if not np.issubdtype(fmt.dtype, np.integer):
        return np.zeros(1, fmt.dtype)
    f32 = np.float32
    if fmt.transfer is None:
        x = np.arange(ONE + 1, dtype=f32) * f32(1.0 / ONE)
    else:
        x = encode_arg(np.arange(ONE + 1, dtype=f32) * (f32(LINEAR_RANGE) / f32(ONE)), fmt.transfer)
    table = with_transfer_tables(device_luts(), fmt.transfer)[2 * (LUT_SIZE + 1):]
    enc = lut_read(table, x).astype(f32)
    pmax = f32(_PMAX[fmt.dtype])
    return np.floor(np.clip(enc * pmax + f32(0.5), 0, pmax)).astype(fmt.dtype)


def ring_range(dtype, linear_input: bool, transfer: str | None = None) -> int:
    """The linear light the ring's 16 bits span, [0, range] (kernels/tss.cl TSS_RANGE): LINEAR_RANGE for linear-light
    float frames and for integer codes of a transfer (HDR video, level_table), else 1."""
    integer = np.issubdtype(np.dtype(dtype), np.integer)
    if (linear_input and not integer) or (transfer is not None and integer and not linear_input):
        return LINEAR_RANGE
    return 1


def ring_of(frame: np.ndarray, bgr: bool, linear_input: bool = False, transfer: str | None = None) -> np.ndarray:
    """(H, W, 3) int32 ring samples L of a frame, as kernels/tss.cl's tss_ingest stores them (float frames and
    integer codes of a `transfer`: at most ONE - 1, OVER where the stored value is over the ring's range)."""
    fmt = with_transfer(frame_format(frame, bgr), transfer)
    if np.issubdtype(fmt.dtype, np.integer) and not linear_input:
        raw = np.asarray(frame).reshape(fmt.height, fmt.width, fmt.channels).astype(np.int64)
        q = level_table(fmt)[raw].astype(np.int32)
        if fmt.channels == 1:
            return np.repeat(q, 3, -1)
        return np.ascontiguousarray(q[..., 2::-1] if fmt.bgr else q[..., :3])
    rng = ring_range(fmt.dtype, linear_input)
    lin = linear_of(frame, bgr, linear_input)
    if rng != 1:
        lin = (lin * np.float32(1.0 / rng)).astype(np.float32)
    raw = linear_of(frame, bgr, True)                  # the stored values, in RGB order
    t = lin * np.float32(ONE) + np.float32(0.5)
    q = np.where(lin > 0, np.minimum(t, np.float32(ONE - 1)), np.float32(0)).astype(np.int32)
    return np.where(raw > rng, OVER, q).astype(np.int32)


def tss_reference(spatial_q: np.ndarray, cur_q: np.ndarray, ring: list[tuple],
                  flow_scale: int = 1, grid: int = GRID, eps: float = EPS,
                  min_cells: int = MIN_CELLS, full_cells: int | None = None,
                  top: int = ONE, rng: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The resolve in numpy: returns (out L (H, W, 3) int32, filled cells (H, W) uint8); spatial_q and
    cur_q are the spatial output's and the current input's ring samples (ring_of). `top`: the largest in-range
    sample (float frames ONE - 1: above it a sample is over range, a box holding one keeps the spatial pixel);
    `rng`: the linear light the ring spans (ring_range).

    ring: (ring samples, map, valid) triples: samples as ring_of gives them (16-bit fixed-point linear),
    map = (dx, dy) translation or a (fh, fw, 2) field at 1/flow_scale, valid = None or (fh, fw) uint8 at
    1/flow_scale (0: no sample of that frame there, read at the flow texel holding the output pixel); the
    current frame itself is one of them (identity); cur_q = its ring samples (the colour box)."""
    f32 = np.float32
    h, w = cur_q.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(f32)
    pad = np.pad(cur_q, ((1, 1), (1, 1), (0, 0)), mode="edge")
    taps = [pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    epsq = eps_q(eps, rng)
    lo = np.minimum.reduce(taps) - epsq
    mx = np.maximum.reduce(taps)
    hi = np.minimum(mx + epsq, top)
    # a flat 3x3 neighbourhood, or one over range: n = 0, the spatial pixel stands
    still = (lo == mx - epsq).all(-1) | (mx > top).any(-1)
    g2 = grid * grid
    full_cells = FULL_CELLS if full_cells is None else full_cells
    sums = np.zeros((h, w, g2, 3), np.int64)
    counts = np.zeros((h, w, g2), np.int32)
    flat = np.arange(h * w)
    for q, m, ok in ring:
        if isinstance(m, TileShifts):
            # per tile one translation: the whole-pixel offset and the cell come from it alone, as the host's
            # tables for tss_resolve_shift give them (the pixel's own position adds whole pixels)
            d = m.shifts[np.minimum(ys.astype(np.int64) // TILE_ROWS, m.shifts.shape[0] - 1),
                         np.minimum(xs.astype(np.int64) // LANES, m.shifts.shape[1] - 1)]
            whole = np.floor(d + f32(0.5))
            px, py = xs + whole[..., 0], ys + whole[..., 1]
            ox, oy = (whole[..., 0] - d[..., 0]).astype(f32), (whole[..., 1] - d[..., 1]).astype(f32)
        elif isinstance(m, np.ndarray):
            off = sample_field(m, flow_scale, xs, ys)
            px, py = xs + off[..., 0], ys + off[..., 1]
        else:
            px, py = xs + f32(m[0]), ys + f32(m[1])
        valid = np.isfinite(px) & np.isfinite(py)
        if ok is not None:
            fh, fw = ok.shape
            valid &= ok[np.minimum(ys.astype(np.int64) // flow_scale, fh - 1),
                        np.minimum(xs.astype(np.int64) // flow_scale, fw - 1)] > 0
        px, py = np.where(valid, px, 0).astype(f32), np.where(valid, py, 0).astype(f32)
        if isinstance(m, TileShifts):
            sx, sy = px, py
        else:
            sx, sy = np.floor(px + f32(0.5)), np.floor(py + f32(0.5))
            ox, oy = sx - px, sy - py                              # in [-0.5, 0.5)
        valid &= (sx >= 0) & (sx <= w - 1) & (sy >= 0) & (sy <= h - 1)
        cx = np.clip(np.floor((ox + f32(0.5)) * f32(grid)), 0, grid - 1).astype(np.int64)
        cy = np.clip(np.floor((oy + f32(0.5)) * f32(grid)), 0, grid - 1).astype(np.int64)
        v = q[np.clip(sy, 0, h - 1).astype(np.int64), np.clip(sx, 0, w - 1).astype(np.int64)]
        valid &= ((v >= lo) & (v <= hi)).all(-1)
        cell = (cy * grid + cx).ravel()
        sel = valid.ravel()
        sums.reshape(-1, g2, 3)[flat[sel], cell[sel]] += v.reshape(-1, 3)[sel]
        counts.reshape(-1, g2)[flat[sel], cell[sel]] += 1
    n = np.where(still, 0, (counts > 0).sum(-1))
    m = np.zeros((h, w, 3), f32)
    for k in range(g2):     # cells in ascending order, each (float)sum * (1 / count), as the kernels add them
        c = counts[..., k]
        inv = (f32(1.0) / np.maximum(c, 1).astype(f32))[..., None]
        m = np.where((c > 0)[..., None], m + sums[..., k, :].astype(f32) * inv, m).astype(f32)
    fn = np.maximum(n, 1).astype(f32)[..., None]
    a = np.where(n < full_cells, n.astype(f32) / f32(full_cells), f32(1.0)).astype(f32)[..., None]
    sp = spatial_q.astype(f32)
    t = (sp + (m / fn - sp) * a + f32(0.5)).astype(f32)
    out = np.where(t > 0, np.where(t < f32(ONE), t, f32(ONE)), f32(0)).astype(np.int32)
    return out, n.astype(np.uint8)


def eps_q(eps: float, rng: int = 1) -> int:
    """The colour box's widening in ring units (16-bit fixed-point linear over [0, rng])."""
    return int(round(float(eps) * ONE / rng))


def encode_levels(q: np.ndarray, like: np.ndarray, bgr: bool, linear_input: bool = False,
                  transfer: str | None = None) -> np.ndarray:
    """Ring samples L (H, W, 3) back to the frame's type and layout (alpha taken from `like`), as
    tss_store does: etab for integer frames (codes of a `transfer`: its etab), the encode table for float frames,
    L / ONE for linear input."""
    f32 = np.float32
    fmt = with_transfer(frame_format(like, bgr), transfer)
    h, w = fmt.height, fmt.width
    raw = np.asarray(like).reshape(h, w, fmt.channels)
    if linear_input:
        x = q.astype(f32) * (f32(ring_range(fmt.dtype, True)) / f32(ONE))
        pmax = f32(_PMAX[fmt.dtype])
        stored = x if fmt.dtype == np.float32 else np.floor(np.clip(x * pmax + f32(0.5), 0, pmax)).astype(fmt.dtype)
    elif np.issubdtype(fmt.dtype, np.integer):
        stored = encode_table(fmt)[q]
    else:
        stored = lut_read(device_luts()[2 * (LUT_SIZE + 1):], q.astype(f32) * f32(1.0 / ONE)).astype(fmt.dtype)
    if fmt.channels == 1:
        out = stored[..., :1]       # grey frames: the three channels are equal by construction
    else:
        rgb = stored[..., ::-1] if fmt.bgr else stored
        out = np.concatenate([rgb, raw[..., 3:4]], -1) if fmt.channels == 4 else rgb
    return out.reshape(np.shape(like)).astype(np.asarray(like).dtype)


def tss_frame_reference(spatial: np.ndarray, cur: np.ndarray, ring: list[tuple], bgr: bool,
                        flow_scale: int = 1, grid: int = GRID, eps: float = EPS,
                        min_cells: int = MIN_CELLS, full_cells: int | None = None,
                        linear_input: bool = False, transfer: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """kernels/tss.cl on whole frames: ring = (input frame, map, valid) triples (frames in the input's
    type); returns (output frame like `spatial`, filled cells (H, W) uint8). Where fewer than
    min_cells are filled, or the spatial pixel is over range (float frames, codes of a transfer), the spatial pixel
    is copied bit for bit. `transfer`: integer frames are codes of it (HDR video: the ring holds their light)."""
    rq = [(ring_of(f, bgr, linear_input, transfer), m, ok) for f, m, ok in ring]
    dtype = frame_format(spatial, bgr).dtype
    rng = ring_range(dtype, linear_input, transfer)
    top = ONE if np.issubdtype(dtype, np.integer) and rng == 1 else ONE - 1
    sq = ring_of(spatial, bgr, linear_input, transfer)
    q, n = tss_reference(sq, ring_of(cur, bgr, linear_input, transfer), rq, flow_scale, grid, eps, min_cells,
                         full_cells, top, rng)
    enc = encode_levels(q, spatial, bgr, linear_input, transfer)
    keep = ((n < min_cells) | (sq > top).any(-1)).reshape(n.shape + (1,) * (np.ndim(spatial) - 2))
    keep = keep | within_dead_zone(enc, spatial, bgr, linear_input)
    if rng != 1 and np.issubdtype(dtype, np.integer):
        # codes of a transfer: the spatial pixel also stands where the resolve is within one ring step of its L in
        # every channel (the ring's step spans more than one 8-bit level of PQ's codes below ~0.2 cd/m2; tss.cl)
        keep = keep | (np.abs(q - sq) <= 1).all(-1).reshape(keep.shape)
    return np.where(keep, spatial, enc).astype(spatial.dtype), n


def within_dead_zone(out: np.ndarray, spatial: np.ndarray, bgr: bool, linear_input: bool = False) -> np.ndarray:
    """True (shaped to broadcast over the channels) where every colour channel of `out` is within one
    8-bit level of the spatial output's (DEAD_CODES codes of an integer frame, 1/255 of a float one):
    there the resolve moved the pixel by no more than rounding and codec noise would, and the spatial
    pixel is kept (bench rendered_pan: such 1-level moves on 3 % of the pixels away from edges raised
    damage 0.397 -> 0.400; docs/temporal.md)."""
    fmt = frame_format(spatial, bgr)
    h, w = fmt.height, fmt.width
    a = np.asarray(out).reshape(h, w, fmt.channels)[..., :min(fmt.channels, 3)]
    b = np.asarray(spatial).reshape(h, w, fmt.channels)[..., :min(fmt.channels, 3)]
    if linear_input:   # one level of the sRGB-encoded values (the encode table, as the kernel reads it); above
        # 1 as if the brighter of the two were shown at white
        f32, table = np.float32, device_luts()[2 * (LUT_SIZE + 1):]
        scale = f32(1.0 / _PMAX[fmt.dtype])
        a, b = a.astype(f32) * scale, b.astype(f32) * scale
        top = np.maximum(a, b)
        k = np.where(top > 1, f32(1.0) / np.where(top > 1, top, f32(1)), f32(1)).astype(f32)
        ea = lut_read(table, (a * k).astype(f32)).astype(f32)
        eb = lut_read(table, (b * k).astype(f32)).astype(f32)
        dead = (np.abs(ea - eb) <= f32(1.0 / 255.0)).all(-1)
    elif np.issubdtype(fmt.dtype, np.integer):
        dead = (np.abs(a.astype(np.int64) - b.astype(np.int64)) <= dead_codes(fmt.dtype)).all(-1)
    else:
        dead = (np.abs(a.astype(np.float32) - b.astype(np.float32)) <= np.float32(1.0 / 255.0)).all(-1)
    return dead.reshape((h, w) + (1,) * (np.ndim(spatial) - 2))


def dead_codes(dtype) -> int:
    """One 8-bit level in the codes of an integer frame type (uint8: 1, uint16: 257)."""
    return int(round(float(_PMAX[np.dtype(dtype)]) / 255.0))


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
