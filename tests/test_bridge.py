"""Bridging the dash chains of sub-pixel wires: kernel vs numpy reference, known answers, what must not change.

Tolerances: the kernel and the reference take the same decisions in float32 from the same stored samples (the
set of written pixels must be identical) and compute the written values with the same float32 operations and
tables (FP_CONTRACT off), so values may differ by at most 1 stored level (8/16-bit) or 1e-6 (float32); on
these frames they agree exactly. Known answers: the written coverage is checked against the band model
computed here from exact sRGB formulas, within 1 level (the tables interpolate).
"""
from __future__ import annotations

import numpy as np
import pytest

from mlaa_stream.spatial.bridge import BridgeOptions, Bridger, bridge, bridge_reference
from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.device.formats import frame_format
from mlaa_stream.yardstick.scenes import Layer, _ui_layers, encode8, rect, render, stroke, text_polygons

BG = (228, 226, 218)
INK = (24, 24, 32)


def both(src: np.ndarray, dst: np.ndarray | None = None, **kw) -> np.ndarray:
    """Kernel output, after checking it against the reference: same pixels written, values within 1 level."""
    out = bridge(src, dst, **kw)
    ref = bridge_reference(src, dst, **kw)
    base = src if dst is None else dst
    changed_k = np.any((out != base).reshape(*src.shape[:2], -1), -1)
    changed_r = np.any((ref != base).reshape(*src.shape[:2], -1), -1)
    np.testing.assert_array_equal(changed_k, changed_r)
    tol = 1e-6 if src.dtype.kind == "f" else 1
    np.testing.assert_allclose(out.astype(np.float64), ref.astype(np.float64), rtol=0, atol=tol)
    return out


def canvas(h: int = 24, w: int = 48, colour=BG) -> np.ndarray:
    img = np.empty((h, w, 3), np.uint8)
    img[:] = colour
    return img


def dash_chain(img: np.ndarray, x0: int, y0: int, n: int, g: int, count: int, d: int = 1) -> list[tuple]:
    """Dashes of n pixels with gaps of g, each one row below (d=1) the last: the 1-spp samples of a thin wire
    of slope d/(n+g) and width n/(n+g). Returns the dashes as (row, first column, last column)."""
    dashes = []
    for k in range(count):
        x, y = x0 + k * (n + g), y0 + k * d
        img[y, x:x + n] = INK
        dashes.append((y, x, x + n - 1))
    return dashes


def coverage_of(out: np.ndarray) -> np.ndarray:
    """Ink coverage per pixel read back from an output over BG with INK, in linear light."""
    lin = srgb_to_linear(out[..., 0] / 255.0)
    b, i = srgb_to_linear(BG[0] / 255.0), srgb_to_linear(INK[0] / 255.0)
    return (lin - b) / (i - b)


# --- known answers ----------------------------------------------------------------------------------

def test_dash_chain_gaps_are_filled_with_the_band_coverage(device):
    img = canvas()
    n, g = 3, 3
    dashes = dash_chain(img, 4, 6, n, g, 5)
    out = both(img)
    # every gap pixel of the inner links, in both rows, now shows the wire
    for (r, _, e), (r2, s, _) in zip(dashes[:-1], dashes[1:]):
        assert (out[r, e + 1:s] != BG).any(-1).all() and (out[r2, e + 1:s] != BG).any(-1).all()
    # the band model, computed here: W = n / (n + g) rows, centre from the middle of dash k (row r) to the
    # middle of dash k+1 (row r+1); a pixel's coverage = overlap of [u - W/2, u + W/2] with its row
    W = n / (n + g)
    (r, a, e), (_, s, b) = dashes[1], dashes[2]
    m1, m2 = (a + e) / 2, (s + b) / 2
    for c in range(int(np.ceil(m1)), int(np.ceil(m2))):
        u = (c - m1) / (m2 - m1)
        for row, lo in ((r, -0.5), (r + 1, 0.5)):
            cov = max(0.0, min(u + W / 2, lo + 1) - max(u - W / 2, lo))
            want = linear_to_srgb(srgb_to_linear(np.array(BG) / 255) * (1 - cov) +
                                  srgb_to_linear(np.array(INK) / 255) * cov) * 255
            np.testing.assert_allclose(out[row, c].astype(float), want, atol=1.0, err_msg=f"row {row} col {c}")
    # the band keeps its width: each column between the dash middles holds W of ink over the two rows
    cols = range(int(np.ceil(m1)), int(np.ceil(m2)))
    np.testing.assert_allclose([coverage_of(out)[r:r + 2, c].sum() for c in cols], W, atol=0.02)
    # dashes are dimmed toward the wire's width; nothing outside rows of the chain changes
    assert 0.4 < coverage_of(out)[r, a + 1] < 0.6
    rows = sorted({d[0] for d in dashes})
    untouched = np.ones(img.shape[:2], bool)
    untouched[rows] = False
    np.testing.assert_array_equal(out[untouched], img[untouched])


