"""The temporal stage across chunk boundaries on Dask (issue 18): each chunk first runs the frames before it
through the stage unwritten (mlaa_stream/cluster/temporal.py). On a LocalCluster of two worker processes,
24 frames of a sub-pixel pan in 3 chunks: TSS gives the single machine's outputs bit for bit, the blend
stays within its stated tolerance (docs/cluster.md), for a PNG sequence and a lossless video."""
from __future__ import annotations

import os

import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.bench.temporal import scene_pan
from mlaa_stream.cli.main import main
from mlaa_stream.cluster.temporal import BLEND_WARMUP, TemporalSpec
from mlaa_stream.io.images import read_image, write_image

pytest.importorskip("distributed", reason="Dask is in the [cluster] and [test] extras")

N, CHUNK, K = 24, 8, 4  # 3 chunks; a ring of 4 frames, so chunks 1 and 2 warm up on frames of the one before
BLEND_TOLERANCE = 1     # levels after BLEND_WARMUP frames (docs/cluster.md: measured max on the bench scenes)


@pytest.fixture(scope="module")
def pan() -> np.ndarray:
    return scene_pan(N, 240, 136).inputs  # (0.35, 0.15) px per frame: every frame "global" at this size (smaller
    # ones are classed dense now and then, which restarts the ring), so the ring is full at every chunk start


@pytest.fixture(scope="module")
def seq(tmp_path_factory, pan):
    root = tmp_path_factory.mktemp("pan")
    (root / "in").mkdir()
    for k, img in enumerate(pan):
        write_image(str(root / "in" / f"p.{101 + k:04d}.png"), img)
    return root


def frames_of(folder) -> list[np.ndarray]:
    return [read_image(str(folder / n)).pixels for n in sorted(os.listdir(folder))]


def single_machine(seq, name: str, *args: str) -> list[np.ndarray]:
    out = seq / name
    if not out.exists():
        r = CliRunner().invoke(main, [str(seq / "in" / "p.%04d.png"), "-o", str(out / "c.%04d.png"), "--temporal",
                                      *args])
        assert r.exit_code == 0, r.output
    return frames_of(out)


def paused(pan: np.ndarray) -> np.ndarray:
    """The pan held on frame 12 for 3 more frames: they sit inside the K before the third chunk."""
    return np.concatenate([pan[:13], np.repeat(pan[12:13], 3, 0), pan[13:N - 3]])


def test_the_warm_up_matters_on_these_sequences(pan):
    """Without a warm-up the chunks' first frames differ, and K frames are not enough where frames are
    held (TSS does not push a repeated frame): the equalities below check the warm-up and its extension."""
    from mlaa_stream.bench.warmup import measure
    from mlaa_stream.spatial.filter import Filter

    with Filter(bgr=False) as filt:
        res = measure(TemporalSpec("tss", K), filt, pan, CHUNK, [0, K])
        held = measure(TemporalSpec("tss", K), filt, paused(pan), CHUNK, [K, 2 * K])
    assert res[0][0] > 10 and res[K] == (0, 0.0)
    assert held[K][0] > 10 and held[2 * K] == (0, 0.0)


def test_held_frames_before_a_chunk_lengthen_its_warm_up(client, pan, tmp_path):
    from mlaa_stream.cluster.frames import filter_on_cluster

    (tmp_path / "in").mkdir()
    for k, img in enumerate(paused(pan)):
        write_image(str(tmp_path / "in" / f"p.{101 + k:04d}.png"), img)
    ref = single_machine(tmp_path, "ref", "--temporal-frames", str(K), "--lookahead", "0")
    report = filter_on_cluster(client, str(tmp_path / "in" / "p.%04d.png"), str(tmp_path / "c" / "c.%04d.png"),
                               chunk_frames=CHUNK, temporal=TemporalSpec("tss", K))
    assert len(report.written) == N and not report.warnings
    got = frames_of(tmp_path / "c")
    assert len(got) == N and all(np.array_equal(a, b) for a, b in zip(got, ref))


