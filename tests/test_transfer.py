"""HDR video's transfers (device/transfer.py): PQ / HLG codes filtered in the light they code, coded back."""
from __future__ import annotations

import av
import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main as cli
from mlaa_stream.bench.hdr_video import coded   # linear light -> exact 16-bit codes
from mlaa_stream.io.video import probe_video
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.device.colour import device_luts, lut_read
from mlaa_stream.device.transfer import (_HLG_WHITE, TRANSFERS, decode_table, hlg_to_linear, kernel_defines,
                                          linear_to_hlg, linear_to_pq, pq_to_linear, with_transfer_tables)
from mlaa_stream.yardstick import metrics as M


def half_plane(h: int, w: int, samples: int, slope: float, offset: float, bright: float, dark: float) -> np.ndarray:
    """(h, w, 3) linear light: `bright` below the line y = slope x + offset, `dark` above, the box mean of
    samples x samples point samples per pixel (1: the pixel centre)."""
    y, x = (np.mgrid[0:h * samples, 0:w * samples] + 0.5) / samples
    img = np.where(y > slope * x + offset, bright, dark).reshape(h, samples, w, samples).mean(axis=(1, 3))
    return np.repeat(img[..., None], 3, axis=2)


def test_curves_at_known_points():
    """BT.2408: reference white (203 cd/m2) is PQ 58 % and HLG 75 %; PQ's peak is 10000 cd/m2; HLG's square-root
    segment ends at a signal of 0.5 (E = 1/12)."""
    assert float(linear_to_pq(np.float64(1.0))) == pytest.approx(0.5807, abs=2e-4)
    assert float(linear_to_pq(np.float64(100 / 203))) == pytest.approx(0.5081, abs=2e-4)
    assert float(pq_to_linear(1.0)) == pytest.approx(10000 / 203, rel=1e-9)
    assert float(hlg_to_linear(0.75)) == pytest.approx(1.0, rel=1e-9)
    assert float(linear_to_hlg(np.float64(1.0))) == pytest.approx(0.75, abs=1e-9)
    assert float(hlg_to_linear(0.5)) * _HLG_WHITE == pytest.approx(1 / 12, rel=1e-9)
    assert float(hlg_to_linear(0.5 - 1e-9)) == pytest.approx(float(hlg_to_linear(0.5 + 1e-9)), rel=1e-6)
    for transfer in TRANSFERS:
        v = np.linspace(0.001, 1, 1000)  # PQ codes light 0 at a signal of 7e-7, not 0
        back = (linear_to_pq if transfer == "pq" else linear_to_hlg)(
            (pq_to_linear if transfer == "pq" else hlg_to_linear)(v))
        assert np.abs(back - v).max() < 1e-8  # HLG: its published constants meet at 1 to 5e-9


@pytest.mark.parametrize("transfer", TRANSFERS)
def test_tables_code_light_within_a_code(transfer):
    """The device's tables as the kernels read them (common.cl lut_read, encode_arg): the encode lands within 0.05 of
    a 16-bit code of the exact curve from 1e-6 of reference white to the peak; a code decoded and coded again comes
    back within 5 codes of 65535 (the darkest codes, where the decode table's first entries interpolate a steep
    curve) and within 1 from code 1024 up."""
    luts = with_transfer_tables(device_luts(), transfer)
    n = luts.size // 3
    scale = np.float32(kernel_defines(transfer)["ENCODE_SCALE"])
    assert kernel_defines(transfer)["ENCODE_WARP"] == 1 and kernel_defines(None) == {}

    def encode_mix(v):
        return lut_read(luts[2 * n:], np.sqrt(np.sqrt(np.asarray(v, np.float32) * scale)))

    light = np.geomspace(1e-6, float(decode_table(transfer, 65535)[-1]), 100000)
    exact = (linear_to_pq if transfer == "pq" else linear_to_hlg)(light)
    assert np.abs(encode_mix(light) - exact).max() * 65535 < 0.05
    codes = np.arange(65536)
    again = encode_mix(lut_read(luts[:n], (codes / 65535).astype(np.float32))) * 65535
    assert np.abs(again - codes).max() < 5 and np.abs(again - codes)[1024:].max() < 1
    assert decode_table(transfer, 65535)[-1] == pytest.approx(10000 / 203 if transfer == "pq" else 3.7741, rel=1e-4)
    assert np.array_equal(with_transfer_tables(luts, None), luts)


