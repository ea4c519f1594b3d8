"""mlaa_stream.Antialiaser: the capture-loop API on BGR frames, driven by a real cv2.VideoCapture."""
from __future__ import annotations

import os
import re
import threading

import cv2
import numpy as np
import pytest

import mlaa_stream
from mlaa_stream import Antialiaser
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.pipeline import PipelineError

CLIP = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")


def captured_frames() -> list[np.ndarray]:
    cap = cv2.VideoCapture(CLIP)
    frames = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame)
    cap.release()
    return frames


def pipeline_threads():
    return [t for t in threading.enumerate() if t.name.startswith("mlaa-stream-")]


def test_exported_from_the_package():
    assert mlaa_stream.Antialiaser is Antialiaser


def test_call_matches_the_filter_with_bgr_order():
    frames = captured_frames()
    assert len(frames) == 10 and frames[0].shape == (48, 64, 3) and frames[0].dtype == np.uint8
    with Antialiaser() as aa, Filter(bgr=True) as f:
        for frame in frames[:3]:
            out = aa(frame)
            assert out.shape == frame.shape and out.dtype == np.uint8
            np.testing.assert_array_equal(out, f.process(frame))
        assert aa.index == 3
    # BGR matters for the Lab metric: filtering the RGB view gives the same result, reordered
    with Filter(bgr=False) as f_rgb:
        np.testing.assert_array_equal(f_rgb.process(frames[0][:, :, ::-1].copy())[:, :, ::-1],
                                      Filter(bgr=True).process(frames[0]))


def test_stream_over_a_real_video_capture_matches_frame_by_frame():
    frames = captured_frames()
    with Antialiaser() as aa:
        expected = [aa(f) for f in frames]
    cap = cv2.VideoCapture(CLIP)
    assert cap.isOpened()
    try:
        with Antialiaser() as aa:
            got = list(aa.stream(cap))
            assert aa.index == 10
    finally:
        cap.release()
    assert len(got) == 10
    for e, g in zip(expected, got):
        np.testing.assert_array_equal(g, e)
    assert sum(not np.array_equal(e, f) for e, f in zip(expected, frames)) >= 8
    assert pipeline_threads() == []


def test_stream_accepts_any_iterable_and_keeps_the_frame_index_across_calls():
    frames = captured_frames()[:6]
    seen = []
    with Antialiaser(post_hooks=[lambda fr, i: (seen.append(i), fr)[1]]) as aa:
        aa(frames[0])
        list(aa.stream(iter(frames[1:4])))
        aa(frames[4])
        list(aa.stream(frames[5:]))
    assert seen == [0, 1, 2, 3, 4, 5]


def test_temporal_stage_sees_input_and_filtered_frames():
    frames = captured_frames()[:4]
    calls = []

    def temporal(frame_in, filtered, index):
        calls.append(index)
        assert frame_in.shape == filtered.shape
        return filtered

    with Antialiaser(temporal=temporal) as aa:
        list(aa.stream(frames))
    assert calls == [0, 1, 2, 3]


def test_breaking_out_of_a_stream_stops_its_reader():
    cap = cv2.VideoCapture(CLIP)
    try:
        with Antialiaser() as aa:
            for i, _ in enumerate(aa.stream(cap)):
                if i == 2:
                    break
    finally:
        cap.release()
    for t in pipeline_threads():
        t.join(timeout=2)
    assert pipeline_threads() == []


def test_a_bad_frame_names_its_index():
    frames = captured_frames()[:3] + [np.zeros((4, 4, 2), np.uint8)]
    with Antialiaser() as aa:
        with pytest.raises(PipelineError, match="filter failed at frame 3"):
            list(aa.stream(frames))
    assert pipeline_threads() == []


@pytest.mark.parametrize("dtype", [np.int64, np.bool_])
def test_a_frame_of_another_sample_type_is_refused_naming_every_type_taken(dtype):
    """numpy arithmetic on uint8 frames makes int64: the message listed float16 and float32 but not float64,
    which is taken too, and said nothing of how to convert."""
    with Antialiaser() as aa:
        with pytest.raises(ValueError, match=r"expected uint8, uint16, float16, float32 or float64 samples, got "
                                             rf"{np.dtype(dtype).name} \(e\.g\. frame\.clip\(0, 255\)"):
            aa(np.zeros((6, 8, 3), dtype))