def test_tss_chunks_equal_one_machine(client, seq, tmp_path):
    from mlaa_stream.cluster.frames import filter_on_cluster

    ref = single_machine(seq, "ref_tss", "--temporal-frames", str(K), "--lookahead", "0")
    report = filter_on_cluster(client, str(seq / "in" / "p.%04d.png"), str(tmp_path / "c.%04d.png"),
                               chunk_frames=CHUNK, temporal=TemporalSpec("tss", K))
    assert len(report.written) == N and not report.failed
    got = frames_of(tmp_path)
    assert len(got) == N and all(np.array_equal(a, b) for a, b in zip(got, ref))
    assert sum(not np.array_equal(a, b) for a, b in zip(ref, single_machine(seq, "ref_spatial", "--no-temporal"))) \
        > N // 2  # the stage changed most frames: the equality is not the spatial filter's


def test_tss_lookahead_chunks_equal_one_machine(client, seq, tmp_path):
    """--lookahead 2 on the cluster: each chunk reads the 2 frames after its end (unwritten), so its last frames
    read what one machine's do: bit for bit (they differ from the causal run's)."""
    from mlaa_stream.cluster.frames import filter_on_cluster

    ref = single_machine(seq, "ref_tss_ahead", "--temporal-method", "tss", "--temporal-frames", str(K),
                         "--lookahead", "2")
    report = filter_on_cluster(client, str(seq / "in" / "p.%04d.png"), str(tmp_path / "c.%04d.png"),
                               chunk_frames=CHUNK, temporal=TemporalSpec("tss", K, lookahead=2))
    assert len(report.written) == N and not report.failed
    got = frames_of(tmp_path)
    assert len(got) == N and all(np.array_equal(a, b) for a, b in zip(got, ref))
    causal = single_machine(seq, "ref_tss", "--temporal-frames", str(K), "--lookahead", "0")
    assert not np.array_equal(ref[CHUNK - 1], causal[CHUNK - 1])   # a chunk's last frame read ahead


def _interrupted(seq, ref_name: str, out) -> list[int]:
    """`out` as an interrupted run leaves it: the reference's outputs but a hole inside the second chunk and the
    whole third chunk; returns the missing frames' places."""
    import shutil
    missing = list(range(CHUNK + 2, CHUNK + 6)) + list(range(2 * CHUNK, N))
    out.mkdir()
    for k, name in enumerate(sorted(os.listdir(seq / ref_name))):
        if k not in missing:
            shutil.copy(seq / ref_name / name, out / name)
    return missing


def test_resume_on_the_cluster_warms_up_from_the_complete_outputs(client, seq, tmp_path):
    """--resume with the temporal stage: the chunks still read the frames before them (and after, the look-ahead)
    whose outputs are complete. The plan used to leave them out, so the first frames after each hole came out
    without their history: up to 5 frames differed from the uninterrupted run's."""
    from mlaa_stream.cluster.frames import filter_on_cluster

    ref = single_machine(seq, "ref_tss_ahead", "--temporal-method", "tss", "--temporal-frames", str(K),
                         "--lookahead", "2")
    missing = _interrupted(seq, "ref_tss_ahead", tmp_path / "api")
    report = filter_on_cluster(client, str(seq / "in" / "p.%04d.png"), str(tmp_path / "api" / "c.%04d.png"),
                               chunk_frames=CHUNK, temporal=TemporalSpec("tss", K, lookahead=2), resume=True)
    assert len(report.written) == len(missing) and not report.skipped and not report.failed
    got = frames_of(tmp_path / "api")
    assert len(got) == N and all(np.array_equal(a, b) for a, b in zip(got, ref))
    # the command line: the same, and it says what it wrote
    missing = _interrupted(seq, "ref_tss_ahead", tmp_path / "cli")
    r = CliRunner().invoke(main, [str(seq / "in" / "p.%04d.png"), "-o", str(tmp_path / "cli" / "c.%04d.png"),
                                  "--temporal-method", "tss", "--temporal-frames", str(K), "--lookahead", "2",
                                  "--cluster", "local:2", "--chunk-frames", str(CHUNK), "--resume", "-v"])
    assert r.exit_code == 0, r.output
    assert f"{len(missing)} written, {N - len(missing)} skipped" in r.output
    got = frames_of(tmp_path / "cli")
    assert len(got) == N and all(np.array_equal(a, b) for a, b in zip(got, ref))


