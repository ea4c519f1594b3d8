"""The jobs of `mlaa-stream INPUT -o OUTPUT` (filter_cmd.py): an image, a folder of images or a frame sequence
(ImageJob), and a video (VideoJob), each from its source through the filter and the pipeline to its sink; Job
holds what they share, SequenceTemporal the temporal stage's warm-up on a sequence. convert_jobs.py changes the kind
of the source or the sink."""
from __future__ import annotations

import os
import sys
import tempfile
from typing import Callable

from mlaa_stream.cli.console import EXIT_BROKEN_PIPE, EXIT_FAILED, EXIT_OK, Console, Failed, Usage, is_broken_pipe
from mlaa_stream.device.transfer import TRANSFER_NAMES
from mlaa_stream.spatial.fast_filter import FastFilter


def deinterlace_note(con: Console, input_path: str):
    """What read_video's on_deinterlace calls, once, when it makes the input progressive: says so, and how not to."""
    from mlaa_stream.io.deinterlace import FORCED

    label = "standard input" if input_path == "-" else input_path

    def note(name: str, why: str) -> None:
        if why == FORCED:
            con.note(f"{label}: deinterlaced with {name} (--deinterlace on; the stream does not say it is interlaced)")
        else:
            con.note(f"{label}: interlaced ({why}): deinterlaced with {name}; --deinterlace off to keep the fields")
    return note


def video_transfer(info, choice: str, opencv: bool = False) -> str | None:
    """The HDR transfer a video's codes are filtered through (device/transfer.py): --transfer's `choice`, or for
    "auto" the stream's colour tags (HDR10's PQ, HLG; OpenCV's decoder does not say what its frames code)."""
    from mlaa_stream.device.transfer import FFMPEG_TRC
    if choice == "auto":
        return None if opencv else FFMPEG_TRC.get(info.colour.get("color_trc"))
    return None if choice == "sdr" else choice


def check_writable(folder: str) -> None:
    """Create and remove a file in `folder`: the only test that holds for root, ACLs, read-only mounts."""
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".mlaa-tmp-probe"):
            pass
    except OSError as exc:
        raise OSError(exc.errno, f"{folder}: cannot write in this folder ({exc.strerror})") from exc


def video_trim(opts: dict, info) -> tuple[float | None, float | None]:
    """--start/--end of a video input in seconds on its timestamps (None: not given); refused when empty or backwards.
    The user's times count from the video's first timestamp (VideoInfo.start_time: an MPEG-TS capture's may be hours),
    as FFmpeg's -ss: taken as timestamps, --start 1:30 kept the whole of a video starting at 10 s and shifted it."""
    from mlaa_stream.io.video import parse_time

    try:
        start = parse_time(opts["start"], info.fps) if opts.get("start") is not None else None
        end = parse_time(opts["end"], info.fps) if opts.get("end") is not None else None
    except ValueError as exc:
        raise Usage(f"--start/--end: {exc}") from exc
    if start is not None and end is not None and end <= start:
        raise Usage(f"--end ({opts['end']}) must come after --start ({opts['start']})")
    if opts["video_backend"] == "opencv" and (start or end is not None):
        raise Usage("--start/--end need the pyav video backend")
    t0 = getattr(info, "start_time", 0.0)
    return (None if start is None else start + t0), (None if end is None else end + t0)


