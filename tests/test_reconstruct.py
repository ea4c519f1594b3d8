"""Topological reconstruction (seed 000 §4 + the extended rules): tables, known cases, kernel vs reference.

Tolerances: the kernel and the numpy reference compute CIELAB from the same tables in float32, so the
set of reconstructed pixels agrees on >= 99.9% of pixels (only ΔE ties at the threshold may differ) and
the values on the agreed pixels within 1 level (8/16-bit; the mean is rounded once) or 1e-5 (float32).
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mlaa_stream.device.colour import device_luts, rgb_to_lab
from mlaa_stream.device.formats import frame_format
from mlaa_stream.spatial.reconstruct import (RING, SEGMENT, Reconstructor, _device_table, cheap_bound, cheap_levels,
                                     connexity_table, gap_table, reconstruct, reconstruct_reference)

BG = (40, 90, 160)  # a non-black background
INKS = [(250, 230, 20), (235, 235, 235), (10, 10, 10), (200, 40, 40)]


def both(img: np.ndarray, extended: bool, **kw) -> np.ndarray:
    """Kernel output, after checking that the reference agrees exactly on a known-answer image."""
    out = reconstruct(img, extended=extended, **kw)
    np.testing.assert_array_equal(out, reconstruct_reference(img, extended=extended, **kw))
    return out


# --- tables ---------------------------------------------------------------------------------------

def _ring_image(mask: int) -> np.ndarray:
    img = np.zeros((3, 3), np.uint8)
    for k, (dx, dy) in enumerate(RING):
        if mask >> k & 1:
            img[1 + dy, 1 + dx] = 1
    return img


def test_connexity_table_matches_brute_force_components():
    # T8(A, X): 8-components of N8*(A) ∩ X (every one is 8-adjacent to A), counted by OpenCV
    t8 = connexity_table()
    assert t8.shape == (256,)
    for m in range(256):
        n, _ = cv2.connectedComponents(_ring_image(m), connectivity=8)
        assert t8[m] == n - 1, f"mask {m:08b}: expected {n - 1} components, got {t8[m]}"


def test_connexity_known_values():
    t8 = connexity_table()
    bit = {name: 1 << k for k, name in enumerate(["NW", "N", "NE", "E", "SE", "S", "SW", "W"])}
    assert t8[0] == 0 and t8[255] == 1
    assert t8[bit["W"] | bit["E"]] == 2
    assert t8[bit["N"] | bit["E"] | bit["S"] | bit["W"]] == 1  # 4-neighbours touch diagonally
    assert t8[bit["NW"] | bit["NE"] | bit["SE"] | bit["SW"]] == 4


def test_gap_table_choices():
    gap = gap_table()
    b = {name: 1 << k for k, name in enumerate(["NW", "N", "NE", "E", "SE", "S", "SW", "W"])}
    assert gap[b["NW"] | b["SE"]] == 1  # diagonal gap: T8(X)=2, T8(X-bar)=1 (the paper's case)
    assert gap[b["W"] | b["SE"]] == 1  # knight-move gap of a shallow staircase
    assert gap[b["W"] | b["E"]] == 1  # straight gap: T8(X-bar)=2 with two 3-pixel background rows
    assert gap[b["SW"] | b["SE"]] == 0  # 90 degrees apart: the notch of a 'v', not a gap
    rows = b["NW"] | b["N"] | b["NE"] | b["SW"] | b["S"] | b["SE"]
    assert gap[rows] == 0  # A on a 1-px line of its own colour between two regions
    assert gap[b["N"]] == 0 and gap[0] == 0


def test_cheap_bound_is_sound():
    # two colours closer than the bound in every channel are never more than the threshold apart
    rng = np.random.default_rng(5)
    for thr in (2.0, 10.0):
        bound = cheap_bound(thr)
        a = rng.random((20000, 3))
        b = np.clip(a + rng.uniform(-bound, bound, a.shape) * 0.999, 0, 1)
        de = np.linalg.norm(rgb_to_lab(a) - rgb_to_lab(b), axis=-1)
        assert de.max() <= thr, f"expected ΔE <= {thr} below the bound {bound}, got {de.max()}"
    assert cheap_bound(10.0) * 255 > 2  # and it is useful: more than 2 levels of 8-bit


def test_cheap_levels_are_the_smallest_integers_over_the_bound():
    # integer frames compare stored levels: d >= near must be exactly d > bound * pixel_max
    for pmax in (255.0, 65535.0):
        for linear in (False, True):
            bound = cheap_bound(10.0, linear) * pmax
            near, far = cheap_levels(10.0, pmax, linear)
            assert near - 1 <= bound < near, f"pmax {pmax}: expected {bound} in [{near - 1}, {near}), got {near}"
            assert far - 1 <= 2 * bound < far, f"pmax {pmax}: expected {2 * bound} in [{far - 1}, {far}), got {far}"


def test_gap_subset_bit_is_a_pair_at_ring_distance_three():
    # the kernel's 8-bit RGB gate (gate_rgb8) tests "some sub-mask of `maybe` is a gap" (table bit 1) as "two ring
    # neighbours at ring distance >= 3 are in `maybe`": the same for all 256 masks
    table = _device_table()
    for m in range(256):
        bits = [k for k in range(8) if m >> k & 1]
        pair = any(min((a - b) % 8, (b - a) % 8) >= 3 for a in bits for b in bits)
        assert bool(table[m] & 2) == pair, f"mask {m:08b}: expected table bit 1 = {pair}"


def _all_colours(fmt: str) -> np.ndarray:
    if fmt in ("uint8", "uint8-bgr", "uint8-linear"):
        v = np.arange(256 ** 3, dtype=np.uint32)
        return np.stack([v & 255, v >> 8 & 255, v >> 16], -1).astype(np.uint8).reshape(4096, 4096, 3)
    if fmt == "gray":
        return np.arange(256, dtype=np.uint8).reshape(8, 32)
    rng = np.random.default_rng(11)  # uint16, rgba8: a million random pixels
    if fmt == "uint16":
        return rng.integers(0, 65536, (1024, 1024, 3)).astype(np.uint16)
    return rng.integers(0, 256, (1024, 1024, 4)).astype(np.uint8)


@pytest.mark.parametrize("fmt", ["uint8", "uint8-bgr", "uint8-linear", "gray", "uint16", "rgba8"])
def test_lane_cielab_is_bit_identical_to_scalar(device, fmt):
    # the kernel's CIELAB a lane per pixel (lab_group) and a pixel at a time (lab_px) give the same bits: for
    # every 8-bit colour (RGB, BGR order, linear input), every gray level, a million 16-bit / RGBA pixels.
    # reconstruct_at mixes the two (ring from lanes, 5x5 window a pixel at a time), as the reference does not
    import pyopencl as cl
    img = _all_colours(fmt)
    rec = Reconstructor(device, frame_format(img, fmt == "uint8-bgr"), linear_input=fmt == "uint8-linear")
    k = device.kernel("reconstruct", "reconstruct_lab_check", rec.defines)
    mf = cl.mem_flags
    src = cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(img))
    luts = cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=device_luts())
    groups = img.shape[0] * img.shape[1] // 8
    bad = np.full(groups, -1, np.int32)
    bad_buf = device.buffer(bad.nbytes)
    items = 1024
    scratch = device.buffer(4 * 3 * (SEGMENT + 8) * items)
    k(device.queue, (items,), None, src, luts, rec._lin, scratch, bad_buf, np.int32(groups)).wait()
    cl.enqueue_copy(device.queue, bad, bad_buf)
    assert bad.min() == 0 and bad.sum() == 0, f"{fmt}: expected 0 pixels with differing CIELAB, got {bad.sum()}"


# --- known answers --------------------------------------------------------------------------------

def canvas(h: int = 24, w: int = 24, bg=BG) -> np.ndarray:
    img = np.empty((h, w, 3), np.uint8)
    img[:] = bg
    return img


LINES = {"horizontal": ((2, 11), (21, 11)), "vertical": ((11, 2), (11, 21)),
         "diagonal": ((2, 2), (21, 21)), "antidiagonal": ((22, 0), (0, 22))}


def broken_line(direction: str, ink, gap: int) -> tuple[np.ndarray, np.ndarray]:
    """A 1-px line (Bresenham) and the same line with `gap` pixels removed in its middle."""
    (x0, y0), (x1, y1) = LINES[direction]
    whole = canvas()
    cv2.line(whole, (x0, y0), (x1, y1), ink, 1, cv2.LINE_8)
    sx, sy = int(np.sign(x1 - x0)), int(np.sign(y1 - y0))
    broken = whole.copy()
    for i in range(gap):
        broken[11 + i * sy if sy else 11, 11 + i * sx if sx else 11] = BG
    assert (broken != whole).any(-1).sum() == gap
    return whole, broken


@pytest.mark.parametrize("direction", list(LINES))
@pytest.mark.parametrize("ink", INKS)
def test_one_pixel_gap_closes(device, direction, ink):
    whole, broken = broken_line(direction, ink, 1)
    for extended in (False, True):
        np.testing.assert_array_equal(both(broken, extended), whole)


@pytest.mark.parametrize("direction", list(LINES))
@pytest.mark.parametrize("ink", INKS[:2])
def test_two_pixel_gap_closes_only_when_extended(device, direction, ink):
    whole, broken = broken_line(direction, ink, 2)
    np.testing.assert_array_equal(both(broken, True), whole)
    np.testing.assert_array_equal(both(broken, False), broken)


@pytest.mark.parametrize("fmt", ["uint8", "gray", "uint16", "rgba8"])
def test_gaps_at_group_and_segment_borders_close(device, fmt):
    # the passes work in groups of 8 and segments of 64 pixels of a row and skip flat ones: gaps at and next
    # to those borders, on a wide flat canvas, close as the reference says (1-px gaps; the 2-px one extended)
    h, w = 40, 3 * 64 + 13
    bg, ink = np.array(BG) / 255, np.array(INKS[1]) / 255
    whole = np.empty((h, w, 3), np.float64)
    whole[:] = bg
    cols = [8, 15, 40, 63, 68, 127, 132, 192, 199]   # vertical lines, one gap each in row 11 + 3 r
    whole[8:h - 1, cols] = ink
    whole[2, 1:w - 1] = ink                          # horizontal lines: 1-px gaps at group/segment borders,
    whole[5, 1:w - 1] = ink                          # a 2-px gap across the first segment border
    broken = whole.copy()
    for r, c in enumerate(cols):
        broken[11 + 3 * r, c] = bg
    gaps_h = [16, 64, 128, 191]
    broken[2, gaps_h] = bg
    broken[5, 63:65] = bg
    w_img, b_img = as_format(whole, fmt), as_format(broken, fmt)
    for extended in (False, True):
        out = both(b_img, extended)
        fixed = (out != b_img).reshape(h, w, -1).any(-1)
        assert fixed[11 + 3 * np.arange(len(cols)), cols].all(), f"{fmt}: a vertical gap stayed open"
        assert fixed[2, gaps_h].all(), f"{fmt}: a horizontal gap stayed open"
        assert fixed[5, 63:65].all() == extended and fixed.sum() == len(cols) + len(gaps_h) + 2 * extended
        np.testing.assert_array_equal(out, w_img if extended else np.where(fixed[..., None] if out.ndim == 3
                                                                           else fixed, w_img, b_img))


def test_gap_in_line_over_gradient_closes_when_extended(device):
    # X relative to the line colour: the background differs across the gap by more than the threshold
    img = np.empty((24, 24, 3), np.uint8)
    img[:] = np.linspace(60, 150, 24).astype(np.uint8)[:, None, None] * np.array([1, 1, 1], np.uint8)
    img[..., 2] = 170
    img[3:21, 11] = (250, 240, 30)
    img[11, 11] = img[11, 10]
    out = both(img, True)
    np.testing.assert_array_equal(out[11, 11], (250, 240, 30))
    assert (out != img).any(-1).sum() == 1


def unchanged_cases() -> dict[str, np.ndarray]:
    cases = {}
    img = canvas(); img[8, 9] = INKS[0]; cases["isolated dot"] = img
    img = canvas(); img[10, 3:12] = INKS[0]; cases["line end"] = img
    img = canvas(); img[6, 3:20] = INKS[0]; img[6:20, 12] = INKS[0]; cases["T-junction"] = img
    img = canvas(); img[6:18:2, 6:18:2] = INKS[1]; img[7:18:2, 7:18:2] = INKS[1]; cases["checkerboard"] = img
    img = canvas(); img[5:15, 6:19] = INKS[3]; cases["filled rectangle"] = img
    img = canvas(); cv2.line(img, (2, 20), (21, 4), INKS[1], 1, cv2.LINE_8); cases["unbroken slope"] = img
    img = canvas(); img[8, 3:20] = INKS[0]; img[10, 3:20] = INKS[0]; cases["'=' two lines 1 px apart"] = img
    img = canvas(); img[9, 3:11] = INKS[2]; img[11, 11:20] = INKS[2]; cases["offset parallel strokes"] = img
    return cases


GLYPHS = {  # 5x7 bitmap glyphs with 1-px strokes: dots, counters and near-touching strokes
    "i": ["..#..", ".....", ".##..", "..#..", "..#..", "..#..", ".###."],
    "m": [".....", ".....", "##.#.", "#.#.#", "#.#.#", "#.#.#", "#.#.#"],
    "e": [".....", ".....", ".###.", "#...#", "#####", "#....", ".###."],
    "s": [".....", ".....", ".####", "#....", ".###.", "....#", "####."],
    "j": ["...#.", ".....", "..##.", "...#.", "...#.", "#..#.", ".##.."],
    "%": ["##...", "##..#", "...#.", "..#..", ".#...", "#..##", "...##"],
    "B": ["####.", "#...#", "#...#", "####.", "#...#", "#...#", "####."],
    "k": ["#....", "#....", "#..#.", "#.#..", "##...", "#.#..", "#..#."],
}


def glyph_text(ink, bg) -> np.ndarray:
    img = canvas(11, 8 + 6 * len(GLYPHS), bg)
    for g, rows in enumerate(GLYPHS.values()):
        for r, row in enumerate(rows):
            for c, ch in enumerate(row):
                if ch == "#":
                    img[2 + r, 4 + 6 * g + c] = ink
    return img


def hershey_text(scale: float, font: int) -> np.ndarray:
    """OpenCV's stroke font, binarised (aliased text with 2-3 px strokes)."""
    img = np.full((40, 420, 3), 230, np.uint8)
    cv2.putText(img, "Sphinx of black quartz, judge my vow 0123", (2, 28), font, scale, (20, 20, 20), 1)
    return np.where(img < 125, 20, 230).astype(np.uint8)


