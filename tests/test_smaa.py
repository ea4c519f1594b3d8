"""mlaa_stream.bench.smaa (SMAA 1x ultra, numpy) against answers worked out here, independently of its area table.

Tolerances: blended 8-bit pixels within 1 level of the exact linear-light blend (the code quantises once, from
float32; the expected values are float64); pixels SMAA must not touch come back bit for bit. No timings.
"""
from __future__ import annotations

import numpy as np
import pytest

from mlaa_stream.bench import accuracy as B
from mlaa_stream.bench.smaa import SMAA, area_table, detect_edges, diag_area_table
from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear

STEP = 8   # the stair-step test's run length: a line of slope 1/8


@pytest.fixture(scope="module", params=[False, True], ids=["orthogonal", "diagonals"])
def smaa(request) -> SMAA:
    """The default (orthogonal patterns) and the opt-in diagonal patterns: every known answer below but the
    long 45-degree line holds for both (their lines are no diagonals of 4+ pixels)."""
    return SMAA(diagonals=request.param)


def two_colours(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Two seeded RGB colours whose luma differs by far more than the 0.05 threshold."""
    a = rng.integers(20, 90, 3).astype(np.uint8)
    b = rng.integers(170, 240, 3).astype(np.uint8)
    return a, b


def mix(own: np.ndarray, other: np.ndarray, share: float) -> np.ndarray:
    """`own` taking `share` of `other`, in linear light, as 8-bit sRGB (float, unrounded)."""
    lin = (1.0 - share) * srgb_to_linear(own / 255.0) + share * srgb_to_linear(other / 255.0)
    return linear_to_srgb(lin) * 255.0


def revectorised_coverage(i: int, n: int = STEP, samples: int = 4096) -> float:
    """Share of pixel i (0..n-1) of a stair step of length n on the far side of the revectorised line, which
    runs from +0.5 (the middle of the crossing edge at the step's start) to -0.5 (the middle of the next one):
    the mean of max(line, 0) (i < n/2) or max(-line, 0) (i >= n/2) over the pixel, by dense sampling."""
    t = i + (np.arange(samples) + 0.5) / samples
    line = 0.5 - t / n
    return float(np.mean(np.maximum(line, 0.0) + np.maximum(-line, 0.0)))


def staircase(a: np.ndarray, b: np.ndarray, h: int = 48, w: int = 12 * STEP) -> tuple[np.ndarray, np.ndarray]:
    """Colour a above a boundary that drops one row every STEP columns, b below; and the image SMAA should give:
    in each step (one row boundary, STEP pixels long) the pixels above the boundary in the step's first half
    take b, those below it in its second half take a, each by its revectorised coverage."""
    ys, xs = np.mgrid[0:h, 0:w]
    boundary = 8 + xs // STEP
    img = np.where((ys < boundary)[..., None], a, b).astype(np.uint8)
    want = img.astype(np.float64)
    for x in range(w):
        y, i = 8 + x // STEP, x % STEP
        share = revectorised_coverage(i)
        if i < STEP // 2:
            want[y - 1, x] = mix(a, b, share)
        else:
            want[y, x] = mix(b, a, share)
    return img, want


def test_area_table_against_dense_sampling():
    """A few table entries against the area between the revectorised line and the edge, sampled densely."""
    table = area_table()
    t = (np.arange(20000) + 0.5) / 20000

    def covered(f, left: int) -> tuple[float, float]:
        v = f(left + t)
        return float(np.mean(np.maximum(-v, 0))), float(np.mean(np.maximum(v, 0)))

    for left, right in [(0, 0), (0, 6), (3, 4), (5, 2), (10, 30), (63, 64)]:
        d = left + right + 1
        # Z: up at the left end (+0.5), down at the right (-0.5), one straight line.
        z = covered(lambda x: 0.5 - x / d, left)
        np.testing.assert_allclose(table[2, 1, left, right], z, atol=1e-4)
        # L: crossing edge down at the left end only: the line's left half, for the pixels of that half.
        half = covered(lambda x: np.where(x <= d / 2, -0.5 + x / d, 0.0), left)
        np.testing.assert_allclose(table[1, 0, left, right], half if left <= right else (0, 0), atol=1e-4)
        # U: both ends down: two halves meeting the edge in the middle.
        u = covered(lambda x: -0.5 + np.minimum(x, d - x) / d, left)
        np.testing.assert_allclose(table[1, 1, left, right], u, atol=1e-4)
        # No crossing edge, or both crossings at one end and none at the other: nothing to blend.
        assert not table[0, 0, left, right].any() and not table[3, 0, left, right].any()
        # Both crossings at one end count as the opposite of the other end: a Z.
        np.testing.assert_allclose(table[3, 1, left, right], z, atol=1e-4)


@pytest.mark.parametrize("transpose", [False, True], ids=["horizontal", "vertical"])
@pytest.mark.parametrize("mirror", [False, True], ids=["falling", "rising"])
def test_stair_step_gets_revectorised_coverage(smaa, transpose, mirror):
    """A 1:8 stair step between two flat colours: every pixel within 1 level of its coverage by the line through
    the steps' half-pixel points, blended in linear light (away from the frame's left and right borders, where
    the steps are cut off); the rest of the frame unchanged."""
    a, b = two_colours(np.random.default_rng(3))
    img, want = staircase(a, b)
    if mirror:
        img, want = img[:, ::-1], want[:, ::-1]
    if transpose:
        img, want = img.transpose(1, 0, 2), want.transpose(1, 0, 2)
    img = np.ascontiguousarray(img)
    out = smaa.process(img)
    core = (slice(None), slice(STEP, -STEP)) if not transpose else (slice(STEP, -STEP), slice(None))
    diff = np.abs(out[core].astype(np.float64) - want[core])
    assert diff.max() <= 1.0, f"max difference {diff.max():.2f} levels"
    # Sanity of the answer itself: it blends about half the pixels along the boundary.
    assert (np.abs(want[core] - img[core]).max(-1) > 1).sum() >= 4 * STEP


def test_diagonal_area_table_against_dense_sampling():
    """Diagonal areas against a 2-D grid of samples of the half-plane: the current pixel (square (1 + l, l) of
    the pattern frame) above the line, its neighbour across the top edge (square (1 + l, 1 + l)) below it."""
    table = diag_area_table()
    g = (np.arange(200) + 0.5) / 200
    gx, gy = np.meshgrid(g, g)

    def shares(p1, p2, left: int) -> np.ndarray:
        def below(sx, sy):
            x, y = sx + gx, sy + gy
            return np.mean(y < p1[1] + (p2[1] - p1[1]) / (p2[0] - p1[0]) * (x - p1[0]))
        return np.array([1.0 - below(1 + left, left), below(1 + left, 1 + left)])

    for left, right in [(0, 3), (2, 2), (5, 9), (15, 15), (16, 3)]:
        d = left + right + 1
        outer, inner = ((1, 0), (1 + d, d)), ((1, 1), (1 + d, 1 + d))
        # No crossing edge at either end: the mean of the lines through the steps' outer and inner corners.
        np.testing.assert_allclose(table[0, 0, left, right], (shares(*outer, left) + shares(*inner, left)) / 2,
                                   atol=0.01)
        # A vertical crossing at the start and a horizontal one at the end: the line through the outer corners.
        np.testing.assert_allclose(table[1, 2, left, right], shares(*outer, left), atol=0.01)
        np.testing.assert_allclose(table[2, 1, left, right], shares(*inner, left), atol=0.01)
        # A horizontal crossing at the start, a vertical one at the end: from the inner corner to the outer one.
        np.testing.assert_allclose(table[2, 2, left, right], shares((1, 1), (1 + d, d), left), atol=0.01)
    np.testing.assert_allclose(table[0, 0, 16, 15], (0.25, 0.25), atol=1e-6)


@pytest.mark.parametrize("diagonals", [True, False], ids=["diagonals", "orthogonal"])
@pytest.mark.parametrize("rising", [True, False], ids=["slash", "backslash"])
def test_long_diagonal_line(rising, diagonals):
    """A long 45-degree edge. With diagonals=True the diagonal search finds it, its ends are out of reach (16
    steps), so each pixel of the staircase and the pixel across its top edge mix 25 % of each other (the mean
    of the line through the steps' outer corners, which halves the staircase pixels, and the one through their
    inner corners, which halves the pixels across). Orthogonal patterns alone (the default) see 1-pixel Z
    steps: 12.5 % (a triangle of legs 1/2). Away from the line: unchanged."""
    smaa = SMAA(diagonals=diagonals)
    share = 0.25 if diagonals else 0.125
    a, b = two_colours(np.random.default_rng(19))
    h, w = 80, 80
    ys, xs = np.mgrid[0:h, 0:w]
    below = (ys + xs >= 79) if rising else (ys - xs >= 0)
    img = np.where(below[..., None], b, a).astype(np.uint8)
    out = smaa.process(img)
    want = img.astype(np.float64)
    for y in range(20, 60):
        x = 79 - y if rising else y               # the staircase pixel of row y (b, with a above it)
        want[y, x] = mix(b, a, share)
        want[y - 1, x] = mix(a, b, share)
    core = (slice(20, 59), slice(20, 60))
    diff = np.abs(out[core].astype(np.float64) - want[core])
    assert diff.max() <= 1.0, f"max difference {diff.max():.2f} levels"


@pytest.mark.parametrize("axis", [0, 1], ids=["horizontal", "vertical"])
def test_straight_step_unchanged(smaa, axis):
    """A straight edge across the whole frame has no crossing edges: nothing to revectorise."""
    a, b = two_colours(np.random.default_rng(5))
    h, w = 40, 56
    pos = np.arange(h if axis == 0 else w)[:, None] if axis == 0 else np.arange(w)[None, :]
    img = np.where((np.broadcast_to(pos, (h, w)) < 17)[..., None], a, b).astype(np.uint8)
    np.testing.assert_array_equal(smaa.process(img), img)


def test_rectangle_sides_and_corner_rounding(smaa):
    """A flat rectangle: each side is a U pattern (crossing edges at both ends on the rectangle's side), and the
    crossing edges go on past the side's two rows, so corner rounding keeps 25 % of the U's area: a side pixel i
    of a side n pixels long takes 0.25 * (0.5 - (i + 0.5) / n) (i < n / 2, mirrored beyond) from across the
    side. Inside pixels of each side within 1 level of that; the corners change by at most that; the rest not."""
    a, b = two_colours(np.random.default_rng(17))
    img = np.broadcast_to(a, (30, 32, 3)).copy()
    y0, y1, x0, x1 = 10, 20, 8, 20                    # rows 10..19, columns 8..19: 10 tall, 12 wide
    img[y0:y1, x0:x1] = b
    out = smaa.process(img)

    def u_share(i: int, n: int) -> float:
        i = min(i, n - 1 - i)
        return 0.25 * (0.5 - (i + 0.5) / n)

    want = img.astype(np.float64)
    w, h = x1 - x0, y1 - y0
    for i in range(1, w - 1):
        want[y0, x0 + i] = mix(b, a, u_share(i, w))       # top side: the inside row takes from the row above
        want[y1 - 1, x0 + i] = mix(b, a, u_share(i, w))   # bottom side
    for i in range(1, h - 1):
        want[y0 + i, x0] = mix(b, a, u_share(i, h))       # left and right sides
        want[y0 + i, x1 - 1] = mix(b, a, u_share(i, h))
    corners = np.zeros(img.shape[:2], bool)
    corners[[y0, y0, y1 - 1, y1 - 1], [x0, x1 - 1, x0, x1 - 1]] = True
    diff = np.abs(out.astype(np.float64) - want)[~corners]
    assert diff.max() <= 1.0, f"max difference {diff.max():.2f} levels"
    limit = np.abs(mix(b, a, u_share(0, h)) - b) + 1.0
    assert (np.abs(out[corners].astype(np.float64) - b) <= limit).all()


def test_flat_and_smooth_gradient_unchanged(smaa):
    """A flat colour and a seeded smooth photograph-like field (low-frequency colour with 1-level grain; no
    neighbour step near the 0.05 luma threshold): no edges, every sample back bit for bit."""
    rng = np.random.default_rng(11)
    flat = np.broadcast_to(rng.integers(30, 220, 3).astype(np.uint8), (32, 48, 3)).copy()
    np.testing.assert_array_equal(smaa.process(flat), flat)
    h, w = 96, 128
    coarse = rng.uniform(40, 210, (4, 5, 3))
    yi, xi = np.linspace(0, 3, h), np.linspace(0, 4, w)
    # Bilinear upsampling of the coarse field: steps of at most (170 / 24) levels per pixel.
    y0, x0 = np.minimum(yi.astype(int), 2), np.minimum(xi.astype(int), 3)
    fy, fx = (yi - y0)[:, None, None], (xi - x0)[None, :, None]
    top = coarse[y0][:, x0] * (1 - fx) + coarse[y0][:, x0 + 1] * fx
    bottom = coarse[y0 + 1][:, x0] * (1 - fx) + coarse[y0 + 1][:, x0 + 1] * fx
    smooth = top * (1 - fy) + bottom * fy + rng.integers(-1, 2, (h, w, 3))
    smooth = np.clip(np.rint(smooth), 0, 255).astype(np.uint8)
    luma = (smooth / 255.0) @ np.array([0.2126, 0.7152, 0.0722])
    assert max(np.abs(np.diff(luma, axis=0)).max(), np.abs(np.diff(luma, axis=1)).max()) < 0.04
    np.testing.assert_array_equal(smaa.process(smooth), smooth)


def test_isolated_pixel_stays_within_its_neighbourhood(smaa):
    """A single pixel of another colour: only its 3x3 neighbourhood may change, and it keeps most of itself
    (SMAA blends each pixel with its four neighbours only, by at most half)."""
    rng = np.random.default_rng(7)
    bg, dot = two_colours(rng)
    img = np.broadcast_to(bg, (21, 23, 3)).copy()
    img[10, 11] = dot
    out = smaa.process(img)
    changed = np.argwhere((out != img).any(-1))
    assert changed.size, "the dot should be antialiased a little"
    assert (np.abs(changed - [10, 11]) <= 1).all(), f"changed outside the 3x3: {changed.tolist()}"
    lin = [srgb_to_linear(v / 255.0) for v in (bg, dot, out[10, 11])]
    kept = (lin[2] - lin[0]) / (lin[1] - lin[0])
    assert (kept >= 0.5).all(), f"the dot kept only {kept} of its contrast"


def test_local_contrast_adaptation():
    """A weak step (0.08) next to a strong one (0.6) is no edge; alone, it is; under the threshold it never is."""
    luma = np.full((8, 12), 0.2, np.float32)
    luma[:, 6:] = 0.28            # weak step at x = 6
    left, _ = detect_edges(luma)
    assert left[:, 6].all() and left.sum() == 8
    luma[:, 7:] = 0.88            # a strong step right after it: the weak one is dropped
    left, _ = detect_edges(luma)
    assert not left[:, 6].any() and left[:, 7].all()
    luma[:, :] = 0.2
    luma[:, 6:] = 0.245           # under the 0.05 threshold
    assert not detect_edges(luma)[0].any()


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize("channels", [None, 1, 2, 3, 4])
def test_dtype_shape_alpha(smaa, dtype, channels):
    """Same shape and dtype back for grey (h, w) and (h, w, 1), grey+alpha, RGB and RGBA in every sample type;
    alpha bit for bit; the colour the same as without alpha; and the stair step antialiased in every type."""
    rng = np.random.default_rng(13)
    a, b = two_colours(rng)
    img8, _ = staircase(a, b, h=24, w=6 * STEP)
    if channels in (None, 1, 2):
        img8 = np.rint((img8 / 255.0) @ np.array([0.2126, 0.7152, 0.0722]) * 255).astype(np.uint8)[..., None]
    scale = {np.uint8: 1, np.uint16: 257, np.float32: 1 / 255}[dtype]
    colour = (img8.astype(np.float64) * scale).astype(dtype)
    if channels in (2, 4):
        alpha = (rng.uniform(0.2, 1.0, img8.shape[:2] + (1,)) * (255 * scale if dtype != np.float32 else 1))
        frame = np.concatenate([colour, alpha.astype(dtype)], -1)
    else:
        frame = colour[..., 0] if channels is None else colour
    out = smaa.process(frame)
    assert out.shape == frame.shape and out.dtype == frame.dtype
    plain = smaa.process(colour)
    if channels in (2, 4):
        np.testing.assert_array_equal(out[..., -1], frame[..., -1])
        np.testing.assert_array_equal(out[..., :-1], plain)
    moved = np.abs(plain.astype(np.float64) - colour) / scale
    assert moved.max() > 40, "the stair step should be antialiased"
    # The 8-bit result scaled: the same blend within a level, whatever the sample type.
    ref = smaa.process(img8).astype(np.float64)
    assert np.abs(plain.astype(np.float64) / scale - ref).max() <= 1.0


def test_registered_in_the_bench():
    """`--methods smaa` reaches it; its device name says it is numpy, not OpenCL."""
    proc = B.METHODS["smaa"](None)
    assert isinstance(proc, SMAA) and "numpy" in proc.device_name and "SMAA 1x" in proc.device_name
    proc.close()