class SequenceTemporal:
    """The temporal stage for folders and sequences: frames in name/number order; the stage is called
    with the frame number (a gap in the numbering is a jump: the history resets) and says when it
    resets for a gap or a change of size. Positions map to files through the runner's plan as read."""

    def __init__(self, stage, runner: "ImageJob", con: Console):
        self.stage, self.runner, self.con = stage, runner, con
        self.lookahead = getattr(stage, "lookahead", 0)   # the pipeline hands in that many frames ahead
        self._prev: tuple | None = None   # (number, shape) of the previous frame

    def __call__(self, frame_in, frame_out, index: int, future=()):
        from mlaa_stream.io.sequence import consecutive_ahead, frame_number
        ff = self.runner.read_order.get(index)
        number = frame_number(self.runner.read_order, index)
        future = consecutive_ahead(self.runner.read_order, index, future)
        shape = (frame_in.shape, frame_in.dtype)
        if self._prev is not None:
            label = ff.label if ff is not None else f"frame {index}"
            if number != self._prev[0] + 1:
                self.con.info(f"{label}: temporal history reset (gap in the numbering after "
                              f"{self._prev[0]})")
            elif shape != self._prev[1]:
                self.con.info(f"{label}: temporal history reset (the frame size or type changed)")
        if self._use_linear(self.runner.read_linear.pop(index, False)) and self._prev is not None:
            self.con.info(f"{ff.label if ff is not None else f'frame {index}'}: temporal history reset (linear "
                          f"light and display-encoded frames take separate histories)")
        self._prev = (number, shape)
        self.runner.read_order.pop(index, None)
        return self.stage(frame_in, frame_out, number, future=future) if self.lookahead else \
            self.stage(frame_in, frame_out, number)

    def _use_linear(self, linear: bool) -> bool:
        """The stage's colour space for the next frame (linear light: EXR, untagged float); True when it changed."""
        use = getattr(self.stage, "set_linear_input", None)
        return bool(use(linear)) if use is not None else False

    def warm(self, frame_in, frame_out, ff, linear: bool = False, future=()) -> None:
        """A frame before the first one to write (--resume): through the stage, output discarded. `future`: the
        raw frames after it (look-ahead), as the pipeline hands them in."""
        self._use_linear(linear)
        number = ff.sequence_number if ff.sequence_number is not None else (self._prev[0] + 1 if self._prev else 0)
        self._prev = (number, (frame_in.shape, frame_in.dtype))
        if self.lookahead:
            self.stage(frame_in, frame_out, number, future=list(future)[:self.lookahead])
        else:
            self.stage(frame_in, frame_out, number)


def frame_hooks(post_hooks: list, index_of: Callable[[int], int],
                kind_of: Callable[[int], tuple[bool, bool]]) -> list:
    """Post hooks on the pipeline's positions: each gets its frame's index (index_of), and a hook that takes them (the
    --overlay hook: `per_frame_format`) whether the frame holds linear light and premultiplied alpha (kind_of: an
    EXR among PNGs). Drawn as sRGB codes into a linear-light frame, an overlay's colours came out washed out
    (#3080ff's red 0.19, not 0.03); over premultiplied colour taken for straight, too light where alpha < 1."""
    def wrap(hook: Callable) -> Callable:
        if getattr(hook, "per_frame_format", False):
            def hooked(f, i):
                linear, premultiplied = kind_of(i)
                return hook(f, index_of(i), linear=linear, premultiplied=premultiplied)
            return hooked
        return lambda f, i: hook(f, index_of(i))
    return [wrap(h) for h in post_hooks]


class Job:
    def __init__(self, input_path: str, output: str, kind: str, con: Console, **opts):
        self.input, self.output, self.kind, self.con, self.opts = input_path, output, kind, con, opts
        self.written = 0
        self.failed_early = False

    def _progress(self, total: int | None):
        from mlaa_stream.io.progress import Progress

        path = self.opts.get("progress_path")
        if path and getattr(self, "_machine", None) is None:
            try:
                self._machine = sys.stdout if path == "-" else open(path, "w", buffering=1)
            except OSError as exc:
                raise Failed(f"{path}: cannot write progress ({exc.strerror})") from exc
        return Progress(total, label=os.path.basename(self.input.rstrip("/")) or self.input,
                        enabled=None if not self.con.quiet else False, machine=getattr(self, "_machine", None))

    def unwritten_indices(self) -> set:
        """The temporal stage's indices of frames it ran on but that are not written (--resume): left out of --stats."""
        return set()

    def close_progress(self) -> None:
        machine = getattr(self, "_machine", None)
        if machine is not None and machine is not sys.stdout:
            machine.close()


