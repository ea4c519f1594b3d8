"""The streaming pipeline: order, overlap of frames in flight, hooks, errors with frame indices,
Ctrl-C, and no thread left behind in any of these cases.

Most tests drive the pipeline with `HostFilter`, a small numpy filter with the Filter protocol
(submit -> pending.result()) that logs the order of calls; one test runs the real OpenCL Filter.
"""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from mlaa_stream.pipeline import Item, PipelineError, StageTimes, run_pipeline, stream_items


def frames(n: int, seed: int = 0, shape=(6, 8, 3)) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.integers(1, 255, shape, dtype=np.uint8) for _ in range(n)]


class HostFilter:
    """Inverts frames on the host; logs ('submit', i) and ('result', i) in call order."""

    def __init__(self, fail_submit_at: int | None = None, fail_result_at: int | None = None):
        self.log: list[tuple[str, int]] = []
        self.n = 0
        self.fail_submit_at, self.fail_result_at = fail_submit_at, fail_result_at

    def submit(self, frame):
        i = self.n
        self.n += 1
        if i == self.fail_submit_at:
            raise RuntimeError("device lost")
        self.log.append(("submit", i))
        parent = self

        class Pending:
            def result(self_inner):
                parent.log.append(("result", i))
                if i == parent.fail_result_at:
                    raise RuntimeError("kernel failed")
                return 255 - frame

        return Pending()


def pipeline_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("mlaa-stream-")]


@pytest.fixture(autouse=True)
def no_threads_left():
    assert pipeline_threads() == []
    yield
    deadline = time.time() + 2
    while pipeline_threads() and time.time() < deadline:
        time.sleep(0.01)
    assert pipeline_threads() == [], "a pipeline thread is still running"


def test_frames_come_out_in_order_and_filtered():
    src = frames(25)
    out: list[Item] = []
    n = run_pipeline(src, HostFilter(), out.append, queue_size=2)
    assert n == 25
    assert [it.index for it in out] == list(range(25))
    for a, it in zip(src, out):
        np.testing.assert_array_equal(it.frame, 255 - a)


def test_a_source_that_reuses_one_buffer_gets_each_frame_filtered():
    """A generator that reads every frame into one array (`ok, buf = cap.read(buf)`) overwrote the frames the
    reader had queued: each came out as a later one. The reader copies them."""
    src = frames(6)

    def one_buffer():
        buf = np.empty_like(src[0])
        for f in src:
            buf[...] = f
            yield buf

    out = [item.frame for item in stream_items(one_buffer(), HostFilter(), in_flight=2)]
    assert len(out) == len(src)
    for got, f in zip(out, src):
        np.testing.assert_array_equal(got, 255 - f)



@pytest.mark.parametrize("pool", [2, 3, 12])
def test_a_source_that_cycles_through_a_pool_of_buffers_gets_each_frame_filtered(pool):
    """Double buffering, a camera's ring of buffers: the reader copied only a frame in the memory of the one just
    before it, so with two buffers or more every frame after the first was queued as the source's own array
    and came out as a later one."""
    src = frames(30)

    def buffers():
        ring = [np.empty_like(src[0]) for _ in range(pool)]
        for i, f in enumerate(src):
            ring[i % pool][...] = f
            yield ring[i % pool]

    out = []
    for item in stream_items(buffers(), HostFilter(), in_flight=2):
        time.sleep(0.002)   # a slow loop body: the reader fills its queue ahead
        out.append(item.frame)
    assert len(out) == len(src)
    for got, f in zip(out, src):
        np.testing.assert_array_equal(got, 255 - f)

def test_slow_reader_and_writer_keep_order():
    rng = np.random.default_rng(3)
    delays = rng.uniform(0, 0.004, 40)

    def slow_source():
        for i, f in enumerate(frames(20, seed=4)):
            time.sleep(delays[i])
            yield f

    got = []

    def sink(item):
        time.sleep(delays[20 + item.index])
        got.append(int(item.frame[0, 0, 0]))

    run_pipeline(slow_source(), HostFilter(), sink)
    assert got == [255 - int(f[0, 0, 0]) for f in frames(20, seed=4)]


@pytest.mark.parametrize("in_flight", [1, 2, 3])
def test_in_flight_frames_are_submitted_before_the_oldest_result(in_flight):
    f = HostFilter()
    run_pipeline(frames(8), f, lambda item: None, in_flight=in_flight)
    submits = [i for op, i in f.log if op == "submit"]
    results = [i for op, i in f.log if op == "result"]
    assert submits == results == list(range(8))
    for i in range(8):
        # with k frames in flight, frame i's result is taken after frame i+k-1 was submitted
        last_submitted = f.log.index(("submit", min(i + in_flight - 1, 7)))
        assert last_submitted < f.log.index(("result", i))
        if in_flight == 1:
            assert f.log.index(("result", i)) < f.log.index(("submit", min(i + 1, 7))) or i == 7


