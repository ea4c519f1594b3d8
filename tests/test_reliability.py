"""Faults and bad input (issue 21): non-finite samples, a full disk for every output format, --resume
over incomplete outputs and stale temporary files, SIGTERM, multi-frame images, colour-model notes,
and the filter fuzzed in a subprocess (a native crash fails the test instead of killing pytest)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.images import check_complete, read_image, write_image
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.spatial.nonfinite import SAMPLE_LIMIT, replace_non_finite

HERE = os.path.dirname(__file__)
CLI = [sys.executable, "-c", "from mlaa_stream.cli.main import main; main()"]


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def noise(h: int, w: int, c: int = 3, seed: int = 0, dtype=np.uint8) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if np.dtype(dtype).kind == "f":
        return rng.random((h, w, c), dtype=np.float32).astype(dtype)
    return rng.integers(0, np.iinfo(dtype).max, (h, w, c), endpoint=True).astype(dtype)


def staircase(h: int = 40, w: int = 56, seed: int = 0) -> np.ndarray:
    """A dark shape with stepped edges on a light ground, float32 in [0, 1], plus mild noise-free texture."""
    y, x = np.mgrid[0:h, 0:w]
    img = np.where((y * 3 > x + 10)[..., None], [0.1, 0.15, 0.2], [0.9, 0.85, 0.8]).astype(np.float32)
    img[::9, :] = 0.5
    return img


def temp_files(folder) -> list[str]:
    return [n for r, _, fs in os.walk(folder) for n in fs if ".mlaa-tmp" in n]


# -- non-finite samples ---------------------------------------------------------------------------
def test_replace_non_finite_fills_from_the_row_and_restores(tmp_path):
    frame = np.array([[[1.0], [np.nan], [3.0]], [[np.inf], [-np.inf], [5.0]],
                      [[np.nan], [np.nan], [2e30]]], np.float32)
    work = frame.copy()
    nf = replace_non_finite(work)
    # nearest finite sample on the left, else on the right, else 0 (row 3 has none in range)
    assert work[..., 0].tolist() == [[1.0, 1.0, 3.0], [5.0, 5.0, 5.0], [0.0, 0.0, 0.0]]
    out = nf.restore(work.copy())
    assert np.array_equal(out, frame, equal_nan=True)
    assert replace_non_finite(np.ones((2, 2, 3), np.float32)) is None
    assert replace_non_finite(np.ones((2, 2, 3), np.uint8)) is None


@pytest.mark.parametrize("linear_input", [False, True])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf, 3e38])
def test_non_finite_samples_pass_through_and_do_not_spread(bad, linear_input):
    frame = staircase()
    frame[20, 30, 1] = bad  # one channel of a pixel on the edge
    frame[5, 0] = bad  # a whole pixel at the frame's border
    filled = frame.copy()
    replace_non_finite(filled)
    f = Filter(linear_input=linear_input)
    out, ref = f.process(frame), f.process(filled)
    bad_mask = ~(np.abs(frame) <= SAMPLE_LIMIT)
    assert np.array_equal(out[bad_mask], frame[bad_mask], equal_nan=True)  # unchanged
    # everything else is exactly the frame filtered with the row-neighbour fill: nothing spread
    assert np.array_equal(out[~bad_mask], ref[~bad_mask])
    assert np.isfinite(out[~bad_mask]).all()
    assert (out != frame)[~bad_mask].any()  # and the frame was still antialiased


def test_float64_samples_beyond_float32_pass_through_finite():
    """A float64 sample beyond float32's range (1e300) became inf on upload and came back inf: finite inputs
    gave non-finite outputs. It passes through as it was, like any sample beyond SAMPLE_LIMIT."""
    frame = staircase().astype(np.float64)
    frame[20, 30, 1] = 1e300
    frame[5, 0] = -1e300
    frame[7, 7, 2] = 1e20  # within float32's range, beyond SAMPLE_LIMIT: restored at float64 precision
    filled = np.where(np.abs(frame) > SAMPLE_LIMIT, np.inf, frame).astype(np.float32)
    replace_non_finite(filled)  # each out-of-range sample replaced by its row neighbour, as the filter does
    with Filter() as f:
        out = f.process(frame)
        ref = f.process(filled)
    big = np.abs(frame) > SAMPLE_LIMIT
    assert out.dtype == np.float64 and np.isfinite(out).all()
    assert np.array_equal(out[big], frame[big])
    assert (out[~big] != frame[~big]).any()  # and the frame was still antialiased
    assert np.array_equal(out[~big], ref[~big])  # nothing spread


@pytest.mark.filterwarnings("error::RuntimeWarning")   # half frames: no overflow in the range test either
@pytest.mark.parametrize("method,dtype", [("tss", np.float32), ("blend", np.float32), ("tss", np.float16)])
def test_non_finite_samples_pass_the_temporal_stage(method, dtype):
    """Antialiaser(temporal=...) on float frames (display-encoded, as OpenCV loops hold them): NaN, inf and
    out-of-range samples came out as history (finite values) from the second frame on; they pass through."""
    from mlaa_stream import Antialiaser
    base = staircase().astype(dtype)
    with Antialiaser(temporal=method) as aa:
        for k in range(4):
            frame = np.roll(base, k, axis=1)  # a pan: history to take from
            frame[12, 20, 0], frame[30, 40] = np.nan, np.inf
            frame[3, 50, 2], frame[35, 5, 1] = -np.inf, 1e30 if dtype == np.float32 else np.inf
            out = aa(frame)
            bad = ~(np.abs(frame) <= np.float64(SAMPLE_LIMIT))
            assert np.array_equal(out[bad], frame[bad], equal_nan=True), k
            assert np.isfinite(out[~bad]).all(), k


def test_fuzzed_filter_never_crashes_and_keeps_finite_outputs():
    """tests/fuzz_filter.py: hypothesis, derandomized, 60 examples over 2 sizes, 21 format/option cases."""
    r = subprocess.run([sys.executable, os.path.join(HERE, "fuzz_filter.py"), "60"], capture_output=True,
                       text=True, timeout=540)
    assert r.returncode == 0, f"exit {r.returncode}\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    assert "examples 60 " in r.stdout


# -- a full disk, for every output format ---------------------------------------------------------
@pytest.fixture
def small_disk(tmp_path):
    """A 96 KiB tmpfs: a real full disk. Needs root (mount); skipped elsewhere."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=96k", "tmpfs", str(mnt)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs to fill up (needs root): {r.stderr.decode().strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


@pytest.mark.parametrize("ext,dtype", [("png", np.uint8), ("png", np.uint16), ("jpg", np.uint8),
                                       ("tif", np.uint8), ("exr", np.float16), ("dpx", np.uint16)])
def test_a_full_disk_fails_naming_the_file_and_leaves_nothing(tmp_path, small_disk, ext, dtype):
    src = tmp_path / f"in.{ext}"
    write_image(str(src), noise(200, 240, dtype=dtype))
    r = subprocess.run([*CLI, str(src), "-o", str(small_disk / f"out.{ext}")], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 1, r.stderr
    assert "mlaa-stream: error:" in r.stderr and f"out.{ext}" in r.stderr and "No space left" in r.stderr
    assert os.listdir(small_disk) == []  # nothing under the final name, no temporary file


def test_a_full_disk_stops_a_folder_and_resume_finishes_it(tmp_path, small_disk):
    src = tmp_path / "in"
    src.mkdir()
    for i in range(4):
        write_image(str(src / f"f{i}.png"), noise(110, 120, seed=i))  # ~40 KB each: two fit
    r = subprocess.run([*CLI, str(src), "-o", str(small_disk)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 1 and "No space left" in r.stderr, r.stderr
    written = sorted(os.listdir(small_disk))
    assert written == ["f0.png", "f1.png"]
    for name in written:
        assert check_complete(str(small_disk / name), 120, 110, 3) is None
    subprocess.run(["mount", "-o", "remount,size=1m", str(small_disk)], check=True)
    r = subprocess.run([*CLI, str(src), "-o", str(small_disk), "--resume"], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    assert sorted(os.listdir(small_disk)) == ["f0.png", "f1.png", "f2.png", "f3.png"]


# -- --resume trusts only complete outputs ---------------------------------------------------------
def test_resume_redoes_a_truncated_output_and_removes_stale_temporary_files(tmp_path):
    src, out = tmp_path / "in", tmp_path / "out"
    src.mkdir()
    out.mkdir()
    for i in range(3):
        write_image(str(src / f"f{i}.png"), noise(30, 40, seed=i))
    assert run(src, "-o", out).exit_code == 0
    good = (out / "f0.png").read_bytes()
    data = (out / "f1.png").read_bytes()
    (out / "f1.png").write_bytes(data[: len(data) // 2])  # what an unchecked write left on a full disk
    (out / "f2.png").write_bytes(b"")
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # a process id that no longer runs
    stale = out / f".f0.mlaa-tmp{dead.pid}-0.png"
    stale.write_bytes(data[:100])
    r = run(src, "-o", out, "--resume", "-v")
    assert r.exit_code == 0, r.output
    assert "f1.png: incomplete" in r.output and "f2.png: incomplete" in r.output
    assert "removed (a temporary file left by an interrupted run)" in r.output
    assert temp_files(out) == []
    assert (out / "f0.png").read_bytes() == good  # a complete output is kept as it was
    for i in (1, 2):
        assert check_complete(str(out / f"f{i}.png"), 40, 30, 3) is None


def test_check_complete_catches_cut_png_and_jpeg(tmp_path):
    for ext in ("png", "jpg"):
        path = tmp_path / f"a.{ext}"
        write_image(str(path), noise(64, 64))
        assert check_complete(str(path), 64, 64, 3) is None
        assert "expected 32x64" in check_complete(str(path), 32, 64, 3)
        data = path.read_bytes()
        for cut in (len(data) - 2, len(data) // 2):
            path.write_bytes(data[:cut])
            assert check_complete(str(path)) is not None
            assert check_complete(str(path), decode=False) is not None


@pytest.mark.parametrize("ext,tile", [(".exr", 0), (".exr", 16), (".tif", 0), (".tif", 16)])
def test_check_complete_without_decoding_catches_a_cut_exr_or_tiff(tmp_path, ext, tile):
    # no trailer to look for: --resume's header check took a copy cut short for a complete output
    import OpenImageIO as oiio

    path = str(tmp_path / f"a{ext}")
    spec = oiio.ImageSpec(40, 64, 3, "half" if ext == ".exr" else "uint8")
    spec.attribute("compression", "none")
    spec.tile_width = spec.tile_height = tile
    out = oiio.ImageOutput.create(path)
    assert out.open(path, spec) and out.write_image(noise(64, 40, seed=3)) and out.close()
    del out
    assert check_complete(path, 40, 64, 3, decode=False) is None
    data = open(path, "rb").read()
    for cut in (len(data) * 3 // 4, len(data) - 64):
        with open(path, "wb") as fh:
            fh.write(data[:cut])
        assert check_complete(path, 40, 64, 3, decode=False) is not None, cut


# -- SIGTERM and SIGHUP ---------------------------------------------------------------------------
@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_sigterm_stops_cleanly_and_resume_goes_on(tmp_path, sig, code):
    src, out = tmp_path / "in", tmp_path / "out"
    src.mkdir()
    for i in range(40):
        write_image(str(src / f"f{i:02d}.png"), noise(300, 400, seed=i))
    proc = subprocess.Popen([*CLI, str(src), "-o", str(out)], stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while time.time() < deadline and not (out.is_dir() and any(n.endswith(".png") for n in os.listdir(out))):
        time.sleep(0.05)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    assert f"terminated by {signal.Signals(sig).name}" in err
    done = sorted(n for n in os.listdir(out) if not n.startswith("."))
    assert 1 <= len(done) < 40 and temp_files(out) == []
    for name in done:
        assert check_complete(str(out / name), 400, 300, 3) is None
    r = run(src, "-o", out, "--resume")
    assert r.exit_code == 0 and len(os.listdir(out)) == 40


def test_sigterm_during_a_video_removes_the_output(tmp_path, monkeypatch):
    from mlaa_stream.io import video as video_io

    real = video_io.VideoWriter.write

    def write(self, frame, when=None):
        if self.frames_written == 3:
            os.kill(os.getpid(), signal.SIGTERM)  # the command's own handler turns it into a clean stop
        return real(self, frame, when)

    monkeypatch.setattr(video_io.VideoWriter, "write", write)
    r = run(os.path.join(HERE, "..", "fixtures", "demo", "clip.mp4"), "-o", tmp_path / "o.mp4")
    assert r.exit_code == 143 and "terminated by SIGTERM" in r.output
    assert os.listdir(tmp_path) == []
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # the handler is gone after the command


# -- multi-frame images and colour models -----------------------------------------------------------
def test_an_animated_gif_is_refused_clearly(tmp_path):
    from PIL import Image as PILImage

    frames = [PILImage.fromarray(np.roll(noise(20, 30), k, axis=1)) for k in range(3)]
    frames[0].save(tmp_path / "anim.gif", save_all=True, append_images=frames[1:])
    r = run(tmp_path / "anim.gif", "-o", tmp_path / "out.gif")
    assert r.exit_code == 1
    assert "anim.gif: expected a single image, got 3" in r.output
    assert not (tmp_path / "out.gif").exists()


def test_a_multi_part_exr_is_refused_naming_its_parts(tmp_path):
    """A multi-part EXR (beauty + depth) was refused as 'an animated or multi-page file' with FFmpeg's advice,
    which cannot split it: the message names the parts and how to take one out."""
    import OpenImageIO as oiio
    path = str(tmp_path / "multi.exr")
    beauty, depth = oiio.ImageSpec(8, 6, 3, "half"), oiio.ImageSpec(8, 6, 1, "float")
    beauty.attribute("name", "beauty")
    depth.attribute("name", "depth")
    depth.channelnames = ("Z",)
    out = oiio.ImageOutput.create(path)
    assert out.open(path, (beauty, depth)) and out.write_image(noise(6, 8, 3, dtype=np.float32)), oiio.geterror()
    assert out.open(path, depth, "AppendSubimage") and out.write_image(noise(6, 8, 1, dtype=np.float32))
    out.close()
    r = run(path, "-o", tmp_path / "out.exr")
    assert r.exit_code == 1
    assert "multi.exr: expected a single-part EXR, got a multi-part file with 2 parts (beauty, depth)" in r.output
    assert "ffmpeg" not in r.output and not (tmp_path / "out.exr").exists()


def test_cmyk_and_palette_conversions_are_reported_with_v(tmp_path):
    from PIL import Image as PILImage

    src = tmp_path / "in"
    src.mkdir()
    PILImage.fromarray(noise(20, 30)).convert("CMYK").save(src / "cmyk.jpg")
    PILImage.fromarray(noise(20, 30)).convert("P").save(src / "pal.png")
    r = run(src, "-o", tmp_path / "out", "-v")
    assert r.exit_code == 0, r.output
    assert "cmyk.jpg: CMYK converted to RGB" in r.output
    assert "pal.png: palette colours expanded to RGB" in r.output
    assert read_image(str(tmp_path / "out" / "cmyk.jpg")).pixels.shape == (20, 30, 3)
