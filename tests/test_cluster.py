"""Scale-out on Dask (issue 18): a LocalCluster of two worker processes gives the single-machine outputs
bit for bit, survives a worker killed mid-job, names the chunk and frame that fails, and leaves nothing
half-written."""
from __future__ import annotations

import os
import signal

import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.images import check_complete, write_image

pytest.importorskip("distributed", reason="Dask is in the [cluster] and [test] extras")


def sequence(folder, n: int = 60, size=(40, 64)):
    folder.mkdir(parents=True, exist_ok=True)
    y, x = np.mgrid[0:size[0], 0:size[1]]
    for k in range(n):
        img = np.where(((y * (2 + k % 4)) > x + k % 7)[..., None], [20, 30, 200 - k], [230, 220, 200]).astype(np.uint8)
        write_image(str(folder / f"shot.{1001 + k:04d}.png"), img)


def files(folder) -> dict[str, bytes]:
    return {n: (folder / n).read_bytes() for n in sorted(os.listdir(folder))}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The 60-frame sequence and its single-machine outputs."""
    root = tmp_path_factory.mktemp("seq")
    sequence(root / "in")
    r = CliRunner().invoke(main, [str(root / "in" / "shot.%04d.png"), "-o", str(root / "ref" / "c.%04d.png")])
    assert r.exit_code == 0, r.output
    return root


def test_a_sequence_on_two_workers_equals_one_machine(client, reference, tmp_path):
    from mlaa_stream.cluster.frames import filter_on_cluster

    report = filter_on_cluster(client, str(reference / "in" / "shot.%04d.png"), str(tmp_path / "c.%04d.png"),
                               chunk_frames=7)
    assert len(report.written) == 60 and not report.failed
    assert files(tmp_path) == files(reference / "ref")
    workers = {w["name"] for w in client.scheduler_info()["workers"].values()}
    assert len(workers) == 2


def test_a_worker_killed_mid_job_the_job_finishes_and_nothing_is_partial(client, reference, tmp_path):
    from mlaa_stream.cluster.frames import run_chunks
    from mlaa_stream.io.sequence import expand_pattern, plan_images

    found, _ = expand_pattern(str(reference / "in" / "shot.%04d.png"))
    plan = plan_images([p for _, p in found], str(tmp_path / "c.%04d.png"), [n for n, _ in found])
    pids = list(client.run(os.getpid).values())
    killed = []

    def kill_one(done: int) -> None:
        if not killed:  # after the first chunk: one worker process dies (SIGKILL, as the OOM killer does)
            os.kill(pids[0], signal.SIGKILL)
            killed.append(pids[0])

    report = run_chunks(client, plan, {}, overwrite=False, strict=True, chunk_frames=4, on_frames=kill_one)
    assert killed and not report.failed
    assert len(report.written) + len(report.skipped) == 60
    assert files(tmp_path) == files(reference / "ref")  # every output complete and as on one machine
    assert [n for n in os.listdir(tmp_path) if ".mlaa-tmp" in n] == []
    client.wait_for_workers(2, timeout=60)  # the nanny restarted it


def test_a_bad_frame_names_its_chunk_and_frame(client, tmp_path):
    from mlaa_stream.cluster.frames import ClusterJobError, filter_on_cluster

    sequence(tmp_path / "in", n=12)
    (tmp_path / "in" / "shot.1007.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")
    with pytest.raises(ClusterJobError, match=r"chunk 1 \(frames 1005-1008\): frame 1007 .*shot.1007.png"):
        filter_on_cluster(client, str(tmp_path / "in" / "shot.%04d.png"), str(tmp_path / "out" / "c.%04d.png"),
                          chunk_frames=4)
    assert [n for n in os.listdir(tmp_path / "out") if ".mlaa-tmp" in n] == []
    for name in os.listdir(tmp_path / "out"):
        assert check_complete(str(tmp_path / "out" / name)) is None


def test_the_command_line_on_a_local_cluster(reference, tmp_path):
    r = CliRunner().invoke(main, [str(reference / "in"), "-o", str(tmp_path / "o"), "--cluster", "local:2",
                                  "--chunk-frames", "16"])
    assert r.exit_code == 0, r.output
    ref = files(reference / "ref")
    got = files(tmp_path / "o")
    assert sorted(got) == sorted(n.replace("c.", "shot.") for n in ref)
    assert list(got.values()) == list(ref.values())
    r = CliRunner().invoke(main, [os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4"),
                                  "-o", "-", "-f", "nut", "--cluster", "local:2"])
    assert r.exit_code == 2 and "--cluster needs a video file in and out" in r.output
    r = CliRunner().invoke(main, [str(reference / "in"), "-o", str(tmp_path / "p"), "--cluster", "not an address"])
    assert r.exit_code == 2 and "expected local:N or a scheduler address" in r.output


# -- video ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def clip60(tmp_path_factory):
    from demo_maker import make_demo
    path = str(tmp_path_factory.mktemp("clip") / "c60.mkv")
    make_demo.write_clip(path, frames=60, audio=True)
    return path


def decoded(path) -> tuple[list, list]:
    import av
    with av.open(str(path)) as c:
        streams = [(s.type, s.codec_context.name) for s in c.streams]
        return [f.to_ndarray(format="rgb24") for f in c.decode(video=0)], streams


def test_a_video_in_segments_equals_one_machine(client, clip60, tmp_path):
    from mlaa_stream.cluster.video import filter_video_on_cluster

    r = CliRunner().invoke(main, [clip60, "-o", str(tmp_path / "ref.mkv"), "--codec", "ffv1"])
    assert r.exit_code == 0, r.output
    n = filter_video_on_cluster(client, clip60, str(tmp_path / "cl.mkv"), codec="ffv1", segment_seconds=0.4)
    assert n == 60
    (a, sa), (b, sb) = decoded(tmp_path / "ref.mkv"), decoded(tmp_path / "cl.mkv")
    assert sa == sb == [("video", "ffv1"), ("audio", "aac")]  # audio copied once, from the source
    assert len(a) == len(b) == 60 and all(np.array_equal(x, y) for x, y in zip(a, b))  # lossless: the same frames
    assert sorted(os.listdir(tmp_path)) == ["cl.mkv", "ref.mkv"]  # no segment or temporary file left


def test_a_video_on_the_command_line_cluster(clip60, tmp_path):
    r = CliRunner().invoke(main, [clip60, "-o", str(tmp_path / "o.mp4"), "--cluster", "local:2",
                                  "--chunk-frames", "20"])
    assert r.exit_code == 0, r.output
    frames, streams = decoded(tmp_path / "o.mp4")
    assert len(frames) == 60 and streams == [("video", "h264"), ("audio", "aac")]


def test_a_joined_video_keeps_chapters_and_attachments(client, tmp_path):
    from mlaa_stream.cluster.video import filter_video_on_cluster
    from test_video_streams import FONT, attachments, chapters, make_chaptered

    make_chaptered(str(tmp_path / "c.mkv"))
    warnings = []
    n = filter_video_on_cluster(client, str(tmp_path / "c.mkv"), str(tmp_path / "o.mkv"), codec="ffv1",
                                segment_seconds=0.25, warn=warnings.append)
    assert n == 24 and warnings == []
    assert chapters(tmp_path / "o.mkv") == [(0.0, 0.5, "One"), (0.5, 1.0, "Two")]
    assert attachments(tmp_path / "o.mkv") == [("Font One.ttf", "application/x-truetype-font", FONT)]


def test_keep_rectangles_travel_to_the_workers(client, reference, tmp_path):
    """filter_on_cluster(keep=...): each worker's filter leaves the rectangle as the input has it."""
    from mlaa_stream.cluster.frames import filter_on_cluster
    from mlaa_stream.io.images import read_image

    report = filter_on_cluster(client, str(reference / "in" / "shot.%04d.png"), str(tmp_path / "c.%04d.png"),
                               chunk_frames=20, keep=["0,50%,100%,50%"])
    assert len(report.written) == 60 and not report.failed
    changed = []
    for k in (1001, 1030, 1060):
        src = read_image(str(reference / "in" / f"shot.{k}.png")).pixels
        out = read_image(str(tmp_path / f"c.{k}.png")).pixels
        ref = read_image(str(reference / "ref" / f"c.{k}.png")).pixels
        np.testing.assert_array_equal(out[20:], src[20:])
        np.testing.assert_array_equal(out[:20], ref[:20])
        changed.append(np.any(ref[20:] != src[20:]))
    assert any(changed)  # the filter would change the kept half


