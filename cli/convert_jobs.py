"""Frames <-> video for `mlaa-stream INPUT -o OUTPUT`: an image folder or frame pattern encoded into one
video file, and a video written out as numbered images. The filter and the pipeline are the same as for
the other jobs (filter_cmd.py); only the source or the sink changes kind."""
from __future__ import annotations

import os
from fractions import Fraction

from mlaa_stream.cli.console import EXIT_FAILED, EXIT_OK, Failed, Usage
from mlaa_stream.cli.filter_jobs import Job, check_writable, deinterlace_note, video_transfer, video_trim
from mlaa_stream.device.transfer import TRC_OF
from mlaa_stream.io.sequence import FIRST_FRAME_NUMBER, image_transfer


def _sequence_plan(job: Job) -> list:
    """The input images in order (folder: name order; pattern: frame numbers), as FrameFile items."""
    from mlaa_stream.io.sequence import FrameFile, expand_pattern, format_spans, list_folder, parse_frames

    if job.kind == "folder":
        srcs, others = list_folder(job.input)
        for path in others:
            job.con.warn(f"{path}: skipped (not an image file by its extension)")
        if not srcs:
            raise Failed(f"{job.input}: expected image files, found none")
        return [FrameFile(p, "", None) for p in srcs]
    rng = None
    if job.opts["frames"] is not None:
        try:
            rng = parse_frames(job.opts["frames"])
        except ValueError as exc:
            raise Usage(str(exc)) from exc
    found, missing = expand_pattern(job.input, rng)
    if not found:
        raise Usage(f"{job.input}: no files match this frame pattern")
    if missing:
        job.con.warn(f"{job.input}: missing frames {format_spans(missing)} (the video skips them)")
    return [FrameFile(p, "", n) for n, p in found]


_BT2020 = 9                   # H.273 / FFmpeg colour primaries and (non-constant luminance) matrix of BT.2020


def hdr_cicp(colour: dict, transfer: str | None) -> tuple[int, int, int, int] | None:
    """The cICP (primaries, transfer, matrix 0: RGB, full range) an image written from a video with an HDR
    transfer carries, from the video's colour tags (io/images.py write_image); None without a transfer."""
    if transfer is None:
        return None
    return int(colour.get("color_primaries", 2) or 2), TRC_OF[transfer], 0, 1


def hdr_colour_tags(first, transfer: str | None) -> dict:
    """The colour tags (VideoInfo.colour) of a video made from HDR images: BT.2020 (or the images' cICP primaries)
    with the transfer; {} (untagged, as before) without one."""
    if transfer is None:
        return {}
    cicp = first.spec.getattribute("CICP")
    primaries = int(cicp[0]) if cicp is not None and len(cicp) >= 1 and int(cicp[0]) not in (0, 2) else _BT2020
    return {"color_primaries": primaries, "color_trc": TRC_OF[transfer],
            "colorspace": _BT2020 if primaries == _BT2020 else 1, "color_range": 1}


