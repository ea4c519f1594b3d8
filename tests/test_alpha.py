"""Alpha as coverage (spatial/alpha.py, Filter(alpha=...)): an element over transparency, one sample per pixel,
against its 8x8 supersampled truth; opaque frames and untouched pixels bit for bit."""
import numpy as np
import pytest

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.spatial.alpha import AlphaSplit, MergePass, has_coverage, varied_box, varied_tiles
from mlaa_stream.spatial.filter import Filter

SPP = 8


def element(seed: int, h: int = 72, w: int = 96, samples: int = 1):
    """Discs and triangles of random flat colours over transparency, sampled on a samples x samples grid per pixel:
    (premultiplied linear colour (h, w, 3), coverage (h, w)), both averages of the samples."""
    rng = np.random.default_rng(seed)
    shapes = []
    for _ in range(5):
        colour = rng.uniform(0.05, 0.95, 3)
        if rng.random() < 0.5:
            cx, cy, r = rng.uniform(10, w - 10), rng.uniform(10, h - 10), rng.uniform(5, 16)
            shapes.append((colour, lambda x, y, cx=cx, cy=cy, r=r: (x - cx) ** 2 + (y - cy) ** 2 < r * r))
        else:
            p = rng.uniform([0, 0], [w, h], (3, 2))

            def tri(x, y, p=p):
                s = [(p[(k + 1) % 3, 0] - p[k, 0]) * (y - p[k, 1]) - (p[(k + 1) % 3, 1] - p[k, 1]) * (x - p[k, 0])
                     for k in range(3)]
                return ((s[0] > 0) & (s[1] > 0) & (s[2] > 0)) | ((s[0] < 0) & (s[1] < 0) & (s[2] < 0))
            shapes.append((colour, tri))
    colour, cover = np.zeros((h, w, 3)), np.zeros((h, w))
    offsets = (np.arange(samples) + 0.5) / samples
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    for oy in offsets:
        for ox in offsets:
            c, a = np.zeros((h, w, 3)), np.zeros((h, w), bool)
            for rgb, inside in shapes:  # later shapes in front
                hit = inside(xx + ox, yy + oy)
                c[hit], a[hit] = rgb, True
            colour += c * a[..., None]
            cover += a
    n = samples * samples
    return colour / n, cover / n


