"""Video inputs a serious user brings: no video stream at all, sizes of one pixel, anamorphic pixels,
several video streams, damaged timestamps, containers the source's codec cannot go in."""
from __future__ import annotations

import os
from fractions import Fraction

import av
import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.video import VideoError, VideoWriter, choose_pix_fmt, probe_video
from demo_maker import make_demo
from clips import mux_moving_edge



def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def write_audio_only(path: str) -> None:
    with av.open(path, "w") as out:
        a = out.add_stream("aac", rate=48000, layout="mono")
        for i in range(8):
            fr = av.AudioFrame.from_ndarray(np.zeros((1, 1024), np.float32), format="fltp", layout="mono")
            fr.sample_rate, fr.pts = 48000, i * 1024
            for p in a.encode(fr):
                out.mux(p)
        for p in a.encode():
            out.mux(p)


def test_an_audio_only_file_is_refused_naming_it(tmp_path):
    src = str(tmp_path / "song.mp4")
    write_audio_only(src)
    with pytest.raises(VideoError, match="song.mp4: expected a video stream, found none"):
        probe_video(src)
    r = run(src, "-o", tmp_path / "out.mp4")
    assert r.exit_code == 1 and isinstance(r.exception, SystemExit), r.output  # no traceback
    assert "expected a video stream, found none" in r.output
    assert os.listdir(tmp_path) == ["song.mp4"]


@pytest.mark.parametrize("w,h", [(1, 17), (16, 1)])
def test_a_one_pixel_wide_or_tall_video_is_encoded(tmp_path, w, h):
    # A 1-pixel dimension has chroma as wide as the frame in every format: 4:2:x looked unsubsampled there
    # and libx264 refused yuv422p / yuv420p ('Generic error in an external library').
    assert choose_pix_fmt("libx264", "rgb24", 1, 17) == "yuv444p"
    assert choose_pix_fmt("libx264", "yuv420p", 16, 1) != "yuv420p"
    assert choose_pix_fmt("libx264", "yuv420p", 64, 48) == "yuv420p"
    src = str(tmp_path / "thin.nut")
    make_demo.write_clip(src, frames=3, w=w, h=h, codec="rawvideo", pix_fmt="rgb24", audio=False)
    out = tmp_path / "thin.mp4"
    r = run(src, "-o", out, "-q")
    assert r.exit_code == 0, r.output
    info = probe_video(str(out))
    assert (info.width, info.height) == (w, h) and info.frames == 3


def write_anamorphic(path: str, sar: Fraction, frames: int = 3) -> None:
    """64x48 stored, shown 4:3 wider (DV, DVD and HDV store 720 or 1440 columns for a wider picture)."""
    with av.open(path, "w") as out:
        s = out.add_stream("libx264", rate=24)
        s.width, s.height, s.pix_fmt = 64, 48, "yuv420p"
        s.codec_context.sample_aspect_ratio = sar
        for i in range(frames):
            f = av.VideoFrame.from_ndarray(np.full((48, 64, 3), 40 * i, np.uint8), format="rgb24")
            f.pts = i
            for p in s.encode(f):
                out.mux(p)
        for p in s.encode():
            out.mux(p)


@pytest.mark.parametrize("ext,codec", [("mp4", None), ("mkv", None), ("mov", "prores_ks")])
def test_an_anamorphic_video_keeps_its_pixel_aspect_ratio(tmp_path, ext, codec):
    src = str(tmp_path / "dv.mp4")
    write_anamorphic(src, Fraction(4, 3))
    assert probe_video(src).sar == Fraction(4, 3)
    out = tmp_path / f"out.{ext}"
    r = run(src, "-o", out, *(("--codec", codec) if codec else ()))
    assert r.exit_code == 0, r.output
    assert probe_video(str(out)).sar == Fraction(4, 3)  # was square: the picture shown 3/4 as wide


def test_a_pixel_aspect_ratio_matroska_cannot_take_is_named(tmp_path):
    src = str(tmp_path / "dv.mp4")
    write_anamorphic(src, Fraction(4, 3))
    r = run(src, "-o", tmp_path / "out.mkv", "--codec", "ffv1")
    assert r.exit_code == 0, r.output
    assert "pixel aspect ratio 4/3 of" in r.output and "not kept" in r.output