class SequenceToVideoJob(Job):
    """A folder of images or a frame pattern -> one video file (frame rate from --rate)."""

    def prepare(self) -> None:
        import numpy as np

        from mlaa_stream.io.images import ImageReadError, image_shape, read_image
        from mlaa_stream.io.video import VideoError, VideoInfo, VideoWriter, container_format_for

        o = self.opts
        if os.path.exists(self.output) and not o["overwrite"]:
            raise Usage(f"{self.output}: exists; use --overwrite (-y) to replace it")
        folder = os.path.dirname(os.path.abspath(self.output))
        if not os.path.isdir(folder):
            raise Failed(f"{folder}: the output folder does not exist")
        check_writable(folder)
        self.plan = _sequence_plan(self)
        try:
            first = read_image(self.plan[0].src)   # its type, channels and tags set the video's
        except ImageReadError as exc:   # a corrupt or empty first frame: an error naming it, not a traceback
            raise Failed(f"{exc}; {self.output} not written") from exc
        if first.pixels.dtype.kind == "f":
            # PNG frames of linear-light EXRs are sRGB-encoded (io/images.py write_image); float TIFFs stay float
            raise Usage(f"{self.plan[0].src}: float (linear-light) images cannot be encoded to video here; "
                        f"filter them to PNG frames first (linear light is encoded to sRGB there), then make the "
                        f"video from those")
        if first.pixels.dtype not in (np.uint8, np.uint16):   # a TIFF's signed or 32-bit integers
            raise Usage(f"{self.plan[0].src}: {first.pixels.dtype} samples cannot be encoded to video here (8- and "
                        f"16-bit unsigned only); filter them to PNG frames first, then make the video from those")
        w, h, c = image_shape(self.plan[0].src)
        bits = 16 if first.pixels.dtype.itemsize == 2 else 8
        rate = Fraction(o["rate"]).limit_denominator(1001)
        # RGBA or grey + alpha, alpha last: kept where the encoder stores it (VP9 in WebM, qtrle, ffv1, png ...), named
        # by the writer where it does not (libx264)
        self.alpha = c in (2, 4) and first.spec.alpha_channel == c - 1
        # HDR frames (a PQ / HLG PNG's cICP, or --transfer): filtered as the light they code, the video tagged so
        self.transfer = image_transfer(first, o.get("transfer", "auto"))
        self.info = VideoInfo(path=self.input, width=w, height=h, fps=rate, time_base=1 / rate,
                              # as a player expects (4:2:0; 10-bit from 16-bit frames): the encoder's
                              # closest format to it, 4:4:4 only where the size is odd
                              frames=len(self.plan), bits=bits, has_alpha=self.alpha,
                              pix_fmt=("yuva420p" if self.alpha else "yuv420p") + ("10le" if bits > 8 else ""),
                              codec="images", colour=hdr_colour_tags(first, self.transfer), audio_streams=0)
        if c in (2, 4) and not self.alpha:
            self.con.warn(f"{self.input}: alpha is not kept in the video")
        try:
            # -f/--format as for a video in (VideoJob); images have no audio to copy (--audio copy/aac: a warning)
            self.writer = VideoWriter(self.output, self.info, codec=o["codec"], crf=o["crf"],
                                      preset=o["encoder_preset"], pix_fmt=o["pix_fmt"], audio="none",
                                      overwrite=o["overwrite"],
                                      container_format=container_format_for(o.get("container"), self.output))
        except VideoError as exc:
            raise Failed(str(exc)) from exc
        import av
        if self.alpha and not any(comp.is_alpha for comp in av.VideoFormat(self.writer.pix_fmt).components):
            self.con.warn(f"{self.input}: alpha is not kept in the video: {self.writer.codec} ({self.writer.pix_fmt}) "
                          f"has none (WebM's VP9, --codec ffv1, png or qtrle keep it)")
        self.con.info(f"{len(self.plan)} frames {w}x{h} at {rate} fps -> {self.output} "
                      f"({self.writer.codec} {self.writer.pix_fmt})")

    def nothing_to_do(self) -> bool:
        return False

    def run(self, filt, post_hooks, in_flight, times, temporal=None) -> int:
        import numpy as np

        from mlaa_stream.io.sequence import Report, image_source, is_linear
        from mlaa_stream.pipeline import PipelineError, run_pipeline

        report = Report(say=self.con.error, inform=self.con.info)
        progress = self._progress(len(self.plan))
        rgb = slice(0, 3)

        def sink(item) -> None:
            frame = item.frame if item.frame.ndim == 3 else item.frame[..., None]
            if self.alpha:  # the channels the filter left out (grey's alpha) put back: RGB(A) with alpha last
                full = item.meta[2](frame)
                colour, alpha = full[..., :-1], full[..., -1:]
                colour = np.repeat(colour, 3, axis=2) if colour.shape[2] < 3 else colour[..., rgb]
                frame = np.concatenate([colour, alpha], axis=2)
            else:
                frame = np.repeat(frame, 3, axis=2) if frame.shape[2] < 3 else frame[..., rgb]
            self.writer.write(np.ascontiguousarray(frame))

        self.read_order: dict = {}  # position -> FrameFile, for the temporal stage (SequenceTemporal)
        self.read_linear: dict = {}  # position -> the frame is linear light: SequenceTemporal reads it too

        def source():
            for position, item in enumerate(image_source(self.plan, report, strict=True)):
                self.read_order[position] = item.meta[0]
                self.read_linear[position] = is_linear(item.meta[1])
                yield item

        try:
            run_pipeline(source(), filt, sink, in_flight=in_flight, temporal=temporal,
                         post_hooks=post_hooks, times=times, on_frame=progress.update)
            self.writer.commit()
            self._finished = True
        except PipelineError as exc:
            # a read error has no item: its index is the failing file's place in the plan (a sequence stops at the
            # first one), not its frame number -- "frame 3: read failed: frame 4 (a.0004.png): ..." named two frames
            ff = exc.meta[0] if exc.meta else self.plan[exc.index] if 0 <= exc.index < len(self.plan) else None
            cause = str(exc.cause)
            where = "" if ff is not None and ff.src in cause else \
                f"{ff.label if ff is not None else f'frame {exc.index}'}: {exc.stage} failed: "
            self.con.error(f"{where}{cause}; {self.output} not written")
            return EXIT_FAILED
        finally:
            progress.close()
            self.written = self.writer.frames_written
        return EXIT_OK

    def abort(self) -> None:
        writer = getattr(self, "writer", None)
        if writer is not None and not getattr(self, "_finished", False):
            writer.abort()


