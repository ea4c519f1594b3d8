"""The temporal stage across chunk boundaries: each chunk first runs the frames before its start through
the spatial filter and the temporal stage (warm-up, not written), so that its first written frame sees
the state a single machine had there.

What each method carries from frame to frame (mlaa_stream/temporal), and so how long the warm-up is:
  - tss: the ring of the last K input frames (MotionRing.entries) with each one's translation, refined
    directly against every frame it spends in the ring; a frame's entry starts at (0, 0) when it enters
    and depends on nothing before it, and the per-frame decision (choose_model) reads only the previous
    and the current frame. After K warm-up frames the ring holds exactly the frames a single machine's
    holds, with the same maps: the output is identical (measured: K - 1 is the least that is). But a
    frame whose grey equals the previous one's is not pushed (the previous output is returned), so the
    ring holds the last K *distinct* frames: held frames before a chunk need a longer warm-up.
    WarmedStage counts the changing frames and the worker reads further back until there are K (at
    most MAX_WARMUP_FACTOR x K frames back; beyond that the chunk says its outputs may differ).
  - blend: the previous output in linear light (a recursive history: every past frame leaves a share
    that decays by the history weight, <= strength 0.5, per frame); it never becomes exactly identical,
    BLEND_WARMUP frames bring it within a measured tolerance (docs/cluster.md).
  - tss+blend: both, the longer warm-up.
"""
from __future__ import annotations

from dataclasses import dataclass

# frames of warm-up for the blend: measured max difference after this many frames in docs/cluster.md
BLEND_WARMUP = 8


@dataclass(frozen=True)
class TemporalSpec:
    """The temporal stage's settings, sent to the workers (each builds its own stage per chunk)."""

    method: str = "auto"     # one of temporal.methods.METHODS (the CLI's --temporal-method)
    frames: int | None = None  # K, the TSS ring (None: tss.DEFAULT_FRAMES)
    mode: str = "adaptive"
    k: float | None = None   # the blend's velocity-difference strength (None: its default)
    lookahead: int = 0       # frames after the current one TSS also reads: each chunk reads that many past its end
    dense_samples: bool = False   # TSS tracks per-tile motion where one translation fails (the CLI's --dense-motion)

    def __post_init__(self):
        from mlaa_stream.temporal.methods import check
        check(self.method)

    @property
    def ring(self) -> int:
        from mlaa_stream.temporal.tss import DEFAULT_FRAMES
        return int(self.frames or DEFAULT_FRAMES)

    @property
    def warmup(self) -> int:
        """Frames each chunk reads before its start (see the module's docstring)."""
        return {"tss": self.ring, "blend": BLEND_WARMUP}.get(self.method, max(self.ring, BLEND_WARMUP))

    def stage(self, filt, show: str | None = None):
        """A new stage (fresh state) on the OpenCL context of `filt` (the spatial Filter whose frames it gets;
        made with keep_regions=needs_regions(method)), frames in RGB order; TSS averages light in `filt`'s transfer
        (HDR video) as the filter mixes it."""
        from mlaa_stream.temporal.methods import make_stage
        return make_stage(self.method, filt.context, bgr=False, frames=self.frames, mode=self.mode, k=self.k,
                          show=show, regions_from=filt, lookahead=self.lookahead,
                          dense_samples=self.dense_samples and self.method != "blend",
                          transfer=getattr(filt, "transfer", None))


# A chunk's warm-up may reach back at most this many times `warmup` frames to find `warmup` changes.
MAX_WARMUP_FACTOR = 4


class ShortWarmup(Exception):
    """Raised at a chunk's first frame: its warm-up held `missing` too few frames that change the stage."""

    def __init__(self, missing: int):
        super().__init__(f"the warm-up needs {missing} more changing frames")
        self.missing = missing


class WarmedStage:
    """The temporal stage of one chunk, called with `warm` True for its warm-up frames. It counts the
    warm-up frames whose grey differs from the previous frame's (both methods return the previous output
    for a repeated frame and keep their state as it is: a held frame does not count), and at the chunk's
    first frame raises ShortWarmup when they are fewer than `need` and `can_extend` (the caller reads
    further back and runs again). `from_start`: the warm-up begins at the stream's first frame, where a
    single machine starts too (nothing is missing)."""

    def __init__(self, stage, need: int, *, can_extend: bool, from_start: bool):
        self.stage, self.need, self.can_extend, self.from_start = stage, need, can_extend, from_start
        self.lookahead = getattr(stage, "lookahead", 0)   # the chunk's pipeline hands in that many frames ahead
        self.changes, self.checked, self._prev = 0, False, None
        self.short = 0  # changes missing where the warm-up could not be extended (outputs may differ)

    def __call__(self, frame_in, frame_out, index: int, warm: bool, future=()):
        if not self.checked:
            import numpy as np
            from mlaa_stream.temporal.stage import grey8
            grey = grey8(frame_in, False)
            if self._prev is not None and not np.array_equal(grey, self._prev):
                self.changes += 1
            self._prev = grey
            if not warm:
                self.checked, self._prev = True, None
                if self.changes < self.need and not self.from_start:
                    if self.can_extend:
                        raise ShortWarmup(self.need - self.changes)
                    self.short = self.need - self.changes
        if self.lookahead:
            return self.stage(frame_in, frame_out, index, future=future)
        return self.stage(frame_in, frame_out, index)

    def close(self) -> None:
        self.stage.close()