class ImageJob(Job):
    """An image, a folder of images or a numbered sequence."""

    def prepare(self) -> None:
        from mlaa_stream.io.images import has_writer, is_image_path, remove_quietly, stale_temp_files
        from mlaa_stream.io.sequence import (Report, expand_pattern, format_spans, is_pattern, list_folder,
                                output_over_input, parse_frames, plan_images, same_file)

        o, con = self.opts, self.con
        self.strict = self.kind == "pattern"
        self.report = Report(say=con.error, inform=con.info, caution=con.warn)
        numbers = None
        if self.kind == "image":
            srcs = [self.input]
        elif self.kind == "folder":
            srcs, others = list_folder(self.input)
            for path in others:
                con.warn(f"{path}: skipped (not an image file by its extension)")
            if same_file(self.input, self.output):
                raise Usage(f"{self.output}: is the input folder; choose another output folder")
            if not srcs:
                raise Failed(f"{self.input}: expected image files, found none")
        else:
            rng = None
            if o["frames"] is not None:
                try:
                    rng = parse_frames(o["frames"])
                except ValueError as exc:
                    raise Usage(str(exc)) from exc
            found, missing = expand_pattern(self.input, rng)
            if not found:
                raise Usage(f"{self.input}: no files match this frame pattern"
                            + (f" for frames {o['frames']}" if rng else ""))
            if missing:
                msg = f"{self.input}: missing frames {format_spans(missing)}"
                if rng is not None:
                    self.report.fail(msg)  # frames asked for by --frames that are not there
                    self.failed_early = True
                else:
                    con.warn(msg + " (gap in the numbering)")
            numbers = [n for n, _ in found]
            srcs = [p for _, p in found]
        if self.kind != "image" and not is_pattern(self.output):
            if os.path.exists(self.output) and not os.path.isdir(self.output):
                raise Usage(f"{self.output}: expected a folder (or a %04d pattern) for "
                            f"{'a folder' if self.kind == 'folder' else 'a sequence'}, got a file")
            if not os.path.exists(self.output) and is_image_path(self.output):
                # out.png would become a folder named out.png: more likely one image was meant, which many are not
                stem, ext = os.path.splitext(self.output)
                many = "a folder" if self.kind == "folder" else "a sequence"
                raise Usage(f"{self.output}: names one image, and {many} has many; give a folder or a frame "
                            f"pattern such as {stem}/%04d{ext} (a folder named so: end it with /)")
            self.output = os.path.join(self.output, "")  # a folder, created below
        self.plan = plan_images(srcs, self.output, numbers)
        # each file's place in the whole plan: the post hooks' frame index (--overlay's frames), whatever
        # --resume skips, look-ahead reads add or an unreadable file of a folder leaves out
        self.positions = {id(ff): i for i, ff in enumerate(self.plan)}
        clash = output_over_input(self.plan)
        if clash is not None:
            raise Usage(clash)
        if is_pattern(self.output) and self.plan and not has_writer(self.plan[0].dst):
            # one extension for every output: said before anything is filtered, not once per frame after its filter
            ext = os.path.splitext(self.output)[1]
            raise Usage(f"{self.output}: OpenImageIO has no writer for {ext or 'a name without an extension'}; "
                        f"name an image format (.exr, .png, .tif, .jpg ...)")
        dst_dirs = sorted({os.path.dirname(os.path.abspath(ff.dst)) for ff in self.plan})
        if self.kind != "image" or is_pattern(self.output):   # a pattern's folder is made, as for a video's frames
            for d in dst_dirs:
                try:
                    os.makedirs(d, exist_ok=True)
                except OSError as exc:
                    raise OSError(exc.errno, f"cannot create the output folder ({exc.strerror})",
                                  d) from exc
        for d in dst_dirs:  # temporary files of a run that was killed (SIGKILL, power cut)
            for path in stale_temp_files(d):
                remove_quietly(path)
                con.info(f"{path}: removed (a temporary file left by an interrupted run)")
        existing = [ff for ff in self.plan if os.path.exists(ff.dst)]
        if existing and o["resume"]:
            existing = self._keep_complete(existing)
            self.report.skipped.extend(ff.dst for ff in existing)
            con.info(f"--resume: {len(existing)} outputs exist and are skipped")
            skipped = set(id(ff) for ff in existing)
            first = next((i for i, ff in enumerate(self.plan) if id(ff) not in skipped), None)
            # the temporal stage's warm-up: the skipped frames just before the first one to write,
            # consecutive in number or, in a folder, in name order (issue 16: --resume warms up from the K frames
            # before it)
            warm: list = []
            if first is not None:
                for ff in reversed(self.plan[:first]):
                    nxt = warm[0] if warm else self.plan[first]
                    if id(ff) not in skipped or ff.sequence_number is None or nxt.sequence_number is None \
                            or ff.sequence_number != nxt.sequence_number - 1:
                        break
                    warm.insert(0, ff)
            self.warm_up = warm
            whole, self.plan = self.plan, [ff for ff in self.plan if id(ff) not in skipped]
            self.whole_plan = whole   # --cluster --temporal: the chunks of the first run (_run_on_cluster)
            self._read_ahead_of(whole, skipped)
        elif existing and not o["overwrite"]:
            more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
            raise Usage(f"{existing[0].dst}: exists{more}; use --overwrite to replace "
                        f"or --resume to skip existing outputs")
        for d in dst_dirs:
            if not os.path.isdir(d):
                raise Failed(f"{d}: the output folder does not exist")
            check_writable(d)

    def _read_ahead_of(self, whole: list, skipped: set) -> None:
        """--resume with --lookahead N: after each file to write, the (skipped) files that follow it, up to N and
        consecutive, are read too but not written (`read_ahead`), so that its output reads the frames ahead an
        uninterrupted run read."""
        n = self.opts.get("lookahead", 0)
        extra: list = []
        for i, ff in enumerate(whole):
            if id(ff) in skipped:
                continue
            for nxt, prev in zip(whole[i + 1:i + 1 + n], whole[i:i + n]):
                if id(nxt) not in skipped or prev.sequence_number is None or nxt.sequence_number is None \
                        or nxt.sequence_number != prev.sequence_number + 1:
                    break
                extra.append(nxt)
        ids = {id(ff) for ff in extra}
        self.read_ahead = ids
        self.read_ahead_numbers = {ff.sequence_number for ff in extra}
        self.read_plan = [ff for ff in whole if id(ff) not in skipped or id(ff) in ids]

    def _warm_ups_after_holes(self, ring: int) -> None:
        """--resume with the temporal stage: before each frame to write that follows outputs skipped (a hole: a
        cluster's chunks done out of order, an earlier --frames range), up to `ring` of the skipped frames just
        before it are read too, not written, as _warm_up_images does before the first one: else the stage reset
        there ("gap in the numbering") and the frames after the hole came out unlike the whole run's."""
        whole, read = getattr(self, "whole_plan", None), getattr(self, "read_ahead", None)
        if not whole or read is None or not self.plan:
            return
        todo = {id(ff) for ff in self.plan}
        first = next(i for i, ff in enumerate(whole) if id(ff) in todo)
        extra = []
        for i in range(first + 1, len(whole)):
            if id(whole[i]) not in todo or id(whole[i - 1]) in todo:
                continue
            j = i - 1
            while j > first and i - j <= ring and id(whole[j]) not in todo and whole[j].sequence_number is not None \
                    and whole[j + 1].sequence_number is not None \
                    and whole[j].sequence_number == whole[j + 1].sequence_number - 1:
                extra.append(whole[j])
                j -= 1
        if not extra:
            return
        self.read_ahead = read | {id(ff) for ff in extra}
        self.read_ahead_numbers = self.read_ahead_numbers | {ff.sequence_number for ff in extra}
        wanted = todo | self.read_ahead
        self.read_plan = [ff for ff in whole if id(ff) in wanted]

    def _warm_up(self, filt, temporal) -> None:
        _warm_up_images(self, filt, temporal)

    def unwritten_indices(self) -> set:
        return getattr(self, "read_ahead_numbers", set())   # warm-up frames' rows are dropped by _warm_up_images

    def _keep_complete(self, existing: list) -> list:
        """--resume: the existing outputs that are complete (header of the input's size, PNG/JPEG end
        marker, EXR/TIFF first and last rows decode); an incomplete one (e.g. from a version that did not check
        writes, a copy cut short) is removed and redone."""
        from mlaa_stream.io.images import check_complete, image_shape

        complete = []
        for ff in existing:
            shape = image_shape(ff.src)
            why = check_complete(ff.dst, *shape, decode=False) if shape else None
            if why is None:
                complete.append(ff)
                continue
            self.con.warn(f"{ff.dst}: incomplete ({why}); it is written again")
            try:
                os.unlink(ff.dst)
            except OSError as exc:
                raise Failed(f"{ff.dst}: incomplete and cannot be removed ({exc.strerror})") from exc
        return complete

    def nothing_to_do(self) -> bool:
        return not self.plan

    def run(self, filt, post_hooks, in_flight, times, temporal=None) -> int:
        from mlaa_stream.spatial.filter import Filter
        from mlaa_stream.pipeline import PipelineError, run_pipeline
        from mlaa_stream.io.sequence import FilterSet, image_sink, image_source, is_linear

        encoded = filt

        def make_variant(options: dict):
            """Linear-light inputs (EXR, untagged float) are not sRGB-decoded before blending; HDR images (PQ / HLG
            PNGs) are decoded by their transfer (device/transfer.py)."""
            kwargs = dict(self.opts["filter_kwargs"], **options)
            what = ("linear-light" if "linear_input" in options else
                    f"HDR ({TRANSFER_NAMES.get(options.get('transfer'), options.get('transfer'))})")
            if "transfer" in options and not kwargs.get("linear", True):   # --display-space: the codes' own mix
                return encoded
            try:
                made = (FastFilter if kwargs.get("fast") else Filter)(context=encoded.context, bgr=False, **kwargs)
            except TypeError as exc:  # a Filter without the option: treat them as encoded
                self.con.warn(f"{what} inputs filtered as display-encoded ({exc})")
                return encoded
            if "transfer" in options:
                self.con.info(f"{what} images: filtered in the linear light their codes stand for")
            return made

        if self.opts.get("cluster"):
            return self._run_on_cluster()
        filt = FilterSet(encoded, make_variant, self.opts.get("transfer", "auto"))
        if temporal is not None:
            self._warm_ups_after_holes(_ring_frames(temporal.stage))
        read_plan = getattr(self, "read_plan", self.plan) if temporal is not None else self.plan
        read_ahead = getattr(self, "read_ahead", set())
        progress = self._progress(len(read_plan))
        say = self.report.say
        self.report.say = lambda msg: (progress.clear(), say(msg))
        caution = self.report.caution
        self.report.caution = lambda msg: (progress.clear(), caution(msg))
        write = image_sink(self.report, overwrite=self.opts["overwrite"], strict=self.strict,
                           jpeg_quality=self.opts.get("jpeg_quality"))

        def sink(item) -> None:
            if id(item.meta[0]) not in read_ahead:   # a look-ahead frame of --resume: read, not written
                write(item)
        self.read_order: dict = {}
        self.read_linear: dict = {}   # position -> the frame is linear light (the temporal stage's colour space)
        positions = getattr(self, "positions", {})
        hook_index: dict = {}   # position read -> the file's place in the whole plan (self.positions)
        hook_kind: dict = {}  # position read -> (linear light, premultiplied alpha) for the --overlay hook

        def source():
            """image_source, remembering which file each position is (for the temporal stage and the hooks)."""
            inner = image_source(read_plan, self.report, strict=self.strict, optional=frozenset(read_ahead))
            try:
                for position, item in enumerate(inner):
                    if not item.passthrough:   # a file copied unchanged: neither the stage's nor the hooks'
                        self.read_order[position] = item.meta[0]
                        self.read_linear[position] = is_linear(item.meta[1])
                        hook_index[position] = positions.get(id(item.meta[0]), position)
                        hook_kind[position] = (self.read_linear[position], item.premultiplied)  # (read_linear: popped)
                    yield item
            finally:
                inner.close()
        post_hooks = frame_hooks(post_hooks, lambda i: hook_index.get(i, i), lambda i: hook_kind.get(i, (False, False)))
        if temporal is not None and getattr(self, "warm_up", None):
            self._warm_up(filt, temporal)
        try:
            run_pipeline(source(), filt, sink, temporal=temporal,
                         in_flight=in_flight, post_hooks=post_hooks, times=times,
                         on_frame=progress.update)
            stopped = None
        except PipelineError as exc:
            stopped = exc
        finally:
            progress.close()
            filt.close()
            self.written = len(self.report.written)
        if stopped is not None:
            ff = stopped.meta[0] if stopped.meta else None
            cause = str(stopped.cause)
            named = ff is not None and (ff.src in cause or ff.dst in cause)
            if ff is None and self.strict and stopped.stage == "read":
                named = True  # a sequence's read errors name their file or frame themselves
            self.con.error(cause if named else f"{ff.label if ff else f'frame {stopped.index}'}: "
                           f"{stopped.stage} failed: {cause}")
            self.con.error(f"stopped: {self.written} of {len(self.plan)} outputs written")
            return EXIT_FAILED
        if self.report.failed:
            self.con.error(f"{len(self.report.failed)} failed, {self.written} written")
            return EXIT_FAILED
        copied = f" ({len(self.report.copied)} copied unchanged: no colour)" if self.report.copied else ""
        self.con.info(f"{self.written} written{copied}, {len(self.report.skipped)} skipped")
        return EXIT_OK

    def _run_on_cluster(self) -> int:
        """The same plan, filtered in chunks by the workers of a Dask cluster (mlaa_stream.cluster)."""
        from mlaa_stream.cluster.connect import ClusterAddressError, connect
        from mlaa_stream.cluster.frames import ClusterJobError, run_chunks

        progress = self._progress(len(self.plan))
        temporal = self.opts.get("temporal_spec")
        files, done = self.plan, frozenset()
        if temporal is not None and getattr(self, "whole_plan", None):
            # --resume: the whole job with the complete outputs marked done, so that each chunk still reads its
            # warm-up (and look-ahead) frames, as one machine warms up from the skipped frames before it
            files, done = self.whole_plan, frozenset(self.report.skipped)
        connected = False
        try:
            with connect(self.opts["cluster"]) as client:
                connected = True
                self.con.info(f"cluster: {len(client.scheduler_info()['workers'])} workers")
                report = run_chunks(client, files, self.opts["filter_kwargs"],
                                    overwrite=self.opts["overwrite"], strict=self.strict,
                                    chunk_frames=self.opts["chunk_frames"], on_frames=progress.update,
                                    temporal=temporal, done=done, jpeg_quality=self.opts.get("jpeg_quality"),
                                    transfer=self.opts.get("transfer", "auto"),
                                    say=lambda msg: (progress.clear(), self.con.error(msg)),
                                    caution=lambda msg: (progress.clear(), self.con.warn(msg)))
        except ClusterAddressError as exc:
            progress.close()
            raise Usage(str(exc)) from exc
        except (ClusterJobError, OSError) as exc:
            progress.close()
            self.con.error(str(exc))
            # a scheduler never reached wrote nothing: "the outputs written are complete" told of outputs there were not
            self.con.error("stopped: the outputs written are complete; --resume goes on from there" if connected else
                           f"stopped: no frame was filtered, nothing written (the cluster at {self.opts['cluster']} "
                           f"was not reached)")
            return EXIT_FAILED
        progress.close()
        self.written = len(report.written) + len(report.skipped)
        if report.failed:
            self.con.error(f"{len(report.failed)} failed, {self.written} written")
            return EXIT_FAILED
        self.con.info(f"{self.written} written, {len(self.report.skipped)} skipped")   # as one machine says it
        return EXIT_OK

    def abort(self) -> None:
        pass


