"""A trim that holds no frame (--start at or past the end, --end 0) is an error and writes nothing, instead of
an empty, unplayable video with exit code 0; --start/--end refuse NaN, infinity and negative frame numbers
(NaN used to end in a traceback)."""
from __future__ import annotations

import os

import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.video import parse_time

CLIP = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")  # 10 frames at 24 fps


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def stderr(r) -> str:
    return r.stderr if hasattr(r, "stderr") else r.output


@pytest.mark.parametrize("trim", [("--start", "10"), ("--start", "10f"), ("--end", "0")])
def test_a_trim_without_frames_fails_and_writes_nothing(tmp_path, trim):
    out = tmp_path / "t.mp4"
    r = run(CLIP, "-o", out, *trim)
    assert r.exit_code == 1, stderr(r)
    assert "no frame between" in stderr(r) and "not written" in stderr(r)
    assert os.listdir(tmp_path) == []


def test_a_trim_without_frames_keeps_the_output_it_would_overwrite(tmp_path):
    out = tmp_path / "t.mp4"
    out.write_bytes(b"earlier output")
    r = run(CLIP, "-o", out, "-y", "--start", "9:00")
    assert r.exit_code == 1 and out.read_bytes() == b"earlier output"


@pytest.mark.parametrize("bad", ["nan", "infinity", "1e400", "-5f", "1:nan"])
def test_parse_time_refuses_non_finite_times_and_negative_frames(bad):
    with pytest.raises(ValueError, match="expected a time"):
        parse_time(bad, None)


def test_a_nan_start_is_a_usage_error(tmp_path):
    r = run(CLIP, "-o", tmp_path / "t.mp4", "--start", "nan")
    assert r.exit_code == 2 and "expected a time" in stderr(r)


def _clip_from(path, first_ms: int, n: int = 25) -> None:
    """An H.264 MKV of `n` frames at 25 fps whose timestamps start at `first_ms` (an MPEG-TS capture's, a cut
    segment's), a moving edge on each frame."""
    import av
    import numpy as np
    from fractions import Fraction

    tb = Fraction(1, 1000)
    with av.open(str(path), "w") as out:
        s = out.add_stream("libx264", rate=25)
        s.width, s.height, s.pix_fmt = 96, 64, "yuv420p"
        s.time_base = s.codec_context.time_base = tb
        for i in range(n):
            img = np.zeros((64, 96, 3), np.uint8)
            img[:, 20 + i:] = 200
            f = av.VideoFrame.from_ndarray(img, format="rgb24")
            f.pts, f.time_base = first_ms + 40 * i, tb
            for p in s.encode(f):
                out.mux(p)
        for p in s.encode():
            out.mux(p)


def test_start_and_end_count_from_the_first_timestamp(tmp_path):
    """--start/--end count from the video's first timestamp, as FFmpeg's -ss does: on a video whose timestamps start
    at 10 s, --start 0.2 --end 0.4 was 'no frame between 0.2 s and 0.4 s', and --start 0.2 alone kept every frame."""
    import av

    src, out = tmp_path / "late.mkv", tmp_path / "t.mkv"
    _clip_from(src, 10_000)
    r = run(src, "-o", out, "--start", "0.2", "--end", "0.4")
    assert r.exit_code == 0, stderr(r)
    with av.open(str(out)) as c:
        pts = [f.pts for f in c.decode(video=0)]
    assert pts == [0, 40, 80, 120, 160]   # frames 5..9 of the source, the output from 0 as --help says
    r = run(src, "-o", out, "-y", "--start", "0.8")
    assert r.exit_code == 0, stderr(r)
    with av.open(str(out)) as c:
        assert len(list(c.decode(video=0))) == 5   # frames 20..24, not all 25 shifted by -0.8 s
    r = run(src, "-o", out, "-y", "--start", "2")
    assert r.exit_code == 1 and "no frame between 2 s and the end" in stderr(r)


def test_a_start_between_two_frames_writes_every_frame_it_counts(tmp_path):
    """--start half way between two frames keeps the frame nearest to it, up to half a frame before; that frame got a
    negative time, and MP4's edit list hid it: '5 frames' written, 4 played. The output now starts at it."""
    import av

    out = tmp_path / "t.mp4"
    r = run(CLIP, "-o", out, "--start", "0.1", "--end", "0.3")   # frames at 24 fps: 0.083 is nearest to 0.1
    assert r.exit_code == 0, stderr(r)
    with av.open(str(out)) as c:
        s = c.streams.video[0]
        assert s.frames == 5
        pts = [f.pts for f in c.decode(video=0)]
    assert len(pts) == 5 and pts[0] == 0 and s.average_rate == 24


def _gop_clip(path, fmt: str | None = None, n: int = 50, gop: int = 10) -> None:
    """H.264 at 25 fps, a keyframe every `gop` frames, frame i's bright band at x = 10 + i (which frame it is)."""
    import av
    import numpy as np

    with av.open(str(path), "w", format=fmt) as out:
        s = out.add_stream("libx264", rate=25, options={"g": str(gop), "keyint_min": str(gop), "sc_threshold": "0"})
        s.width, s.height, s.pix_fmt = 96, 64, "yuv420p"
        for i in range(n):
            img = np.full((64, 96, 3), 30, np.uint8)
            img[:, i + 10:i + 14] = 230
            for p in s.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                out.mux(p)
        for p in s.encode():
            out.mux(p)


def _columns(path) -> list[int]:
    """Where each frame of `path` has its bright band (which source frame it is): the centre of its light."""
    import av
    import numpy as np

    out = []
    with av.open(str(path)) as c:
        for f in c.decode(video=0):
            light = np.clip(f.to_ndarray(format="gray")[32].astype(float) - 100, 0, None)
            out.append(int(round((light * np.arange(light.size)).sum() / light.sum() - 11.5)))
    return out