def test_rising_and_steep_chains_are_bridged_like_their_mirror_and_transpose(device):
    img = canvas(32, 48)
    dash_chain(img, 3, 20, 4, 5, 5, d=-1)
    out = both(img)
    assert (out != img).any(-1).sum() > 20
    flipped = both(np.ascontiguousarray(img[::-1]))
    np.testing.assert_array_equal(flipped[::-1], out)  # the falling chain: rows mirrored
    steep = both(np.ascontiguousarray(img.transpose(1, 0, 2)))  # columns orientation
    np.testing.assert_array_equal(steep.transpose(1, 0, 2), out)


def test_near_diagonal_chain_is_bridged(device):
    # a thin wire near 40 degrees: runs along the diagonal, each next run one pixel to the right
    img = canvas(40, 40)
    for k in range(5):
        for t in range(3):
            img[4 + 5 * k + t, 4 + 6 * k + t] = INK
    out = both(img)
    gap = out[4 + 3, 4 + 3]  # the pixel after the first run, on its diagonal
    assert (gap != BG).any() and coverage_of(out)[7, 7] > 0.05


def test_crossing_wires_of_two_colours_are_both_bridged(device):
    # a shallow dashed wire (INK) crossed by a steep red one (its transpose) through their gaps: each sees the
    # other's pixels in its link windows as another colour and bridges across them; neither paints the other
    img = canvas(48, 48)
    dashes = dash_chain(img, 2, 20, 3, 4, 7)
    steep = canvas(48, 48)
    steep_dashes = dash_chain(steep, 2, 17, 3, 4, 7)  # (column, first row, last row) once transposed
    other = (steep.transpose(1, 0, 2) != BG).any(-1)
    img[other] = (150, 30, 30)
    out = both(img)
    # the red pixels stay red (dimmed by their own links toward the wire's width, never painted with INK)
    red = out[other].astype(int)
    assert (red[:, 0] - red[:, 2] >= 20).all()
    changed = (out != img).any(-1)
    (r, _, e), (r2, s, _) = dashes[2], dashes[3]  # the shallow wire's gap the steep one crosses
    assert changed[r, e + 1:s].sum() >= 2 and changed[r2, e + 1:s].sum() >= 2
    (c, _, e), (c2, s, _) = steep_dashes[2], steep_dashes[3]  # and the steep wire's gap the shallow one crosses
    assert changed[e + 1:s, c].sum() >= 2 and changed[e + 1:s, c2].sum() >= 2


def test_dash_ending_under_another_colour_is_still_linked(device):
    # the last ink pixel of one dash is covered by a red wire's pixel: the dash ends under it (occluded), so the
    # gaps on both sides of that dash are still bridged, and the red pixel is kept
    img = canvas()
    dashes = dash_chain(img, 2, 4, 3, 4, 6)
    r, _, e = dashes[2]
    img[r, e] = (150, 30, 30)
    out = both(img)
    np.testing.assert_array_equal(out[r, e], img[r, e])
    # each gap column on both sides of that dash carries about the band's ink (W = 3/7 over the two rows;
    # the occluded dash counts 2 px, so its links' bands are a little thinner)
    cov = coverage_of(out)
    for (r1, _, e1), (r2, s2, _) in ((dashes[1], dashes[2]), (dashes[2], dashes[3])):
        np.testing.assert_allclose(cov[r1:r2 + 1, e1 + 1:s2].sum(0), 3 / 7, atol=0.1)