def test_a_failing_post_hook_is_named_by_the_index_it_was_given():
    # after two calls the stream's frames are 2, 3, ...: the error names the number the hook got, as index does
    frames = captured_frames()[:5]

    def hook(frame, i):
        if i == 3:
            raise ValueError("bad overlay")
        return frame
    with Antialiaser(post_hooks=[hook]) as aa:
        aa(frames[0])
        aa(frames[1])
        with pytest.raises(PipelineError, match="post failed at frame 3: bad overlay") as info:
            list(aa.stream(frames[2:]))
        # the hook was given 3: the failed frame keeps it, as in aa(frame) (the next frame would repeat it)
        assert info.value.index == 3 and aa.index == 4
        aa(frames[0])
        assert aa.index == 5
    assert pipeline_threads() == []


def test_a_capture_that_did_not_open_is_an_error_not_an_empty_stream():
    cap = cv2.VideoCapture(os.path.join(os.path.dirname(CLIP), "no_such_clip.mp4"))
    assert not cap.isOpened()
    with Antialiaser() as aa:
        with pytest.raises(ValueError, match="capture is not open"):
            list(aa.stream(cap))
        assert aa.index == 0
    assert pipeline_threads() == []

def test_closed_antialiaser_refuses_work_and_presets_are_checked():
    aa = Antialiaser(preset=sorted(mlaa_stream.PRESETS)[0])
    aa.close()
    with pytest.raises(RuntimeError, match="closed"):
        aa(captured_frames()[0])
    with pytest.raises(ValueError, match="expected a preset among"):
        Antialiaser(preset="nonesuch")
    # closed in the middle of a stream: the next frame is refused (it went on, refilling freed device buffers)
    aa = Antialiaser(temporal="tss")
    frames = aa.stream(captured_frames()[:5])
    next(frames)
    aa.close()
    with pytest.raises(RuntimeError, match="closed"):
        next(frames)
    assert aa.index == 1 and pipeline_threads() == []



def test_temporal_frames_where_no_ring_takes_them_is_refused():
    # it was dropped silently without TSS, and 0 became the default ring of 16
    for kwargs in ({}, {"temporal": "blend"}, {"temporal": lambda a, b, i: b}):
        with pytest.raises(ValueError, match="temporal_frames"):
            Antialiaser(temporal_frames=4, **kwargs)
    with pytest.raises(ValueError, match="temporal_frames: expected an integer from 2 to 64, got 0"):
        Antialiaser(temporal="tss", temporal_frames=0)
    with Antialiaser(temporal="tss", temporal_frames=3) as aa:
        assert aa.temporal.frames == 3


@pytest.mark.parametrize("method", [True, "tss", "tss+blend"])
def test_a_ring_of_one_frame_or_past_the_command_lines_range_is_refused_when_made(method):
    """A ring of one frame holds no history (the current frame only: TSS then returns the spatial output every frame)
    and was taken; the command line's --temporal-frames takes 2 to 64, and so does the API now, at construction."""
    for frames in (1, -3, 65, 2.5, "4", True):
        with pytest.raises(ValueError, match=re.escape(f"temporal_frames: expected an integer from 2 to 64, "
                                                       f"got {frames!r}")):
            Antialiaser(temporal=method, temporal_frames=frames)
    for k in (2, np.int64(64)):
        with Antialiaser(temporal=method, temporal_frames=k) as aa:
            assert (aa.temporal.tss if method != "tss" else aa.temporal).frames == k


def test_temporal_true_keeps_history_between_calls():
    """Antialiaser(temporal=True): the second frame of a static shot uses the history (model 'static')."""
    import numpy as np
    from mlaa_stream import Antialiaser
    rng = np.random.default_rng(3)
    frame = np.full((48, 64, 3), 30, np.uint8)
    frame[10:30, 5:50] = rng.integers(0, 256, 3)
    frame[np.arange(48), (np.arange(48) * 1.3).astype(int)] = 240
    with Antialiaser(temporal=True) as aa:
        aa(frame)
        aa(frame)
        models = [row["model"] for row in aa.temporal.stats]
    assert models[0] == "reset" and models[1] != "reset"


