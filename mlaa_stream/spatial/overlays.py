"""Text over a render -- subtitles, a HUD's lettering, a slate -- leaves the render regions (kernels/overlays.cl).

In a frame judged a 1-spp render every busy neighbourhood is a render region (spatial/fallback.py), and there the FXAA
fallback and the footprint and refine tables move every pixel toward what a box filter over the point samples
would give. Antialiased text composited over the render is no point sample: those passes blur it (white subtitles
over the bench's renders by 20 levels RMSE, outlined ones by 34; docs/spatial_tuning.md, "Text over a render").
Its signature is the subtitle renderer's blend: an exactly flat, extreme ink colour with coverage mixes beside it,
which a 1-spp render does not make. The kernel's comment gives the rule; this module holds its constants and its
numpy reference, which tests/test_overlays.py holds the kernel to.
"""
from __future__ import annotations

import numpy as np

from mlaa_stream.device.formats import LUMA256, levels8

# (tuning: docs/spatial_tuning.md, "Text over a render")
OVERLAY_CONTRAST = 64   # levels (8-bit, RGB distance) between a boundary pixel and the flat colour beside it
OVERLAY_EXTREME = 2     # levels of luma from the darkest or lightest of the tile's window: the flat colour is ink
OVERLAY_LO, OVERLAY_OFF = 20, 10  # a mix: t in (1/20, 19/20) along flat -> beyond, off the segment <= 1/10 of it
OVERLAY_SEED_MIN, OVERLAY_SEED_PCT, OVERLAY_GROW_DIV = 32, 35, 5
OVERLAY_GROW_STEPS = 2  # kernels/overlays.cl overlay_tiles: two steps (its counts reach three tiles from a region)
# a video codec's test: white or black ink (luma within OVERLAY_INK levels), flat within OVERLAY_NOISY_FLAT levels per
# channel, extreme within OVERLAY_NOISY_EXTREME, and the ramp ends at Q (the next step along <= 1/OVERLAY_RAMP_END)
OVERLAY_INK, OVERLAY_NOISY_FLAT, OVERLAY_NOISY_EXTREME, OVERLAY_RAMP_END = 20, 4, 8, 10
TILE, RADIUS = 8, 2     # fallback.py FALLBACK_TILE; the tile's window reaches RADIUS pixels around it


def overlay_defines() -> dict:
    """The constants as kernels/overlays.cl's defines."""
    return {"OVERLAY_CONTRAST": OVERLAY_CONTRAST, "OVERLAY_EXTREME": OVERLAY_EXTREME, "OVERLAY_LO": OVERLAY_LO,
            "OVERLAY_OFF": OVERLAY_OFF, "OVERLAY_SEED_MIN": OVERLAY_SEED_MIN, "OVERLAY_SEED_PCT": OVERLAY_SEED_PCT,
            "OVERLAY_GROW_DIV": OVERLAY_GROW_DIV, "OVERLAY_INK": OVERLAY_INK, "OVERLAY_NOISY_FLAT": OVERLAY_NOISY_FLAT,
            "OVERLAY_NOISY_EXTREME": OVERLAY_NOISY_EXTREME, "OVERLAY_RAMP_END": OVERLAY_RAMP_END}