def straight8(premul: np.ndarray, cover: np.ndarray) -> np.ndarray:
    """A straight-alpha 8-bit sRGB frame (as a PNG holds it; 0 where transparent)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        straight = np.where(cover[..., None] > 0, premul / cover[..., None], 0.0)
    return np.dstack([np.rint(linear_to_srgb(straight) * 255), np.rint(cover * 255)]).astype(np.uint8)


def composite(frame8: np.ndarray, plate: np.ndarray) -> np.ndarray:
    """A straight 8-bit RGBA frame over a linear plate, in linear light."""
    a = frame8[..., 3:].astype(np.float64) / 255
    return srgb_to_linear(frame8[..., :3] / 255.0) * a + (1 - a) * plate


def removed(out: np.ndarray, inp: np.ndarray, truth: np.ndarray) -> float:
    return 1 - float(np.mean((out - truth) ** 2) / np.mean((inp - truth) ** 2))


@pytest.fixture(scope="module")
def filters():
    with Filter() as cover, Filter(alpha="keep") as keep:
        yield cover, keep


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_silhouette_against_transparency_is_antialiased_in_alpha(filters, seed):
    """The alpha removes most of its error against the 8x8 coverage, and the composite over a plate follows; with
    alpha='keep' (the colour alone) the alpha stays binary and the composite over a bright plate gets worse."""
    coverage, keep = filters
    inp = straight8(*element(seed))
    truth_p, truth_a = element(seed, samples=SPP)
    plate = np.full(truth_p.shape, 0.8)
    truth = truth_p + (1 - truth_a[..., None]) * plate
    base = composite(inp, plate)
    out, old = coverage.process(inp), keep.process(inp)
    a_in, a_out = inp[..., 3] / 255.0, out[..., 3] / 255.0
    assert removed(a_out, a_in, truth_a) > 0.6                       # measured 0.64-0.70
    assert removed(composite(out, plate), base, truth) > 0.55        # 0.59-0.71
    assert np.array_equal(old[..., 3], inp[..., 3])
    assert removed(composite(old, plate), base, truth) < 0            # -0.47 .. -1.71: a dark rim


def test_rim_pixels_keep_the_element_colour(filters):
    """A flat orange disc over transparent black: every pixel the filter gives alpha keeps the disc's colour
    (straight alpha: no dark fringe), and the transparent pixels it leaves keep theirs."""
    coverage, _ = filters
    yy, xx = np.mgrid[0:64, 0:64] + 0.5
    inside = (xx - 30.3) ** 2 + (yy - 33.7) ** 2 < 20.2 ** 2
    frame = np.zeros((64, 64, 4), np.uint8)
    frame[inside] = (230, 120, 40, 255)
    out = coverage.process(frame)
    rim = (out[..., 3] != frame[..., 3])
    assert rim.sum() > 60
    seen = out[..., 3] > 0
    assert np.abs(out[seen][:, :3].astype(int) - (230, 120, 40)).max() <= 1
    assert np.array_equal(out[~seen], frame[~seen])


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_opaque_rgba_is_filtered_as_before(filters, dtype):
    """Alpha one value everywhere: the colour filter alone, bit for bit, alpha kept."""
    coverage, keep = filters
    rng = np.random.default_rng(3)
    top = np.iinfo(dtype).max
    frame = np.zeros((48, 64, 4), dtype)
    frame[..., :3] = (rng.random((48, 64, 1)) > 0.5) * rng.integers(0, top, 3)  # two-tone noise blocks
    frame[..., 3] = top
    assert not has_coverage(frame)
    out = coverage.process(frame)
    assert np.array_equal(out, keep.process(frame))
    assert not np.array_equal(out, frame)


def test_untouched_pixels_and_semi_transparent_areas_bit_for_bit(filters):
    """Pixels no filter changes come back exactly, fractional alpha included (a 50 % glass pane, away from the
    silhouettes)."""
    coverage, _ = filters
    inp = straight8(*element(4))
    inp[5:20, 5:30] = (90, 150, 210, 128)
    out = coverage.process(inp)
    changed = (out != inp).any(axis=2)
    assert 0 < changed.sum() < 0.2 * changed.size
    assert np.array_equal(out[8:17, 8:27], inp[8:17, 8:27])


def test_premultiplied_float_frame():
    """EXR's convention: where the alpha stays 1, and on light with no coverage, the colour is the colour filter's
    alone (what alpha='keep' gives); nothing (alpha 0, colour 0) gains no light; the colour stays premultiplied
    (never over its alpha's share of the element's brightest colour) and the alpha is antialiased."""
    premul, cover = element(5)
    truth_p, truth_a = element(5, samples=SPP)
    frame = np.dstack([premul, cover]).astype(np.float32)
    frame[1:5, 1:5, :3], frame[1:5, 1:5, 3] = (3.0, 2.0, 1.0), 0.0  # light with no coverage
    with Filter(linear_input=True) as f, Filter(linear_input=True, alpha="keep") as k:
        out, old = f.process(frame, premultiplied=True), k.process(frame, premultiplied=True)
    stay = out[..., 3] == frame[..., 3]
    inside = stay & ((frame[..., 3] == 1) | (frame[..., :3] != 0).any(axis=2))
    assert np.array_equal(out[inside], old[inside]) and inside[1:5, 1:5].all()
    nothing = stay & (frame == 0).all(axis=2)
    assert (out[nothing] == 0).all() and (old[nothing] != 0).any()
    assert removed(out[..., 3], cover, truth_a) > 0.6    # measured 0.69
    away = np.ones(cover.shape, bool)
    away[:7, :7] = False  # the light patch is in neither the element nor its truth
    assert removed(out[away][:, :3], premul[away], truth_p[away]) > 0.6   # 0.70
    assert np.all(out[:, 7:, :3] <= out[:, 7:, 3:] * premul.max() + 1e-6)


def test_non_finite_samples_pass_through():
    premul, cover = element(6)
    frame = np.dstack([premul, cover]).astype(np.float32)
    frame[10, 10, 0], frame[11, 40, 3] = np.nan, np.inf
    with Filter(linear_input=True) as f:
        out = f.process(frame, premultiplied=True)
    assert np.isnan(out[10, 10, 0]) and np.isinf(out[11, 40, 3])
    assert np.isfinite(np.delete(out.reshape(-1, 4), [10 * 96 + 10, 11 * 96 + 40], axis=0)).all()


def test_keep_rectangles_keep_alpha_too():
    inp = straight8(*element(0))
    with Filter(keep=["0,0,48,36"]) as f:
        out = f.process(inp)
    assert np.array_equal(out[:36, :48], inp[:36, :48])
    assert not np.array_equal(out, inp)


def test_split_merge_known_answers():
    """The split premultiplies in linear light (0 where transparent, the colour where opaque) and a merge of the
    unchanged planes gives the frame back."""
    frame = np.array([[[200, 100, 50, 0], [200, 100, 50, 255], [200, 100, 50, 128]]], np.uint8)
    split = AlphaSplit(frame, premultiplied=False, decode=True)
    assert split.colour[0, 0].tolist() == [0, 0, 0] and split.colour[0, 1].tolist() == [200, 100, 50]
    half = np.rint(linear_to_srgb(srgb_to_linear(np.array([200, 100, 50]) / 255) * 128 / 255) * 255)
    assert split.colour[0, 2].tolist() == half.tolist()
    assert np.array_equal(split.merge(split.colour, split.alpha), frame)


def test_varied_tiles():
    plane = np.zeros((32, 40), np.uint8)
    plane[12, 20] = 255
    tiles = varied_tiles(plane, 8)
    assert tiles.shape == (4, 5)
    assert tiles.sum() == 1 and tiles[1, 2]  # the pixels of its steps (x and y 11-13 / 19-21) and 2 px around
    plane[12, 21] = 255
    assert varied_tiles(plane, 8)[1, 3]      # x 24 now
    plane[20:, :] = np.arange(40) * 2   # a ramp: varied, but no step over HARD_STEP
    assert varied_tiles(plane, 8)[3].all() and not varied_tiles(plane, 8, 0.125)[3].any()


def test_alpha_mode_is_checked():
    with pytest.raises(ValueError, match="alpha: expected one of coverage, keep"):
        Filter(alpha="straight")


def test_alpha_bench_scores_renders_over_transparency():
    """`python -m mlaa_stream.bench.alpha` at a small size, one world: on every view and both formats, coverage
    leaves the composite closer to the truth than the colour filtered alone, and the alpha removes error."""
    from mlaa_stream.yardstick import rendered as R
    ok, why = R.egl_available()
    if not ok:
        pytest.skip(why)
    from mlaa_stream.bench.alpha import run
    res = run([(192, 108)], ["plaza"], log=lambda line: None)
    for fmt in ("png", "exr"):
        keep, cover = np.array(res[(fmt, "keep")]), np.array(res[(fmt, "coverage")])
        assert (cover[:, :3] > keep[:, :3]).all() and (cover[:, 3] > 50).all(), (fmt, cover, keep)  # >= 57.8
        assert (keep[:, 3] == 0).all()


def test_command_line_png_and_exr_over_transparency(tmp_path):
    """Through `mlaa-stream`: a straight-alpha PNG and a premultiplied EXR of one element get their alpha antialiased
    (the EXR's colour stays premultiplied: never over alpha times the element's brightest colour); `--alpha keep`
    leaves the alpha as read."""
    import OpenImageIO as oiio
    from click.testing import CliRunner

    from mlaa_stream.cli.main import main
    from mlaa_stream.io.images import read_image
    premul, cover = element(7)
    src = tmp_path / "in"
    src.mkdir()
    oiio.ImageBuf(straight8(premul, cover)).write(str(src / "el.png"))
    oiio.ImageBuf(np.dstack([premul, cover]).astype(np.float32)).write(str(src / "el.exr"))
    for args, changed in (([], True), (["--alpha", "keep"], False)):
        out = tmp_path / f"out{len(args)}"
        r = CliRunner().invoke(main, [str(src), "-o", str(out), *args])
        assert r.exit_code == 0, r.output
        for name in ("el.png", "el.exr"):
            a, b = read_image(str(src / name)).pixels, read_image(str(out / name)).pixels
            assert (not np.array_equal(a[..., 3], b[..., 3])) == changed, (name, args)
        exr = read_image(str(out / "el.exr")).pixels
        # the colour alone (keep) spreads light into transparent pixels whose alpha stays 0
        assert np.all(exr[..., :3] <= exr[..., 3:] * premul.max() + 1e-3) == changed


def test_temporal_output_keeps_the_spatial_rims():
    """After a temporal stage (which resolves straight colour from input samples, black where transparent) every
    pixel at or beside partial coverage is the spatial output's; elsewhere the stage's."""
    from mlaa_stream.spatial.alpha import spatial_at_rims
    spatial = np.zeros((8, 10, 4), np.uint8)
    spatial[:, :5] = (200, 100, 50, 255)
    spatial[:, 5, 3] = 128
    spatial[:, 5, :3] = (200, 100, 50)
    temporal = spatial.copy()
    temporal[..., :3] //= 2   # a dark stage everywhere
    out = spatial_at_rims(spatial, temporal)
    assert np.array_equal(out[:, 4:7], spatial[:, 4:7])
    assert np.array_equal(out[:, :4], temporal[:, :4]) and np.array_equal(out[:, 7:], temporal[:, 7:])
    opaque = spatial.copy()
    opaque[..., 3] = 255
    assert spatial_at_rims(opaque, temporal) is temporal


def test_antialiaser_takes_the_alpha_mode():
    from mlaa_stream.antialiaser import Antialiaser
    bgra = straight8(*element(8))[..., [2, 1, 0, 3]].copy()
    with Antialiaser() as aa, Antialiaser(alpha="keep") as keep:
        assert not np.array_equal(aa(bgra)[..., 3], bgra[..., 3])
        assert np.array_equal(keep(bgra)[..., 3], bgra[..., 3])
    with pytest.raises(ValueError, match="alpha"):
        Antialiaser(alpha="premultiplied")


def test_the_colour_stored_under_transparency_does_not_matter(filters):
    """Straight alpha leaves the colour of transparent pixels free (black, white, the colour bled outwards): the
    composite of the output is the same whatever it is, and those pixels the filter leaves keep theirs."""
    coverage, _ = filters
    black = straight8(*element(9))
    noisy = black.copy()
    clear = black[..., 3] == 0
    noisy[clear, :3] = np.random.default_rng(9).integers(0, 256, (int(clear.sum()), 3))
    a, b = coverage.process(black), coverage.process(noisy)
    plate = np.full(black.shape[:2] + (3,), 0.5)
    assert np.array_equal(a[..., 3], b[..., 3])
    assert np.abs(composite(a, plate) - composite(b, plate)).max() < 1e-12
    left = b[..., 3] == 0
    assert np.array_equal(b[left], noisy[left])


def test_grey_and_alpha_png(tmp_path):
    """A grey + alpha PNG: the alpha antialiased with the grey, the rim keeping the element's grey."""
    import OpenImageIO as oiio
    from click.testing import CliRunner

    from mlaa_stream.cli.main import main
    rgba = straight8(*element(3))
    la = np.ascontiguousarray(rgba[..., [1, 3]])
    spec = oiio.ImageSpec(la.shape[1], la.shape[0], 2, "uint8")
    spec.channelnames, spec.alpha_channel = ("Y", "A"), 1
    out = oiio.ImageOutput.create(str(tmp_path / "la.png"))
    assert out.open(str(tmp_path / "la.png"), spec) and out.write_image(la)
    out.close()
    r = CliRunner().invoke(main, [str(tmp_path / "la.png"), "-o", str(tmp_path / "out.png")])
    assert r.exit_code == 0, r.output
    got = oiio.ImageBuf(str(tmp_path / "out.png")).get_pixels(oiio.UINT8)
    assert got.shape == la.shape
    moved = got[..., 1] != la[..., 1]
    assert moved.sum() > 100
    rim = moved & (la[..., 1] == 0) & (got[..., 1] > 0)   # coverage spread outwards: the grey of a neighbour
    assert rim.any() and (got[rim][:, 0] > 0).all()