def test_temporal_supersampling_on_a_pan_and_blend_mode():
    """Antialiaser(temporal=True) is temporal supersampling (a ring of `temporal_frames` inputs);
    temporal="blend" the older reprojection blending."""
    import numpy as np
    from mlaa_stream import Antialiaser
    from mlaa_stream.bench.temporal import scene_pan
    frames = [np.ascontiguousarray(f[..., ::-1]) for f in scene_pan(5, 320, 180).inputs]
    with Antialiaser(temporal=True, temporal_frames=3) as aa:
        outs = [aa(f) for f in frames]
        assert max(r["ring"] for r in aa.temporal.stats) == 3
        assert all(o.shape == frames[0].shape for o in outs)
    with Antialiaser(temporal="blend") as aa:
        aa(frames[0])
        assert "history_weight_mean" in aa.temporal.stats[0]
    with pytest.raises(ValueError, match="temporal: expected"):
        Antialiaser(temporal="nonesuch")


def test_stream_with_lookahead_reads_the_frames_ahead():
    """Antialiaser(temporal="tss", lookahead=2).stream gives what the filter and a TSSStage reading two frames
    ahead give, bit for bit; aa(frame) reads the past only."""
    from mlaa_stream.bench.temporal import scene_pan
    from mlaa_stream.temporal.tss import TSSStage
    frames = [np.ascontiguousarray(f[..., ::-1]) for f in scene_pan(5, 240, 136).inputs]   # BGR
    with Antialiaser(temporal="tss", lookahead=2) as aa:
        outs = list(aa.stream(frames))
        assert [r["lookahead"] for r in aa.temporal.stats] == [2, 2, 2, 1, 0]
        with TSSStage(bgr=True, lookahead=2, context=aa._filter.context) as stage:
            expected = [stage(f, aa._filter.process(f), i, future=frames[i + 1:i + 3]) for i, f in enumerate(frames)]
        aa(frames[0])
        assert aa.temporal.stats[-1]["lookahead"] == 0
    assert all(np.array_equal(a, b) for a, b in zip(outs, expected))
    with pytest.raises(ValueError, match="lookahead"):
        Antialiaser(lookahead=2)
    with pytest.raises(ValueError, match="dense_motion"):
        Antialiaser(dense_motion=True)


def test_dense_motion_tracks_a_dolly(zoom_frames):
    """Antialiaser(temporal="tss", dense_motion=True): TSS's dense_samples; a dolly (one camera motion per frame
    would be a translation) gets tracked tiles after its first frames."""
    frames, _, _ = zoom_frames(1.01, w=320, h=240)
    with Antialiaser(temporal="tss", dense_motion=True) as aa:
        assert aa.temporal.motion.dense_samples
        aa.temporal.motion.mode = "global"   # one camera motion per frame: the translation the tiles replace
        for f in frames:
            aa(np.repeat(f[..., None], 3, -1))
        assert all(r.get("tracked") for r in aa.temporal.stats[2:])


def test_linear_input_frames_match_the_filter_and_stage_made_for_linear_light():
    """Antialiaser(linear_input=True, temporal="tss") on linear-light BGR float frames with highlights over 1 gives
    what Filter(linear_input=True) and TSSStage(linear_input=True) give, bit for bit; the highlights come back."""
    import numpy as np
    from mlaa_stream import Antialiaser
    from mlaa_stream.bench.temporal import scene_pan
    from mlaa_stream.spatial.filter import Filter
    from mlaa_stream.temporal.tss import TSSStage
    frames = [np.ascontiguousarray(3.0 * (f[..., ::-1].astype(np.float32) / 255.0) ** 2.2)
              for f in scene_pan(5, 160, 90).inputs]
    with Antialiaser(linear_input=True, temporal="tss") as aa:
        outs = [aa(f) for f in frames]
    stage = TSSStage(bgr=True, linear_input=True)
    with Filter(None, bgr=True, linear_input=True) as filt:
        want = [stage(f, filt.process(f), i) for i, f in enumerate(frames)]
    assert all(np.array_equal(a, b) for a, b in zip(outs, want))
    assert max(float(o.max()) for o in outs) > 2.0 and all(np.isfinite(o).all() for o in outs)
    assert any(not np.array_equal(o, f) for o, f in zip(outs[2:], frames[2:]))


@pytest.mark.parametrize("kwargs", [dict(temporal=True), dict(temporal="tss+blend"), dict(temporal="blend"),
                                    dict(temporal="tss", dense_motion=True)])