def _vfr_clip(path: str, times_ms: list[int]) -> None:
    """An MKV whose frames sit at `times_ms` (a variable frame rate: 25 fps declared), FFV1, 64x40."""
    import av
    from fractions import Fraction

    rng = np.random.default_rng(5)
    with av.open(path, "w") as out:
        vs = out.add_stream("ffv1", rate=25)
        vs.width, vs.height, vs.pix_fmt = 64, 40, "bgr0"
        vs.codec_context.time_base = Fraction(1, 1000)
        for t in times_ms:
            img = np.where(rng.random((40, 64, 1)) > 0.5, [200, 40, 30], [20, 30, 220]).astype(np.uint8)
            f = av.VideoFrame.from_ndarray(img, format="rgb24")
            f.pts, f.time_base = t, Fraction(1, 1000)
            for p in vs.encode(f):
                out.mux(p)
        for p in vs.encode():
            out.mux(p)


def frame_times(path) -> list[float]:
    import av
    with av.open(str(path)) as c:
        return [round(float(f.time), 3) for f in c.decode(video=0)]


def test_a_variable_rate_video_keeps_its_timestamps_in_segments(client, tmp_path):
    """Segments of 3 frames (0.12 s at 25 fps) over frames at irregular times: the frame at 0.11 s belongs to the
    second segment (by half a frame) but lies before its nominal start. Segments used to be written shifted by
    that start: its time came out negative, the muxer moved it to 0 and the segment's later frames with it
    (0.11 -> 0.12, 0.13 -> 0.14 ...). Now every frame keeps the source's time, as one machine keeps it."""
    from mlaa_stream.cluster.video import filter_video_on_cluster

    times = [0, 40, 60, 110, 130, 200, 260, 270]
    _vfr_clip(str(tmp_path / "vfr.mkv"), times)
    n = filter_video_on_cluster(client, str(tmp_path / "vfr.mkv"), str(tmp_path / "cl.mkv"), codec="ffv1",
                                segment_seconds=0.12)
    assert n == len(times)
    assert frame_times(tmp_path / "cl.mkv") == [t / 1000 for t in times]