@pytest.mark.skipif("qtrle" not in __import__("av").codecs_available, reason="this FFmpeg has no qtrle encoder")
def test_video_with_alpha(tmp_path):
    """A QuickTime Animation clip of an element over transparency (straight alpha, as video carries it): its alpha
    comes out antialiased, and the rim keeps the element's colour."""
    import av
    from click.testing import CliRunner

    from mlaa_stream.cli.main import main
    src, out = tmp_path / "el.mov", tmp_path / "out.mov"
    frames = [straight8(*element(10 + k)) for k in range(2)]
    with av.open(str(src), "w") as c:
        s = c.add_stream("qtrle", rate=25)
        s.width, s.height, s.pix_fmt = 96, 72, "argb"
        for f in frames:
            for p in s.encode(av.VideoFrame.from_ndarray(f, format="rgba").reformat(format="argb")):
                c.mux(p)
        for p in s.encode():
            c.mux(p)
    r = CliRunner().invoke(main, [str(src), "-o", str(out)])
    assert r.exit_code == 0, r.output
    with av.open(str(out)) as c:
        got = [f.to_ndarray(format="rgba") for f in c.decode(video=0)]
    assert len(got) == 2
    for f, g in zip(frames, got):
        assert (g[..., 3] != f[..., 3]).sum() > 100
        gained = (f[..., 3] == 0) & (g[..., 3] > 0)
        assert gained.any() and (g[gained][:, :3].max(axis=1) > 0).all()  # not the transparent pixels' black