def test_temporal_methods_take_thin_and_tiny_frames(kwargs):
    """OpenCV's DIS flow raises under 8 px across (or 12 both ways) and the dense tiles indexed a centre past a
    frame under half a tile: a 3x4097 EXR strip or a 10x10 thumbnail stopped the run with cv2.error or
    IndexError. They take the global translation (and one tile) instead."""
    for h, w in [(3, 64), (10, 10), (16, 5)]:
        y, x = np.mgrid[0:h, 0:w]
        with Antialiaser(**kwargs) as aa:
            for k in range(5):  # a pan, so the flow and the tiles run
                frame = np.repeat(((x + k + 2 * y) % 9 < 4)[..., None], 3, 2).astype(np.uint8) * 255
                out = aa(frame)
                assert out.shape == frame.shape and out.dtype == np.uint8


def run_in_threads(work, threads: int = 4) -> None:
    """work(k) in `threads` threads at once, switching between any two bytecodes (the races show within a few
    frames)."""
    import sys
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        running = [threading.Thread(target=work, args=(k,)) for k in range(threads)]
        for t in running:
            t.start()
        for t in running:
            t.join()
    finally:
        sys.setswitchinterval(interval)


@pytest.mark.parametrize("preset", ["default", "fast"])
def test_antialiasers_in_threads_each_get_their_own_frames(preset):
    """Filters share the context's kernel objects, and a launch sets the arguments before it enqueues: four
    Antialiasers, one per thread, filtered frames with another thread's buffers (1 in 10 wrong, 4 in 10 with fast).
    The frames are unrelated: each is judged alone (hold_render=False), so the order each thread takes them in does
    not matter."""
    rng = np.random.default_rng(7)
    frames = [(rng.random((24, 32, 3)) < 0.3).astype(np.uint8) * 255 for _ in range(4)]
    with Antialiaser(preset=preset, hold_render=False) as aa:
        expected = [aa(f) for f in frames]
    wrong, errors = [], []

    def work(k: int) -> None:
        try:
            with Antialiaser(preset=preset, hold_render=False) as own:
                for j in range(60):
                    i = (k + j) % 4
                    if not np.array_equal(own(frames[i]), expected[i]):
                        wrong.append((k, j))
        except Exception as exc:   # noqa: BLE001 - reported below
            errors.append(exc)

    run_in_threads(work)
    assert errors == [] and wrong == []


def test_streams_in_threads_sharing_a_spatial_antialiaser_get_their_own_indices():
    """Each stream counted from the index when it began: two streams at once on one spatial Antialiaser gave
    their post hooks the same indices (and `index` went back and forth). Every frame now takes the next index when
    it reaches the hooks: unique across the streams (and calls), increasing within each stream."""
    rng = np.random.default_rng(11)
    frames = [(rng.random((24, 32, 3)) < 0.3).astype(np.uint8) * 255 for _ in range(8)]
    hooked: dict[int, list[int]] = {}
    errors = []

    def hook(frame, index):
        hooked.setdefault(threading.get_ident(), []).append(index)
        return frame

    with Antialiaser(post_hooks=[hook]) as aa:
        def work(k: int) -> None:
            try:
                assert len(list(aa.stream(frames))) == 8
            except Exception as exc:   # noqa: BLE001 - reported below
                errors.append(exc)

        run_in_threads(work)
        assert errors == []
        assert sorted(i for seen in hooked.values() for i in seen) == list(range(32)) and aa.index == 32
        assert all(seen == sorted(seen) for seen in hooked.values())
        aa(frames[0])
        assert max(max(seen) for seen in hooked.values()) == 32
    assert pipeline_threads() == []