def test_chain_cut_by_a_crossing_of_the_same_ink_goes_on_across_it(device):
    # a shallow chain crossed by a 1-px vertical line of the same ink: the links whose windows hold the line are
    # refused (in text a glyph's other strokes look the same), so the chain is cut; both parts are chains of two
    # links or more with the same period and phase, so the band is drawn across the cut over the background
    img = canvas(24, 64)
    dashes = dash_chain(img, 2, 4, 3, 4, 9)
    img[:, 30] = INK
    out = both(img)
    np.testing.assert_array_equal(out[:, 30], img[:, 30])
    cut = both(img, options=BridgeOptions(max_skip=0))
    W = 3 / 7
    # every gap column (background over the chain's rows) between the first and last dash carries the band's
    # ink, W over those rows (within 0.1); without the cut rule, the gap columns around the line do not. (A
    # dash inside the cut is ink, so no band writes it: it keeps its value.)
    rows = slice(dashes[0][0], dashes[-1][0] + 1)
    cols = [c for c in range(dashes[0][2] + 1, dashes[-1][1]) if (img[rows, c] == BG).all()]
    cov = np.array([coverage_of(out)[rows, c].sum() for c in cols])
    np.testing.assert_allclose(cov, W, atol=0.1)
    assert (np.array([coverage_of(cut)[rows, c].sum() for c in cols]) < W / 2).sum() >= 4
    assert (out != cut).any(-1).sum() >= 8


@pytest.mark.parametrize("case", ["end", "end_under_dash_end", "wide_end", "short_dashes"])
def test_wire_end_of_the_same_ink_two_rows_from_a_dash(device, case):
    # a chain of four dashes; a vertical wire of the same ink comes up from the bottom and ends two rows below
    # dash 3 (in row 2d of the last link's window, beside its dash 1). Its end counts as clear: the last link is
    # drawn (its gap carries the band, W over the two rows), and the wire's pixels keep their values. Not when
    # the end lies under the dash's step next to the gap, is 3 px wide (POKE_RUN = 2), or the dashes are
    # shorter than POKE_DASH = 3 (in text, a glyph's strokes near small dashes look the same).
    n, g = (2, 3) if case == "short_dashes" else (5, 6)
    img = canvas(24, 48)
    dashes = dash_chain(img, 2, 4, n, g, 4)
    (r, a, e), (r2, s, _) = dashes[2], dashes[3]
    col = {"end": a + 1, "end_under_dash_end": e, "wide_end": a, "short_dashes": a}[case]
    img[r + 2:, col:col + (3 if case == "wide_end" else 1)] = INK
    out = both(img)
    np.testing.assert_array_equal(out[r + 2:], img[r + 2:])
    cov = coverage_of(out)[r:r2 + 1, e + 1:s].sum(0)
    if case == "end":
        np.testing.assert_allclose(cov, n / (n + g), atol=0.1)
        off = both(img, options=BridgeOptions(poke_run=0))
        assert (coverage_of(off)[r:r2 + 1, e + 1:s].sum(0) < 0.1).all()
    else:
        assert (cov < 0.1).all()


