"""The FXAA fallback: FXAA 3.11 for the pixels the MLAA passes left, where the frame shows 1-spp aliasing.

Runs after blending (and bridging) in the default chain (Filter(fallback=True)); kernels/fallback.cl says
what it does and why. `fallback_reference` computes the same in numpy.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from mlaa_stream.device.colour import device_luts, lut_read
from mlaa_stream.device.context import Context
from mlaa_stream.device.formats import LUT_SIZE, FrameFormat, frame_format
from mlaa_stream.spatial.footprint import (BUCKETS, STRENGTH_FLOOR, STRENGTH_LEVELS, STRENGTH_REF, WEIGHTS,
                                           footprint_reference, table_of)
from mlaa_stream.spatial.fxaa import _MAX, fxaa_defines, fxaa_mix_reference, luma_reference
from mlaa_stream.spatial.noise import NOISE_BINS, noise_defines, quiet_pixels
from mlaa_stream.spatial.overlays import overlay_defines, overlay_tiles
from mlaa_stream.spatial.refine import REFINE_GATE, REFINE_WEIGHTS, gate, refine_reference, refine_table_of
from mlaa_stream.spatial.shots import HELD_SUPERSAMPLED_RUN, RENDER_HOLD_FRAMES

SEGMENT = 64  # pixels of a tile band per work item of count_changed (a multiple of FALLBACK_TILE)

# Tiles of FALLBACK_TILE^2 pixels; a pixel's region is its tile and the eight around it. A pixel is eligible where
# it borders an edge and its region is busy 1-spp content -- at least FALLBACK_RICH_MIN pixels that MLAA changed
# and whose 3x3 window holds FALLBACK_COLOURS bit-identical colours or more, and at least 1 / FALLBACK_RICH_DIV of
# the region's edge-bordering pixels -- or, if MLAA left it, where its region holds FALLBACK_MIN_CHANGED pixels
# that MLAA changed and its own window FALLBACK_COLOURS colours (equal within FALLBACK_SAME / 255 of full scale
# per channel). A pixel MLAA left
# takes FALLBACK_WEIGHT of FXAA's colour, one it changed moves FALLBACK_MIX of the way from MLAA's to FXAA's.
FALLBACK_TILE, FALLBACK_MIN_CHANGED, FALLBACK_COLOURS, FALLBACK_SAME, FALLBACK_WEIGHT = 8, 24, 4, 2.5, 0.8
FALLBACK_RICH_MIN, FALLBACK_RICH_DIV, FALLBACK_MIX = 12, 20, 0.5
# ... except a pixel on a straight edge run of FALLBACK_KEEP_RUN pixels or more: MLAA's verdict on a straight edge
# stands, so pixel-aligned rules and stems keep their sharpness where noise or compression makes windows busy.
FALLBACK_KEEP_RUN = 16
# In render regions (below) the run must be REGION_KEEP_RUN pixels or more, for FXAA and the footprint tables: a
# render's straight runs of 16-31 px are mostly edges at sub-pixel offsets (docs/spatial_tuning.md, "REGION_KEEP_RUN").
REGION_KEEP_RUN = 32
# Render regions (kernels/fallback.cl): a tile whose neighbourhood of RENDER_RADIUS tiles each way holds at least
# RENDER_MIN busy pixels in tiles of a luma range of RENDER_RANGE or more, busy pixels at least 1 / RENDER_DIV of its
# edge-bordering pixels, and busy tiles with on average at most RENDER_NEAR_PCT % of their pixels within a tenth of
# the tile's luma range from its extremes, counts as busy, and every pixel there takes the footprint table
# (spatial/footprint.py): the point samples of a 1-spp render towards the average over their footprint. A frame in
# which at least RENDER_FRAME_PCT % of the tiles holding edge-bordering pixels are render regions is a render: there
# every tile whose neighbourhood holds a busy pixel is a region (thin features on flat backgrounds are two-toned in
# renders too, and a video codec's smoothing fails the busy counts; flat-colour art has no busy pixel).
RENDER_RADIUS, RENDER_MIN, RENDER_DIV, RENDER_NEAR_PCT, RENDER_RANGE = 7, 48, 10, 88, 24 / 255
RENDER_FRAME_PCT = 45
# In a frame whose hard stair ends are SUPERSAMPLED_HARD_PCT % or more of its strong steps (1-spp geometry, below),
# busy pixels need only be 1 / RENDER_DIV_1SPP of the edge-bordering ones: a video codec's blur makes the MLAA passes
# skip many of a compressed render's edges as already antialiased (docs/spatial_tuning.md, "RENDER_DIV_1SPP").
RENDER_DIV_1SPP = 20
# A supersampled frame (several samples per pixel, or downscaled) is no 1-spp render: where at least SUPERSAMPLED_PCT %
# of the luma steps of SUPERSAMPLED_STEP or more between neighbours (px_luma clipped to 1; in the tiles holding
# edge-bordering pixels, a quarter of them sampled; at least SUPERSAMPLED_MIN steps) are ramps -- the step before or
# after goes the same way by half as much or more -- no pixel outside render regions takes FXAA (1-spp renders with
# procedural textures 0-9 %, supersampled ones 21-47 %: docs/spatial_tuning.md, "SUPERSAMPLED_PCT") ...
SUPERSAMPLED_STEP, SUPERSAMPLED_PCT, SUPERSAMPLED_MIN = 0.2, 14, 64
# ... and there render regions are judged locally: a tile stays one where, in its neighbourhood's sampled tiles,
# under RENDER_RAMP_PCT % of the clean transitions are ramps -- a transition is clean where the luma steps beside
# it are at most RAMP_FLANK of it: a hard step at a stair's end (1-spp geometry) or one pixel between two plateaus
# (a coverage blend; a magnified texture's too). Photographic textures push a 1-spp render's frame-wide ramp share
# to 21 %, its geometric edges stay hard (docs/spatial_tuning.md, "RENDER_RAMP_PCT").
RENDER_RAMP_PCT, RAMP_FLANK = 50, 0.2
# A frame is judged supersampled too where SUPERSAMPLED_CLEAN_PCT % or more of its clean transitions (at least
# SUPERSAMPLED_MIN) are ramps: photo-textured renders with 3x3 samples per pixel whose strong steps are under
# SUPERSAMPLED_PCT % ramps (1-spp renders: 0-73 %, photo-textured ones the top; docs/spatial_tuning.md).
SUPERSAMPLED_CLEAN_PCT = 75
# Neither makes a frame supersampled where SUPERSAMPLED_HARD_PCT % or more of its strong steps are hard stair ends
# (clean transitions that are no ramps): 1-spp geometry, whatever ramps its textures make (1-spp renders that their
# photographic textures' ramps took for supersampled 10.0-22.8 %, 3x3-sampled frames 1.0-9.5 %, 2x2-sampled
# 3.6-14.6 %; docs/spatial_tuning.md, "SUPERSAMPLED_HARD_PCT").
SUPERSAMPLED_HARD_PCT = 12
COUNTS, NOT_MEASURED = 16, 255  # bytes per tile of count_changed's output (9 used); k = 3 of a tile not measured
SHOW_DIM = 0.35  # Filter(show="regions"): pixels outside render regions keep this share of their colour

def fallback_defines(fmt: FrameFormat, linear: bool, linear_input: bool, everywhere: bool = False,
                     regions: bool = True, table: bool = True, refine: bool = False) -> dict:
    """Defines for kernels/fallback.cl (FXAA's own at the shader's defaults, plus FALLBACK_*); `everywhere`
    drops the region and colour tests: every edge-bordering pixel is eligible; `regions` False: no render
    regions (no tile is one unless `everywhere`); `table` False: render regions without the footprint table;
    `refine`: the refine table's kernel (spatial/refine.py) is built too."""
    return {**fxaa_defines(fmt, linear=linear, linear_input=linear_input), "SEGMENT": SEGMENT,
            "FALLBACK_TILE": FALLBACK_TILE, "FALLBACK_MIN_CHANGED": 0 if everywhere else FALLBACK_MIN_CHANGED,
            "FALLBACK_COLOURS": 0 if everywhere else FALLBACK_COLOURS, "FALLBACK_SAME": float(FALLBACK_SAME / 255.0),
            "FALLBACK_SAME_LEVELS": int(np.floor(FALLBACK_SAME / 255.0 * _MAX[np.dtype(fmt.dtype)])),
            "FALLBACK_WEIGHT": float(FALLBACK_WEIGHT), "FALLBACK_MIX": float(FALLBACK_MIX),
            "FALLBACK_RICH_MIN": FALLBACK_RICH_MIN, "FALLBACK_RICH_DIV": FALLBACK_RICH_DIV,
            "FALLBACK_KEEP_RUN": 0 if everywhere else FALLBACK_KEEP_RUN,
            "REGION_KEEP_RUN": 0 if everywhere else REGION_KEEP_RUN, "RENDER_RADIUS": RENDER_RADIUS,
            "RENDER_MIN": RENDER_MIN, "RENDER_DIV": RENDER_DIV, "RENDER_DIV_1SPP": RENDER_DIV_1SPP,
            "RENDER_NEAR_PCT": RENDER_NEAR_PCT,
            "RENDER_FRAME_PCT": RENDER_FRAME_PCT, "RENDER_HOLD_FRAMES": RENDER_HOLD_FRAMES,
            "HELD_SUPERSAMPLED_RUN": HELD_SUPERSAMPLED_RUN,
            "SUPERSAMPLED_STEP": float(SUPERSAMPLED_STEP),
            "SUPERSAMPLED_PCT": SUPERSAMPLED_PCT, "SUPERSAMPLED_MIN": SUPERSAMPLED_MIN,
            "RENDER_RAMP_PCT": RENDER_RAMP_PCT, "RAMP_FLANK": float(RAMP_FLANK),
            "SUPERSAMPLED_CLEAN_PCT": SUPERSAMPLED_CLEAN_PCT, "SUPERSAMPLED_HARD_PCT": SUPERSAMPLED_HARD_PCT,
            "RENDER_RANGE": float(RENDER_RANGE), "RENDER_REGIONS": int(regions),
            "FOOTPRINT_TABLE": int(table), "FOOTPRINT_BUCKETS": BUCKETS, "FOOTPRINT_WEIGHTS": WEIGHTS,
            "STRENGTH_LO": float(STRENGTH_LEVELS[0]), "STRENGTH_HI": float(STRENGTH_LEVELS[1]),
            "STRENGTH_FLOOR": float(STRENGTH_FLOOR), "STRENGTH_UNIT": float(np.float32(1.0 / STRENGTH_REF)),
            "REFINE_TABLE": int(refine), "REFINE_WEIGHTS": REFINE_WEIGHTS, "REFINE_GATE": float(REFINE_GATE),
            "REFINE_GATE_LEVELS": int(np.ceil(REFINE_GATE * _MAX[np.dtype(fmt.dtype)])), **noise_defines()}