def _ring_frames(stage) -> int:
    """How many frames before the first one to write the temporal stage wants, as a cluster's chunk reads them
    (cluster/temporal.py TemporalSpec.warmup): TSS its ring of K frames, the blend BLEND_WARMUP (its recursive history
    never becomes identical; 3 frames left the first written frame 12 levels off the uninterrupted run's), both the
    longer."""
    from mlaa_stream.cluster.temporal import BLEND_WARMUP
    from mlaa_stream.temporal.tss import TSSStage

    tss = stage if isinstance(stage, TSSStage) else getattr(stage, "tss", None)
    ring = int(tss.frames) if tss is not None else 0
    return ring if isinstance(stage, TSSStage) else max(ring, BLEND_WARMUP)


def _warm_up_images(job: "ImageJob", filt, temporal: "SequenceTemporal") -> None:
    """--resume with the temporal stage: the inputs of the last skipped frames before the first one to
    write go through the spatial filter and the stage (outputs discarded, not in --stats), so the
    first written frame has the history it would have had in an uninterrupted run."""
    from mlaa_stream.io.sequence import Report, image_source, is_linear
    from mlaa_stream.temporal.methods import stats_lists
    warm = job.warm_up[-_ring_frames(temporal.stage):]
    stage = temporal.stage
    keep = [(rows, len(rows)) for rows in stats_lists(stage)]
    done = 0
    items: list = []
    for ff in warm:
        # a warm-up frame's output is done: one that cannot be read now (damaged since, a size of its own) is no
        # failure of this run -- it stopped a sequence in an ImageReadError traceback, and counted as failed in a
        # folder --, said in a warning; the history starts after it, as the stage resets at a gap
        unread = Report()
        got = list(image_source([ff], unread, strict=False))
        if unread.failed:
            why = unread.failed[-1].removeprefix(f"{ff.src}: ")
            job.con.warn(f"{ff.src}: not read for the temporal warm-up, whose history starts after it: {why}")
            items = []
        items += got
    n_warm = len(items)
    if temporal.lookahead and warm:
        # with --lookahead the uninterrupted run handed each warm-up frame the N frames after it, and the stage keeps
        # what it measured of them (their motion decisions, ring slots): without them the first written frames
        # came out different. The frames after the warm-up (the first ones to write ...) are read here too; one
        # that fails ends the look-ahead there, and the run reports it when it reads it
        at = job.positions.get(id(warm[-1]))
        after = job.whole_plan[at + 1:at + 1 + temporal.lookahead] if at is not None else []
        items += list(image_source(after, Report(), strict=False))
    try:
        for k, item in enumerate(items[:n_warm]):
            if item.passthrough:   # no colour: not of the stage's sequence
                continue
            future = []
            for prev, nxt in zip(items[k:], items[k + 1:k + 1 + temporal.lookahead]):
                # as the pipeline's look-ahead: consecutive numbers, up to a file without colour
                if nxt.passthrough or prev.meta[0].sequence_number is None or \
                        nxt.meta[0].sequence_number != prev.meta[0].sequence_number + 1:
                    break
                future.append(nxt.frame)
            f = filt.for_item(item) if hasattr(filt, "for_item") else filt
            temporal.warm(item.frame, f.process(item.frame), item.meta[0], is_linear(item.meta[1]), future)
            done += 1
    finally:
        for rows, n in keep:
            del rows[n:]
    if done:
        job.con.info(f"--resume: temporal history warmed up from {done} frames before "
                     f"{job.plan[0].label if job.plan else 'the end'}")