@pytest.mark.parametrize("case", ["crossing", "short_dashes", "touching_dash_2"])
def test_wire_of_the_same_ink_crossing_the_gap(device, case):
    # a chain of four dashes (8 px, gaps of 10: W = 8/18); a steep wire of the same ink (2 px a row, one step a
    # row) crosses the gap of link 2 (dash 2 in row 5, dash 3 in row 6) in all its window rows, over steps 3..7.
    # The crossing counts as clear and the gap in row d runs past it (it cannot start dash 2: the ink beside it
    # in row 0 would refuse that link): link 2 is drawn with the band, and the crossing keeps its pixels. Link 3
    # (the last) is drawn too: looking back for the link that ends at its dash 1, `incoming` passes the crossing.
    # Neither when the dashes are shorter than XING_DASH = 4 (3 px, gaps of 8), nor when the crossing reaches
    # step s - 1 (it touches dash 2).
    n, g = (3, 8) if case == "short_dashes" else (8, 10)
    img = canvas(24, 96)
    dashes = dash_chain(img, 2, 4, n, g, 4)
    (r, _, e), (r2, s, e2), (r3, s3, _) = dashes[1:]
    c0 = e + (5 if case != "touching_dash_2" else 9) - r2   # the crossing's first column in row r2 is c0 + r2
    wire = np.zeros(img.shape[:2], bool)
    for y in range(img.shape[0]):
        wire[y, c0 + y:c0 + y + 2] = True
    img[wire] = INK
    out = both(img)
    np.testing.assert_array_equal(out[wire], img[wire])
    cols = [c for c in range(e + 1, s) if not wire[r:r2 + 1, c].any()]
    cov = coverage_of(out)[r:r2 + 1, cols].sum(0)
    cov3 = coverage_of(out)[r2:r3 + 1, e2 + 1:s3].sum(0)
    if case == "crossing":
        np.testing.assert_allclose(cov, n / (n + g), atol=0.1)
        np.testing.assert_allclose(cov3, n / (n + g), atol=0.1)
        off = both(img, options=BridgeOptions(xing_run=0))
        assert (coverage_of(off)[r:r2 + 1, cols].sum(0) < 0.1).all()
        assert (coverage_of(off)[r2:r3 + 1, e2 + 1:s3].sum(0) < 0.1).all()
    else:
        assert (cov < 0.1).all() and (cov3 < 0.1).all()


def band_cover(img_shape, rows_cols, m1: float, m2: float, r: int, W: float) -> np.ndarray:
    """The band model on rows r and r + 1: coverage of pixel (row, c) by a band of thickness W whose centre goes
    from column m1 (row r) to column m2 (row r + 1), extended straight beyond them."""
    cov = np.zeros(img_shape[:2])
    for row, c in rows_cols:
        u = (c - m1) / (m2 - m1)
        lo = row - r - 0.5
        cov[row, c] = max(0.0, min(u + W / 2, lo + 1) - max(u - W / 2, lo))
    return cov


def test_wire_entering_at_the_frame_edge_gets_its_first_gap_bridged(device):
    # a shallow wire cut by the left edge: its first dash shows 2 of its 3 pixels. The cut dash is taken as long
    # as the next one (3 px: middle at column 0), so the first gap carries the band of W = 3/6 from column 0
    # (row 4) to column 6 (row 5), exactly as an inner gap does; mirrored, the last gap at the right edge
    n, g = 3, 3
    img = canvas(16, 40)
    for k in range(5):
        img[4 + k, max(0, -1 + k * (n + g)):-1 + k * (n + g) + n] = INK
    out = both(img)
    W = n / (n + g)
    cov = coverage_of(out)
    want = band_cover(img.shape, [(r, c) for r in (4, 5) for c in range(2, 5)], 0.0, 6.0, 4, W)
    np.testing.assert_allclose(cov[4:6, 2:5], want[4:6, 2:5], atol=0.01)
    np.testing.assert_allclose(cov[4:6, 2:5].sum(0), W, atol=0.01)
    mirror = both(np.ascontiguousarray(img[::-1, ::-1]))
    np.testing.assert_array_equal(mirror[::-1, ::-1], out)
    steep = both(np.ascontiguousarray(img.transpose(1, 0, 2)))  # a steep wire cut by the top edge
    np.testing.assert_array_equal(steep.transpose(1, 0, 2), out)
    # a lone pair of dashes at the edge (no chain beyond the cut link) stays as it is
    pair = canvas(16, 40)
    pair[4, 0:2] = INK
    pair[5, 5:8] = INK
    np.testing.assert_array_equal(both(pair), pair)