class FallbackPass:
    """The kernels of kernels/fallback.cl and their per-tile buffers, for one frame format."""

    def __init__(self, context: Context, fmt: FrameFormat, linear: bool, linear_input: bool,
                 everywhere: bool = False, regions: bool = True, table: np.ndarray | None = None,
                 refine: np.ndarray | None = None):
        """`table`: the footprint table for render regions (spatial/footprint.py; None: none); `refine`: the
        refine table after it (spatial/refine.py; None: none; only with a footprint table)."""
        refine = refine if table is not None and (regions or everywhere) else None
        defs = fallback_defines(fmt, linear, linear_input, everywhere, regions, table is not None,
                                refine is not None)
        self.fmt = fmt
        self.everywhere = everywhere
        self.regions = regions and not everywhere
        self.tiles = (-(-fmt.width // FALLBACK_TILE), -(-fmt.height // FALLBACK_TILE))
        self._count = context.kernel("fallback", "count_changed", defs)
        self._fxaa = context.kernel("fallback", "fxaa_fallback", defs)
        self._rows = context.kernel("fallback", "render_rows", defs)
        self._render_tiles = context.kernel("fallback", "render_tiles", defs)
        self._render_frame = context.kernel("fallback", "render_frame", defs)
        n = self.tiles[0] * self.tiles[1]
        # grain over a render leaves the regions (kernels/noise.cl): the frame's level, 0 (none) without regions, and
        # grain_verdict's flag (busy pixels within the grain do not count)
        self._noise = context.buffer(8)
        cl.enqueue_copy(context.queue, self._noise, np.zeros(2, np.int32), is_blocking=True)
        if self.regions:
            self._grain_verdict = context.kernel("fallback", "grain_verdict", defs)
        if self.regions or everywhere:
            self._noise_census = context.kernel("fallback", "noise_census", defs)
            self._noise_level = context.kernel("fallback", "noise_level", defs)
            self._noise_mask = context.kernel("fallback", "noise_mask", defs)
            self._census = context.buffer(4 * NOISE_BINS * self.tiles[1])
        self._quiet = context.buffer(fmt.width * fmt.height if self.regions or everywhere else 1)  # noise_mask's
        if self.regions:  # text over a render leaves the regions (kernels/overlays.cl): its own program and buffers
            overlay_defs = {**defs, **overlay_defines()}
            self._overlay_counts = context.kernel("overlays", "overlay_counts", overlay_defs)
            self._overlay_seeds = context.kernel("overlays", "overlay_seeds", overlay_defs)
            self._overlay_tiles = context.kernel("overlays", "overlay_tiles", overlay_defs)
            self._overlays = context.buffer(2 * n)  # overlay_counts' two per tile
            self._seeds = context.buffer(n)  # overlay_seeds' flag per tile
        self._counts = context.buffer(COUNTS * n)  # count_changed's nine per tile
        self._row_sums = context.buffer(32 * n)  # render_rows' int8 per tile
        self._render = context.buffer(n)  # render_tiles' flag per tile
        self._shares = context.buffer(32 * self.tiles[0])  # render_tiles' int8 per tile column
        # render_frame's held verdict (spatial/shots.py): frames left in the hold, read from [parity], written to the
        # other; frames run in order (each frame's passes wait for the previous frame's)
        self._hold = context.buffer(16)  # and frames in a row that look supersampled, the same way
        cl.enqueue_copy(context.queue, self._hold, np.zeros(4, np.int32), is_blocking=True)
        self._parity = 0
        self._table = context.buffer(4 * BUCKETS * WEIGHTS)  # the footprint table (unused without one)
        if table is not None:
            cl.enqueue_copy(context.queue, self._table, np.ascontiguousarray(table, np.float32), is_blocking=True)
        self._refine = None
        if refine is not None:  # its kernel reads a copy of fxaa_fallback's output (mid) and writes dst
            self._refine = context.kernel("fallback", "refine_fallback", defs)
            self._refine_table = context.buffer(4 * BUCKETS * REFINE_WEIGHTS)
            cl.enqueue_copy(context.queue, self._refine_table, np.ascontiguousarray(refine, np.float32),
                            is_blocking=True)
            self._mid = context.buffer(fmt.nbytes)

    def device_bytes(self) -> int:
        """Bytes of the per-frame buffers (the tables' 15 and 20 KB do not grow with the frame)."""
        mid = self._mid.size if self._refine is not None else 0
        overlays = self._overlays.size + self._seeds.size if self.regions else 0
        census = self._census.size + self._quiet.size if self.regions or self.everywhere else 0
        return (self._counts.size + self._row_sums.size + self._render.size + self._shares.size + overlays + mid
                + census)

    def read_regions(self, queue, wait_for: list) -> tuple[np.ndarray, cl.Event | None]:
        """The last frame's render-region flag per tile, (tiles_y, tiles_x) uint8, and the event of its copy to
        the host (None: known without a copy -- every tile in "everywhere", none without regions)."""
        shape = (self.tiles[1], self.tiles[0])
        if not self.regions:
            return np.full(shape, 1 if self.everywhere else 0, np.uint8), None
        flags = np.empty(shape, np.uint8)
        return flags, cl.enqueue_copy(queue, flags, self._render, wait_for=wait_for, is_blocking=False)

    def enqueue(self, queue, src, dst, edges, hdist, vdist, luts, lin, wait_for: list, events: dict,
                cut: bool = True) -> cl.Event:
        """dst holds the MLAA passes' output of src, `edges`, `hdist` and `vdist` their edge and line-distance
        buffers, `lin` the frame format's linear_levels table; returns the event after which dst holds the
        result. `cut`: no frame before this one holds the render verdict (spatial/shots.py)."""
        W, H = np.int32(self.fmt.width), np.int32(self.fmt.height)
        tx, ty = np.int32(self.tiles[0]), np.int32(self.tiles[1])
        noise = []
        if self.regions or self.everywhere:  # the frame's noise level (kernels/noise.cl), from the input alone
            events["noise_census"] = self._noise_census(queue, (self.tiles[1],), None, src, self._census, W, H,
                                                        wait_for=wait_for)
            events["noise_level"] = self._noise_level(queue, (1,), None, self._census, self._noise, ty,
                                                      wait_for=[events["noise_census"]])
            noise = [events["noise_level"]]
        if not self.everywhere:  # "everywhere" reads no counts: every tile is a render region
            events["fallback_count"] = self._count(queue, (-(-self.fmt.width // SEGMENT), self.tiles[1]), None,
                                                   src, dst, edges, self._noise, self._counts, W, H, tx,
                                                   wait_for=[*wait_for, *noise])
            wait_for = [events["fallback_count"]]
            if self.regions:
                events["grain_verdict"] = self._grain_verdict(queue, (1,), None, self._counts, self._noise,
                                                              np.int32(self.tiles[0] * self.tiles[1]),
                                                              wait_for=wait_for)
                events["render_rows"] = self._rows(queue, (self.tiles[1],), None, self._counts, self._noise,
                                                   self._row_sums, tx, ty, wait_for=[events["grain_verdict"]])
                events["render_tiles"] = self._render_tiles(queue, (self.tiles[0],), None, self._row_sums,
                                                            self._counts, self._render, self._shares, tx, ty,
                                                            wait_for=[events["render_rows"]])
                events["render_frame"] = self._render_frame(queue, (self.tiles[0],), None, self._render,
                                                            self._counts, self._shares, self._hold,
                                                            np.int32(self._parity), np.int32(bool(cut)), tx, ty,
                                                            wait_for=[events["render_tiles"]])
                self._parity ^= 1
                events["overlay_counts"] = self._overlay_counts(queue, (-(-self.fmt.width // SEGMENT), self.tiles[1]),
                                                                None, src, self._render, self._overlays, W, H, tx, ty,
                                                                wait_for=[events["render_frame"]])
                events["overlay_seeds"] = self._overlay_seeds(queue, (self.tiles[1],), None, self._overlays,
                                                              self._seeds, tx, ty, wait_for=[events["overlay_counts"]])
                events["overlay_tiles"] = self._overlay_tiles(queue, (self.tiles[1],), None, self._overlays,
                                                              self._seeds, self._render, tx, ty,
                                                              wait_for=[events["overlay_seeds"]])
                wait_for = [events["overlay_tiles"]]
        if noise:  # the quiet flags, where the final render regions are
            events["noise_mask"] = self._noise_mask(queue, (-(-self.fmt.width // SEGMENT), self.fmt.height), None,
                                                    src, self._noise, self._render, self._quiet, W, H, tx,
                                                    wait_for=[*wait_for, *noise])
            noise = [events["noise_mask"]]
        events["fallback"] = self._fxaa(queue, (-(-self.fmt.width // SEGMENT), self.tiles[1]), None,
                                        src, luts, lin, edges, hdist, vdist, self._counts, self._render,
                                        self._table, self._noise, self._quiet, dst, W, H, tx, ty,
                                        wait_for=[*wait_for, *noise])
        if self._refine is None:
            return events["fallback"]
        events["refine_copy"] = cl.enqueue_copy(queue, self._mid, dst, wait_for=[events["fallback"]])
        events["refine"] = self._refine(queue, (-(-self.fmt.width // SEGMENT), self.tiles[1]), None,
                                        src, luts, lin, edges, hdist, vdist, self._render, self._refine_table,
                                        self._noise, self._quiet, self._mid, dst, W, H, tx, ty,
                                        wait_for=[events["refine_copy"]])
        return events["refine"]


def region_pixels(tiles: np.ndarray, height: int, width: int) -> np.ndarray:
    """Render-region flags per FALLBACK_TILE^2 tile (FallbackPass.read_regions, Filter.last_regions) -> per pixel,
    (height, width) bool."""
    return np.repeat(np.repeat(np.asarray(tiles) > 0, FALLBACK_TILE, 0), FALLBACK_TILE, 1)[:height, :width]


def tile_sums(mask: np.ndarray) -> np.ndarray:
    """A (h, w) mask counted per FALLBACK_TILE^2 tile (partial tiles at the right and bottom edges): (tiles_y,
    tiles_x) int64."""
    t = FALLBACK_TILE
    h, w = mask.shape
    th, tw = -(-h // t), -(-w // t)
    tiles = np.zeros((th * t, tw * t), np.int64)
    tiles[:h, :w] = mask
    return tiles.reshape(th, t, tw, t).sum((1, 3))


def table_pixels(regions: np.ndarray, runs: np.ndarray, changed: np.ndarray) -> np.ndarray:
    """The pixels the footprint table takes (kernels/fallback.cl fallback_tile): render regions, but for pixels the
    chain changed on a straight edge run (long_runs)."""
    return regions & ~(runs & changed)


def dim_outside_regions(frame: np.ndarray, tiles: np.ndarray | None) -> np.ndarray:
    """Filter(show="regions")'s view: `frame` ((h, w) or (h, w, ch)) with every pixel outside render regions
    (`tiles`: one flag per FALLBACK_TILE^2 tile; None: no regions) at SHOW_DIM of its colour; alpha is kept."""
    h, w = frame.shape[:2]
    inside = np.zeros((h, w), bool) if tiles is None else region_pixels(tiles, h, w)
    out = frame.copy()
    colour = out if out.ndim == 2 else out[..., :3]
    dimmed = colour[~inside].astype(np.float32) * np.float32(SHOW_DIM)
    colour[~inside] = dimmed if np.issubdtype(frame.dtype, np.floating) else np.rint(dimmed).astype(frame.dtype)
    return out


def _window_colours(rgb: np.ndarray, same: float = FALLBACK_SAME) -> np.ndarray:
    """kernels/fallback.cl's colour count of every pixel's 3x3 window (rgb normalised, (h, w, 3)): colours equal
    within `same` / 255 of full scale per channel count once (0: bit-identical, window_has_exact_colours)."""
    h, w = rgb.shape[:2]
    pad = np.pad(rgb, ((1, 1), (1, 1), (0, 0)), mode="edge")
    win = [pad[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)]
    same = np.float32(same / 255.0)
    distinct = np.zeros((h, w), np.int32)
    for a in range(9):
        twin = np.zeros((h, w), bool)
        for o in range(a):
            twin |= np.all(np.abs(win[a] - win[o]) <= same, -1)
        distinct += ~twin
    return distinct


def long_runs(edges: np.ndarray, hdist: np.ndarray, vdist: np.ndarray, min_run: int | None = None) -> np.ndarray:
    """kernels/fallback.cl on_long_run for every pixel: the longest straight run among the edges it borders is
    `min_run` pixels or more (default REGION_KEEP_RUN, the render regions' and so the footprint tables'; 0: none)
    (hdist, vdist: (h, w, 2) as distances.cl writes them)."""
    min_run = REGION_KEEP_RUN if min_run is None else min_run
    e = np.asarray(edges)
    hl = np.where(e & 1, hdist.astype(np.int64).sum(-1) + 1, 0)
    vl = np.where(e & 2, vdist.astype(np.int64).sum(-1) + 1, 0)
    run = np.maximum(hl, vl)
    run[1:] = np.maximum(run[1:], hl[:-1])
    run[:, 1:] = np.maximum(run[:, 1:], vl[:, :-1])
    return run >= min_run if min_run > 0 else np.zeros(e.shape, bool)


def _frame_masks(src: np.ndarray, mlaa_out: np.ndarray, edges: np.ndarray, bgr: bool) -> tuple:
    """(format, src (h, w, ch), MLAA output (h, w, ch), edge-bordering pixels, pixels the MLAA passes changed,
    normalised RGB of src in RGB order (h, w, 3) float32)."""
    fmt = frame_format(src, bgr)
    h, w, ch = fmt.height, fmt.width, fmt.channels
    a = np.asarray(src).reshape(h, w, ch)
    mlaa = np.asarray(mlaa_out).reshape(h, w, ch)
    e = np.asarray(edges)
    borders = e != 0
    borders[1:] |= (e[:-1] & 1) > 0
    borders[:, 1:] |= (e[:, :-1] & 2) > 0
    norm = a.astype(np.float32) * (np.float32(1.0) / np.float32(_MAX[fmt.dtype]))
    rgb = np.repeat(norm[..., :1], 3, -1) if ch == 1 else norm[..., :3]
    return fmt, a, mlaa, borders, np.any(a != mlaa, -1), (rgb[..., ::-1] if fmt.bgr else rgb)


def render_regions_of(src: np.ndarray, mlaa_out: np.ndarray, edges: np.ndarray, *, linear_input: bool = False,
                      bgr: bool = False, held: bool = False) -> np.ndarray:
    """The render regions kernels/fallback.cl finds in `src` (per pixel, (h, w) bool), given the MLAA passes'
    output and edge buffer (Filter.intermediates: "out", "edges"); `held`: in a shot held as a render."""
    _, _, _, borders, changed, rgb = _frame_masks(src, mlaa_out, edges, bgr)
    luma = luma_reference(rgb, linear_input)
    return render_regions(_busy_pixels(changed, borders, rgb, quiet_pixels(src, bgr), luma), borders, luma,
                          overlay_tiles(src, bgr), held)


def _busy_pixels(changed: np.ndarray, borders: np.ndarray, rgb: np.ndarray, quiet: np.ndarray,
                 luma: np.ndarray) -> np.ndarray:
    """count_changed's k = 2 per pixel as the regions count it: edge-bordering pixels the MLAA passes changed whose
    3x3 window holds FALLBACK_COLOURS bit-identical colours or more -- but for those `quiet` (spatial/noise.py
    quiet_pixels: within the frame's grain) in a frame without 1-spp geometry (grain_verdict; `luma` px_luma)."""
    busy = changed & borders & (_window_colours(rgb, 0.0) >= FALLBACK_COLOURS)
    if quiet.any():
        strong, _, clean, clean_ramps = (int(a.sum()) for a in step_counts(borders, luma))
        if not one_spp_geometry(strong, clean, clean_ramps):
            busy &= ~quiet
    return busy


def to_mix_space(px: np.ndarray, fmt: FrameFormat, decode: bool) -> np.ndarray:
    """(h, w, ch) stored pixels -> (h, w, 3) float32 RGB in the kernels' mix space (linear light through the
    device LUT when `decode`)."""
    f32 = np.float32
    n = px.astype(f32) * (f32(1.0) / f32(_MAX[fmt.dtype]))
    c = np.repeat(n[..., :1], 3, -1) if fmt.channels == 1 else n[..., :3]
    c = c[..., ::-1] if fmt.bgr else c
    return lut_read(device_luts(), c).astype(f32) if decode else c


def from_mix_space(c: np.ndarray, like: np.ndarray, fmt: FrameFormat, decode: bool) -> np.ndarray:
    """Mix-space RGB (h, w, 3) -> stored pixels over `like` ((h, w, ch): alpha is kept), as the kernels store."""
    f32 = np.float32
    pmax = f32(_MAX[fmt.dtype])
    if decode:
        c = lut_read(device_luts()[2 * (LUT_SIZE + 1):], c).astype(f32)
    c = c[..., ::-1] if fmt.bgr else c
    new = like.astype(f32) * (f32(1.0) / pmax)
    if fmt.channels == 1:
        new[..., 0] = c[..., 0]
    else:
        new[..., :3] = c
    if fmt.dtype != np.float32:
        new = np.clip(np.floor(new * pmax + f32(0.5)), 0, pmax)  # to_pixel: round half up
    return new.astype(like.dtype)


def fallback_reference(src: np.ndarray, mlaa_out: np.ndarray, edges: np.ndarray, hdist: np.ndarray,
                       vdist: np.ndarray, *, linear: bool = True, linear_input: bool = False, bgr: bool = False,
                       everywhere: bool = False, regions: bool = True,
                       table: np.ndarray | None | str = "default",
                       refine: np.ndarray | None | str = "default", held: bool = False,
                       held_supersampled: bool = False) -> np.ndarray:
    """What kernels/fallback.cl makes of `mlaa_out`, the MLAA passes' output of `src` with edge buffer
    `edges` ((h, w) uint8, EDGE_BOTTOM 1 | EDGE_RIGHT 2) and line distances `hdist`, `vdist`, in numpy.
    `table`: the footprint table ("default": the shipped one; None: none); `refine`: the refine table after it
    (spatial/refine.py; the same); `held`: a frame of a shot held as a render (spatial/shots.py); `held_supersampled`:
    held whether or not it looks supersampled (one of at most HELD_SUPERSAMPLED_RUN such frames in a row)."""
    table, refine = table_of(table), refine_table_of(refine)
    fmt, a, mlaa, borders, changed, rgb = _frame_masks(src, mlaa_out, edges, bgr)
    f32 = np.float32
    h, w = fmt.height, fmt.width
    out = mlaa.copy()
    e = np.asarray(edges)
    # quiet pixels (grain over a render, spatial/noise.py) are no region pixels; the level is 0 without regions
    quiet = quiet_pixels(src, bgr) if regions or everywhere else np.zeros((h, w), bool)
    if everywhere:
        rendered = ~quiet
        eligible = borders & rendered
        runs = np.zeros((h, w), bool)
    else:
        t = FALLBACK_TILE
        th, tw = -(-h // t), -(-w // t)

        def region_sums(mask: np.ndarray) -> np.ndarray:  # per pixel: the mask's count over its 3x3 tiles
            pad = np.pad(tile_sums(mask), 1)
            s3 = sum(pad[dy:dy + th, dx:dx + tw] for dy in range(3) for dx in range(3))
            return np.repeat(np.repeat(s3, t, 0), t, 1)[:h, :w]

        busy_window = _window_colours(rgb) >= FALLBACK_COLOURS
        luma = luma_reference(rgb, linear_input)
        busy_px = _busy_pixels(changed, borders, rgb, quiet, luma)
        busy_changed = region_sums(busy_px)
        # render_frame then clears every tile's counts
        frame_supersampled = regions and supersampled(borders, luma) and not (held and held_supersampled)
        rendered = np.zeros((h, w), bool)
        if regions:
            rendered = render_regions(busy_px, borders, luma, overlay_tiles(src, bgr), held, held_supersampled) & ~quiet
        busy = rendered | ((busy_changed >= FALLBACK_RICH_MIN)
                           & (busy_changed * FALLBACK_RICH_DIV >= region_sums(borders)))
        evidence = region_sums(changed & borders) >= FALLBACK_MIN_CHANGED
        eligible = borders & (busy | (evidence & busy_window & ~changed))
        if frame_supersampled:  # no tile busy, none with evidence: FXAA in render regions only
            eligible &= rendered
        runs = long_runs(e, hdist, vdist)
        eligible &= ~np.where(rendered, runs, long_runs(e, hdist, vdist, FALLBACK_KEEP_RUN))
    early, fx = fxaa_mix_reference(src, linear=linear, linear_input=linear_input, bgr=bgr)
    eligible &= ~early
    decode = linear and not linear_input

    def mix_space(px: np.ndarray) -> np.ndarray:
        return to_mix_space(px, fmt, decode)

    def stored(c: np.ndarray, like: np.ndarray) -> np.ndarray:
        return from_mix_space(c, like, fmt, decode)

    m_src, m_mlaa = mix_space(a), mix_space(mlaa)
    left = stored(m_src + f32(FALLBACK_WEIGHT) * (fx - m_src), a)
    mixed = stored(m_mlaa + f32(FALLBACK_MIX) * (fx - m_mlaa), mlaa)
    out[eligible & ~changed] = left[eligible & ~changed]
    out[eligible & changed] = mixed[eligible & changed]
    if table is not None and rendered.any():
        chain = out.reshape(a.shape)
        now_changed = np.any(chain != a, -1)
        new, kept = footprint_reference(m_src, mix_space(chain), now_changed, table)
        take = table_pixels(rendered, runs, now_changed) & ~kept
        out[take] = stored(new, chain)[take]
        if refine is not None:
            mid = out.reshape(a.shape).copy()
            mid_changed = np.any(mid != a, -1)
            new = refine_reference(m_src, mix_space(mid), mid_changed, refine)
            take = table_pixels(rendered, runs, mid_changed) & gate(a, _MAX[fmt.dtype])
            out[take] = stored(new, mid)[take]
    return out.reshape(np.asarray(mlaa_out).shape)


def step_counts(borders: np.ndarray, luma: np.ndarray) -> tuple[np.ndarray, ...]:
    """kernels/fallback.cl tile_ramps per pixel, both directions summed: (strong steps, ramps among them, clean
    transitions, ramps among them), each (h, w) int, counted from the pixels of sampled tiles (even tile rows and
    columns) holding edge-bordering pixels (`borders`, (h, w) bool) to their right and lower neighbours; `luma`
    px_luma of the input (h, w)."""
    f32 = np.float32
    h, w = luma.shape
    edge_tiles = tile_sums(borders) > 0
    edge_tiles[1::2] = False
    edge_tiles[:, 1::2] = False
    counted = region_pixels(edge_tiles, h, w)
    pad = np.pad(np.minimum(np.asarray(luma, f32), f32(1)), 3, mode="edge")  # ramp_luma: clipped to display white
    q, big = f32(RAMP_FLANK), f32(SUPERSAMPLED_STEP)
    out = [np.zeros((h, w), np.int64) for _ in range(4)]
    for dy, dx in ((0, 1), (1, 0)):
        def at(k: int, side: int = 0) -> np.ndarray:
            # luma k steps along (dy, dx) and `side` across it from every pixel, clamped to the frame
            y0, x0 = 3 + k * dy + side * dx, 3 + k * dx + side * dy
            return pad[y0:y0 + h, x0:x0 + w]
        a, b, l2 = at(0), at(1), at(2)
        c = b - a
        before, after, mid = a - at(-1), l2 - b, f32(0.5) * c
        inside = np.ones((h, w), bool)  # the neighbour lies in the frame
        inside[h - dy:] = False
        inside[:, w - dx:] = False
        step = counted & inside & (np.abs(c) >= big)
        ramp = np.where(c > 0, (before >= mid) | (after >= mid), (before <= mid) | (after <= mid))
        inside[h - 2 * dy:] = False  # a clean transition needs the pixel after the neighbour in the frame too
        inside[:, w - 2 * dx:] = False
        t, ac, aa = c + after, np.abs(c), np.abs(after)
        at_ = np.abs(t)
        d2 = at(3) - l2
        goes_on = np.ones((h, w), bool)  # the step goes on beside the pixel, on both sides across the direction
        for side in (-1, 1):
            cs = at(1, side) - at(0, side)
            goes_on &= (cs * c > 0) & (np.abs(cs) >= f32(0.5) * ac)
        hard = (ac >= big) & (np.abs(before) <= q * ac) & (aa <= q * ac) & ~goes_on
        clean_ramp = ((at_ >= big) & (c * t > 0) & (after * t > 0) & (np.minimum(ac, aa) > q * at_)
                      & (np.abs(before) <= q * at_) & (np.abs(d2) <= q * at_))
        m = counted & inside
        out[0] += step
        out[1] += step & ramp
        out[2] += m & (hard | clean_ramp)
        out[3] += m & clean_ramp
    return tuple(out)


def ramp_counts(borders: np.ndarray, luma: np.ndarray) -> tuple[int, int]:
    """The frame's strong steps and ramps among them (step_counts summed: render_frame's evidence)."""
    strong, ramps, _, _ = step_counts(borders, luma)
    return int(strong.sum()), int(ramps.sum())


def supersampled(borders: np.ndarray, luma: np.ndarray) -> bool:
    """kernels/fallback.cl's verdict that a frame is already supersampled (render_frame): at least SUPERSAMPLED_MIN
    strong steps, SUPERSAMPLED_PCT % of them ramps, or at least SUPERSAMPLED_MIN clean transitions,
    SUPERSAMPLED_CLEAN_PCT % of them ramps (step_counts); either only while hard stair ends (clean transitions that
    are no ramps) number under SUPERSAMPLED_HARD_PCT % of the strong steps."""
    return _supersampled_by(step_counts(borders, luma))


def one_spp_geometry(strong: int, clean: int, clean_ramps: int) -> bool:
    """kernels/fallback.cl render_frame's `one_spp`: hard stair ends (clean transitions that are no ramps) are
    SUPERSAMPLED_HARD_PCT % or more of the frame's strong steps (and it has some)."""
    return strong > 0 and (clean - clean_ramps) * 100 >= SUPERSAMPLED_HARD_PCT * strong


def _supersampled_by(counts: tuple[np.ndarray, ...]) -> bool:
    """supersampled's verdict from step_counts' four per-pixel counts."""
    strong, ramps, clean, clean_ramps = (int(a.sum()) for a in counts)
    return (((strong >= SUPERSAMPLED_MIN and ramps * 100 >= SUPERSAMPLED_PCT * strong)
             or (clean >= SUPERSAMPLED_MIN and clean_ramps * 100 >= SUPERSAMPLED_CLEAN_PCT * clean))
            and (clean - clean_ramps) * 100 < SUPERSAMPLED_HARD_PCT * strong)


def render_regions(busy: np.ndarray, borders: np.ndarray, luma: np.ndarray,
                   overlays: np.ndarray | None = None, held: bool = False,
                   held_supersampled: bool = False) -> np.ndarray:
    """kernels/fallback.cl's render regions per pixel (render_tiles and render_frame): `busy` and `borders` the pixel
    masks of count_changed's k = 2 and k = 1, `luma` px_luma of the input (h, w); `overlays` (per tile, spatial/
    overlays.py overlay_tiles, kernels/overlays.cl after render_frame): tiles of text over a render, no regions;
    `held`: a frame of a shot held as a render (spatial/shots.py), a render whatever its own share unless it looks
    supersampled; `held_supersampled`: even then (fallback_reference)."""
    t, r = FALLBACK_TILE, RENDER_RADIUS
    h, w = busy.shape
    th, tw = -(-h // t), -(-w // t)
    busy_t, border_t = tile_sums(busy), tile_sums(borders)
    f32 = np.float32
    lum = np.full((th * t, tw * t), np.nan, f32)
    lum[:h, :w] = luma
    blocks = lum.reshape(th, t, tw, t).transpose(0, 2, 1, 3).reshape(th, tw, t * t)
    lo, hi = np.nanmin(blocks, -1, keepdims=True), np.nanmax(blocks, -1, keepdims=True)
    rng = hi - lo
    near = (((blocks - lo) * f32(10) <= rng) | ((hi - blocks) * f32(10) <= rng)).sum(-1)
    measured = (busy_t > 0) & (rng[..., 0] >= f32(RENDER_RANGE))
    weighted = np.where(measured, busy_t * near, 0)
    busy_m = np.where(measured, busy_t, 0)

    def window(a: np.ndarray) -> np.ndarray:  # sums over tiles within r each way, clamped to the frame
        c = np.pad(np.cumsum(np.cumsum(a, 0), 1), ((1, 0), (1, 0)))
        y0, y1 = np.clip(np.arange(th) - r, 0, th), np.clip(np.arange(th) + r + 1, 0, th)
        x0, x1 = np.clip(np.arange(tw) - r, 0, tw), np.clip(np.arange(tw) + r + 1, 0, tw)
        return c[y1][:, x1] - c[y0][:, x1] - c[y1][:, x0] + c[y0][:, x0]

    b, a, bm, nw = window(busy_t), window(border_t), window(busy_m), window(weighted)
    counts = step_counts(borders, luma)
    strong, _, clean, clean_ramps = (int(c.sum()) for c in counts)
    div = RENDER_DIV_1SPP if one_spp_geometry(strong, clean, clean_ramps) else RENDER_DIV
    flag = (bm >= RENDER_MIN) & (b * div >= a) & (nw * 100 <= RENDER_NEAR_PCT * t * t * bm)
    edge_tiles = border_t > 0
    frame_supersampled = _supersampled_by(counts) and not (held and held_supersampled)
    if edge_tiles.any() and ((held and not frame_supersampled)
                             or (flag & edge_tiles).sum() * 100 >= RENDER_FRAME_PCT * edge_tiles.sum()):
        flag = b > 0  # a render: every tile near a busy pixel
    if frame_supersampled:  # regions only where the neighbourhood's clean transitions are mostly hard
        _, _, clean_px, clean_ramps_px = counts
        flag &= window(tile_sums(clean_ramps_px)) * 100 < RENDER_RAMP_PCT * np.maximum(window(tile_sums(clean_px)), 1)
    if overlays is not None:
        flag &= ~overlays
    return region_pixels(flag, h, w)