def test_a_trim_of_an_mpeg_ts_keeps_the_frames_before_the_next_keyframe(tmp_path):
    """MPEG-TS seeks land on the packet at the time asked, keyframe or not, and nothing decodes until the next one:
    --start 0.5 --end 1.0 kept only the frames from the keyframe after 0.5 s on (or none at all)."""
    src = tmp_path / "in.ts"
    _gop_clip(src, "mpegts")
    r = run(src, "-o", tmp_path / "t.mkv", "--start", "0.5", "--end", "1.0")
    assert r.exit_code == 0, stderr(r)
    got = _columns(tmp_path / "t.mkv")
    assert len(got) >= 12 and got == list(range(got[0], got[0] + len(got))) and 12 <= got[0] <= 13


def test_a_trim_of_standard_input_reads_on_to_the_start(tmp_path):
    """Standard input cannot seek: the trim seeked it anyway ('read failed at frame 0: Operation not permitted' for
    MPEG-TS, 'no frame between 1 s and 1.4 s' for an MKV with audio and one keyframe); its frames before --start are
    read and dropped."""
    import subprocess
    import sys

    src, out = tmp_path / "in.ts", tmp_path / "t.mkv"
    _gop_clip(src, "mpegts")
    with open(src, "rb") as stdin:
        r = subprocess.run([sys.executable, "-c", "from mlaa_stream.cli.main import main; main()", "-", "-o", str(out),
                            "--start", "1", "--end", "1.4"], stdin=stdin, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert _columns(out) == list(range(25, 35))


def test_a_trim_of_a_raw_h264_stream_counts_its_frames(tmp_path):
    """A raw H.264 stream (a Raspberry Pi camera's .h264) has no timestamps: FFmpeg cannot seek it ('decoding stopped
    at frame 0: Operation not permitted'), and a trim could not place its frames; they are placed at the nominal
    rate, as the writer times them, and read from the beginning."""
    src = tmp_path / "cam.h264"
    _gop_clip(src, "h264")
    r = run(src, "-o", tmp_path / "t.mkv", "--start", "0.5", "--end", "1.0")
    assert r.exit_code == 0, stderr(r)
    assert _columns(tmp_path / "t.mkv") == list(range(12, 25))
    r = run(src, "-o", tmp_path / "e.mkv", "--end", "0.4")
    assert r.exit_code == 0, stderr(r)
    assert _columns(tmp_path / "e.mkv") == list(range(0, 10))


def _late_ts(path, first_s: int = 1000) -> None:
    """An MPEG-TS capture whose clock starts at `first_s` seconds: 25 frames at 25 fps and a second of AAC from the
    same time."""
    import av
    import numpy as np
    from fractions import Fraction

    tb = Fraction(1, 90000)
    with av.open(str(path), "w", format="mpegts") as out:
        v = out.add_stream("libx264", rate=25)
        v.width, v.height, v.pix_fmt = 96, 64, "yuv420p"
        v.time_base = v.codec_context.time_base = tb
        a = out.add_stream("aac", rate=48000)
        for i in range(25):
            img = np.full((64, 96, 3), 30, np.uint8)
            img[:, 10 + i:14 + i] = 230
            f = av.VideoFrame.from_ndarray(img, format="rgb24")
            f.pts, f.time_base = first_s * 90000 + 3600 * i, tb
            for p in v.encode(f):
                out.mux(p)
        for p in v.encode():
            out.mux(p)
        tone = (0.2 * np.sin(np.arange(48000) / 10)).astype(np.float32)[None]
        for k in range(0, 48000, 1024):
            f = av.AudioFrame.from_ndarray(tone[:, k:k + 1024], format="fltp", layout="mono")
            f.sample_rate, f.pts, f.time_base = 48000, first_s * 48000 + k, Fraction(1, 48000)
            for p in a.encode(f):
                out.mux(p)
        for p in a.encode():
            out.mux(p)


def test_a_capture_whose_clock_starts_late_is_written_from_zero(tmp_path):
    """An MPEG-TS capture's timestamps start where the broadcast clock was (here 1000 s): kept as they were, a 1-s MKV
    said it lasted 16:41 and an MP4 opened on an empty edit that long. The output starts at 0, as FFmpeg writes files;
    the streams keep their places against each other and every audio packet is copied."""
    import av

    src = tmp_path / "cap.ts"
    _late_ts(src)
    r = run(src, "-o", tmp_path / "out.mkv")
    assert r.exit_code == 0, stderr(r)
    with av.open(str(src)) as c:
        src_audio = sum(1 for p in c.demux(audio=0) if p.size)
        v0 = float(c.streams.video[0].start_time * c.streams.video[0].time_base)
        a0 = float(c.streams.audio[0].start_time * c.streams.audio[0].time_base)
    with av.open(str(tmp_path / "out.mkv")) as c:
        assert c.duration / 1e6 < 2
        assert sum(1 for p in c.demux(audio=0) if p.size) == src_audio
    with av.open(str(tmp_path / "out.mkv")) as c:
        video = [float(f.pts * f.time_base) for f in c.decode(video=0)]
    with av.open(str(tmp_path / "out.mkv")) as c:
        audio = [float(p.pts * p.time_base) for p in c.demux(audio=0) if p.size]
    assert len(video) == 25 and min(video[0], audio[0]) < 0.01
    assert abs((video[0] - audio[0]) - (v0 - a0)) < 0.002   # in sync as in the source