def test_wire_entering_in_a_gap_has_its_band_drawn_to_the_frame_edge(device):
    # the wire enters the frame in a gap: its first dash (columns 2-4 of row 4) is whole and the dash before it
    # (row 3) lies outside. Within one gap of the edge, a chain of three links or more draws its first link's
    # band on to the edge, in rows 3 and 4; a chain starting farther in than its gap does not
    n, g = 3, 3
    for x0, extends in ((2, True), (3, True), (4, False)):
        img = canvas(16, 40)
        dashes = dash_chain(img, x0, 4, n, g, 5)
        out = both(img)
        cov = coverage_of(out)
        (r, a, e), (_, s, b) = dashes[0], dashes[1]
        want = band_cover(img.shape, [(rr, c) for rr in (r - 1, r) for c in range(a)], (a + e) / 2, (s + b) / 2, r,
                          n / (n + g))
        if extends:
            np.testing.assert_allclose(cov[r - 1:r + 1, :a], want[r - 1:r + 1, :a], atol=0.01)
            assert cov[r - 1:r + 1, :a].sum(0).min() > 0.2
        else:
            np.testing.assert_array_equal(out[r - 1:r + 1, :a], img[r - 1:r + 1, :a])
    # a chain of two links (three dashes) is not enough to extend
    img = canvas(16, 40)
    dashes = dash_chain(img, 2, 4, n, g, 3)
    out = both(img)
    np.testing.assert_array_equal(out[:, :2], img[:, :2])


def test_ink_colour_and_channels(device):
    img = canvas()
    dash_chain(img, 2, 4, 3, 4, 6)
    img[..., 2] = 0  # a yellow background: channels other than R take part
    img[img[..., 0] < 100] = (150, 30, 30)
    for frame, kw in ((img, {}), (img[..., ::-1].copy(), {"bgr": True}),
                      (np.dstack([img, np.full(img.shape[:2], 77, np.uint8)]), {}),
                      (img.astype(np.uint16) * 257, {}), (img.astype(np.float32) / 255, {}),
                      (np.ascontiguousarray(img[..., 0]), {})):
        out = both(frame, **kw)
        assert (out != frame).any(), f"{frame.dtype} {frame.shape}"
        if frame.ndim == 3 and frame.shape[2] == 4:
            np.testing.assert_array_equal(out[..., 3], frame[..., 3])  # alpha untouched


# --- what must not change ----------------------------------------------------------------------------

def render_1spp(layers, w, h) -> np.ndarray:
    return encode8(render([Layer(None, BG), *layers], w, h, 1))


@pytest.mark.parametrize("case", ["same_row_dashes", "filled_rect", "rotated_rect", "dot", "line_end",
                                  "lone_pair", "staircase", "ui_text"])
def test_unchanged(device, case):
    img = canvas(40, 96)
    if case == "same_row_dashes":  # an intentionally dashed line: gaps in the same row
        for x in range(2, 90, 7):
            img[20, x:x + 4] = INK
    elif case == "filled_rect":
        img[8:30, 10:70] = INK
    elif case == "rotated_rect":
        img = render_1spp([Layer((stroke(np.array([[5.0, 10.0], [90.0, 16.0]]), 8.0),), INK)], 96, 40)
    elif case == "dot":
        img[20, 40] = INK
    elif case == "line_end":  # a 1-px line that ends, and one a row below that starts after it
        img[20, 5:40] = INK
    elif case == "lone_pair":  # two dashes one row apart, nothing else: not a chain
        img[20, 10:14] = INK
        img[21, 18:22] = INK
    elif case == "staircase":  # a 1-px aliased line: runs touch diagonally, no gap to bridge
        for k in range(8):
            img[5 + k, 4 + 6 * k:10 + 6 * k] = INK
    elif case == "ui_text":  # the yardstick's text: DejaVu 6-20 px in boxes with 1-px borders, 1 spp
        layers, _ = _ui_layers(160, 120, np.random.default_rng(3), False)
        img = encode8(render(layers, 160, 120, 1))
    out = both(img)
    np.testing.assert_array_equal(out, img)


def test_free_text_is_never_bridged_across_glyphs(device):
    # Text without boxes: thin strokes of small glyphs (the diagonal of a 6-px '7', the curve of a 9-px
    # 'C') are dash chains themselves and may be bridged; nothing may appear away from the ink (a link
    # between specks of different glyphs or lines: what GAP_PER_RUN and the chain rule exclude).
    img = render_1spp([Layer(text_polygons("Settings mnw Il1 -=- e", 2.0, 12.0, 7.0), INK),
                       Layer(text_polygons("Cancel OK @% jumps", 2.0, 26.0, 9.0), INK),
                       Layer(text_polygons("lazy dogs 4567", 2.0, 37.0, 6.0), INK)], 96, 40)
    out = both(img)
    changed = (out != img).any(-1)
    ink = (img != BG).any(-1)
    near = ink.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            near |= np.roll(np.roll(ink, dy, 0), dx, 1)
    assert not (changed & ~near).any()
    assert changed.sum() <= 0.005 * changed.size


