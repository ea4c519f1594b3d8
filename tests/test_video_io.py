"""Video through PyAV: frame rate, timestamps, size, bit depth, audio and colour kept; truncated and
non-video inputs reported with the frame where decoding stopped; the OpenCV fallback works."""
from __future__ import annotations

import os
from fractions import Fraction

import av
import numpy as np
import pytest

from mlaa_stream.io.video import (CvVideoWriter, VideoError, VideoReadError, VideoWriter,
                                  choose_pix_fmt, probe_video, probe_video_cv, read_video,
                                  read_video_cv)
from demo_maker import ROOT, make_demo

CLIP = os.path.join(ROOT, "fixtures", "demo", "clip.mp4")


def decoded(path: str, fmt: str = "rgb24") -> tuple[list[np.ndarray], list[float]]:
    with av.open(path) as c:
        frames = list(c.decode(video=0))
        return [f.to_ndarray(format=fmt) for f in frames], [float(f.time) for f in frames]


def transcode(src: str, dst: str, **kw) -> VideoWriter:
    info = probe_video(src)
    w = VideoWriter(dst, info, **kw)
    for item in read_video(info):
        w.write(item.frame, item.meta)
    w.commit()
    return w


def test_probe_describes_the_demo_clip():
    info = probe_video(CLIP)
    assert (info.width, info.height, info.fps, info.frames) == (64, 48, Fraction(24), 10)
    assert info.pix_fmt == "yuv420p" and info.bits == 8 and info.sample_format == "rgb24"
    assert info.audio_streams == 1


def test_frames_decode_in_order_with_their_timestamps():
    info = probe_video(CLIP)
    items = list(read_video(info))
    assert len(items) == 10
    assert all(it.frame.shape == (48, 64, 3) and it.frame.dtype == np.uint8 for it in items)
    times = [float(it.meta.pts * it.meta.time_base) for it in items]
    assert times == pytest.approx([i / 24 for i in range(10)])


def test_transcode_keeps_rate_timestamps_size_and_audio(tmp_path):
    out = str(tmp_path / "out.mp4")
    w = transcode(CLIP, out)
    assert w.pix_fmt == "yuv420p" and w.frames_written == 10
    info = probe_video(out)
    assert (info.width, info.height, info.fps, info.frames, info.audio_streams) == (64, 48, 24, 10, 1)
    src_frames, src_times = decoded(CLIP)
    out_frames, out_times = decoded(out)
    assert out_times == pytest.approx(src_times)
    # crf 18 re-encode of the same pixels: close to the source, and no colour shift (a wrong matrix
    # or range, or the default swscale rounding, moves the mean by a level or more)
    diff = np.stack([b.astype(int) - a.astype(int) for a, b in zip(src_frames, out_frames)])
    assert np.abs(diff).mean() < 3.0
    assert np.all(np.abs(diff.mean(axis=(0, 1, 2))) < 0.5)
    with av.open(CLIP) as a, av.open(out) as b:
        sa, sb = a.streams.audio[0], b.streams.audio[0]
        assert sb.codec_context.name == sa.codec_context.name == "aac"
        assert sb.codec_context.sample_rate == 48000
        pa = [p.size for p in a.demux(sa) if p.size]
        pb = [p.size for p in b.demux(sb) if p.size]
        assert pb == pa  # copied packet for packet, not re-encoded
    assert [n for n in os.listdir(tmp_path)] == ["out.mp4"]


def test_ten_bit_stays_ten_bit(tmp_path):
    src = str(tmp_path / "ten.mkv")
    make_demo.write_clip(src, frames=6, pix_fmt="yuv420p10le", audio=False)
    info = probe_video(src)
    assert info.bits == 10 and info.sample_format == "rgb48le"
    items = list(read_video(info))
    assert items[0].frame.dtype == np.uint16
    out = str(tmp_path / "out.mkv")
    w = transcode(src, out)
    assert w.pix_fmt == "yuv420p10le" and w.warnings == []
    assert probe_video(out).pix_fmt == "yuv420p10le"
    a, _ = decoded(src, "rgb48le")
    b, _ = decoded(out, "rgb48le")
    assert np.mean([np.abs(x.astype(int) - y.astype(int)).mean() for x, y in zip(a, b)]) < 3 * 256