class VideoToImagesJob(Job):
    """A video -> numbered images through a frame pattern (clean/%04d.png), numbered from 1 as ffmpeg does."""

    FIRST_NUMBER = FIRST_FRAME_NUMBER   # as a folder written through a pattern (io/sequence.py plan_images)

    def prepare(self) -> None:
        from mlaa_stream.io.video import PIPE, VideoError, open_pipe, probe_video

        o = self.opts
        folder = os.path.dirname(os.path.abspath(self.output))
        os.makedirs(folder, exist_ok=True)
        check_writable(folder)
        self.pipe_in = None
        try:
            if self.input == PIPE:  # read once: the open container goes on to read_video
                self.info, self.pipe_in = open_pipe()
            else:
                self.info = probe_video(self.input)
        except VideoError as exc:
            raise Failed(str(exc)) from exc
        self.start, self.end = video_trim(self.opts, self.info)  # --start/--end, as for a video out
        self.transfer = video_transfer(self.info, o.get("transfer", "auto"))   # HDR codes filtered as light
        if self.info.audio_streams:
            self.con.warn(f"{self.input}: audio is not written to images")
        if self.info.rotation:  # a phone's video: a player turns it, an image viewer will not
            self.con.warn(f"{self.input}: displayed rotated by {self.info.rotation} degrees; the images are "
                          f"written as stored, not rotated")
        self.overwrite = o["overwrite"]
        self.done: set[int] = set()   # frame numbers whose complete output exists (--resume): not written again
        existing = self._existing_outputs()
        if existing and o["resume"]:
            self.done = self._complete(existing)
            self.con.info(f"--resume: {len(self.done)} outputs exist and are skipped")
        elif existing and not o["overwrite"]:
            more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
            raise Usage(f"{existing[0][1]}: exists{more}; use --overwrite to replace or --resume to skip "
                        f"existing outputs")

    def _existing_outputs(self) -> list[tuple[int, str]]:
        """(number, path) of the files the frame pattern already names, from FIRST_NUMBER on (checked before
        decoding: the frame count of a trimmed or piped video is known only at its end)."""
        from mlaa_stream.io.sequence import expand_pattern

        found, _ = expand_pattern(self.output)
        return [(n, path) for n, path in found if n >= self.FIRST_NUMBER]

    def _complete(self, existing: list[tuple[int, str]]) -> set[int]:
        """--resume: the numbers of the existing outputs that are complete (the video's size and channels, PNG/JPEG
        end marker), as for a folder (ImageJob._keep_complete); an incomplete one is removed and written again."""
        from mlaa_stream.io.images import check_complete

        channels = 4 if self.info.has_alpha else 3
        done = set()
        for n, path in existing:
            why = check_complete(path, self.info.width, self.info.height, channels, decode=False)
            if why is None:
                done.add(n)
                continue
            self.con.warn(f"{path}: incomplete ({why}); it is written again")
            try:
                os.unlink(path)
            except OSError as exc:
                raise Failed(f"{path}: incomplete and cannot be removed ({exc.strerror})") from exc
        return done

    def nothing_to_do(self) -> bool:
        return False

    def unwritten_indices(self) -> set:
        """--resume with the temporal stage: the frames done run through it (its history) but are not written; the
        stage counts a video's frames from 0, the outputs are numbered from FIRST_NUMBER."""
        return {n - self.FIRST_NUMBER for n in self.done}

    def run(self, filt, post_hooks, in_flight, times, temporal=None) -> int:
        from mlaa_stream.io.images import ImageWriteError, write_image
        from mlaa_stream.io.item import Item
        from mlaa_stream.io.sequence import frame_path
        from mlaa_stream.io.video import VideoReadError, read_video
        from mlaa_stream.pipeline import PipelineError, run_pipeline

        # --resume: the frames already written are still decoded (the video is read in order) but, unless the
        # temporal stage (its history) or an overlay (its frame numbers: the pipeline's positions) needs the
        # whole stream, not filtered; either way not written again.
        drop = bool(self.done) and temporal is None and not post_hooks
        total = self.info.frames
        progress = self._progress(total - len(self.done) if drop and total else total)

        def source():
            """The decoded frames, each with its output's number (meta), those done left out where `drop`."""
            inner = read_video(self.info, start=self.start, end=self.end, container=self.pipe_in,
                               require_frames=True, deinterlace=self.opts.get("deinterlace", "off"),
                               on_deinterlace=deinterlace_note(self.con, self.input))
            try:
                for position, item in enumerate(inner):
                    number = self.FIRST_NUMBER + position
                    if not (drop and number in self.done):
                        yield Item(item.frame, number)
            finally:
                inner.close()

        cicp = hdr_cicp(self.info.colour, self.transfer)

        def sink(item) -> None:
            if item.meta in self.done:
                return
            write_image(frame_path(self.output, item.meta), item.frame, overwrite=self.overwrite,
                        quality=self.opts.get("jpeg_quality"), cicp=cicp)
            self.written += 1

        try:
            run_pipeline(source(), filt, sink,
                         in_flight=in_flight, post_hooks=post_hooks, temporal=temporal, times=times,
                         on_frame=progress.update)
        except PipelineError as exc:
            cause = exc.cause
            if isinstance(cause, (VideoReadError, ImageWriteError)):
                self.con.error(str(cause))
            else:
                self.con.error(f"frame {exc.index}: {exc.stage} failed: {cause}")
            self.con.error(f"stopped: {self.written} images written")
            return EXIT_FAILED
        finally:
            progress.close()
        return EXIT_OK

    def abort(self) -> None:
        pass
