"""Interlaced video (broadcast H.264 / MPEG-2 with its fields woven into each frame) is made progressive before the
filter (--deinterlace auto|on|off, mlaa_stream/io/deinterlace.py): the combing of moving edges is not taken for
jaggies, and the frame count and timestamps stay the source's."""
from __future__ import annotations

import dataclasses

import av
import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.deinterlace import FLAGGED, FORCED, reason
from mlaa_stream.io.video import probe_video, read_video

W, H, FRAMES = 128, 64, 8
BAR, SPEED, X0 = 12, 4, 8   # a bright bar BAR px wide, moving SPEED px per field from X0


def woven(i: int) -> np.ndarray:
    """Frame i as an interlaced camera takes it: the top field (even rows) at time 2i, the bottom one at 2i + 1
    (a field-time later), so the moving bar's rows alternate between two positions: combing."""
    img = np.full((H, W, 3), 40, np.uint8)
    for parity in (0, 1):
        x = X0 + SPEED * (2 * i + parity)
        img[parity::2, x:x + BAR] = 220
    return img


def write_clip(path, codec: str = "libx264", options: dict | None = None, frames=woven, pix_fmt: str = "yuv420p"):
    """An 8-frame clip at 25 fps; libx264 with x264's interlaced=1:tff=1 writes a stream of field order tt whose
    frames are flagged interlaced, mpeg2video with +ilme+ildct one of field order bb."""
    with av.open(str(path), "w") as out:
        s = out.add_stream(codec, rate=25, options=options or {})
        s.width, s.height, s.pix_fmt = W, H, pix_fmt
        for i in range(FRAMES):
            vf = av.VideoFrame.from_ndarray(frames(i), format="rgb24").reformat(format=pix_fmt)
            vf.pts = i
            for p in s.encode(vf):
                out.mux(p)
        for p in s.encode():
            out.mux(p)


INTERLACED_H264 = {"x264-params": "interlaced=1:tff=1"}
INTERLACED_MPEG2 = {"flags": "+ilme+ildct"}


def comb(grey: np.ndarray) -> float:
    """Mean |row y - (row y-1 + row y+1) / 2| over the columns the bar crosses: large where two fields disagree."""
    a = grey.astype(np.float64)[:, X0:X0 + SPEED * 2 * FRAMES + BAR]
    return float(np.abs(a[1:-1] - (a[:-2] + a[2:]) / 2).mean())


def decoded(path) -> tuple[list[np.ndarray], list[float], object]:
    """Luma of every frame, each frame's time in seconds, and the stream's field order."""
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        frames = list(c.decode(s))
        return ([f.to_ndarray(format="gray") for f in frames], [float(f.pts * f.time_base) for f in frames],
                s.codec_context.field_order)


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def interlaced(tmp_path_factory):
    path = tmp_path_factory.mktemp("interlaced") / "tt.mp4"
    write_clip(path, options=INTERLACED_H264)
    return path


def test_auto_deinterlaces_an_interlaced_video_and_says_so_once(interlaced, tmp_path):
    assert probe_video(str(interlaced)).interlaced == "top field first"   # PyAV wrote a stream that says so
    out_auto, out_off = tmp_path / "auto.mp4", tmp_path / "off.mp4"
    res = run(interlaced, "-o", out_auto)   # auto is the default
    assert res.exit_code == 0, res.output
    note = f"{interlaced}: interlaced (top field first): deinterlaced with bwdif; --deinterlace off to keep the fields"
    assert res.output.count(note) == 1, res.output
    assert "warning" not in res.output
    res = run(interlaced, "-o", out_off, "--deinterlace", "off")
    assert res.exit_code == 0, res.output
    assert "deinterlaced with" not in res.output and "is interlaced (top field first)" in res.output

    src, src_t, _ = decoded(interlaced)
    auto, auto_t, auto_order = decoded(out_auto)
    off, off_t, _ = decoded(out_off)
    assert len(auto) == len(off) == len(src) == FRAMES   # one progressive frame per frame
    assert auto_t == off_t == src_t                      # at the source's timestamps
    assert auto_order in (0, 1)                          # written progressive (unknown or progressive)
    src_comb = np.mean([comb(g) for g in src])
    assert min(comb(g) for g in src) > 10   # every input frame combs
    auto_comb = np.mean([comb(g) for g in auto])
    off_comb = np.mean([comb(g) for g in off])
    assert auto_comb < 0.1 * src_comb, (auto_comb, src_comb)
    assert off_comb > 5 * auto_comb, (off_comb, auto_comb)   # off: the fields' combing stays (smeared by the filter)


