"""The resolve of temporal supersampling in numpy, and the ring's sample codes (mlaa_stream.temporal.tss runs it
on the device with kernels/tss.cl, this module is its plain statement and its tables).

Ring samples: linear light in 16-bit fixed point, L = floor(clamp(lin, 0, 1) 65535 + 0.5) (`ring_of`); linear-light
float frames and the codes of HDR video (their light relative to reference white, device/transfer.py): lin /
LINEAR_RANGE; a sample over the range is marked OVER and never averaged, and a pixel near one keeps the spatial
output.

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
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mlaa_stream.device.colour import device_luts, lut_read
from mlaa_stream.device.formats import LUT_SIZE, frame_format, with_transfer
from mlaa_stream.device.transfer import encode_arg, with_transfer_tables
from mlaa_stream.temporal.stage import _PMAX, decode_table, sample_field


GRID = 4              # footprint cells per side (GRID^2 strata)
EPS = 0.03            # linear-light widening of the current 3x3 colour box (issue 16: 0.02-0.05)
MIN_CELLS = 2         # fewer filled cells: the spatial output stands
FULL_CELLS = 9        # filled cells at which the samples alone resolve the pixel (below: n / 9 of it)
ONE = 65535           # ring samples: linear light in 16-bit fixed point (kernels/tss.cl, ring_of)
OVER = 65535          # a float frame's sample over the ring's range: never averaged; in-range ones top out at ONE - 1
LINEAR_RANGE = 16     # linear-light float frames (EXR): the ring holds [0, 16] (highlights 4 stops over white; one
                      # step 2.4e-4: 0.8 of an 8-bit level of the sRGB-encoded value at black, 0.07 at mid-grey)
LANES = 16            # pixels of a row per work item of tss_resolve_shift (int16 / float16 vectors)
TILE_ROWS = 16        # rows of a tile of projective maps (tss_resolve_shift: one translation per tile and ring frame)


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
