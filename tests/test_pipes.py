"""Pipes (issue 17): `-` as input (y4m, NUT, ... on standard input, read once) and `-o - -f FORMAT` as
output, chained with another process the way vspipe | mlaa-stream | ffmpeg chains are. The other end is
PyAV in a child process (FFmpeg's own libraries), or a real `ffmpeg` where one is installed."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

import av
import numpy as np
import pytest

from demo_maker import make_demo

DEMO_CLIP = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")
CLI = [sys.executable, "-c", "from mlaa_stream.cli.main import main; main()"]

Y4M_WRITER = r"""
import sys, av, numpy as np
pix = sys.argv[1]
out = av.open(sys.stdout.buffer, "w", format="yuv4mpegpipe", options={"strict": "-1"})
s = out.add_stream("rawvideo", rate=25)
s.width, s.height, s.pix_fmt = 64, 48, pix
y, x = np.mgrid[0:48, 0:64]
for i in range(12):
    img = np.where(((y * 2 + i) > x)[..., None], [30, 40, 200], [230, 220, 200]).astype(np.uint8)
    f = av.VideoFrame.from_ndarray(img, format="rgb24")
    f.pts = i
    for p in s.encode(f):
        out.mux(p)
for p in s.encode():
    out.mux(p)
out.close()
"""

Y4M_READER = r"""
import sys, av
c = av.open(sys.stdin.buffer)
s = c.streams.video[0]
print(c.format.name, s.codec_context.name, s.codec_context.format.name, s.average_rate, sum(1 for _ in c.decode(s)))
"""


def chain(first: list[str], second: list[str]) -> tuple[subprocess.CompletedProcess, subprocess.CompletedProcess]:
    a = subprocess.Popen(first, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    b = subprocess.run(second, stdin=a.stdout, capture_output=True, timeout=300)
    a.stdout.close()
    a_err = a.stderr.read()
    a.wait(timeout=60)
    return subprocess.CompletedProcess(first, a.returncode, b"", a_err), b


@pytest.mark.parametrize("pix", ["yuv420p", "yuv420p10le"])
def test_y4m_on_standard_input(tmp_path, pix):
    out = tmp_path / "out.mkv"
    a, b = chain([sys.executable, "-c", Y4M_WRITER, pix], [*CLI, "-", "-o", str(out)])
    assert a.returncode == 0 and b.returncode == 0, b.stderr.decode()
    with av.open(str(out)) as c:
        frames = [f for f in c.decode(video=0)]
    assert len(frames) == 12 and frames[0].format.name.startswith(pix[:7])


@pytest.mark.parametrize("fmt,expect", [("y4m", "yuv4mpegpipe rawvideo yuv420p 24 10"),
                                        ("nut", "nut rawvideo yuv420p 24 10")])
def test_standard_output_in_the_format_asked(fmt, expect):
    a, b = chain([*CLI, DEMO_CLIP, "-o", "-", "-f", fmt], [sys.executable, "-c", Y4M_READER])
    assert a.returncode == 0, a.stderr.decode()
    assert b.stdout.decode().strip() == expect


@pytest.mark.parametrize("marker", [b"FRAME\n", b"FRAME Ip\n"])
def test_a_y4m_stream_cut_mid_frame_on_a_pipe_is_named_truncated(tmp_path, marker):
    """`cat cut.y4m | mlaa-stream - ...`: FFmpeg's y4m reader ends at the last whole frame without an error, and a pipe
    cannot be measured afterwards as a file is; it exited 0 with the frames before it. Now the bytes read are counted
    against where the demuxer's last frame ends: exit 1 naming it, the whole frames kept. A whole stream, also one
    whose frames carry parameters (FRAME Ip), runs clean."""
    whole = subprocess.run([sys.executable, "-c", Y4M_WRITER, "yuv420p"], capture_output=True, check=True,
                           timeout=120).stdout.replace(b"FRAME\n", marker)
    r = subprocess.run([*CLI, "-", "-o", str(tmp_path / "cut.mkv")], input=whole[:-100], capture_output=True,
                       timeout=300)
    assert r.returncode == 1, r.stderr.decode()
    assert b"standard input: the stream ended at frame 11, " in r.stderr and b"bytes of a frame after it" in r.stderr
    with av.open(str(tmp_path / "cut.mkv")) as c:
        assert sum(1 for _ in c.decode(video=0)) == 11
    r = subprocess.run([*CLI, "-", "-o", str(tmp_path / "whole.mkv")], input=whole, capture_output=True, timeout=300)
    assert r.returncode == 0 and b"truncated" not in r.stderr, r.stderr.decode()


def test_pipe_through_pipe_keeps_ten_bits():
    writer = subprocess.Popen([sys.executable, "-c", Y4M_WRITER, "yuv420p10le"], stdout=subprocess.PIPE)
    filt = subprocess.Popen([*CLI, "-", "-o", "-", "-f", "y4m"], stdin=writer.stdout, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    writer.stdout.close()
    r = subprocess.run([sys.executable, "-c", Y4M_READER], stdin=filt.stdout, capture_output=True, timeout=300)
    filt.stdout.close()
    assert filt.wait(timeout=60) == 0 and writer.wait(timeout=60) == 0
    assert r.stdout.decode().split()[2:] == ["yuv420p10le", "25", "12"]


@pytest.mark.parametrize("fmt", ["y4m", "nut"])
def test_a_reader_that_goes_away_stops_the_run_quietly(tmp_path, fmt):
    """`mlaa-stream in.mkv -o - -f y4m | head -c 1000`: the reader has what it wanted and closes its end. The run
    exited 1 with 'write failed at frame N: [Errno 32] Broken pipe'; Unix tools stop without a word, with the status
    a shell reports for SIGPIPE (141), and no 'Exception ignored' from Python's last flush of standard output."""
    src = tmp_path / "big.mkv"   # ~115 kB a frame out: far more than the pipe's buffer
    make_demo.write_clip(str(src), frames=8, w=320, h=240, codec="ffv1", audio=False)
    p = subprocess.Popen([*CLI, str(src), "-o", "-", "-f", fmt], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = p.stdout.read(1000)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=300) == 141, err
    assert len(first) == 1000 and "error" not in err and "Traceback" not in err and "Exception" not in err, err