@pytest.mark.parametrize("transfer", TRANSFERS)
def test_edges_between_lights_are_blended_as_light(transfer):
    """Half-planes at three slopes between two lights (a lamp on a dark wall, a highlight on a lit one, shadow
    detail), 1 spp against a 16x16 box truth in linear light, scored on the codes: with the transfer the filter
    removes 0.66 or more of the error on every case (the codes as sRGB: 0.50-0.96) and more than without it on
    average; a blend in the codes' sRGB decode put the rim too dark."""
    gains, scores = [], []
    for bright, dark in ((1000, 0.5), (1000, 300), (150, 20)):
        for slope in (0.3, 0.7, 2.5):
            inp = coded(half_plane(48, 64, 1, slope, 10.3, bright / 203, dark / 203), transfer)
            truth = coded(half_plane(48, 64, 16, slope, 10.3, bright / 203, dark / 203), transfer)
            with Filter(transfer=transfer) as f, Filter() as plain:
                out, before = f.process(inp), plain.process(inp)
            scores.append(M.error_removed(out, inp, truth))
            gains.append(scores[-1] - M.error_removed(before, inp, truth))
    assert min(scores) >= 0.66, scores
    assert np.mean(gains) >= 0.08, gains


def test_untouched_pixels_keep_their_codes_and_alpha_round_trips():
    """A flat field and a textured one keep every code where the filter changed nothing; an RGBA frame's alpha (a
    coverage, coded linearly) comes back as it was where it is one value."""
    rng = np.random.default_rng(5)
    base = coded(half_plane(40, 56, 1, 0.4, 12.2, 600 / 203, 2 / 203), "pq")
    base[30:, :] = 30000   # a flat band
    with Filter(transfer="pq") as f:
        out = f.process(base)
    assert np.array_equal(out[32:, 2:-2], base[32:, 2:-2])
    assert (out != base).any()
    rgba = np.concatenate([base, np.full(base.shape[:2] + (1,), 65535, np.uint16)], axis=2)
    rgba[..., :3] = np.clip(rgba[..., :3].astype(np.int64) + rng.integers(0, 2, rgba[..., :3].shape), 0, 65535)
    with Filter(transfer="pq") as f:
        out4 = f.process(rgba)
    assert np.array_equal(out4[..., 3], rgba[..., 3])


def test_edge_tests_read_the_codes():
    """With a transfer the edge tests read the codes as they read any integer frame (Filter._lin_lab): the edges found
    are those of the filter without the transfer, bit for bit."""
    rng = np.random.default_rng(11)
    lin = np.repeat(rng.choice([0.01, 0.3, 1.0, 4.0, 20.0], size=(36, 48, 1)), 3, axis=2)
    codes = coded(lin, "pq")
    with Filter(transfer="pq") as f, Filter() as plain:
        edges_transfer = f.intermediates(codes)["edges"]
        edges_codes = plain.intermediates(codes)["edges"]
        assert edges_codes.any()
        assert np.array_equal(edges_transfer, edges_codes)
        assert not np.array_equal(f.process(codes), plain.process(codes))   # the same edges, blended in light


def test_bad_transfer_and_float_frames_are_refused():
    with pytest.raises(ValueError, match="transfer"):
        Filter(transfer="gamma")
    with pytest.raises(ValueError, match="exclude each other"):
        Filter(transfer="pq", linear_input=True)
    with Filter(transfer="pq") as f, pytest.raises(ValueError, match="8- or 16-bit codes"):
        f.process(np.full((8, 8, 3), 0.5, np.float32))