@pytest.mark.parametrize("name", list(unchanged_cases()))
def test_shapes_stay_unchanged(device, name):
    img = unchanged_cases()[name]
    for extended in (False, True):
        np.testing.assert_array_equal(both(img, extended), img, err_msg=f"{name}, extended={extended}")


KNOWN_TEXT_DAMAGE = ("known shortfall (docs/reconstruct.md): aliased 1-px glyphs with 1-px letter spacing and the "
                     "open 'e' look locally like broken staircase lines; a few pixels per line of text are joined")


@pytest.mark.xfail(strict=True, reason=KNOWN_TEXT_DAMAGE)
@pytest.mark.parametrize("ink,bg", [(INKS[2], (238, 238, 234)), (INKS[1], (40, 70, 160))])
def test_glyph_strokes_stay_unchanged(device, ink, bg):
    img = glyph_text(ink, bg)
    for extended in (False, True):
        np.testing.assert_array_equal(both(img, extended), img)


@pytest.mark.xfail(strict=True, reason=KNOWN_TEXT_DAMAGE)
@pytest.mark.parametrize("scale,font", [(0.5, cv2.FONT_HERSHEY_SIMPLEX), (0.5, cv2.FONT_HERSHEY_PLAIN)])
def test_binarised_stroke_font_text_stays_unchanged(device, scale, font):
    img = hershey_text(scale, font)
    np.testing.assert_array_equal(reconstruct(img, extended=False), img)