def test_failing_chunks_are_each_reported_once(client, tmp_path):
    """Two chunks that fail: the first is raised, the second said, each naming its chunk once (the second's
    message used to carry its chunk twice, and the first was said and raised: printed twice)."""
    from mlaa_stream.cluster.frames import ClusterJobError, filter_on_cluster, run_chunks
    from mlaa_stream.io.sequence import expand_pattern, plan_images

    sequence(tmp_path / "in", n=12)
    for k in (1002, 1010):
        (tmp_path / "in" / f"shot.{k}.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")
    found, _ = expand_pattern(str(tmp_path / "in" / "shot.%04d.png"))
    plan = plan_images([p for _, p in found], str(tmp_path / "out" / "c.%04d.png"), [n for n, _ in found])
    (tmp_path / "out").mkdir()
    said: list[str] = []
    with pytest.raises(ClusterJobError) as info:
        run_chunks(client, plan, {}, overwrite=False, strict=True, chunk_frames=4, say=said.append)
    messages = said + [str(info.value)]
    assert len(messages) == 2, messages
    assert sorted(m.split(":")[0] for m in messages) == ["chunk 0 (frames 1001-1004)", "chunk 2 (frames 1009-1012)"]
    assert all(m.count("chunk ") == 1 for m in messages), messages


def test_the_command_line_on_a_cluster_says_what_it_wrote(reference, tmp_path):
    """-v on a cluster: the summary one machine gives, not a table of stage times that the workers spent (zeros,
    "0 frames"); the local cluster's workers keep their logs of failed tasks to themselves (the job reports it)."""
    import logging

    from mlaa_stream.cluster.connect import connect

    r = CliRunner().invoke(main, [str(reference / "in"), "-o", str(tmp_path / "o"), "--cluster", "local:2",
                                  "--chunk-frames", "30", "-v"])
    assert r.exit_code == 0, r.output
    assert "60 written, 0 skipped" in r.output and "(0 frames)" not in r.output and "ms/frame" not in r.output
    def handler_levels() -> list[int]:   # what LocalCluster(silence_logs=...) sets in each worker process
        return [h.level for h in logging.getLogger("distributed").handlers if isinstance(h, logging.StreamHandler)]

    with connect("local:1") as client:
        levels = list(client.run(handler_levels).values())
    assert len(levels) == 1 and levels[0] and set(levels[0]) == {logging.CRITICAL}