@pytest.mark.parametrize("transfer", TRANSFERS)
def test_an_element_over_transparency_keeps_its_colour(transfer):
    """An RGBA frame of HDR codes whose alpha is a 1-spp silhouette (spatial/alpha.py): the alpha is antialiased and
    the rim's straight colour is the element's own within 8 codes of 65535 (its premultiplied light divided by the
    filtered alpha, through the transfer's curves), not darkened towards the transparent pixels."""
    cover = half_plane(40, 56, 1, 0.6, 8.4, 1.0, 0.0)[..., 0]
    element = coded(np.full((40, 56, 3), 2.5), transfer)
    rgba = np.concatenate([element * (cover[..., None] > 0), (cover[..., None] * 65535).astype(np.uint16)], axis=2)
    with Filter(transfer=transfer) as f:
        out = f.process(rgba)
    rim = (out[..., 3] > 0) & (out[..., 3] < 65535)
    assert rim.sum() >= 20
    assert np.abs(out[rim][:, :3].astype(np.int64) - element[0, 0].astype(np.int64)).max() <= 8


@pytest.mark.skipif("libx265" not in av.codecs_available, reason="this FFmpeg has no libx265 to write an HDR10 source")
def test_an_hdr10_video_is_filtered_in_light(tmp_path):
    """An HEVC 10-bit BT.2020 / PQ clip of a bright diagonal on a dark ground: the command line reads its transfer
    (said with -v) and the output keeps it; the blended rim is brighter than when the same clip says it is BT.709
    (the codes mixed through the sRGB decode: too dark), and the flat ground keeps its codes."""
    frame = coded(half_plane(48, 64, 1, 0.45, 9.7, 1000 / 203, 1 / 203), "pq")
    clips = {}
    for name, trc in (("pq", 16), ("sdr", 1)):
        src = tmp_path / f"{name}.mkv"
        _hdr10_clip(src, frame, trc)
        res = CliRunner().invoke(cli, [str(src), "-v", "-o", str(tmp_path / f"{name}_out.mkv"),
                                       "--codec", "ffv1"])
        assert res.exit_code == 0, res.output
        assert ("SMPTE ST 2084" in res.output) == (name == "pq")
        assert probe_video(str(tmp_path / f"{name}_out.mkv")).colour["color_trc"] == trc
        with av.open(str(tmp_path / f"{name}_out.mkv")) as c:
            clips[name] = next(c.decode(video=0)).to_ndarray(format="rgb48le").astype(np.int64)
    rim = (clips["pq"] != clips["sdr"]).any(axis=2)   # the same clip, the same encode: the blends differ only
    assert rim.sum() >= 20
    assert clips["pq"][rim].mean() > clips["sdr"][rim].mean() + 1000
    assert np.array_equal(clips["pq"][40:, :4], clips["sdr"][40:, :4])


def test_fast_preset_and_antialiaser_take_the_transfer():
    """The fast preset (FastFilter: on a CPU the kernels read the frame itself) and the OpenCV-loop API (BGR frames)
    mix the transfer's light: on a lamp-on-dark-ground edge their rims differ from the codes' sRGB mix and are
    brighter, and a flat area keeps its codes."""
    from mlaa_stream import Antialiaser
    from mlaa_stream.spatial.fast_filter import FastFilter

    frame = coded(half_plane(40, 56, 1, 0.45, 9.7, 1000 / 203, 1 / 203), "pq")
    frame[32:, :] = 20000
    with FastFilter(transfer="pq") as f, FastFilter() as plain:
        fast, fast_plain = f.process(frame).astype(np.int64), plain.process(frame).astype(np.int64)
    bgr = np.ascontiguousarray(frame[..., ::-1])
    with Antialiaser(transfer="pq") as aa, Antialiaser() as plain_aa:
        api, api_plain = aa(bgr).astype(np.int64), plain_aa(bgr).astype(np.int64)
    for got, before, source in ((fast, fast_plain, frame), (api, api_plain, bgr)):
        rim = (got != before).any(axis=2)
        assert rim.sum() >= 10 and got[rim].mean() > before[rim].mean() + 500
        assert np.array_equal(got[36:, 2:-2], source[36:, 2:-2])


