"""The temporal stage across chunk boundaries: each chunk first runs the frames before its start through
the spatial filter and the temporal stage (warm-up, not written), so that its first written frame sees
the state a single machine had there.

What each method carries from frame to frame (mlaa_stream/temporal), and so how long the warm-up is:
  - tss: the ring of the last K input frames (MotionRing.entries) with each one's translation, refined
    directly against every frame it spends in the ring; a frame's entry starts at (0, 0) when it enters
    and depends on nothing before it, and the per-frame decision (choose_model) reads only the previous
    and the current frame. After K warm-up frames the ring holds exactly the frames a single machine's
    holds, with the same maps: the output is identical. Exception (not fixable here without changing
    tss.py): a frame whose grey equals the previous one's is not pushed (the previous output is
    returned), so the ring holds the last K *distinct* frames; repeated frames inside the K before a
    chunk leave its first frames' rings shorter than a single machine's (docs/cluster.md).
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

    method: str = "tss"      # tss, blend or tss+blend (the CLI's --temporal-method)
    frames: int | None = None  # K, the TSS ring (None: tss.DEFAULT_FRAMES)
    mode: str = "adaptive"
    k: float | None = None   # the blend's velocity-difference strength (None: its default)

    def __post_init__(self):
        if self.method not in ("tss", "blend", "tss+blend"):
            raise ValueError(f"temporal method: expected tss, blend or tss+blend, got {self.method!r}")

    @property
    def ring(self) -> int:
        from mlaa_stream.temporal.tss import DEFAULT_FRAMES
        return int(self.frames or DEFAULT_FRAMES)

    @property
    def warmup(self) -> int:
        """Frames each chunk reads before its start (see the module's docstring)."""
        return {"tss": self.ring, "blend": BLEND_WARMUP, "tss+blend": max(self.ring, BLEND_WARMUP)}[self.method]

    def stage(self, context, show: str | None = None):
        """A new stage (fresh state) on `context` (the filter's OpenCL context), frames in RGB order."""
        if self.method == "blend":
            from mlaa_stream.temporal.stage import TemporalStage
            kw = {} if self.k is None else {"k": self.k}
            return TemporalStage(context=context, mode=self.mode, bgr=False, show=show, **kw)
        from mlaa_stream.temporal.tss import TSSStage, TSSThenBlend
        cls = TSSThenBlend if self.method == "tss+blend" else TSSStage
        return cls(context=context, frames=self.ring, mode=self.mode, bgr=False, show=show)