def test_meta_travels_with_each_frame_and_hooks_run_in_order():
    src = [Item(fr, meta=f"file{i}") for i, fr in enumerate(frames(5))]
    calls = []

    def temporal(frame_in, filtered, index):
        calls.append(("temporal", index))
        np.testing.assert_array_equal(frame_in, src[index].frame)
        np.testing.assert_array_equal(filtered, 255 - src[index].frame)
        return filtered // 2

    def overlay(frame, index):
        calls.append(("post", index))
        return frame + 1

    out = []
    run_pipeline(src, HostFilter(), out.append, temporal=temporal, post_hooks=[overlay])
    assert [it.meta for it in out] == [f"file{i}" for i in range(5)]
    assert calls == [(s, i) for i in range(5) for s in ("temporal", "post")]
    np.testing.assert_array_equal(out[2].frame, (255 - src[2].frame) // 2 + 1)


def failing_source(n_ok: int):
    for f in frames(n_ok):
        yield f
    raise ValueError("corrupt packet")


def test_read_error_writes_the_frames_before_it_then_names_the_frame():
    out = []
    with pytest.raises(PipelineError) as ei:
        run_pipeline(failing_source(6), HostFilter(), out.append)
    assert ei.value.stage == "read" and ei.value.index == 6
    assert "read failed at frame 6: corrupt packet" in str(ei.value)
    assert [it.index for it in out] == list(range(6))


@pytest.mark.parametrize("where,stage", [("submit", "filter"), ("result", "filter"),
                                         ("temporal", "temporal"), ("post", "post"),
                                         ("write", "write")])
def test_an_error_in_any_stage_stops_all_and_names_the_frame(where, stage):
    bad = 4
    f = HostFilter(fail_submit_at=bad if where == "submit" else None,
                   fail_result_at=bad if where == "result" else None)

    def temporal(a, b, i):
        if where == "temporal" and i == bad:
            raise ArithmeticError("flow diverged")
        return b

    def post(fr, i):
        if where == "post" and i == bad:
            raise KeyError("bad overlay")
        return fr

    written = []

    def sink(item):
        if where == "write" and item.index == bad:
            raise OSError(28, "No space left on device")
        written.append(item.index)

    read = []

    def endless():  # a reader that would never stop by itself
        i = 0
        while True:
            read.append(i)
            yield frames(1, seed=i)[0]
            i += 1

    with pytest.raises(PipelineError) as ei:
        run_pipeline(endless(), f, sink, temporal=temporal, post_hooks=[post])
    assert ei.value.stage == stage and ei.value.index == bad
    assert f"frame {bad}" in str(ei.value)
    assert written == list(range(bad))  # frames before the failure are complete
    assert len(read) < 40  # the reader was stopped, bounded by the queues


class LookaheadStage:
    """A temporal stage reading `lookahead` frames ahead: logs (index, indices of the future frames it got),
    found by their first pixel (each test frame carries its index there)."""

    def __init__(self, lookahead: int, fail_at: int | None = None):
        self.lookahead, self.fail_at, self.calls = lookahead, fail_at, []

    def __call__(self, frame_in, frame_out, index, future=()):
        if index == self.fail_at:
            raise ArithmeticError("flow diverged")
        self.calls.append((index, [int(f[0, 0, 0]) for f in future]))
        return frame_out


def numbered(n: int) -> list[np.ndarray]:
    out = frames(n)
    for i, f in enumerate(out):
        f[0, 0, 0] = i
    return out


@pytest.mark.parametrize("in_flight,lookahead", [(1, 2), (2, 2), (3, 1), (2, 5)])
def test_lookahead_stage_gets_the_raw_frames_after_each_one(in_flight, lookahead):
    """Known answer: frame i's call gets the raw input frames i + 1 .. i + N (fewer at the end), whatever the
    number in flight; every frame comes out once, in order, filtered."""
    src = numbered(7)
    stage = LookaheadStage(lookahead)
    out = []
    run_pipeline(src, HostFilter(), out.append, in_flight=in_flight, temporal=stage)
    assert [it.index for it in out] == list(range(7))
    assert all(np.array_equal(it.frame, 255 - f) for it, f in zip(out, src))
    assert stage.calls == [(i, list(range(i + 1, min(i + 1 + lookahead, 7)))) for i in range(7)]



@pytest.mark.parametrize("in_flight,lookahead", [(1, 0), (2, 2), (3, 1)])
def test_a_passthrough_item_comes_out_in_its_place_as_it_went_in(in_flight, lookahead):
    """An item with nothing to filter (an EXR of depth) is neither submitted to the filter nor given to the
    temporal stage or the hooks, and a look-ahead window ends before it (it is not of the sequence)."""
    src = numbered(7)
    items = [Item(f, meta=i, passthrough=i in (2, 3)) for i, f in enumerate(src)]
    stage, filt, hooked, out = LookaheadStage(lookahead), HostFilter(), [], []
    run_pipeline(items, filt, out.append, in_flight=in_flight, temporal=stage,
                 post_hooks=[lambda f, i: (hooked.append(i), f)[1]])
    assert [it.meta for it in out] == list(range(7)) and filt.n == 5 and hooked == [0, 1, 4, 5, 6]
    assert all(out[i].frame is src[i] for i in (2, 3))
    assert all(np.array_equal(out[i].frame, 255 - src[i]) for i in (0, 1, 4, 5, 6))
    ahead = {0: [1], 1: [], 4: [5, 6], 5: [6], 6: []}
    assert stage.calls == [(i, ahead[i][:lookahead]) for i in (0, 1, 4, 5, 6)]

@pytest.mark.parametrize("where", ["read", "result", "temporal"])
def test_lookahead_errors_write_the_frames_before_and_name_the_frame(where):
    """A read, filter or temporal failure at frame 4 with look-ahead 2: frames 0-3 are written (the stage still
    runs on those the filter finished), the error names frame 4, and no frame after it is handed on as a
    look-ahead frame (after a filter failure frame 4's own raw input may be: it was read)."""
    src = numbered(9)
    stage = LookaheadStage(2, fail_at=4 if where == "temporal" else None)

    def source():
        for i, f in enumerate(src):
            if where == "read" and i == 4:
                raise IOError("corrupt packet")
            yield f

    out = []
    with pytest.raises(PipelineError) as ei:
        run_pipeline(source(), HostFilter(fail_result_at=4 if where == "result" else None), out.append,
                     temporal=stage)
    assert ei.value.index == 4 and ei.value.stage == {"read": "read", "result": "filter"}.get(where, "temporal")
    assert [it.index for it in out] == [0, 1, 2, 3]
    limit = {"read": 4, "result": 5}.get(where, 9)
    assert all(max(fut, default=-1) < limit for _, fut in stage.calls), stage.calls


def test_keyboard_interrupt_stops_every_stage(send_signal):
    written = []

    def sink(item):
        written.append(item.index)
        if item.index == 3:
            send_signal()  # Ctrl-C: KeyboardInterrupt in the main thread
        time.sleep(0.01)

    def endless():
        i = 0
        while True:
            yield frames(1, seed=i)[0]
            i += 1

    with pytest.raises(KeyboardInterrupt):
        run_pipeline(endless(), HostFilter(), sink)
    assert written[:4] == [0, 1, 2, 3]


def test_leaving_stream_items_early_stops_the_reader_and_closes_the_source():
    state = {"closed": False}

    def source():
        try:
            i = 0
            while True:
                yield frames(1, seed=i)[0]
                i += 1
        finally:
            state["closed"] = True

    gen = stream_items(source(), HostFilter())
    for item in gen:
        if item.index == 5:
            break
    gen.close()
    assert state["closed"]


def test_stage_times_count_frames_and_report_every_stage():
    times = StageTimes()
    run_pipeline(frames(7), HostFilter(), lambda item: None, times=times)
    assert times.frames == 7
    report = times.report()
    for name in ("read", "device wait", "temporal", "post hooks", "write", "fps"):
        assert name in report


def test_in_flight_below_one_is_refused():
    with pytest.raises(ValueError, match="expected in_flight >= 1, got 0"):
        list(stream_items(frames(2), HostFilter(), in_flight=0))


def test_real_filter_through_the_pipeline_matches_process():
    from mlaa_stream.spatial.filter import Filter

    rng = np.random.default_rng(11)
    y, x = np.mgrid[0:36, 0:40]
    src = []
    for k in range(6):  # aliased half-planes of slope 1/3 to 1/8: staircases the filter smooths
        colours = rng.integers(0, 255, (2, 3), dtype=np.uint8)
        src.append(np.where((y > x / (3 + k) + 10)[:, :, None], colours[0], colours[1]).astype(np.uint8))
    with Filter() as f:
        expected = [f.process(x) for x in src]
        for in_flight in (1, 2):
            out = []
            run_pipeline(src, f, out.append, in_flight=in_flight)
            for e, it in zip(expected, out):
                np.testing.assert_array_equal(it.frame, e)
    assert all(not np.array_equal(e, x) for e, x in zip(expected, src))


def test_progress_shows_frames_fps_and_time_left_only_on_a_terminal():
    import io

    from mlaa_stream.io.progress import Progress

    p = Progress(100, label="clip.mp4", stream=io.StringIO(), enabled=True, interval=0)
    p.started -= 2.0  # two seconds ago
    line = p.line(50)
    assert line.startswith("clip.mp4  50/100 frames  ")
    fps = float(line.split("frames  ")[1].split(" fps")[0])
    assert 24.0 < fps <= 25.0 and "0:02 left" in line
    p.update(50)
    p.close()
    assert p.stream.getvalue().startswith("\rclip.mp4  50/100") and p.stream.getvalue().endswith("\n")

    class NotATerminal(io.StringIO):
        def isatty(self):
            return False

    quiet = Progress(10, stream=NotATerminal())
    quiet.update(5)
    quiet.close()
    assert quiet.enabled is False and quiet.stream.getvalue() == ""
    assert "7 frames" in Progress(None, enabled=False).line(7)