def test_read_video_keeps_count_and_timestamps_bottom_field_first(tmp_path):
    """MPEG-2 with field order bb: the parity from the stream, the frames' own timestamps (bwdif works in field
    time: its time base is half the stream's), a trim taken after the deinterlacer."""
    path = tmp_path / "bb.mkv"
    write_clip(path, codec="mpeg2video", options=INTERLACED_MPEG2)
    info = probe_video(str(path))
    assert info.interlaced == "bottom field first"
    notes = []
    off = list(read_video(info, deinterlace="off"))
    on = list(read_video(info, deinterlace="auto", on_deinterlace=lambda *a: notes.append(a)))
    assert notes == [("bwdif", "bottom field first")]
    assert [i.meta for i in on] == [i.meta for i in off] and len(on) == FRAMES
    assert max(comb(i.frame[..., 1]) for i in on) < 0.1 * min(comb(i.frame[..., 1]) for i in off)
    tb = off[0].meta.time_base
    start, end = float(off[2].meta.pts * tb), float(off[6].meta.pts * tb)
    trimmed = list(read_video(info, start=start, end=end, deinterlace="auto"))
    assert [i.meta for i in trimmed] == [i.meta for i in off[2:6]]
    assert all(np.array_equal(a.frame, b.frame) for a, b in zip(trimmed, on[2:6]))   # the same neighbours as untrimmed


def test_a_progressive_video_is_untouched_by_auto(tmp_path):
    """auto on a progressive source: no deinterlacer, the output bit for bit what --deinterlace off writes (the
    behaviour before --deinterlace); on forces it and says so."""
    src = tmp_path / "p.mp4"
    write_clip(src, frames=lambda i: np.roll(woven(0), SPEED * 2 * i, axis=1))   # the same comb, not interlaced
    info = probe_video(str(src))
    assert info.interlaced is None
    decoded_off, decoded_auto = list(read_video(info, deinterlace="off")), list(read_video(info, deinterlace="auto"))
    assert all(np.array_equal(a.frame, b.frame) and a.meta == b.meta for a, b in zip(decoded_off, decoded_auto))
    outs = {}
    for mode in ("auto", "off", "on"):
        outs[mode] = tmp_path / f"{mode}.mkv"
        res = run(src, "-o", outs[mode], "--codec", "ffv1", "--deinterlace", mode)
        assert res.exit_code == 0, res.output
        assert ("deinterlaced with" in res.output) == (mode == "on"), res.output
        if mode == "on":
            assert f"{src}: deinterlaced with bwdif (--deinterlace on; the stream does not say it" in res.output
    auto, auto_t, _ = decoded(outs["auto"])
    off, off_t, _ = decoded(outs["off"])
    on, _, _ = decoded(outs["on"])
    assert auto_t == off_t and all(np.array_equal(a, b) for a, b in zip(auto, off, strict=True))
    assert np.mean([comb(g) for g in on]) < 0.1 * np.mean([comb(g) for g in off])   # forced: the comb taken for fields