def test_blend_chunks_within_the_stated_tolerance(client, seq, tmp_path):
    from mlaa_stream.cluster.frames import filter_on_cluster

    ref = single_machine(seq, "ref_blend", "--temporal-method", "blend")
    filter_on_cluster(client, str(seq / "in" / "p.%04d.png"), str(tmp_path / "c.%04d.png"), chunk_frames=CHUNK,
                      temporal=TemporalSpec("blend"))
    got = frames_of(tmp_path)
    assert len(got) == N
    for k, (a, b) in enumerate(zip(got, ref)):
        d = int(np.abs(a.astype(np.int16) - b).max())
        # chunk 1 warms up from frame 0 (BLEND_WARMUP >= CHUNK): exact; chunk 2 after BLEND_WARMUP frames
        assert d <= (0 if k < 2 * CHUNK or BLEND_WARMUP >= 2 * CHUNK else BLEND_TOLERANCE), (k, d)


def test_the_command_line_runs_temporal_on_the_cluster(seq, tmp_path):
    """The command line's defaults (method auto, look-ahead 2) reach the workers: the same frames as one machine."""
    ref = single_machine(seq, "ref_default", "--temporal-frames", str(K))
    r = CliRunner().invoke(main, [str(seq / "in" / "p.%04d.png"), "-o", str(tmp_path / "c.%04d.png"), "--temporal",
                                  "--temporal-frames", str(K), "--cluster", "local:2", "--chunk-frames", str(CHUNK)])
    assert r.exit_code == 0, r.output
    got = frames_of(tmp_path)
    assert len(got) == N and all(np.array_equal(a, b) for a, b in zip(got, ref))
    r = CliRunner().invoke(main, [str(seq / "in" / "p.%04d.png"), "-o", str(tmp_path / "s"), "--temporal",
                                  "--stats", str(tmp_path / "s.csv"), "--cluster", "local:2"])
    assert r.exit_code == 2 and "--stats and --show are not available with --cluster" in r.output


# -- video ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def pan_video(tmp_path_factory, pan) -> str:
    """The paused pan as a lossless video (FFV1, RGB): the third segment's warm-up must reach further back."""
    import av
    from fractions import Fraction

    path = str(tmp_path_factory.mktemp("vid") / "pan.mkv")
    with av.open(path, "w") as out:
        vs = out.add_stream("ffv1", rate=24)
        vs.width, vs.height, vs.pix_fmt = pan.shape[2], pan.shape[1], "bgr0"
        for i, img in enumerate(paused(pan)):
            f = av.VideoFrame.from_ndarray(img, format="rgb24")
            f.pts, f.time_base = i, Fraction(1, 24)
            for p in vs.encode(f):
                out.mux(p)
        for p in vs.encode():
            out.mux(p)
    return path


def decoded(path) -> list[np.ndarray]:
    import av
    with av.open(str(path)) as c:
        return [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]


def test_tss_video_segments_equal_one_machine(client, pan_video, tmp_path):
    from mlaa_stream.cluster.video import filter_video_on_cluster

    r = CliRunner().invoke(main, [pan_video, "-o", str(tmp_path / "ref.mkv"), "--codec", "ffv1", "--temporal",
                                  "--temporal-frames", str(K), "--lookahead", "0"])
    assert r.exit_code == 0, r.output
    n = filter_video_on_cluster(client, pan_video, str(tmp_path / "cl.mkv"), codec="ffv1", segment_seconds=CHUNK / 24,
                                temporal=TemporalSpec("tss", K))
    assert n == N
    a, b = decoded(tmp_path / "ref.mkv"), decoded(tmp_path / "cl.mkv")
    assert len(a) == len(b) == N and all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(b[-1], decoded(pan_video)[-1])  # filtered
    assert sorted(os.listdir(tmp_path)) == ["cl.mkv", "ref.mkv"]