def write_y4m(path, header_tags: str = "", frames: int = 3, size: tuple[int, int] = (64, 48)) -> int:
    """A y4m written by hand (as vspipe writes one): 4:2:0, 8-bit, a diagonal edge; `header_tags` added to the
    stream header ("A16:11", "It"). Returns the bytes of one frame's picture (FRAME line excluded)."""
    w, h = size
    cw, ch = (w + 1) // 2, (h + 1) // 2
    y, x = np.mgrid[0:h, 0:w]
    with open(path, "wb") as f:
        f.write(f"YUV4MPEG2 W{w} H{h} F25:1 C420jpeg {header_tags}".rstrip().encode() + b"\n")
        for i in range(frames):
            f.write(b"FRAME\n" + np.where(y * 2 + i > x, 50, 200).astype(np.uint8).tobytes()
                    + np.full(2 * cw * ch, 128, np.uint8).tobytes())
    return w * h + 2 * cw * ch


@pytest.mark.parametrize("ext,codec", [("y4m", None), ("nut", "ffv1"), ("avi", "ffv1")])
def test_a_pixel_aspect_ratio_other_containers_cannot_take_is_named(tmp_path, ext, codec):
    """y4m's A tag (an anamorphic vspipe output), written back as y4m (the pipe's usual format) or in NUT / AVI
    with an encoder that does not store it in its bitstream: lost (A0:0), so said, as for Matroska."""
    src = tmp_path / "dv.y4m"
    write_y4m(src, "A16:11")
    assert probe_video(str(src)).sar == Fraction(16, 11)
    r = run(src, "-o", tmp_path / f"out.{ext}", *(("--codec", codec) if codec else ()))
    assert r.exit_code == 0, r.output
    assert "pixel aspect ratio 16/11 of" in r.output and "not kept" in r.output
    r = run(src, "-o", tmp_path / "kept.mkv", "--codec", "mpeg4")  # MPEG-4 Part 2 stores it itself: no warning
    assert r.exit_code == 0 and "not kept" not in r.output, r.output
    assert probe_video(str(tmp_path / "kept.mkv")).sar == Fraction(16, 11)


def write_damaged_timestamps(path: str, tmp, shift: int) -> list[int]:
    """An FFV1 MKV (intra only: no reordering) whose 6th frame's timestamp is damaged by `shift` ticks
    (dts kept, as a corrupt block leaves them); returns the decoded timestamps."""
    clean = os.path.join(tmp, "clean.mkv")
    make_demo.write_clip(clean, frames=12, codec="ffv1", pix_fmt="yuv444p", audio=False)
    with av.open(clean) as src, av.open(path, "w") as out:
        s = out.add_stream_from_template(src.streams.video[0])
        for i, pkt in enumerate(p for p in src.demux(src.streams.video[0]) if p.dts is not None):
            if i == 5:
                pkt.pts += shift
            pkt.stream = s
            out.mux(pkt)
    with av.open(path) as c:
        return [f.pts for f in c.decode(video=0)]


@pytest.mark.parametrize("ext", ["mkv", "mp4"])
def test_a_damaged_timestamp_keeps_every_frame(tmp_path, ext):
    pts = write_damaged_timestamps(str(tmp_path / "glitch.mkv"), str(tmp_path), shift=60)
    assert pts[6] < pts[5]  # the 7th frame goes back: the muxer refused it (EINVAL), the output was lost
    out = tmp_path / f"out.{ext}"
    r = run(tmp_path / "glitch.mkv", "-o", out)
    assert r.exit_code == 0, r.output
    assert "frame 6 (and any later like it): timestamp not after the previous frame's" in r.output
    with av.open(str(out)) as c:
        times = [f.time for f in c.decode(video=0)]
    assert len(times) == 12 and all(b > a for a, b in zip(times, times[1:]))


def test_a_damaged_timestamp_ahead_keeps_the_frames_decoded(tmp_path):
    pts = write_damaged_timestamps(str(tmp_path / "glitch.mkv"), str(tmp_path), shift=2000)
    assert pts[5] > pts[6]
    out = tmp_path / "out.mp4"
    r = run(tmp_path / "glitch.mkv", "-o", out)
    assert r.exit_code == 1 and "kept as a valid shorter video" in r.output, r.output  # ends before its duration
    with av.open(str(out)) as c:
        assert sum(1 for _ in c.decode(video=0)) == 12


