"""Every stream and its metadata kept (issue 17): audio tracks and subtitles with their language tags,
the container's title, the display rotation, and the source's codec family when no --codec is given."""
from __future__ import annotations

import os

import av
import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.video import probe_video
from demo_maker import make_demo
from clips import mux_moving_edge



def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def make_rich(path: str, tmp) -> None:
    """An MKV as phones and rippers make them: rotated 90°, titled, two audio tracks (eng, fra) and a
    German subtitle stream (from an SRT through FFmpeg's demuxer)."""
    srt = os.path.join(tmp, "subs.srt")
    with open(srt, "w") as fh:
        fh.write("1\n00:00:00,000 --> 00:00:00,300\nHallo\n\n2\n00:00:00,300 --> 00:00:00,400\nWelt\n")
    sub_in = av.open(srt)
    out = av.open(path, "w")
    out.metadata["title"] = "A phone clip"
    v = out.add_stream("libx264", rate=24)
    v.width, v.height, v.pix_fmt = 64, 48, "yuv420p"
    v.set_display_rotation(90)
    v.metadata["language"] = "eng"
    auds = []
    for lang in ("eng", "fra"):
        a = out.add_stream("aac", rate=48000)
        a.layout = "mono"
        a.metadata["language"] = lang
        auds.append(a)
    s = out.add_stream_from_template(sub_in.streams.subtitles[0])
    s.metadata["language"] = "deu"
    out.start_encoding()
    t = np.arange(48000 // 24 * 10) / 48000
    for k, a in enumerate(auds):
        samples = (0.2 * np.sin(2 * np.pi * (440 + 220 * k) * t)).astype(np.float32)[None, :]
        for i in range(0, samples.shape[1], 1024):
            fr = av.AudioFrame.from_ndarray(np.ascontiguousarray(samples[:, i:i + 1024]), format="fltp",
                                            layout="mono")
            fr.sample_rate, fr.pts = 48000, i
            for p in a.encode(fr):
                out.mux(p)
        for p in a.encode(None):
            out.mux(p)
    for i in range(10):
        f = av.VideoFrame.from_ndarray(np.full((48, 64, 3), i * 20, np.uint8), format="rgb24")
        f.pts = i
        for p in v.encode(f):
            out.mux(p)
    for p in v.encode():
        out.mux(p)
    for pkt in sub_in.demux(sub_in.streams.subtitles[0]):
        if pkt.dts is not None:
            pkt.stream = s
            out.mux(pkt)
    out.close()
    sub_in.close()


def streams(path) -> list[tuple[str, str, str | None]]:
    with av.open(str(path)) as c:
        return [(st.type, st.codec_context.name, st.metadata.get("language")) for st in c.streams]


@pytest.fixture(scope="module")
def rich(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rich")
    path = str(tmp / "rich.mkv")
    make_rich(path, str(tmp))
    return path


def test_streams_tags_and_rotation_are_kept(rich, tmp_path):
    info = probe_video(rich)
    assert info.rotation == 90 and info.audio_streams == 2 and info.subtitle_streams == 1
    r = run(rich, "-o", tmp_path / "out.mkv")
    assert r.exit_code == 0, r.output
    assert streams(tmp_path / "out.mkv") == [("video", "h264", "eng"), ("audio", "aac", "eng"),
                                             ("audio", "aac", "fra"), ("subtitle", "srt", "deu")]
    with av.open(str(tmp_path / "out.mkv")) as c:
        assert c.metadata.get("title") == "A phone clip"
        assert next(c.decode(video=0)).rotation == 90
    with av.open(str(tmp_path / "out.mkv")) as c:
        assert sum(1 for p in c.demux(c.streams.subtitles[0]) if p.size) == 2


def test_audio_none_and_aac(rich, tmp_path):
    assert run(rich, "-o", tmp_path / "none.mkv", "--audio", "none").exit_code == 0
    assert [s[0] for s in streams(tmp_path / "none.mkv")] == ["video"]
    r = run(rich, "-o", tmp_path / "aac.mp4", "--audio", "aac")
    assert r.exit_code == 0, r.output
    kinds = streams(tmp_path / "aac.mp4")
    assert "subtitle streams not kept: mp4 cannot hold them" in r.output  # SRT in MP4: named, not silent
    assert [k[:2] for k in kinds if k[0] == "audio"] == [("audio", "aac"), ("audio", "aac")]


def test_the_codec_family_follows_the_source(tmp_path):
    src = str(tmp_path / "hevc.mkv")
    make_demo.write_clip(src, frames=6, codec="libx265", audio=False, options={"x265-params": "log-level=error"})
    r = run(src, "-o", tmp_path / "out.mkv")
    assert r.exit_code == 0, r.output
    assert streams(tmp_path / "out.mkv")[0][1] == "hevc"
    assert run(src, "-o", tmp_path / "h264.mkv", "--codec", "libx264").exit_code == 0
    assert streams(tmp_path / "h264.mkv")[0][1] == "h264"


FONT = b"\x00\x01\x00\x00" + bytes(range(256)) * 4  # stands for a TrueType font: bytes copied as they are


def make_chaptered(path: str, frames: int = 24) -> None:
    """An MKV with two chapters (0-0.5 s "One", 0.5-1 s "Two") and a font attachment, by PyAV."""
    from fractions import Fraction

    if not hasattr(av.container.OutputContainer, "set_chapters") or \
            not hasattr(av.container.OutputContainer, "add_attachment"):
        pytest.skip(f"PyAV {av.__version__} cannot write chapters and attachments (18 can)")

    with av.open(path, "w") as out:
        v = out.add_stream("ffv1", rate=24)
        v.width, v.height, v.pix_fmt = 32, 16, "yuv444p"
        out.add_attachment("Font One.ttf", "application/x-truetype-font", FONT)
        out.set_chapters([{"id": k + 1, "start": 12 * k, "end": 12 * k + 12, "time_base": Fraction(1, 24),
                           "metadata": {"title": t}} for k, t in enumerate(("One", "Two"))])
        for i in range(frames):
            f = av.VideoFrame.from_ndarray(np.full((16, 32, 3), 10 + i * 9, np.uint8), format="rgb24")
            f.pts, f.time_base = i, Fraction(1, 24)
            for p in v.encode(f):
                out.mux(p)
        for p in v.encode():
            out.mux(p)


def chapters(path) -> list[tuple[float, float, str]]:
    with av.open(str(path)) as c:
        return [(round(float(ch["start"] * ch["time_base"]), 3), round(float(ch["end"] * ch["time_base"]), 3),
                 ch["metadata"].get("title")) for ch in c.chapters()]


def attachments(path) -> list[tuple[str, str, bytes]]:
    with av.open(str(path)) as c:
        return [(s.name, s.mimetype, bytes(s.data)) for s in c.streams if s.type == "attachment"]


@pytest.fixture(scope="module")
def chaptered(tmp_path_factory):
    path = str(tmp_path_factory.mktemp("chap") / "chap.mkv")
    make_chaptered(path)
    assert chapters(path) == [(0.0, 0.5, "One"), (0.5, 1.0, "Two")]
    assert attachments(path) == [("Font One.ttf", "application/x-truetype-font", FONT)]
    return path


def test_chapters_and_attachments_are_kept(chaptered, tmp_path):
    r = run(chaptered, "-o", tmp_path / "o.mkv")
    assert r.exit_code == 0, r.output
    assert chapters(tmp_path / "o.mkv") == [(0.0, 0.5, "One"), (0.5, 1.0, "Two")]
    assert attachments(tmp_path / "o.mkv") == [("Font One.ttf", "application/x-truetype-font", FONT)]
    assert "not kept" not in r.output


def test_trimmed_chapters_shift_and_mp4_names_the_attachments_it_drops(chaptered, tmp_path):
    r = run(chaptered, "-o", tmp_path / "o.mkv", "--start", "0.25", "--end", "0.75")
    assert r.exit_code == 0, r.output
    assert chapters(tmp_path / "o.mkv") == [(0.0, 0.25, "One"), (0.25, 0.5, "Two")]
    r = run(chaptered, "-o", tmp_path / "o.mp4", "--end", "12f")
    assert r.exit_code == 0, r.output
    assert chapters(tmp_path / "o.mp4") == [(0.0, 0.5, "One")]  # the second starts at the end: left out
    assert attachments(tmp_path / "o.mp4") == []
    assert "o.mp4: 1 attachment (Font One.ttf) not kept: mp4 cannot hold them" in r.output
    assert "attachment stream 1" not in r.output  # named once


def test_audio_aac_re_encodes_pcm_of_unspecified_layout(tmp_path):
    """PCM in MKV (or WAV) reads back with a layout of unspecified order ('1 channels'), which the AAC encoder refused:
    --audio aac dropped the audio with 'matroska cannot hold them (... avcodec_open2("aac") ... Invalid argument)'."""
    src, out = tmp_path / "pcm.mkv", tmp_path / "out.mkv"
    with av.open(str(src), "w") as o:
        v = o.add_stream("libx264", rate=25)
        v.width, v.height, v.pix_fmt = 64, 48, "yuv420p"
        a = o.add_stream("pcm_s16le", rate=48000)
        a.layout = "mono"
        mux_moving_edge(o, v, 10, 20, 200)
        tone = (3000 * np.sin(np.arange(19200) / 20)).astype(np.int16)[None]
        for k in range(0, 19200, 960):
            f = av.AudioFrame.from_ndarray(tone[:, k:k + 960], format="s16", layout="mono")
            f.sample_rate, f.pts = 48000, k
            for p in a.encode(f):
                o.mux(p)
        for p in a.encode():
            o.mux(p)
    with av.open(str(src)) as c:
        assert c.streams.audio[0].codec_context.layout.name.endswith("channels")   # what the encoder refused
    r = run(src, "-o", out, "--audio", "aac")
    assert r.exit_code == 0 and "not kept" not in r.output, r.output
    with av.open(str(out)) as c:
        assert c.streams.audio[0].codec_context.name == "aac"
        assert sum(f.samples for f in c.decode(audio=0)) >= 19200 - 1024


@pytest.mark.parametrize("ext,kept", [("mp4", True), ("mkv", True), ("ts", False), ("avi", False)])
def test_a_rotation_the_output_cannot_store_is_named(tmp_path, ext, kept):
    """A phone's clip says it is displayed turned (its display matrix): MP4, MOV, MKV and WebM keep that; AVI, MPEG-TS,
    NUT and y4m have nowhere to put it, and the output played on its side without a word."""
    src = tmp_path / "phone.mp4"
    with av.open(str(src), "w") as out:
        s = out.add_stream("libx264", rate=25)
        s.width, s.height, s.pix_fmt = 64, 48, "yuv420p"
        s.set_display_rotation(90)
        mux_moving_edge(out, s, 12, 20, 200)
    r = run(src, "-o", tmp_path / f"out.{ext}")
    assert r.exit_code == 0, r.output
    with av.open(str(tmp_path / f"out.{ext}")) as c:
        rotation = next(c.decode(video=0)).rotation
    assert (rotation == 90) == kept
    assert ("display rotation of" in r.output and "90 degrees) not kept" in r.output) == (not kept)