@pytest.mark.parametrize("codec,expected", [("ffv1", "bgr0"), ("libx264rgb", "bgr0")])
def test_lossless_intermediates_round_trip_exactly(tmp_path, codec, expected):
    info = probe_video(CLIP)
    rng = np.random.default_rng(7)
    frames = [rng.integers(0, 255, (48, 64, 3), dtype=np.uint8) for _ in range(4)]
    out = str(tmp_path / "mid.mkv")
    w = VideoWriter(out, info, codec=codec, crf=0, copy_audio=False)
    for f in frames:
        w.write(f)
    w.commit()
    assert w.pix_fmt == expected
    back, times = decoded(out)
    assert len(back) == 4 and times == pytest.approx([0, 1 / 24, 2 / 24, 3 / 24], abs=1e-3)  # mkv: ms
    for a, b in zip(frames, back):
        np.testing.assert_array_equal(a, b)


def test_odd_sizes_get_a_pixel_format_without_chroma_subsampling(tmp_path):
    src = str(tmp_path / "odd.mkv")
    make_demo.write_clip(src, frames=3, w=63, h=47, pix_fmt="yuv444p", audio=False)
    out = str(tmp_path / "odd_out.mp4")
    w = transcode(src, out)
    assert w.pix_fmt == "yuv444p"
    assert (probe_video(out).width, probe_video(out).height) == (63, 47)


def test_choose_pix_fmt():
    assert choose_pix_fmt("libx264", "yuv420p", 64, 48) == "yuv420p"
    assert choose_pix_fmt("libx264", "yuv420p10le", 64, 48) == "yuv420p10le"
    assert choose_pix_fmt("libx264", "yuv420p", 63, 48) == "yuv444p"
    assert choose_pix_fmt("libx265", "gbrp10le", 64, 48) == "gbrp10le"
    assert choose_pix_fmt("ffv1", "yuv420p10le", 64, 48) in ("gbrp10le", "rgb48le", "gbrp16le")
    assert choose_pix_fmt("ffv1", "yuva420p", 64, 48) in ("bgra", "gbrap10le")


def test_an_8_bit_codec_for_a_10_bit_source_is_reported(tmp_path):
    src = str(tmp_path / "ten.mkv")
    make_demo.write_clip(src, frames=2, pix_fmt="yuv420p10le", audio=False)
    w = transcode(src, str(tmp_path / "o.mkv"), codec="libx264rgb")
    assert any("10-bit source written as 8-bit" in m for m in w.warnings)


def test_not_a_video_is_refused_naming_the_file(tmp_path):
    bad = tmp_path / "notes.mp4"
    bad.write_text("this is not a video")
    with pytest.raises(VideoError, match="notes.mp4: expected a video"):
        probe_video(str(bad))
    empty = tmp_path / "empty.mkv"
    empty.write_bytes(b"")
    with pytest.raises(VideoError, match="empty.mkv: expected a video, got an empty file"):
        probe_video(str(empty))