def test_text_cut_by_the_frame_edge_is_untouched(device):
    # Glyphs cut by all four edges of the frame (free text, 6-12 px, shifted past the edges, and UI boxes cropped
    # through their text): their clipped strokes are short runs that reach the edge; the cut-dash and to-the-edge
    # rules must not link them (the chain must go on from the dash the frame does not cut; three links or more
    # to draw on to the edge). So the frame's edge makes the pass draw nothing that it does not draw in the same
    # frame given an 8-px margin of background (where no stroke reaches the edge; thin strokes of small glyphs
    # may be bridged there, as in free text above).
    frames = []
    for size, txt in ((7.0, "Settings mnw Il1 -=- e"), (9.0, "Cancel OK @% jumps"), (12.0, "Wavy //\\\\ 7VAW kxz"),
                      (8.0, "Tyvwxz ZY7 /// <>"), (6.0, "lazy dogs 4567")):
        for y0, x0 in ((size * 0.5, -1.3), (size * 0.9, -3.0), (size * 0.7, -2.2)):
            img = render_1spp([Layer(text_polygons(txt, x0, y0, size), INK)], 96, int(size * 2) + 4)
            frames += [img, np.ascontiguousarray(img[::-1, ::-1]), np.ascontiguousarray(img.transpose(1, 0, 2))]
    layers, _ = _ui_layers(160, 120, np.random.default_rng(3), False)
    ui = encode8(render(layers, 160, 120, 1))
    frames += [np.ascontiguousarray(ui[t:120 - b, l:160 - r]) for t, l, b, r in ((5, 7, 0, 0), (0, 0, 11, 3))]
    m = 8
    for img in frames:
        out = both(img)
        padded = canvas(img.shape[0] + 2 * m, img.shape[1] + 2 * m)
        padded[m:-m, m:-m] = img
        inner = bridge_reference(padded)[m:-m, m:-m]
        changed, changed_inner = (out != img).any(-1), (inner != img).any(-1)
        assert not (changed & ~changed_inner).any(), f"{img.shape}: {np.argwhere(changed & ~changed_inner)[:4]}"


# --- kernel vs reference on seeded random frames ----------------------------------------------------

def random_wires(seed: int, w: int = 96, h: int = 64) -> np.ndarray:
    """1-spp thin wires (0.2-0.9 px, any angle) and a few filled shapes on a flat background."""
    rng = np.random.default_rng(seed)
    bg = tuple(int(v) for v in rng.integers(120, 250, 3))
    layers = [Layer(None, bg)]
    for _ in range(3):
        x0, y0 = rng.uniform(0, w), rng.uniform(0, h)
        layers.append(Layer((rect(x0, y0, x0 + rng.uniform(3, 15), y0 + rng.uniform(3, 15)),),
                            tuple(int(v) for v in rng.integers(0, 255, 3))))
    for _ in range(7):
        ang = rng.uniform(0, np.pi)
        c = np.array([rng.uniform(0, w), rng.uniform(0, h)])
        d = np.array([np.cos(ang), np.sin(ang)]) * rng.uniform(20, 80)
        layers.append(Layer((stroke(np.array([c - d, c + d]), rng.uniform(0.2, 0.9)),),
                            tuple(int(v) for v in rng.integers(0, 100, 3))))
    return encode8(render(layers, w, h, 1))


@pytest.mark.parametrize("seed", range(6))
def test_kernel_matches_reference_on_random_wires(device, seed):
    img = random_wires(seed)
    rng = np.random.default_rng(100 + seed)
    other = np.clip(img.astype(np.int16) + rng.integers(-20, 21, img.shape), 0, 255).astype(np.uint8)
    out = both(img, other)  # drawn into another frame (as over the MLAA output)
    assert (out != other).any(), "the random wires should give some links"
    both(img.astype(np.uint16) * 257)
    both(img, options=BridgeOptions(min_dashes=2, max_gap=8, max_run=12, linear=False))