def test_glyphs_with_dots_counters_and_spacing_stay_unchanged(device):
    # the 5x5 checks keep: the dot of 'i'/'j' (a piece must continue outward), the counters of 'm'
    # (A on a 1-px line of its own colour), two parallel strokes ('=', offset strokes: MAX_OFFSET)
    keep = {k: GLYPHS[k] for k in ("i", "j", "m", "k")}
    img = canvas(11, 8 + 7 * len(keep), (238, 238, 234))
    for g, rows in enumerate(keep.values()):
        for r, row in enumerate(rows):
            for c, ch in enumerate(row):
                if ch == "#":
                    img[2 + r, 4 + 7 * g + c] = INKS[2]
    for extended in (False, True):
        np.testing.assert_array_equal(both(img, extended), img)


@pytest.mark.parametrize("scale,font", [(0.5, cv2.FONT_HERSHEY_SIMPLEX), (1.0, cv2.FONT_HERSHEY_SIMPLEX),
                                        (0.7, cv2.FONT_HERSHEY_DUPLEX), (0.5, cv2.FONT_HERSHEY_PLAIN)])
def test_antialiased_text_stays_unchanged(device, scale, font):
    img = np.full((40, 420, 3), 230, np.uint8)
    cv2.putText(img, "Sphinx of black quartz, judge my vow 0123", (2, 28), font, scale, (20, 20, 20), 1)
    for extended in (False, True):
        np.testing.assert_array_equal(reconstruct(img, extended=extended), img)