def _png(path, frame: np.ndarray, cicp: tuple | None) -> None:
    import OpenImageIO as oiio
    spec = oiio.ImageSpec(frame.shape[1], frame.shape[0], 3, "uint16")
    if cicp is not None:
        spec.attribute("CICP", "int[4]", cicp)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(frame)
    out.close()


def test_an_hdr_png_is_filtered_in_light(tmp_path):
    """A 16-bit PNG whose cICP says BT.2020 / PQ (as HDR screenshots are saved), in a folder beside the same image
    untagged: the tagged one's rim is mixed as light (brighter) and it keeps its cICP; the untagged one is filtered
    as sRGB, as before."""
    import OpenImageIO as oiio
    frame = coded(half_plane(40, 56, 1, 0.45, 9.7, 1000 / 203, 1 / 203), "pq")
    (tmp_path / "in").mkdir()
    _png(tmp_path / "in" / "hdr.png", frame, (9, 16, 0, 1))
    _png(tmp_path / "in" / "sdr.png", frame, None)
    res = CliRunner().invoke(cli, [str(tmp_path / "in"), "-v", "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert "SMPTE ST 2084" in res.output
    out = {}
    for name in ("hdr", "sdr"):
        image = oiio.ImageInput.open(str(tmp_path / "out" / f"{name}.png"))
        out[name] = image.read_image(format="uint16").astype(np.int64)
        out[name + "_cicp"] = image.spec().getattribute("CICP")
        image.close()
    assert tuple(out["hdr_cicp"]) == (9, 16, 0, 1) and out["sdr_cicp"] is None
    rim = (out["hdr"] != out["sdr"]).any(axis=2)
    assert rim.sum() >= 20 and out["hdr"][rim].mean() > out["sdr"][rim].mean() + 1000


def test_the_hdr_video_bench_runs():
    """`python -m mlaa_stream.bench.hdr_video` at a small size (the held-out views coded as PQ): a row per view, and
    the transfer removes more error than the codes taken as sRGB on average; `--temporal tss` a row per shot."""
    from mlaa_stream.yardstick.rendered import egl_available
    ok, why = egl_available()
    if not ok:
        pytest.skip(why)
    from mlaa_stream.bench import hdr_video
    lines: list[str] = []
    res = hdr_video.run([(192, 108)], ["pq"], ["plaza"], log=lines.append)
    codes, transfer = res[("pq", "codes")], res[("pq", "transfer")]
    assert len(codes) == len(transfer) == 4 and any("far_tele_192" in line for line in lines)
    assert np.mean([s[0] for s in transfer]) > np.mean([s[0] for s in codes])
    shots = hdr_video.run_temporal((160, 90), ["plaza"], ["tss"], frames=3, log=lines.append)
    assert set(shots) == {"spatial", "tss codes", "tss light"} and len(shots["spatial"]) == 8   # 4 views x pan, dolly
    assert "mean:" in lines[-1]


def _hdr10_clip(path, frame: np.ndarray, trc: int, frames: int = 2) -> None:
    """A lossless HEVC 10-bit 4:4:4 clip of `frame` (16-bit RGB codes) tagged BT.2020 with transfer `trc`."""
    with av.open(str(path), "w") as out:
        s = out.add_stream("libx265", rate=25, options={"x265-params": "log-level=error:lossless=1"})
        s.width, s.height, s.pix_fmt = frame.shape[1], frame.shape[0], "yuv444p10le"
        s.codec_context.color_primaries, s.codec_context.color_trc, s.codec_context.colorspace = 9, trc, 9
        for _ in range(frames):
            vf = av.VideoFrame.from_ndarray(frame, format="rgb48le").reformat(format="yuv444p10le", dst_colorspace=9)
            for p in s.encode(vf):
                out.mux(p)
        for p in s.encode():
            out.mux(p)


def _read_png(path) -> tuple[np.ndarray, tuple | None]:
    import OpenImageIO as oiio
    image = oiio.ImageInput.open(str(path))
    try:
        cicp = image.spec().getattribute("CICP")
        return image.read_image(format="uint16").astype(np.int64), (tuple(cicp) if cicp is not None else None)
    finally:
        image.close()


def test_transfer_option_says_what_files_do_not(tmp_path):
    """--transfer pq filters an untagged 16-bit PNG as the tagged one is filtered (auto), --transfer sdr a tagged
    one as the untagged one is (the codes taken as sRGB)."""
    frame = coded(half_plane(40, 56, 1, 0.45, 9.7, 1000 / 203, 1 / 203), "pq")
    for name, cicp in (("tagged", (9, 16, 0, 1)), ("plain", None)):
        (tmp_path / name).mkdir()
        _png(tmp_path / name / "f.png", frame, cicp)
    runs = {"tagged auto": ("tagged", "auto"), "plain auto": ("plain", "auto"), "plain pq": ("plain", "pq"),
            "tagged sdr": ("tagged", "sdr")}
    out = {}
    for key, (folder, choice) in runs.items():
        dst = tmp_path / key.replace(" ", "_")
        res = CliRunner().invoke(cli, [str(tmp_path / folder), "-o", str(dst), "--transfer", choice])
        assert res.exit_code == 0, res.output
        out[key] = _read_png(dst / "f.png")[0]
    assert np.array_equal(out["plain pq"], out["tagged auto"]) and np.array_equal(out["tagged sdr"], out["plain auto"])
    assert not np.array_equal(out["tagged auto"], out["plain auto"])


@pytest.mark.skipif("libx265" not in av.codecs_available, reason="this FFmpeg has no libx265 to write an HDR10 source")
def test_hdr10_video_to_frames_and_back_keeps_its_transfer(tmp_path):
    """An HDR10 clip written out as PNG frames: filtered through PQ (the frames equal the video filtered to a video,
    decoded) and each frame carries the video's cICP (BT.2020, PQ); those frames made into a video again: it is
    tagged BT.2020 / PQ (before: frames and video untagged, shown as SDR by anything that read them)."""
    frame = coded(half_plane(48, 64, 1, 0.45, 9.7, 1000 / 203, 1 / 203), "pq")
    _hdr10_clip(tmp_path / "in.mkv", frame, 16)
    res = CliRunner().invoke(cli, [str(tmp_path / "in.mkv"), "-o", str(tmp_path / "frames" / "f_%04d.png")])
    assert res.exit_code == 0, res.output
    pixels, cicp = _read_png(tmp_path / "frames" / "f_0001.png")
    assert cicp == (9, 16, 0, 1)
    res = CliRunner().invoke(cli, [str(tmp_path / "in.mkv"), "-o", str(tmp_path / "out.mkv"), "--codec", "ffv1"])
    assert res.exit_code == 0, res.output
    with av.open(str(tmp_path / "out.mkv")) as c:
        video = next(c.decode(video=0)).to_ndarray(format="rgb48le").astype(np.int64)
    assert np.abs(pixels - video).max() <= 64   # the same filter; ffv1's YUV round trip of the video only
    res = CliRunner().invoke(cli, [str(tmp_path / "frames" / "f_%04d.png"), "-o", str(tmp_path / "again.mkv"),
                                   "--codec", "ffv1"])
    assert res.exit_code == 0, res.output
    tags = probe_video(str(tmp_path / "again.mkv")).colour
    assert tags["color_trc"] == 16 and tags["color_primaries"] == 9