def test_tss_lookahead_video_segments_equal_one_machine(client, pan_video, tmp_path):
    """Video segments with look-ahead: each decodes 2 frames past its end for the stage, writes none of them."""
    from mlaa_stream.cluster.video import filter_video_on_cluster

    r = CliRunner().invoke(main, [pan_video, "-o", str(tmp_path / "ref.mkv"), "--codec", "ffv1", "--temporal-method",
                                  "tss", "--temporal-frames", str(K), "--lookahead", "2"])
    assert r.exit_code == 0, r.output
    n = filter_video_on_cluster(client, pan_video, str(tmp_path / "cl.mkv"), codec="ffv1", segment_seconds=CHUNK / 24,
                                temporal=TemporalSpec("tss", K, lookahead=2))
    assert n == N
    a, b = decoded(tmp_path / "ref.mkv"), decoded(tmp_path / "cl.mkv")
    assert len(a) == len(b) == N and all(np.array_equal(x, y) for x, y in zip(a, b))


def test_a_warm_up_that_cannot_reach_back_far_enough_says_so():
    """WarmedStage without a device: held frames are not counted; short of `need` changes it asks for more
    frames, or (at the limit) records how many were missing; from the stream's start nothing is missing."""
    from mlaa_stream.cluster.temporal import ShortWarmup, WarmedStage

    class Echo:
        def __call__(self, frame_in, frame_out, index):
            return frame_out

        def close(self):
            pass

    rng = np.random.default_rng(18)
    a, b = (rng.integers(1, 255, (6, 8, 3), dtype=np.uint8) for _ in range(2))
    frames = [a, a, a, b]  # 3 warm-up frames, two of them held, then the chunk's first: one change of 3
    for can_extend, from_start, expect in [(True, False, ShortWarmup), (False, False, 2), (False, True, 0)]:
        st = WarmedStage(Echo(), 3, can_extend=can_extend, from_start=from_start)
        try:
            for i, f in enumerate(frames):
                assert st(f, f, i, i < 3) is f
        except ShortWarmup as exc:
            assert expect is ShortWarmup and exc.missing == 2
            continue
        assert st.short == expect and st.changes == 1


def test_tss_chunks_of_linear_exr_frames_equal_one_machine(client, pan, tmp_path):
    """Half-float EXRs in linear light with highlights over 1: the workers' stages take them as linear light
    (set_linear_input per frame, as on one machine): bit for bit, and the stage changed most frames."""
    from mlaa_stream.cluster.frames import filter_on_cluster

    (tmp_path / "in").mkdir()
    for k, img in enumerate(pan):
        write_image(str(tmp_path / "in" / f"p.{101 + k:04d}.exr"),
                    (3.0 * (np.asarray(img, np.float32) / 255.0) ** 2.2).astype(np.float16))
    src = str(tmp_path / "in" / "p.%04d.exr")
    refs = {}
    for name, args in (("ref", ["--temporal", "--temporal-frames", str(K), "--lookahead", "0"]), ("sp", [])):
        r = CliRunner().invoke(main, [src, "-o", str(tmp_path / name / "c.%04d.exr"), *args])
        assert r.exit_code == 0, r.output
        refs[name] = frames_of(tmp_path / name)
    report = filter_on_cluster(client, src, str(tmp_path / "c" / "c.%04d.exr"), chunk_frames=CHUNK,
                               temporal=TemporalSpec("tss", K))
    assert len(report.written) == N and not report.failed
    got = frames_of(tmp_path / "c")
    assert len(got) == N and all(np.array_equal(a, b) for a, b in zip(got, refs["ref"]))
    assert all(np.isfinite(a).all() for a in got) and max(float(a.max()) for a in got) > 1.5
    assert sum(not np.array_equal(a, b) for a, b in zip(refs["ref"], refs["sp"])) > N // 2