def test_an_output_that_cannot_be_finished_is_named_not_a_traceback(tmp_path, monkeypatch):
    src = str(tmp_path / "in.mkv")
    make_demo.write_clip(src, frames=3, audio=False)
    info = probe_video(src)
    w = VideoWriter(str(tmp_path / "out.mkv"), info)
    w.write(np.zeros((48, 64, 3), np.uint8))

    def refuse(packet):
        raise av.error.ArgumentError(22, "Invalid argument")

    monkeypatch.setattr(w, "_out", type("Out", (), {"mux": staticmethod(refuse), "close": lambda self: None})())
    with pytest.raises(VideoError, match=r"out\.mkv: cannot finish writing \(.*Invalid argument.*\); not written"):
        w.commit()
    assert sorted(os.listdir(tmp_path)) == ["in.mkv"]


def test_a_second_video_stream_left_out_is_named(tmp_path):
    src = str(tmp_path / "two.mkv")
    with av.open(src, "w") as out:
        streams = [out.add_stream("libx264", rate=24) for _ in range(2)]
        for s, (w, h) in zip(streams, ((64, 48), (32, 24))):
            s.width, s.height, s.pix_fmt = w, h, "yuv420p"
        for i in range(3):
            for s in streams:
                f = av.VideoFrame.from_ndarray(np.full((s.height, s.width, 3), 50 * i, np.uint8), format="rgb24")
                f.pts = i
                for p in s.encode(f):
                    out.mux(p)
        for s in streams:
            for p in s.encode():
                out.mux(p)
    assert probe_video(src).other_streams == ("video stream 1",)
    r = run(src, "-o", tmp_path / "out.mkv")
    assert r.exit_code == 0, r.output
    assert "video stream 1 of" in r.output and "not kept" in r.output  # was dropped without a word


def test_an_rgb_source_through_a_yuv_codec_keeps_its_colours(tmp_path):
    # The source's matrix tag "RGB" (0) went onto the YUV output: decoders showed Y, U, V as G, B, R.
    src = str(tmp_path / "rgb.mkv")
    make_demo.write_clip(src, frames=2, codec="libx264rgb", pix_fmt="rgb24", audio=False, options={"crf": "0"})
    assert probe_video(src).colour["colorspace"] == 0
    out = tmp_path / "out.mkv"
    r = run(src, "-o", out, "--codec", "libx264", "--crf", "0")
    assert r.exit_code == 0, r.output
    with av.open(src) as a, av.open(str(out)) as b:
        x = next(a.decode(video=0)).to_ndarray(format="rgb24").astype(int)
        y = next(b.decode(video=0)).to_ndarray(format="rgb24").astype(int)
    assert np.abs(x - y).mean() < 8  # the filter's changes at edges; was ~50 levels everywhere


def test_a_container_that_cannot_hold_the_sources_codec_takes_its_own(tmp_path):
    src = str(tmp_path / "in.mp4")
    make_demo.write_clip(src, frames=3, audio=False)
    out = tmp_path / "out.webm"
    r = run(src, "-o", out)  # H.264 source: libx264 by default, which WebM cannot hold
    assert r.exit_code == 0, r.output
    assert "webm cannot hold libx264; encoded with libvpx-vp9" in r.output
    assert probe_video(str(out)).codec == "vp9"
    r = run(src, "-o", tmp_path / "asked.webm", "--codec", "libx264")  # asked for: refused, not replaced
    assert r.exit_code == 1 and "'webm' format does not support 'libx264'" in r.output