def test_frames_flagged_interlaced_are_enough_for_auto(interlaced):
    """A stream whose field order says nothing but whose frames are flagged interlaced (PyAV's
    frame.interlaced_frame) is deinterlaced too, the parity from each frame."""
    assert reason("auto", None, True) == FLAGGED
    assert reason("auto", None, False) is None
    assert reason("auto", "top field first", False) == "top field first"
    assert reason("on", None, False) == FORCED
    assert reason("off", "top field first", True) is None
    with pytest.raises(ValueError, match="expected one of auto, on, off, got 'yes'"):
        reason("yes", None, False)
    info = dataclasses.replace(probe_video(str(interlaced)), interlaced=None)   # the stream's word taken away
    notes = []
    items = list(read_video(info, deinterlace="auto", on_deinterlace=lambda *a: notes.append(a)))
    assert notes == [("bwdif", FLAGGED)] and len(items) == FRAMES
    assert max(comb(i.frame[..., 1]) for i in items) < 2


def test_a_video_written_as_images_is_deinterlaced(interlaced, tmp_path):
    res = run(interlaced, "-o", tmp_path / "f%04d.png")
    assert res.exit_code == 0, res.output
    assert "interlaced (top field first): deinterlaced with bwdif" in res.output
    from mlaa_stream.io.images import read_image
    frames = [read_image(str(tmp_path / f"f{n:04d}.png")).pixels for n in range(1, FRAMES + 1)]
    assert max(comb(f[..., 1]) for f in frames) < 2
    assert not (tmp_path / f"f{FRAMES + 1:04d}.png").exists()


def test_deinterlace_where_it_cannot_apply_is_named(tmp_path, interlaced):
    img = tmp_path / "a.png"
    from mlaa_stream.io.images import write_image
    write_image(str(img), woven(0))
    res = run(img, "-o", tmp_path / "b.png", "--deinterlace", "on")
    assert res.exit_code == 0, res.output
    assert "--deinterlace has no effect here" in res.output
    res = run(interlaced, "-o", tmp_path / "cv.mp4", "--deinterlace", "on", "--video-backend", "opencv")
    assert res.exit_code == 2 and "--deinterlace on needs the pyav video backend" in res.output


def test_10_bit_and_rgb_sources_keep_their_format(tmp_path):
    """The deinterlacer runs in the decoded pixel format (10-bit YUV; packed RGB through the conversion libavfilter
    inserts): the frames come out at the source's depth and channels."""
    ten, rgb = tmp_path / "ten.mkv", tmp_path / "rgb.nut"
    write_clip(ten, options=INTERLACED_H264, pix_fmt="yuv420p10le")
    write_clip(rgb, codec="rawvideo", pix_fmt="rgb24")
    for path, mode, dtype in ((ten, "auto", np.uint16), (rgb, "on", np.uint8)):
        info = probe_video(str(path))
        items = list(read_video(info, deinterlace=mode))
        assert len(items) == FRAMES and items[0].frame.dtype == dtype and items[0].frame.shape == (H, W, 3)
        scale = 257 if dtype == np.uint16 else 1
        assert max(comb(i.frame[..., 1] / scale) for i in items) < 2, path
        assert [i.meta for i in items] == [i.meta for i in read_video(info, deinterlace="off")]


def test_segments_on_a_cluster_equal_one_machine(client, interlaced, tmp_path):
    """Each worker deinterlaces its range from the keyframe before it, the trim after the deinterlacer: a segment's
    first frame has its field neighbours, and the joined video is the single machine's frame for frame."""
    from mlaa_stream.cluster.video import filter_video_on_cluster

    res = run(interlaced, "-o", tmp_path / "ref.mkv", "--codec", "ffv1")
    assert res.exit_code == 0, res.output
    n = filter_video_on_cluster(client, str(interlaced), str(tmp_path / "cl.mkv"), codec="ffv1",
                                segment_seconds=0.12, deinterlace="auto")
    assert n == FRAMES
    (ref, ref_t, _), (cl, cl_t, _) = decoded(tmp_path / "ref.mkv"), decoded(tmp_path / "cl.mkv")
    assert ref_t == cl_t and all(np.array_equal(a, b) for a, b in zip(ref, cl, strict=True))
    assert max(comb(g) for g in cl) < 2
