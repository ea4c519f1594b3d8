"""Motion of every ring frame relative to the current one, for temporal supersampling (mlaa_stream.temporal.tss):
which input frames the ring keeps and how the current frame's pixels map into each of them.

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
from dataclasses import dataclass, field

import cv2
import numpy as np

from mlaa_stream.temporal.layers import (STILL_AGE, STILL_SHIFT, CompositionalPoints, ahead_fields, background_of,
                                         find_layers, inverse_compositional, layer_fields, layers_decision,
                                         sample_bilinear, still_background, translation_map)
from mlaa_stream.temporal.stage import LK_ROBUST, Decision, Pyramid, choose_model, dis_refuses


DEFAULT_FRAMES = 16   # K: ring frames (the current one included)
NEWEST_STEPS = 2      # Gauss-Newton steps per frame for the newest ring frame (MotionRing._refine)
REFINE_STEPS = 2      # ... and for each older ring frame refined in that frame
REFINE_EVERY = 3      # older ring frames refined directly at ages 1 + a multiple of this (docs/temporal.md)
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