def test_pipe_misuse_is_refused_clearly(tmp_path):
    r = subprocess.run([*CLI, DEMO_CLIP, "-o", "-"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 1 and "expected a container format (-f y4m" in r.stderr and r.stdout == ""
    r = subprocess.run([*CLI, DEMO_CLIP, "-o", "-", "-f", "y4m", "--progress", "-"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and "both want standard output" in r.stderr
    r = subprocess.run([*CLI, "-", "-o", str(tmp_path / "o.mkv")], input=b"not a video", capture_output=True,
                       timeout=120)
    assert r.returncode == 1 and b"standard input: expected a video stream" in r.stderr


def test_a_y4m_file_gets_its_frame_rate_in_the_header(tmp_path):
    r = subprocess.run([*CLI, DEMO_CLIP, "-o", str(tmp_path / "o.y4m")], capture_output=True, timeout=120)
    assert r.returncode == 0, r.stderr.decode()
    assert (tmp_path / "o.y4m").read_bytes().startswith(b"YUV4MPEG2 W64 H48 F24:1")


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="no ffmpeg binary (Debian package ffmpeg); "
                    "the PyAV chains above cover the same formats")
def test_chained_with_a_real_ffmpeg(tmp_path):
    a, b = chain(["ffmpeg", "-v", "error", "-i", DEMO_CLIP, "-f", "yuv4mpegpipe", "-"],
                 [*CLI, "-", "-o", str(tmp_path / "o.mkv")])
    assert a.returncode == 0 and b.returncode == 0, b.stderr.decode()
    with av.open(str(tmp_path / "o.mkv")) as c:
        assert sum(1 for _ in c.decode(video=0)) == 10


def test_a_y4m_with_a_header_and_no_frame_is_an_error(tmp_path):
    """vspipe failing before its first frame leaves a header alone: exit 1 and nothing written, as for an empty
    stdin (it wrote a video of no frames and exited 0)."""
    header = b"YUV4MPEG2 W64 H48 F25:1 C420jpeg\n"
    r = subprocess.run([*CLI, "-", "-o", "-", "-f", "y4m"], input=header, capture_output=True, timeout=120)
    assert r.returncode == 1 and b"standard input: expected video frames, the stream holds none" in r.stderr
    (tmp_path / "h.y4m").write_bytes(header)
    r = subprocess.run([*CLI, str(tmp_path / "h.y4m"), "-o", str(tmp_path / "o.mkv")], capture_output=True,
                       timeout=120)
    assert r.returncode == 1 and not (tmp_path / "o.mkv").exists(), r.stderr.decode()


def test_audio_on_standard_input_that_is_not_kept_is_named(tmp_path):
    """`cat in.mkv | mlaa-stream - -o out.mkv`: standard input is read once, for its video, so its audio cannot be
    copied; it was dropped without a word (a file's audio is copied by default)."""
    src, out = tmp_path / "in.mkv", tmp_path / "out.mkv"
    with av.open(DEMO_CLIP) as c, av.open(str(src), "w") as o:   # the demo clip (H.264 + AAC) remuxed to MKV
        streams = {s.index: o.add_stream_from_template(s) for s in c.streams if s.type in ("video", "audio")}
        for pkt in c.demux(*[c.streams[i] for i in streams]):
            if pkt.dts is not None:
                pkt.stream = streams[pkt.stream.index]
                o.mux(pkt)
    with open(src, "rb") as stdin:
        r = subprocess.run([*CLI, "-", "-o", str(out)], stdin=stdin, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "audio streams not kept: standard input is read once" in r.stderr
    with open(src, "rb") as stdin:
        r = subprocess.run([*CLI, "-", "-o", str(out), "-y", "--audio", "none"], stdin=stdin, capture_output=True,
                           text=True, timeout=300)
    assert r.returncode == 0 and "not kept" not in r.stderr, r.stderr


def test_standard_output_in_a_format_ffmpeg_lacks_is_an_error_not_a_traceback(tmp_path):
    """`-o - -f FORMAT` with a format FFmpeg has no muxer for: the writer's cleanup unlinked its temporary file, of
    which standard output has none, and a TypeError traceback hid the message."""
    from click.testing import CliRunner

    from mlaa_stream.cli.main import main

    r = CliRunner().invoke(main, [DEMO_CLIP, "-o", "-", "-f", "nosuchformat"])
    assert r.exit_code == 1 and isinstance(r.exception, SystemExit), r.output
    assert "no container format 'nosuchformat'" in r.output


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_named_pipe_as_output_is_written_into_not_replaced(tmp_path):
    """-o FIFO (a player reading a named pipe; /dev/null alike): the video was written under a temporary name and
    renamed over it, replacing the pipe (or, as root, the device node /dev/null) with a regular file."""
    import io
    import stat
    import threading

    from click.testing import CliRunner

    from mlaa_stream.cli.main import main

    fifo = tmp_path / "player"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()), daemon=True)
    reader.start()
    r = CliRunner().invoke(main, [DEMO_CLIP, "-o", str(fifo), "-f", "matroska"])
    reader.join(timeout=10)
    if reader.is_alive():   # nothing opened the pipe to write (the run refused it): let the reader go
        with open(fifo, "wb"):
            pass
        reader.join(timeout=10)
    assert r.exit_code == 0, r.output
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and sorted(os.listdir(tmp_path)) == ["player"]
    with av.open(io.BytesIO(got[0])) as c:
        assert sum(1 for _ in c.decode(video=0)) == 10