class VideoJob(Job):
    """A video file in, a video file out."""

    def prepare(self) -> None:
        from mlaa_stream.io.video import (PIPE, CvVideoWriter, VideoError, VideoWriter, container_format_for,
                                          open_pipe, probe_video, probe_video_cv)

        o = self.opts
        out = self.output
        if out != PIPE:
            self._check_output_file(out)
            out = self.output   # a folder: the input's name in it (the writer was given the folder itself)
        elif o.get("progress_path") == PIPE:
            raise Usage("--progress - and -o - both want standard output; give --progress a file")
        if (self.input == PIPE or out == PIPE) and o["video_backend"] == "opencv":
            raise Usage("pipes (-) need the pyav video backend")
        if o.get("deinterlace") == "on" and o["video_backend"] == "opencv":
            raise Usage("--deinterlace on needs the pyav video backend (libavfilter's bwdif)")
        self.pipe_in = None
        try:
            if self.input == PIPE:  # read once: the open container goes on to read_video
                self.info, self.pipe_in = open_pipe()
            else:
                self.info = (probe_video_cv if o["video_backend"] == "opencv" else probe_video)(self.input)
        except VideoError as exc:
            raise Failed(str(exc)) from exc
        self.start, self.end = self._trim()
        self.transfer = video_transfer(self.info, o.get("transfer", "auto"), o["video_backend"] == "opencv")
        self.con.info(f"{self.input}: {self.info.width}x{self.info.height} {self.info.pix_fmt} "
                      f"{self.info.bits}-bit, {self.info.fps} fps, {self.info.frames or '?'} frames, "
                      f"{self.info.audio_streams} audio streams")
        try:
            if o["video_backend"] == "opencv":
                self.writer = CvVideoWriter(out, self.info, overwrite=o["overwrite"])
            else:
                self.writer = VideoWriter(out, self.info, codec=o["codec"], crf=o["crf"],
                                          preset=o["encoder_preset"], pix_fmt=o["pix_fmt"],
                                          overwrite=o["overwrite"], audio=o["audio"],
                                          # from --start, else from the container's first timestamp, as FFmpeg
                                          # writes a file: an MPEG-TS capture's hours of offset made a 1-s MKV
                                          # 'last' 16:41 and an MP4 open on a long empty edit
                                          offset=self.start if self.start is not None else self.info.start_time,
                                          end=self.end,
                                          container_format=container_format_for(o.get("container"), out))
        except VideoError as exc:
            raise Failed(str(exc)) from exc
        self.con.info(f"encoding {getattr(self.writer, 'codec', 'mp4v')} "
                      f"{getattr(self.writer, 'pix_fmt', 'bgr24')} to {out}")

    def stdout_gone(self) -> int:
        """Standard output's reader went away: no error (head, a player closed), said only with -v."""
        self.con.info(f"standard output closed by its reader after {self.writer.frames_written} frames; stopped")
        return EXIT_BROKEN_PIPE

    def _check_output_file(self, out: str) -> None:
        """A video file out: not the input, not there already (without -y), in a writable folder;
        temporary files of killed runs there are removed."""
        from mlaa_stream.io.images import remove_quietly, stale_temp_files
        from mlaa_stream.io.sequence import same_file
        from mlaa_stream.io.video import PIPE, is_special_file

        o = self.opts
        if os.path.isdir(out) or out.endswith(("/", os.sep)):
            out = os.path.join(out, os.path.basename(self.input) if self.input != PIPE else "out.mkv")
        self.output = out
        if self.input != PIPE and same_file(self.input, out):
            raise Usage(f"{out}: output is the input; choose another output")
        if o["resume"]:
            self.con.warn("--resume applies to folders and sequences; a video is redone")
        if is_special_file(out):   # /dev/null, a named pipe: written into, nothing replaced, nothing left beside it
            return
        if os.path.exists(out) and not o["overwrite"]:
            raise Usage(f"{out}: exists; use --overwrite to replace it")
        folder = os.path.dirname(os.path.abspath(out))
        if not os.path.isdir(folder):
            raise Failed(f"{folder}: the output folder does not exist")
        check_writable(folder)
        for path in stale_temp_files(folder):  # left by a run that was killed
            remove_quietly(path)
            self.con.info(f"{path}: removed (a temporary file left by an interrupted run)")

    def _trim(self) -> tuple[float | None, float | None]:
        return video_trim(self.opts, self.info)

    def nothing_to_do(self) -> bool:
        return False

    def abort(self) -> None:
        writer = getattr(self, "writer", None)
        if writer is not None and not getattr(self, "_finished", False):
            writer.abort()

    def _run_on_cluster(self) -> int:
        """Segments of the video filtered and encoded by the workers, joined here (mlaa_stream.cluster.video)."""
        from mlaa_stream.cluster.connect import connect
        from mlaa_stream.cluster.video import ClusterVideoError, filter_video_on_cluster

        self.writer.abort()  # the workers encode; the join writes the output
        self._finished = True
        o = self.opts
        progress = self._progress(self.info.frames)
        from mlaa_stream.io.deinterlace import filter_name, reason
        why = reason(o.get("deinterlace", "off"), self.info.interlaced, False)   # the first frame's flag: probe_video
        if why is not None:   # each worker decides as read_video does; said here, once
            deinterlace_note(self.con, self.input)(filter_name(), why)
        try:
            with connect(o["cluster"]) as client:
                self.written = filter_video_on_cluster(
                    client, self.input, self.output, codec=o["codec"], crf=o["crf"],
                    encoder_preset=o["encoder_preset"], pix_fmt=o["pix_fmt"], overwrite=o["overwrite"],
                    audio=o["audio"] != "none", on_frames=progress.update,
                    segment_seconds=o["chunk_frames"] / float(self.info.fps or 25),
                    temporal=o.get("temporal_spec"), warn=self.con.warn, deinterlace=o.get("deinterlace", "off"),
                    **o["filter_kwargs"])
        except (ClusterVideoError, OSError) as exc:
            self.con.error(str(exc))
            self.con.error(f"{self.output}: not written")
            return EXIT_FAILED
        finally:
            progress.close()
        self.con.info(f"{self.output}: {self.written} frames")   # as one machine says it
        return EXIT_OK

    def run(self, filt, post_hooks, in_flight, times, temporal=None) -> int:
        from mlaa_stream.pipeline import PipelineError
        from mlaa_stream.io.video import VideoError, VideoReadError, read_video_cv

        if self.opts.get("cluster"):
            return self._run_on_cluster()
        from mlaa_stream.pipeline import filter_video

        from mlaa_stream.io.video import read_video

        if self.opts["video_backend"] == "opencv":
            source = read_video_cv(self.info)
        else:
            source = read_video(self.info, start=self.start, end=self.end, container=self.pipe_in,
                                require_frames=True, deinterlace=self.opts.get("deinterlace", "off"),
                                on_deinterlace=deinterlace_note(self.con, self.input))
        total = self.info.frames
        if total and self.info.fps and (self.start or self.end is not None):
            t0 = self.info.start_time   # the trim's times are timestamps (video_trim)
            duration = (self.end if self.end is not None else t0 + total / float(self.info.fps)) - (self.start or t0)
            total = max(int(round(duration * float(self.info.fps))), 0)
        progress = self._progress(total)
        try:
            filter_video(self.info, self.writer, filt, source=source, post_hooks=post_hooks,
                         temporal=temporal,
                         in_flight=in_flight, times=times, on_frame=progress.update)
            stopped = None
            self._finished = True
        except PipelineError as exc:
            stopped = exc
            self._finished = True  # filter_video kept the shorter file or removed it
        except VideoError as exc:  # finishing the output failed: filter_video removed it
            self._finished = True
            if self.output == "-" and is_broken_pipe(exc):   # the reader went away before the stream's end
                return self.stdout_gone()
            self.con.error(str(exc))
            return EXIT_FAILED
        except BrokenPipeError:   # the muxer's last bytes (its trailer) to a reader that went away
            self._finished = True
            return self.stdout_gone()
        finally:
            progress.close()
            self.written = self.writer.frames_written
            for w in dict.fromkeys(self.writer.warnings):
                self.con.warn(w)
        if stopped is not None and self.output == "-" and is_broken_pipe(stopped):
            return self.stdout_gone()   # `-o - | head`: the reader has what it wanted; Unix tools stop quietly
        if stopped is None:
            self.con.info(f"{self.output}: {self.written} frames")
            return EXIT_OK
        if stopped.stage == "read" and isinstance(stopped.cause, VideoReadError):
            self.con.error(str(stopped.cause))
            if self.written:
                self.con.error(f"{self.output}: kept as a valid shorter video with the "
                               f"{self.written} frames before it")
            else:
                self.con.error(f"{self.output}: not written (no frame decoded)")
        else:
            self.con.error(f"{self.input}: {stopped}; {self.output} not written")
        return EXIT_FAILED