@pytest.mark.parametrize("temporal", ["tss", "recording", None])
def test_one_temporal_antialiaser_shared_by_threads_gives_every_frame_its_own_index(temporal):
    """aa(frame) read `index` before the stage and counted it after: threads sharing one temporal Antialiaser handed
    the stage (and the hooks) one index twice, so TSS restarted its ring and its stats repeated rows. A call is now
    one step of the sequence: every frame gets the next index, and the stage sees them in order. Without a stage
    the calls still overlap, and the hooks get every index once."""
    import time
    frame = (np.random.default_rng(5).random((24, 32, 3)) < 0.3).astype(np.uint8) * 255   # a still shot
    seen, hooked, errors = [], [], []

    def recording(frame_in, frame_filtered, index):
        seen.append(index)
        time.sleep(0.001)   # the stage's own work: another thread's call comes in meanwhile
        return frame_filtered

    def hook(frame, index):
        hooked.append(index)
        return frame

    aa = Antialiaser(temporal=recording if temporal == "recording" else temporal, post_hooks=[hook])
    want = aa(frame)
    aa.index, hooked[:], seen[:] = 0, [], []
    if temporal == "tss":
        aa.temporal.reset()
        aa.temporal.stats.clear()

    def work(k: int) -> None:
        try:
            for _ in range(8):
                aa(frame)
        except Exception as exc:   # noqa: BLE001 - reported below
            errors.append(exc)

    run_in_threads(work)
    with aa:
        assert errors == []
        assert aa.index == 32 and sorted(hooked) == list(range(32))
        if temporal == "recording":
            assert seen == list(range(32))
        elif temporal == "tss":
            assert [row["index"] for row in aa.temporal.stats] == list(range(32))
            assert sum(row["model"] == "reset" for row in aa.temporal.stats) == 1   # one ring, never restarted
        else:
            assert np.array_equal(aa(frame), want)


def test_a_temporal_stage_takes_no_call_from_another_thread_while_a_stream_feeds_it():
    """A call, or a second stream, from another thread while a stream feeds the temporal stage would mix two
    sequences in its history (and give frames the stream's indices): refused, naming what to do. The thread that
    drives the stream may still call (between its frames, after leaving its loop): its own sequence, as before.
    Once the stream ends or is closed, other threads' calls go on from its last index. Without a temporal stage
    calls from other threads are taken."""
    frames = captured_frames()[:4]

    def in_thread(fn):
        box = []
        t = threading.Thread(target=lambda: box.append(_outcome(fn)))
        t.start()
        t.join()
        return box[0]

    with Antialiaser(temporal="tss") as aa:
        running = aa.stream(frames)
        next(running)
        refused = "a stream of this Antialiaser is running in another thread"
        assert refused in in_thread(lambda: aa(frames[0]))
        assert refused in in_thread(lambda: next(aa.stream(frames)))
        assert len(list(running)) == 3 and aa.index == 4
        assert in_thread(lambda: aa(frames[0])) == "ok" and aa.index == 5
        running = aa.stream(frames)
        next(running)
        aa(frames[1])   # this thread's own frames: taken, as before
        running.close()
        assert in_thread(lambda: aa(frames[2])) == "ok" and aa.index == 8
        assert [r["index"] for r in aa.temporal.stats][-3:] == [5, 6, 7]
    with Antialiaser() as aa:
        running = aa.stream(frames)
        next(running)
        assert in_thread(lambda: aa(frames[0])) == "ok"
        running.close()


def _outcome(fn) -> str:
    try:
        fn()
        return "ok"
    except Exception as exc:   # noqa: BLE001 - compared by the caller
        return f"{type(exc).__name__}: {exc}"


@pytest.mark.parametrize("method", [True, "tss", "blend"])
def test_the_temporal_stages_stats_keep_the_last_frames_only(monkeypatch, method):
    """A stage appends a row of stats per frame: a live capture loop with temporal=True grew by about 2.5 KB a
    frame for as long as it ran. The Antialiaser keeps the last STATS_KEPT rows, in __call__ and in stream."""
    import mlaa_stream.antialiaser as api
    monkeypatch.setattr(api, "STATS_KEPT", 3, raising=False)   # (the name is new with the fix)
    frames = captured_frames()[:6]
    with Antialiaser(temporal=method) as aa:
        for f in frames:
            aa(f)
        assert [r["index"] for r in aa.temporal.stats] == [3, 4, 5]
        list(aa.stream(frames))
        assert [r["index"] for r in aa.temporal.stats] == [9, 10, 11]


def test_stream_of_one_frame_is_refused_and_a_stack_of_frames_is_taken():
    """aa.stream(frame) iterated the frame's rows: 48 'frames' of one row's pixels each came out, no error."""
    frames = captured_frames()[:3]
    with Antialiaser() as aa:
        expected = [aa(f) for f in frames]
        for one in (frames[0], frames[0][..., 0], frames[0][..., :1], frames[0][0]):
            words = rf"stream: expected frames .* got one {re.escape(str(one.shape))} array"
            with pytest.raises(ValueError, match=words):
                list(aa.stream(one))
        assert aa.index == 3
        got = list(aa.stream(np.stack(frames)))   # (N, H, W, 3): its frames
        assert all(np.array_equal(g, e) for g, e in zip(got, expected)) and len(got) == 3
        grey = np.stack([f[..., 1] for f in frames])   # (N, H, W) grey frames
        assert [g.shape for g in aa.stream(grey)] == [(48, 64)] * 3
    assert pipeline_threads() == []