def _rgba(rng: np.random.Generator, dtype, premultiplied: bool, h: int = 37, w: int = 53) -> np.ndarray:
    """Seeded RGBA samples: alpha 0 / 1 / partial, colour random (premultiplied when asked), in `dtype`'s scale."""
    top = float(np.iinfo(dtype).max) if np.dtype(dtype).kind in "ui" else 1.0
    a = rng.choice([0.0, 1.0, 0.3, 0.8], size=(h, w), p=[0.3, 0.4, 0.15, 0.15])
    c = rng.random((h, w, 3)) * (a[..., None] if premultiplied else 1.0)
    f = np.concatenate([c, a[..., None]], axis=2) * top
    return (np.rint(f) if top != 1.0 else f).astype(dtype)


@pytest.mark.parametrize("dtype, premultiplied, options, tolerance", [
    (np.uint8, False, {}, 0), (np.uint16, False, {}, 1), (np.float32, False, {}, 2e-5),
    (np.float32, True, {"linear_input": True}, 1e-6), (np.float16, True, {"linear_input": True}, 0),
    (np.uint8, False, {"linear": False}, 1), (np.uint16, False, {"transfer": "pq"}, 1)])
def test_device_merge_matches_its_reference(dtype, premultiplied, options, tolerance):
    """kernels/alpha.cl (MergePass) against AlphaSplit.merge, its numpy reference: seeded frames with transparent,
    opaque and partly covered pixels (non-finite samples in the float ones), a third of the colour and a fifth of
    the alpha changed at random, frame borders included. Equal within `tolerance` (stored units: the tables'
    interpolation against the reference's exact decode); HDR codes below 1024 (under 0.1 cd/m2 in PQ) within 16."""
    rng = np.random.default_rng(7)
    with Filter(**options) as f:
        frame = _rgba(rng, dtype, premultiplied)
        if dtype == np.float32 and premultiplied:
            frame[3, 4, 1], frame[5, 6, 3], frame[0, 0, 0] = np.nan, np.inf, 1e30
        split = AlphaSplit(frame, premultiplied, decode=f.options.linear and not f.options.linear_input,
                           transfer=f.transfer)
        top = float(np.iinfo(dtype).max) if np.dtype(dtype).kind in "ui" else 1.0
        colour, alpha = split.colour.copy(), split.alpha.copy()
        moved = rng.random(colour.shape[:2]) < 0.3
        colour[moved] = (rng.random((int(moved.sum()), 3)) * top).astype(dtype)
        moved = rng.random(alpha.shape) < 0.2
        alpha[moved] = (rng.random(int(moved.sum())) * top).astype(dtype)
        ref = split.merge(colour, alpha).astype(np.float64)
        got = MergePass(f.context, f._luts, f.options.pass_defines()).merge(split, colour, alpha)
    assert got.dtype == frame.dtype and got.shape == frame.shape
    got = got.astype(np.float64)
    with np.errstate(invalid="ignore"):   # inf - inf where both kept an inf
        diff = np.where((got == ref) | (np.isnan(got) & np.isnan(ref)), 0.0, np.abs(got - ref))
    assert np.array_equal(np.isnan(got), np.isnan(ref))
    allowed = np.where(ref < 1024, 16, tolerance) if "transfer" in options else tolerance
    assert (diff <= allowed).all(), diff.max()
    assert (got != frame.astype(np.float64)).any()