def crossed_dashes(seed: int) -> np.ndarray:
    """Dash chains of INK (shallow and steep) with pixels of two other colours and of ink-background mixes
    scattered over them (beside dash ends, in gaps, under dashes: where the kernel's integer pre-tests reject),
    and +-2 levels of noise."""
    rng = np.random.default_rng(seed)
    img = canvas(40, 64)
    for k in range(4):
        dash_chain(img, int(rng.integers(0, 8)), 4 + 9 * k, int(rng.integers(1, 5)), int(rng.integers(2, 7)), 8,
                   1 if k % 2 else -1 if k else 1)
    steep = canvas(64, 40)
    dash_chain(steep, 2, 12, 3, 4, 8)
    img[(steep.transpose(1, 0, 2) != BG).any(-1)] = (150, 30, 30)
    mix = tuple((np.array(BG) + np.array(INK)) // 2)
    for colour, share in (((30, 40, 200), 0.04), ((150, 30, 30), 0.02), (mix, 0.02)):
        img[rng.random(img.shape[:2]) < share] = colour
    return np.clip(img + rng.integers(-2, 3, img.shape), 0, 255).astype(np.uint8)  # background within BG_TOL


@pytest.mark.parametrize("seed", range(3))
def test_kernel_matches_reference_with_other_colours_in_the_windows(device, seed):
    img = crossed_dashes(seed)
    out = both(img)
    assert (out != img).any(), "the dash chains should give some links"
    both(img.astype(np.uint16) * 257)
    both(np.ascontiguousarray(img.transpose(1, 0, 2)))


def poked_chains(seed: int) -> np.ndarray:
    """Shallow dash chains of INK (dashes 2-6 px) with ends of steep wires of the same ink, 1-3 px wide, coming
    from above or below and stopping two rows from a dash, and +-2 levels of noise."""
    rng = np.random.default_rng(seed)
    img = canvas(48, 72)
    for k in range(4):
        d = 1 if k % 2 else -1
        dashes = dash_chain(img, int(rng.integers(0, 6)), 8 + 11 * k + (3 if d < 0 else 0), int(rng.integers(2, 7)),
                            int(rng.integers(2, 8)), 6, d)
        for r, a, e in dashes[1:5]:
            x, w, y = int(rng.integers(a - 1, e + 2)), int(rng.integers(1, 4)), r + int(rng.choice([-5, 2]))
            img[max(0, y):y + 4, x:x + w] = INK
    return np.clip(img + rng.integers(-2, 3, img.shape), 0, 255).astype(np.uint8)  # background within BG_TOL


def crossed_by_the_same_ink(seed: int) -> np.ndarray:
    """Shallow dash chains of INK (dashes 3-9 px, gaps 6-14), two of each chain's gaps crossed near their middle by
    a steep wire of the same ink (1-2 px a row, 0-2 steps every two rows, some dotted: ink every other row), and
    +-2 levels of noise."""
    rng = np.random.default_rng(seed)
    img = canvas(64, 96)
    for k in range(4):
        d = 1 if k % 2 else -1
        dashes = dash_chain(img, int(rng.integers(0, 6)), 8 + 14 * k + (4 if d < 0 else 0), int(rng.integers(3, 10)),
                            int(rng.integers(6, 15)), 6, d)
        for i in rng.choice(4, 2, replace=False) + 1:
            (r, _, e), (_, a2, _) = dashes[i], dashes[i + 1]
            cx, w, step, every = (e + a2) // 2 + int(rng.integers(-1, 2)), int(rng.integers(1, 3)), \
                int(rng.integers(-2, 3)), int(rng.choice([1, 1, 2]))
            for y in range(max(0, r - 6), min(img.shape[0], r + 8), every):
                c = cx + ((y - r) * step) // 2
                img[y, max(0, c):max(0, c + w)] = INK
    return np.clip(img + rng.integers(-2, 3, img.shape), 0, 255).astype(np.uint8)  # background within BG_TOL


# (scene, options without the rule, other option values): each rule's kernel against the reference
SAME_INK_RULES = {"wire_ends": (poked_chains, dict(poke_run=0), dict(poke_run=1, poke_dash=5)),
                  "crossings": (crossed_by_the_same_ink, dict(xing_run=0), dict(xing_run=2, xing_dash=6))}


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("rule", list(SAME_INK_RULES))
def test_kernel_matches_reference_with_same_ink_rules(device, rule, seed):
    scene, off, other = SAME_INK_RULES[rule]
    img = scene(seed)
    out = both(img)
    assert (out != bridge_reference(img, options=BridgeOptions(**off))).any(), "some links need the rule"
    both(img.astype(np.uint16) * 257)
    both(np.ascontiguousarray(img.transpose(1, 0, 2)))
    both(img, options=BridgeOptions(**other))


def test_filter_option_draws_over_the_blended_frame(device):
    from mlaa_stream.spatial.filter import PRESETS, Filter
    img = random_wires(7)
    with Filter(bridge=False) as core, Filter() as bridged:
        base = core.process(img)
        out = bridged.process(img)
    np.testing.assert_array_equal(out, bridge_reference(img, base))
    assert PRESETS["no_bridge"] == {"bridge": False}


# --- host checks ------------------------------------------------------------------------------------

def test_host_checks(device):
    img = canvas()
    with pytest.raises(ValueError, match="expected dst like src"):
        bridge(img, img[:, :10].copy())
    with pytest.raises(ValueError, match="max_gap in 1..30"):
        Bridger(device, frame_format(img), BridgeOptions(max_gap=40))
    with pytest.raises(ValueError, match="min_dashes 2 or 3"):
        Bridger(device, frame_format(img), BridgeOptions(min_dashes=4))
    with pytest.raises(ValueError, match="max_skip in 0..3"):
        Bridger(device, frame_format(img), BridgeOptions(max_skip=4))


def fence(seed: int, w: int = 96, h: int = 64) -> np.ndarray:
    """1-spp samples of a chain-link fence far away: two families of thin diagonal wires (0.15-0.3 px) a few
    pixels apart, over a flat background: scattered dots of one ink."""
    rng = np.random.default_rng(seed)
    layers = [Layer(None, BG)]
    pitch, width = rng.uniform(2.5, 4.0), rng.uniform(0.15, 0.3)
    for k in range(-40, 40):
        for slope in (1.0, -1.0):
            x0 = k * pitch * 1.41
            layers.append(Layer((stroke(np.array([[x0, -5.0], [x0 + slope * (h + 10), h + 5.0]]), width),), INK))
    return encode8(render(layers, w, h, 1))


@pytest.mark.parametrize("seed", [0, 1, 3, 4])
def test_mesh_of_wires_is_not_bridged(device, seed):
    """A fence (a mesh of sub-pixel wires) is sampled as scattered dots: links between 1-2 px dots with more of
    the ink one row further out (MESH_DASH) are refused, so no false bands cross its cells; kernel as reference.
    Without the rule the same frame gets links; a lone wire of 1-px dashes is still bridged."""
    img = fence(seed)
    out = both(img)
    loose = both(img, options=BridgeOptions(mesh_dash=0))
    assert (loose != img).any(), "without the mesh rule the fence gets links"
    assert (out == img).all(), "no link across the fence"
    lone = canvas()
    dash_chain(lone, 4, 4, 1, 2, 8)
    assert (both(lone) != lone).any(), "a lone wire of 1-px dashes is bridged"


def test_zigzag_dots_are_not_a_wire(device):
    """A straight wire's dashes step one way (row r, r + d, r + 2d, ...): 2-px dashes alternating between two rows
    (a mesh's samples, e.g. a fence far away) have no chain of one direction, so nothing is drawn (the old rule,
    which let the previous link come from either row, drew 44 pixels here); kernel as reference."""
    img = canvas()
    for k in range(8):
        img[8 + k % 2, 4 + 4 * k:6 + 4 * k] = INK
    assert (both(img) == img).all()
    straight = canvas()
    dash_chain(straight, 4, 4, 2, 2, 8)
    assert (both(straight) != straight).any()