@pytest.mark.parametrize("tag,field", [("It", "top field first"), ("Ib", "bottom field first"), ("Ip", None)])
def test_an_interlaced_input_is_deinterlaced_or_named(tmp_path, tag, field):
    """A y4m tagged interlaced (It / Ib; a broadcast capture) is deinterlaced before the filter by default, said once;
    with --deinterlace off it is filtered as progressive frames, the combing of its moving edges taken for jaggies,
    and the warning says so; a progressive one says nothing."""
    src = tmp_path / f"in_{tag}.y4m"
    frame = np.random.default_rng(1).integers(0, 256, 32 * 16 * 3 // 2, dtype=np.uint8).tobytes()
    src.write_bytes(f"YUV4MPEG2 W32 H16 F25:1 {tag} A1:1 C420jpeg\n".encode() + (b"FRAME\n" + frame) * 3)
    for mode in ("auto", "off"):
        out = tmp_path / f"out_{tag}_{mode}.mkv"
        res = run(src, "-o", out, "--deinterlace", mode)
        assert res.exit_code == 0, res.output
        assert probe_video(str(out)).frames == 3
        deinterlaced = f"interlaced ({field}): deinterlaced with bwdif; --deinterlace off to keep the fields"
        assert (deinterlaced in res.output) == bool(field and mode == "auto"), res.output
        assert (f"is interlaced ({field}): with --deinterlace off" in res.output) == bool(field and mode == "off")


def write_y4m_planes(path, colourspace: str, w: int = 63, h: int = 47, frames: int = 4) -> None:
    """A y4m file of `frames` frames written by hand, seeded noise: C420jpeg (8-bit 4:2:0), C420p10 (10-bit, 16-bit
    little-endian samples), C444p16 or Cmono."""
    rng = np.random.default_rng(7)
    sub, bits = {"420jpeg": (2, 8), "420p10": (2, 10), "444p16": (1, 16), "mono": (0, 8)}[colourspace]
    planes = [(h, w)] + ([(-(-h // sub), -(-w // sub))] * 2 if sub else [])
    dtype = np.uint8 if bits == 8 else np.dtype("<u2")
    with open(path, "wb") as f:
        f.write(f"YUV4MPEG2 W{w} H{h} F25:1 Ip A1:1 C{colourspace}\n".encode())
        for _ in range(frames):
            samples = [rng.integers(16 << (bits - 8), 235 << (bits - 8), shape).astype(dtype) for shape in planes]
            f.write(b"FRAME\n" + b"".join(p.tobytes() for p in samples))


@pytest.mark.parametrize("colourspace", ["420jpeg", "420p10", "444p16", "mono"])
def test_a_y4m_file_cut_mid_frame_is_named_truncated(tmp_path, colourspace):
    """FFmpeg's y4m reader ends at the last whole frame of a file cut short, without an error: the bytes of a frame
    after it are counted, and the run says so (exit 1, the frames before it kept), as for other truncated inputs;
    the whole file runs clean."""
    src, cut = tmp_path / "whole.y4m", tmp_path / "cut.y4m"
    write_y4m_planes(src, colourspace)
    cut.write_bytes(src.read_bytes()[:-100])
    res = run(src, "-o", tmp_path / "whole.mkv")
    assert res.exit_code == 0 and "truncated" not in res.output, res.output
    res = run(cut, "-o", tmp_path / "cut.mkv")
    assert res.exit_code == 1 and "ended at frame 3" in res.output and "bytes of a frame after it" in res.output
    assert probe_video(str(tmp_path / "cut.mkv")).frames == 3


HDR10 = ("master-display=G(13250,34500)B(7500,3000)R(34000,16000)WP(15635,16450)L(10000000,1)", "max-cll=1000,400")


@pytest.mark.skipif("libx265" not in av.codecs_available, reason="this FFmpeg has no libx265 to write an HDR10 source")
def test_hdr10_static_metadata_is_kept_or_named(tmp_path):
    """An HDR10 master (HEVC 10-bit, BT.2020 / PQ, with a mastering display and content light levels): the colour tags
    were kept but the static metadata was lost (frames are rebuilt from arrays); now it goes to libx265 exactly, and
    an encoder that cannot write it (ffv1) is named."""
    src = tmp_path / "hdr.mkv"
    rng = np.random.default_rng(3)
    with av.open(str(src), "w") as out:
        s = out.add_stream("libx265", rate=25, options={"x265-params": "log-level=error:" + ":".join(HDR10)})
        s.width, s.height, s.pix_fmt = 64, 48, "yuv420p10le"
        s.codec_context.color_primaries, s.codec_context.color_trc, s.codec_context.colorspace = 9, 16, 9
        for _ in range(3):
            rgb = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
            for p in s.encode(av.VideoFrame.from_ndarray(rgb, format="rgb24").reformat(format="yuv420p10le")):
                out.mux(p)
        for p in s.encode():
            out.mux(p)
    assert probe_video(str(src)).hdr10 == HDR10
    res = run(src, "-o", tmp_path / "out.mkv")
    assert res.exit_code == 0, res.output
    kept = probe_video(str(tmp_path / "out.mkv"))
    assert kept.hdr10 == HDR10 and kept.bits == 10 and kept.colour["color_trc"] == 16
    res = run(src, "-o", tmp_path / "lossless.mkv", "--codec", "ffv1")
    assert res.exit_code == 0 and "HDR10 mastering display / light level metadata" in res.output


@pytest.mark.skipif("qtrle" not in av.codecs_available, reason="this FFmpeg has no QuickTime Animation encoder")
def test_a_quicktime_animation_source_keeps_its_codec_and_alpha(tmp_path):
    """A QuickTime Animation (qtrle) clip with alpha, as motion graphics are handed over: it stays qtrle (lossless)
    and keeps its alpha exactly (it was re-encoded to H.264, alpha dropped with a warning)."""
    src, out = tmp_path / "anim.mov", tmp_path / "out.mov"
    rng = np.random.default_rng(4)
    alphas = []
    with av.open(str(src), "w") as c:
        s = c.add_stream("qtrle", rate=25)
        s.width, s.height, s.pix_fmt = 48, 32, "argb"
        for _ in range(3):
            rgba = rng.integers(0, 256, (32, 48, 4), dtype=np.uint8)
            alphas.append(rgba[..., 3].copy())
            for p in s.encode(av.VideoFrame.from_ndarray(rgba, format="rgba").reformat(format="argb")):
                c.mux(p)
        for p in s.encode():
            c.mux(p)
    res = run(src, "-o", out, "--alpha", "keep")  # noise in alpha is no coverage to antialias: carried as it is
    assert res.exit_code == 0 and "not kept" not in res.output, res.output
    info = probe_video(str(out))
    assert info.codec == "qtrle" and info.has_alpha
    with av.open(str(out)) as c:
        got = [f.to_ndarray(format="rgba")[..., 3] for f in c.decode(video=0)]
    assert len(got) == 3 and all(np.array_equal(a, b) for a, b in zip(got, alphas))


def vp9_alphas(path) -> list[np.ndarray]:
    """The alpha planes of a WebM VP9 file, through libvpx's decoder (FFmpeg's own VP9 decoder does not read them)."""
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        assert s.codec_context.name == "vp9" and str(s.metadata.get("alpha_mode")) == "1", dict(s.metadata)
        dec = av.CodecContext.create("libvpx-vp9", "r")
        frames = [f for p in c.demux(s) if p.size for f in dec.decode(p)]
    return [f.to_ndarray(format="rgba")[..., 3] for f in frames]


@pytest.mark.skipif("libvpx-vp9" not in av.codecs_available or "qtrle" not in av.codecs_available,
                    reason="this FFmpeg has no VP9 encoder (libvpx-vp9) or no qtrle to write the source with alpha")
@pytest.mark.parametrize("source,w,h", [("qtrle", 64, 48), ("png", 63, 47)])
def test_a_source_with_alpha_into_webm_keeps_it_in_vp9(tmp_path, source, w, h):
    """RGBA into WebM: a qtrle source failed to start encoding (libvpx-vp9 was given gbrap, which it lists but does
    not open), and PNG frames with alpha lost it with a warning. Both are written as VP9 with alpha (yuva420p, WebM's
    alpha_mode 1), odd sizes too; the alpha read back through libvpx is the source's within VP9's loss."""
    y, x = np.mgrid[0:h, 0:w]
    alpha = np.where(x > w // 3, 255, 60).astype(np.uint8)
    frames = []
    for i in range(3):
        rgba = np.zeros((h, w, 4), np.uint8)
        rgba[..., :3] = np.where(((y * 2 + i) > x)[..., None], [30, 40, 200], [230, 220, 200])
        rgba[..., 3] = alpha
        frames.append(rgba)
    if source == "qtrle":
        src = tmp_path / "anim.mov"
        with av.open(str(src), "w") as c:
            s = c.add_stream("qtrle", rate=25)
            s.width, s.height, s.pix_fmt = w, h, "argb"
            for rgba in frames:
                for p in s.encode(av.VideoFrame.from_ndarray(rgba, format="rgba").reformat(format="argb")):
                    c.mux(p)
            for p in s.encode():
                c.mux(p)
    else:
        src = tmp_path / "frames"
        src.mkdir()
        for i, rgba in enumerate(frames):
            make_demo.write_oiio(str(src / f"f{i:04d}.png"), rgba, "uint8")
    res = run(src, "-o", tmp_path / "out.webm")
    assert res.exit_code == 0 and "alpha is not kept" not in res.output and "alpha dropped" not in res.output, \
        res.output
    got = vp9_alphas(tmp_path / "out.webm")
    assert len(got) == 3
    for a in got:
        assert a.shape == (h, w) and np.abs(a.astype(int) - alpha).mean() < 2, np.abs(a.astype(int) - alpha).mean()


@pytest.mark.skipif("libvpx-vp9" not in av.codecs_available, reason="this FFmpeg has no VP9 encoder")
def test_a_webm_whose_vp9_alpha_is_not_read_is_named(tmp_path):
    """WebM VP9 keeps alpha in a side stream (alpha_mode 1) that FFmpeg's own VP9 decoder does not read: the output
    has no alpha, and the run says so (it was silent)."""
    src = tmp_path / "alpha.webm"
    with av.open(str(src), "w") as c:
        s = c.add_stream("libvpx-vp9", rate=25)
        s.width, s.height, s.pix_fmt = 32, 32, "yuv420p"
        s.metadata["alpha_mode"] = "1"
        for _ in range(2):
            grey = np.full((32, 32, 3), 90, np.uint8)
            for p in s.encode(av.VideoFrame.from_ndarray(grey, format="rgb24").reformat(format="yuv420p")):
                c.mux(p)
        for p in s.encode():
            c.mux(p)
    assert probe_video(str(src)).alpha_unread
    res = run(src, "-o", tmp_path / "out.webm")
    assert res.exit_code == 0 and "alpha (WebM VP9 alpha_mode) is not read" in res.output, res.output
    clip = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")
    assert not probe_video(clip).alpha_unread


def test_a_video_without_a_known_extension_leaves_no_image_library_error(tmp_path):
    """A video named without a video extension (no extension, .vob, .dv) is probed as an image first: the failed
    probe's error was left pending, and OpenImageIO printed 'exited with a pending error message ... could not find
    a format reader' at exit -- on standard output, after the y4m stream of `-o -`, corrupting it."""
    import shutil
    import subprocess
    import sys

    src = tmp_path / "capture"
    shutil.copy(os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4"), src)
    r = subprocess.run([sys.executable, "-c", "from mlaa_stream.cli.main import main; main()", str(src), "-o", "-",
                        "-f", "y4m"], capture_output=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert b"OpenImageIO" not in r.stdout + r.stderr
    frame = 64 * 48 * 3 // 2   # the demo clip: 10 frames of 64x48 4:2:0
    assert r.stdout.startswith(b"YUV4MPEG2 ")
    assert len(r.stdout) == r.stdout.index(b"\n") + 1 + 10 * (len(b"FRAME\n") + frame)


@pytest.mark.parametrize("slash", ["", "/"])
def test_a_video_into_a_folder_takes_its_name(tmp_path, slash):
    """`mlaa-stream in.mp4 -o clean/` (a folder there): the output is clean/in.mp4, as for images; the writer was
    handed the folder itself ('cannot create the output: Could not determine output format')."""
    folder = tmp_path / "clean"
    folder.mkdir()
    src = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")
    r = run(src, "-o", f"{folder}{slash}")
    assert r.exit_code == 0, r.output
    assert os.listdir(folder) == ["clip.mp4"]
    with av.open(str(folder / "clip.mp4")) as c:
        assert sum(1 for _ in c.decode(video=0)) == 10


def test_an_av1_source_stays_av1(tmp_path):
    """No --codec: the source's family where FFmpeg has an encoder for it. An AV1 source decodes with libdav1d, whose
    name no family had, and its family named only libaom-av1 (PyAV's wheels have SVT-AV1): it became H.264, in WebM
    VP9 with a warning that WebM 'cannot hold libx264'."""
    if "libsvtav1" not in av.codecs_available and "libaom-av1" not in av.codecs_available:
        pytest.skip("this FFmpeg has no AV1 encoder")
    encoder = "libsvtav1" if "libsvtav1" in av.codecs_available else "libaom-av1"
    src = tmp_path / "in.webm"
    with av.open(str(src), "w") as out:
        s = out.add_stream(encoder, rate=25)
        s.width, s.height, s.pix_fmt = 96, 64, "yuv420p"
        mux_moving_edge(out, s, 4, 30, 220)
    r = run(src, "-o", tmp_path / "out.webm")
    assert r.exit_code == 0, r.output
    assert "cannot hold" not in r.output
    with av.open(str(tmp_path / "out.webm")) as c:
        assert c.streams.video[0].codec_context.codec.canonical_name == "av1"
        assert sum(1 for _ in c.decode(video=0)) == 4


def test_a_dnxhr_source_and_codec_dnxhd_are_written(tmp_path):
    """FFmpeg's dnxhd encoder opens only with a profile (or a DNxHD bit rate): a DNxHR source (its family kept) and
    --codec dnxhd both failed with 'cannot start encoding with dnxhd (yuv422p): Invalid argument'."""
    if "dnxhd" not in av.codecs_available:
        pytest.skip("this FFmpeg has no dnxhd encoder")
    src = tmp_path / "in.mov"
    with av.open(str(src), "w") as out:
        s = out.add_stream("dnxhd", rate=25, options={"profile": "dnxhr_sq"})
        s.width, s.height, s.pix_fmt = 256, 144, "yuv422p"
        mux_moving_edge(out, s, 3, 100, 220)
    r = run(src, "-o", tmp_path / "out.mov")
    assert r.exit_code == 0, r.output
    with av.open(str(tmp_path / "out.mov")) as c:
        assert c.streams.video[0].codec_context.profile == "DNXHR SQ"   # the source's profile
        assert sum(1 for _ in c.decode(video=0)) == 3
    r = run(src, "-o", tmp_path / "hqx.mov", "--codec", "dnxhd", "--pix-fmt", "yuv422p10le")
    assert r.exit_code == 0, r.output
    with av.open(str(tmp_path / "hqx.mov")) as c:
        assert c.streams.video[0].codec_context.profile == "DNXHR HQX"   # 10-bit: the profile that holds it


@pytest.mark.parametrize("codec", ["apng", "png"])
def test_a_colour_source_into_png_frames_keeps_its_colour(codec):
    """APNG's and PNG's formats list a palette and grey before nothing YUV-like: the pick closest to a YUV source was
    pal8 (every frame failed: 'write failed at frame 0: Operation not supported'), then grey (the colour dropped)."""
    assert choose_pix_fmt(codec, "yuv420p", 64, 48) == "rgb24"
    assert choose_pix_fmt(codec, "yuv420p10le", 64, 48) == "rgb48be"
    assert choose_pix_fmt(codec, "yuva420p", 64, 48) == "rgba"   # not ya8: grey with alpha
    assert choose_pix_fmt(codec, "pal8", 64, 48) == "rgb24"   # a palette's colours


def test_a_gif_is_never_given_a_palette_nor_grey():
    """GIF's encoder lists 3-3-2 RGB, grey and pal8: pal8, which swscale cannot write, or grey (the colour dropped)
    were picked; its 3-3-2 RGB keeps colour (the writer names the 3 bits)."""
    assert choose_pix_fmt("gif", "yuv420p", 64, 48) == "rgb8"
    assert choose_pix_fmt("gif", "pal8", 64, 48) == "rgb8"


def test_a_video_into_an_animated_png_is_written_in_colour(tmp_path):
    src = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")
    r = run(src, "-o", tmp_path / "out.apng", "--audio", "none")
    assert r.exit_code == 0, r.output
    with av.open(str(tmp_path / "out.apng")) as c:
        decoded = list(c.decode(video=0))
    frames = [f.to_ndarray(format="rgb24") for f in decoded]
    assert len(frames) == 10 and decoded[0].format.name == "rgb24"
    assert np.abs(frames[0][..., 0].astype(int) - frames[0][..., 2]).max() > 50   # colour, not grey


@pytest.mark.parametrize("name,audio", [("out.webm", "copy"), ("out.gif", "aac")])
def test_audio_not_kept_suggests_re_encoding_only_where_it_helps(tmp_path, name, audio):
    """The warning for audio a container cannot hold said '(--audio aac re-encodes the audio)' where AAC cannot go
    either (WebM, GIF) and to a user who had asked for --audio aac."""
    src = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")
    r = run(src, "-o", tmp_path / name, "--audio", audio)
    assert r.exit_code == 0, r.output
    assert "audio streams not kept" in r.output and "--audio aac" not in r.output


def test_crf_and_encoder_preset_an_encoder_ignores_are_named(tmp_path):
    """--crf and --encoder-preset set x264 / x265 (--crf VP9 / AV1 too): given with ProRes they were dropped without
    a word, as the options that do nothing for images are not."""
    if "prores_ks" not in av.codecs_available:
        pytest.skip("this FFmpeg has no prores_ks encoder")
    src = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")
    r = run(src, "-o", tmp_path / "out.mov", "--codec", "prores_ks", "--crf", "10", "--encoder-preset", "slow")
    assert r.exit_code == 0, r.output
    assert "--crf, --encoder-preset have no effect with prores_ks" in r.output
    r = run(src, "-o", tmp_path / "out.mp4", "--crf", "10", "--encoder-preset", "slow")
    assert r.exit_code == 0 and "no effect" not in r.output, r.output


def test_a_variable_frame_rate_into_a_container_of_one_rate_is_not_called_damaged(tmp_path):
    """AVI and y4m hold one frame per tick of 1/rate: a variable-rate source's frames closer than that share a tick,
    and the warning blamed the input ('timestamp not after the previous frame's (damaged input?)')."""
    src = tmp_path / "vfr.mkv"
    tb = Fraction(1, 1000)
    with av.open(str(src), "w") as out:
        s = out.add_stream("libx264", rate=25)
        s.width, s.height, s.pix_fmt = 64, 48, "yuv420p"
        s.time_base = s.codec_context.time_base = tb
        t = 0
        for i in range(12):
            img = np.zeros((48, 64, 3), np.uint8)
            img[:, 20 + i:] = 200
            f = av.VideoFrame.from_ndarray(img, format="rgb24")
            f.pts, f.time_base = t, tb
            for p in s.encode(f):
                out.mux(p)
            t += 40 if i % 3 else 100   # 25 fps on average, in steps of 40 and 100 ms
        for p in s.encode():
            out.mux(p)
    r = run(src, "-o", tmp_path / "out.avi")
    assert r.exit_code == 0, r.output
    assert "a variable frame rate" in r.output and "damaged" not in r.output


def test_a_crf_over_x265s_range_is_named_and_encoded_at_its_most(tmp_path):
    """--crf takes up to 63 (VP9, AV1): libx265 refused more than 51 ('cannot start encoding ... Invalid data found
    when processing input'), and libx264 took it as 51 without a word."""
    src = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")
    for codec in ("libx265", "libx264"):
        if codec not in av.codecs_available:
            continue
        out = tmp_path / f"{codec}.mkv"
        r = run(src, "-o", out, "--codec", codec, "--crf", "60")
        assert r.exit_code == 0, r.output
        assert f"--crf 60: {codec} takes 0 to 51" in r.output
        with av.open(str(out)) as c:
            assert sum(1 for _ in c.decode(video=0)) == 10


def test_a_subsampled_pix_fmt_at_an_odd_size_names_the_cause(tmp_path):
    """--pix-fmt yuv420p for a 161x91 source: x264 failed with 'Generic error in an external library', naming no
    cause; the error now says the format halves the chroma, which an odd size cannot."""
    src = tmp_path / "odd.mkv"
    with av.open(str(src), "w") as out:
        s = out.add_stream("libx264", rate=25)
        s.width, s.height, s.pix_fmt = 65, 47, "yuv444p"
        mux_moving_edge(out, s, 3, 20, 200)
    r = run(src, "-o", tmp_path / "out.mkv", "--pix-fmt", "yuv420p")
    assert r.exit_code == 1 and "yuv420p halves the chroma, which 65x47 cannot" in r.output, r.output
    r = run(src, "-o", tmp_path / "out.mkv", "--pix-fmt", "nosuchformat")
    assert r.exit_code == 1 and "not a pixel format" in r.output and "halves" not in r.output, r.output
    assert os.listdir(tmp_path) == ["odd.mkv"]