# --- kernel against the reference on seeded random images ---------------------------------------

def random_scene(seed: int, h: int = 40, w: int = 48) -> np.ndarray:
    """Float RGB in [0, 1]: low-amplitude noise over a gradient, random 1-px lines with random gaps,
    and a patch of full-range noise."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    img = rng.random(3) * 0.5 + 0.25 + 0.2 * (xx + yy)[..., None] * rng.uniform(-1, 1, 3)
    img += rng.normal(0, 0.01, img.shape)
    canvas8 = np.zeros((h, w), np.uint8)
    for _ in range(10):
        p0 = tuple(int(v) for v in rng.integers(0, (w, h)))
        p1 = tuple(int(v) for v in rng.integers(0, (w, h)))
        canvas8[:] = 0
        cv2.line(canvas8, p0, p1, 1, 1, cv2.LINE_8)
        on = canvas8.astype(bool) & (rng.random((h, w)) > 0.25)  # a quarter of the samples missing
        img[on] = rng.random(3)
    img[2:12, w - 12:w - 2] = rng.random((10, 10, 3))
    return np.clip(img, 0, 1)


def as_format(img: np.ndarray, fmt: str) -> np.ndarray:
    if fmt == "uint8":
        return np.rint(img * 255).astype(np.uint8)
    if fmt == "uint8-bgr":
        return np.rint(img[..., ::-1] * 255).astype(np.uint8)
    if fmt == "uint16":
        return np.rint(img * 65535).astype(np.uint16)
    if fmt == "float32":
        return img.astype(np.float32)
    if fmt == "gray":
        return np.rint(img.mean(-1) * 255).astype(np.uint8)
    if fmt == "rgba8":
        rng = np.random.default_rng(1)
        alpha = rng.integers(0, 256, img.shape[:2] + (1,))
        return np.concatenate([np.rint(img * 255), alpha], -1).astype(np.uint8)
    raise ValueError(fmt)


TOL = {"uint8": 1, "uint8-bgr": 1, "uint16": 1, "float32": 1e-5, "gray": 1, "rgba8": 1}


@pytest.mark.parametrize("fmt", list(TOL))
@pytest.mark.parametrize("extended", [False, True])
def test_kernel_matches_reference(device, fmt, extended):
    changed_total = 0
    for seed in (1, 2):
        img = as_format(random_scene(seed), fmt)
        bgr = fmt == "uint8-bgr"
        out = reconstruct(img, extended=extended, bgr=bgr)
        ref = reconstruct_reference(img, extended=extended, bgr=bgr)
        assert out.shape == img.shape and out.dtype == img.dtype
        ch_out = (out != img).reshape(img.shape[0], img.shape[1], -1).any(-1)
        ch_ref = (ref != img).reshape(img.shape[0], img.shape[1], -1).any(-1)
        agree = (ch_out == ch_ref).mean()
        assert agree >= 0.999, f"{fmt}: expected >= 99.9% mask agreement, got {agree:.4%}"
        both_changed = ch_out & ch_ref
        diff = np.abs(out.astype(np.float64) - ref.astype(np.float64))[both_changed]
        assert diff.size == 0 or diff.max() <= TOL[fmt], f"{fmt}: expected <= {TOL[fmt]}, got {diff.max()}"
        # untouched pixels are bit-exact copies
        np.testing.assert_array_equal(out[~ch_out], img[~ch_out])
        if fmt == "rgba8":
            np.testing.assert_array_equal(out[..., 3], img[..., 3])  # alpha passes through
        changed_total += int(ch_ref.sum())
    assert changed_total >= 5, f"{fmt}: the random scenes should exercise the rules, got {changed_total} changes"


@pytest.mark.parametrize("fmt", ["uint8", "uint16", "float32"])
def test_kernel_matches_reference_with_linear_input(device, fmt):
    # LINEAR_INPUT: samples are encoded to sRGB (table) before Lab; integer frames go through the per-level table
    img = as_format(random_scene(4), fmt)
    out = reconstruct(img, linear_input=True)
    ref = reconstruct_reference(img, linear_input=True)
    changed = (ref != img).reshape(img.shape[0], img.shape[1], -1).any(-1)
    agree = ((out != img).reshape(changed.shape + (-1,)).any(-1) == changed).mean()
    assert agree >= 0.999, f"{fmt}: expected >= 99.9% mask agreement, got {agree:.4%}"


def test_bgr_is_rgb_reversed(device):
    img = as_format(random_scene(3), "uint8")
    rgb = reconstruct(img)
    bgr = reconstruct(np.ascontiguousarray(img[..., ::-1]), bgr=True)
    np.testing.assert_array_equal(bgr[..., ::-1], rgb)


def test_enqueue_refuses_dst_equal_to_src(device):
    img = canvas()
    rec = Reconstructor(device, frame_format(img))
    buf = device.buffer(img.nbytes)
    with pytest.raises(ValueError, match="different buffer"):
        rec.enqueue(device.queue, buf, buf, buf)