def test_a_damaged_first_frame_is_the_jobs_error_not_a_traceback(tmp_path):
    # run_chunks reads a sequence's first frame on the client (the size every chunk must keep): a damaged one raised
    # ImageReadError, which --cluster did not catch (a traceback; one machine says it and exits 1)
    from mlaa_stream.cluster.frames import ClusterJobError, run_chunks
    from mlaa_stream.io.sequence import expand_pattern, plan_images

    sequence(tmp_path / "in", n=3)
    whole = (tmp_path / "in" / "shot.1001.png").read_bytes()
    (tmp_path / "in" / "shot.1001.png").write_bytes(whole[:len(whole) // 3])
    found, _ = expand_pattern(str(tmp_path / "in" / "shot.%04d.png"))
    plan = plan_images([p for _, p in found], str(tmp_path / "out" / "c.%04d.png"), [n for n, _ in found])
    with pytest.raises(ClusterJobError, match=r"frame 1001 \(.*shot.1001.png\): read failed"):
        run_chunks(None, plan, {}, overwrite=False, strict=True)   # refused before any task: no client needed
    r = CliRunner().invoke(main, [str(tmp_path / "in" / "shot.%04d.png"), "-o", str(tmp_path / "o" / "c.%04d.png"),
                                  "--cluster", "local:1"])
    assert r.exit_code == 1 and "shot.1001.png" in r.output, r.output
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)


def test_resume_through_the_api_keeps_the_output_of_an_input_that_no_longer_opens(client, tmp_path):
    # filter_on_cluster(resume=True) held each output to its input's size: `*image_shape(src)` of an input that does
    # not open (None) was a TypeError; the command line keeps such an output as done
    from mlaa_stream.cluster.frames import filter_on_cluster

    sequence(tmp_path / "in", n=3)
    r = CliRunner().invoke(main, [str(tmp_path / "in" / "shot.%04d.png"), "-o", str(tmp_path / "out" / "c.%04d.png")])
    assert r.exit_code == 0, r.output
    (tmp_path / "in" / "shot.1002.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")
    before = files(tmp_path / "out")
    report = filter_on_cluster(client, str(tmp_path / "in" / "shot.%04d.png"), str(tmp_path / "out" / "c.%04d.png"),
                               resume=True)   # every output done: no task
    assert not report.failed and not report.written
    assert files(tmp_path / "out") == before


def test_an_mpeg_ts_in_segments_keeps_every_frame(client, tmp_path):
    """Each segment decodes from a seek to its start: MPEG-TS lands on the packet at that time, keyframe or not, and
    nothing decoded until the next keyframe, so each segment after the first lost its first frames (18 of these 50
    written, without an error). read_video now seeks again from further back."""
    import av

    from mlaa_stream.cluster.video import filter_video_on_cluster

    src = str(tmp_path / "in.ts")
    with av.open(src, "w") as out:
        s = out.add_stream("libx264", rate=25, options={"g": "10", "keyint_min": "10", "sc_threshold": "0"})
        s.width, s.height, s.pix_fmt = 64, 48, "yuv420p"
        for i in range(50):
            img = np.full((48, 64, 3), 30, np.uint8)
            img[:, i % 50:] = 220
            for p in s.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                out.mux(p)
        for p in s.encode():
            out.mux(p)
    n = filter_video_on_cluster(client, src, str(tmp_path / "cl.mkv"), segment_seconds=0.3)
    frames, _ = decoded(tmp_path / "cl.mkv")
    assert n == len(frames) == 50


def test_a_scheduler_never_reached_says_nothing_was_written(tmp_path, monkeypatch):
    # connect() failing (a scheduler down: Dask's "Timed out trying to connect" after 30 s) ended in "the outputs
    # written are complete; --resume goes on from there" -- no output had been written
    import mlaa_stream.cluster.connect as connect_module

    def unreachable(address):
        raise OSError(f"Timed out trying to connect to {address} after 30 s")

    monkeypatch.setattr(connect_module, "connect", unreachable)
    sequence(tmp_path / "in", n=2)
    r = CliRunner().invoke(main, [str(tmp_path / "in" / "shot.%04d.png"), "-o", str(tmp_path / "o" / "c.%04d.png"),
                                  "--cluster", "tcp://192.0.2.1:8786"])
    assert r.exit_code == 1, r.output
    assert "nothing written (the cluster at tcp://192.0.2.1:8786 was not reached)" in r.output, r.output
    assert "--resume goes on" not in r.output