def test_with_lookahead_the_blend_reads_each_frames_own_render_regions(monkeypatch):
    """temporal=True (the blend on render regions) with lookahead=2: the stage read the filter's last_regions,
    and the pipeline had collected the next frame by then: each frame's blend took the next frame's regions (a
    render after flat art: none; flat art after a render: all). Each frame's own regions now, as in aa(frame)."""
    from test_fallback import shaded_polygons
    from mlaa_stream.temporal import stage as blend_stage
    render = np.ascontiguousarray(shaded_polygons(1, 96, 128)[..., ::-1])
    flat = np.full_like(render, 90)
    flat[20:60, 30:90] = (200, 40, 40)
    frames = [render, flat, render, render, flat, flat, render]
    seen = []
    call = blend_stage.TemporalStage.__call__

    def spy(self, frame_in, frame_filtered, index, regions=None, measured=None):
        flags = regions if regions is not None else self.regions_from.last_regions
        seen.append(None if flags is None else bool(flags.any()))
        return call(self, frame_in, frame_filtered, index, regions=regions, measured=measured)

    monkeypatch.setattr(blend_stage.TemporalStage, "__call__", spy)
    with Antialiaser(temporal=True, lookahead=2) as aa:
        list(aa.stream(frames))
    assert seen == [f is render for f in frames]


def test_pickling_names_the_object_and_what_to_do():
    """pickle (multiprocessing's arguments) failed with "cannot pickle 'Device' object", pyopencl's, naming neither
    the object nor a way out."""
    import copy
    import pickle
    from mlaa_stream.spatial.fast_filter import FastFilter
    for obj in (Antialiaser(), Antialiaser(temporal="tss"), Filter(), FastFilter()):
        with obj:
            name = type(obj).__name__
            with pytest.raises(TypeError, match=rf"an? {name} holds OpenCL device state and cannot be pickled"):
                pickle.dumps(obj)
            with pytest.raises(TypeError, match="cannot be pickled or copied"):
                copy.copy(obj)


def test_a_stage_or_hook_that_cannot_be_called_is_refused_when_made():
    """temporal=1 and post_hooks=[1] were taken and failed at the first frame ("'int' object is not callable"),
    in_flight=0 at the first stream; one hook not in a list failed as "'function' object is not iterable"."""
    for kwargs, error, words in [(dict(temporal=1), ValueError, "temporal: expected True"),
                                 (dict(post_hooks=[1]), TypeError, "post_hooks: expected a list of"),
                                 (dict(post_hooks=lambda f, i: f), TypeError, "post_hooks: expected a list of"),
                                 (dict(in_flight=0), ValueError, "in_flight: expected 1 or more")]:
        with pytest.raises(error, match=words):
            Antialiaser(**kwargs)
    for temporal in (None, False, lambda a, b, i: b):
        with Antialiaser(temporal=temporal, post_hooks=(lambda f, i: f,), in_flight=1) as aa:
            assert aa(captured_frames()[0]).shape == (48, 64, 3)


def test_no_hooks_as_none_and_whole_frames_for_in_flight_and_lookahead():
    """post_hooks=None (the usual "none" of an optional argument) failed as "'NoneType' object is not iterable";
    in_flight=2.5 and lookahead=1.5 or "2" were taken (the look-ahead cut to 1 without a word): refused, named."""
    with Antialiaser(post_hooks=None) as aa:
        assert aa.post_hooks == [] and aa(captured_frames()[0]).shape == (48, 64, 3)
    for value in (2.5, "2", True, 0):
        with pytest.raises(ValueError, match=re.escape(f"in_flight: expected 1 or more frames on the device at once "
                                                       f"(an integer), got {value!r}")):
            Antialiaser(in_flight=value)
    for value in (1.5, "2", True, -1):
        with pytest.raises(ValueError, match=re.escape(f"lookahead: expected 0 or more frames (an integer), "
                                                       f"got {value!r}")):
            Antialiaser(temporal="tss", lookahead=value)
    with Antialiaser(temporal="tss", lookahead=np.int64(1), in_flight=np.int64(3)) as aa:
        assert aa.temporal.lookahead == 1 and aa.in_flight == 3