def test_the_alpha_filter_box_gives_the_whole_planes_result():
    """Filter.filter_alpha filters only the box of tiles where the alpha varies (plus a margin, grown to few sizes):
    bit for bit what filtering the whole plane gives, for a hard-edged disc in a corner, a disc beside a soft ramp
    (both filters and the tile choice), with the colour's render regions and without; no variation: the plane."""
    y, x = np.mgrid[0:240, 0:328]
    disc = (((x - 260) ** 2 + (y - 50) ** 2) < 37 ** 2).astype(np.uint8) * 255
    ramp = (np.clip((x - 60) / 9.0, 0, 1) * (y > 150) * 255).astype(np.uint8)
    regions = np.zeros((30, 41), np.uint8)
    regions[:12, 25:] = 1
    with Filter() as f:
        for plane in (disc, np.maximum(disc, ramp)):
            for reg in (regions, None):
                whole = f._filter_alpha_box(plane, reg, varied_tiles(plane, 8))
                boxed = f.filter_alpha(plane, reg)
                assert (boxed != plane).any() and np.array_equal(boxed, whole)
        flat = np.full((240, 328), 255, np.uint8)
        assert np.array_equal(f.filter_alpha(flat, regions), flat)
    tiles = np.zeros((30, 41), bool)
    tiles[10:12, 0:3] = True
    assert varied_box(tiles) == (8, 16, 0, 8)   # 2 tiles of margin, sides of 8 tiles
    tiles[:] = False
    tiles[29, 38:] = True
    assert varied_box(tiles) == (22, 30, 33, 41)   # grown inwards at the frame's edge
    assert varied_box(np.ones((30, 41), bool)) == (0, 30, 0, 41) and varied_box(tiles & False) is None