def overlay_counts(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per tile (tiles_y, tiles_x): boundary pixels and mixes of the 8-bit levels `q` (h, w, 3)."""
    h, w = q.shape[:2]
    th, tw = -(-h // TILE), -(-w // TILE)
    lum = q @ LUMA256
    padded = np.pad(lum.astype(np.float64), ((RADIUS, th * TILE - h + RADIUS), (RADIUS, tw * TILE - w + RADIUS)),
                    constant_values=np.nan)
    win = np.lib.stride_tricks.sliding_window_view(padded, (TILE + 2 * RADIUS,) * 2)[::TILE, ::TILE]
    lmax = np.repeat(np.repeat(np.nanmax(win, (2, 3)), TILE, 0), TILE, 1)[:h, :w]
    lmin = np.repeat(np.repeat(np.nanmin(win, (2, 3)), TILE, 0), TILE, 1)[:h, :w]
    qp = np.pad(q, ((1, 1), (1, 1), (0, 0)), constant_values=-1000)  # outside the frame: equal to nothing
    flat, near = np.zeros((h, w), bool), np.zeros((h, w), bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                d = np.abs(qp[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] - q)
                flat |= np.all(d == 0, -1)
                near |= np.all(d <= OVERLAY_NOISY_FLAT, -1)
    flat_p, near_p, lum_p = np.pad(flat, 1), np.pad(near, 1), np.pad(lum, 1)
    inside, inside2 = np.pad(np.ones((h, w), bool), 1), np.pad(np.ones((h, w), bool), 2)
    q2 = np.pad(q, ((2, 2), (2, 2), (0, 0)))
    ext, ext_noisy = OVERLAY_EXTREME * 256, OVERLAY_NOISY_EXTREME * 256
    boundary, mix = np.zeros((h, w), bool), np.zeros((h, w), bool)
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        at_f = (slice(1 + dy, 1 + dy + h), slice(1 + dx, 1 + dx + w))
        at_q = (slice(1 - dy, 1 - dy + h), slice(1 - dx, 1 - dx + w))
        at_c = (slice(2 - 2 * dy, 2 - 2 * dy + h), slice(2 - 2 * dx, 2 - 2 * dx + w))  # the pixel beyond Q
        f, beyond, lf = qp[at_f], qp[at_q], lum_p[at_f]
        v = q - f
        vv = (v * v).sum(-1)
        strong = inside[at_f] & (vv > OVERLAY_CONTRAST * OVERLAY_CONTRAST)
        exact = strong & flat_p[at_f] & ((lf >= lmax - ext) | (lf <= lmin + ext))
        noisy = (strong & near_p[at_f] & ((lf >= (255 - OVERLAY_INK) * 256) | (lf <= OVERLAY_INK * 256))
                 & ((lf >= lmax - ext_noisy) | (lf <= lmin + ext_noisy)))
        e = beyond - f
        dd, vd = (e * e).sum(-1), (v * e).sum(-1)
        between = (inside[at_q] & (dd > 0) & (OVERLAY_LO * vd > dd) & (OVERLAY_LO * vd < (OVERLAY_LO - 1) * dd)
                   & (OVERLAY_OFF * OVERLAY_OFF * (vv * dd - vd * vd) <= dd * dd))
        go_on = ((q2[at_c] - beyond) * e).sum(-1)
        ends = inside2[at_c] & (OVERLAY_RAMP_END * go_on <= dd)
        boundary |= exact | noisy
        mix |= between & (exact | (noisy & ends))

    def per_tile(mask: np.ndarray) -> np.ndarray:
        p = np.zeros((th * TILE, tw * TILE), np.int64)
        p[:h, :w] = mask
        return p.reshape(th, TILE, tw, TILE).sum((1, 3))
    return per_tile(boundary), per_tile(mix)


def _sum3x3(t: np.ndarray) -> np.ndarray:
    p = np.pad(t, 1)
    return sum(p[1 + a:1 + a + t.shape[0], 1 + b:1 + b + t.shape[1]] for a in (-1, 0, 1) for b in (-1, 0, 1))


def overlay_tiles(frame: np.ndarray, bgr: bool = False) -> np.ndarray:
    """kernels/overlays.cl's verdict per tile (tiles_y, tiles_x) bool: the tile holds text over a render (a seed:
    its 3x3 tiles hold OVERLAY_SEED_MIN mixes or more, OVERLAY_SEED_PCT % of their boundary pixels; or, in
    OVERLAY_GROW_STEPS steps from the seeds, a tile with a mix for every OVERLAY_GROW_DIV boundary pixels beside an
    overlay tile). Render regions that are overlay stop being ones."""
    nb, nm = overlay_counts(levels8(frame, bgr))
    sb, sm = _sum3x3(nb), _sum3x3(nm)
    overlay = (sm >= OVERLAY_SEED_MIN) & (100 * sm >= OVERLAY_SEED_PCT * sb)
    grows = (nm >= 1) & (OVERLAY_GROW_DIV * nm >= nb)
    for _ in range(OVERLAY_GROW_STEPS):
        overlay = overlay | (grows & (_sum3x3(overlay.astype(np.int64)) > 0))
    return overlay