def test_a_truncated_mp4_stops_with_the_frame_number(tmp_path):
    src = str(tmp_path / "long.mp4")
    make_demo.write_clip(src, frames=30, audio=False)
    data = open(src, "rb").read()
    cut = str(tmp_path / "cut.mp4")
    open(cut, "wb").write(data[: len(data) * 2 // 3])
    info = probe_video(cut)
    assert info.frames == 30
    got = []
    with pytest.raises(VideoReadError) as ei:
        for item in read_video(info):
            got.append(item)
    assert 0 < ei.value.frames_read == len(got) < 30
    assert f"cut.mp4: " in str(ei.value) and f"frame {len(got)}" in str(ei.value)


def test_a_truncated_mkv_that_decodes_cleanly_is_caught_by_its_length(tmp_path):
    src = str(tmp_path / "long.mkv")
    make_demo.write_clip(src, frames=30, audio=False)
    data = open(src, "rb").read()
    cut = str(tmp_path / "cut.mkv")
    open(cut, "wb").write(data[: len(data) // 2])
    info = probe_video(cut)
    assert not info.frames_declared  # MKV declares a duration, not a frame count
    with pytest.raises(VideoReadError, match=r"ended at frame \d+ \(0\.\d+ s\), expected 1\.\d+ s"):
        list(read_video(info))


def make_vfr_mkv(path: str) -> list[int]:
    """40 frames in milliseconds: 20 at 30 fps, then 20 at 10 fps; returns their timestamps."""
    out = av.open(path, "w")
    s = out.add_stream("ffv1", rate=30)
    s.width, s.height, s.pix_fmt, s.time_base = 64, 48, "yuv420p", Fraction(1, 1000)
    rng = np.random.default_rng(1)
    pts = [33 * i if i < 20 else 660 + 100 * (i - 20) for i in range(40)]
    for t in pts:
        f = av.VideoFrame.from_ndarray((rng.random((48, 64, 3)) * 255).astype(np.uint8), format="rgb24")
        f.pts, f.time_base = t, Fraction(1, 1000)
        for p in s.encode(f):
            out.mux(p)
    for p in s.encode():
        out.mux(p)
    out.close()
    return pts


def test_a_variable_frame_rate_mkv_is_read_whole_without_a_false_truncation(tmp_path):
    src = str(tmp_path / "vfr.mkv")
    pts = make_vfr_mkv(src)
    info = probe_video(src)
    assert not info.frames_declared and info.frames != 40  # duration x mean rate: only an estimate
    items = list(read_video(info))
    got = [it.meta.pts for it in items]
    assert len(got) == 40 and got == sorted(got)
    assert max(abs(a - b) for a, b in zip(got, pts)) <= 34  # the encoder keeps them to 1/30 s


def test_abort_leaves_nothing(tmp_path):
    info = probe_video(CLIP)
    w = VideoWriter(str(tmp_path / "x.mp4"), info)
    w.write(np.zeros((48, 64, 3), np.uint8))
    w.abort()
    assert os.listdir(tmp_path) == []


def test_an_unknown_codec_is_refused(tmp_path):
    with pytest.raises(VideoError, match="expected an encoder FFmpeg has"):
        VideoWriter(str(tmp_path / "x.mp4"), probe_video(CLIP), codec="nonesuch")
    assert os.listdir(tmp_path) == []


def test_opencv_fallback_reads_and_writes(tmp_path):
    info = probe_video_cv(CLIP)
    assert (info.width, info.height, info.frames) == (64, 48, 10)
    items = list(read_video_cv(info))
    assert len(items) == 10 and items[0].frame.shape == (48, 64, 3)
    ref, _ = decoded(CLIP)
    assert np.abs(items[3].frame.astype(int) - ref[3].astype(int)).mean() < 2  # RGB order, not BGR
    out = str(tmp_path / "cv.mp4")
    w = CvVideoWriter(out, info)
    for it in items:
        w.write(it.frame)
    w.commit()
    assert probe_video(out).frames == 10


def test_opencv_fallback_reads_a_variable_frame_rate_mkv_without_a_false_truncation(tmp_path):
    """OpenCV counts an MKV's frames as its duration x the mean rate: a variable rate has fewer, and the fallback
    called the whole file truncated ('expected about N frames', exit 1); a cut one is still caught."""
    src = str(tmp_path / "vfr.mkv")
    make_vfr_mkv(src)
    info = probe_video_cv(src)
    assert info.frames != 40
    assert len(list(read_video_cv(info))) == 40
    long = str(tmp_path / "long.mkv")
    make_demo.write_clip(long, frames=30, audio=False)
    data = open(long, "rb").read()
    cut = str(tmp_path / "cut.mkv")
    open(cut, "wb").write(data[: len(data) // 2])
    with pytest.raises(VideoReadError, match="truncated"):
        list(read_video_cv(probe_video_cv(cut)))
