"""The temporal methods by name (the CLI's --temporal-method, Antialiaser(temporal=...), the cluster's spec).

    stage = make_stage("auto", filt.context, regions_from=filt)   # filt = Filter(keep_regions=True)
    out = stage(frame_in, frame_filtered, index)

- "auto" (the default): temporal supersampling (tss.TSSStage), then the reprojection blend
  (stage.TemporalStage) with dense flow, only on moving pixels of the spatial filter's render regions
  (where="render").
  The blend removes error on 1-spp renders and is worse than spatial only on flat-colour art
  (docs/temporal.md, "Blend in render regions").
- "tss": temporal supersampling alone; "blend": the blend everywhere; "tss+blend": both, the blend everywhere.
"""
from __future__ import annotations

from numbers import Integral

METHODS = ("auto", "tss", "blend", "tss+blend")
DEFAULT_METHOD = "auto"
# frames after the current one that TSS reads where the output may wait (the command line: files and pipes);
# the API's default is 0 (frames may come live). docs/temporal.md, "Look-ahead"
DEFAULT_LOOKAHEAD = 2
# K, the frames in TSS's ring (the current one included), as the command line's --temporal-frames takes it: a ring of
# one frame holds no history (TSS then returns the spatial output every frame); 64 bounds its device memory
RING_FRAMES = (2, 64)


def needs_regions(method: str) -> bool:
    """Whether the method reads the spatial filter's render regions (make the Filter with keep_regions=True)."""
    return method == "auto"


def check(method: str) -> str:
    if method not in METHODS:
        raise ValueError(f"temporal method: expected one of {', '.join(METHODS)}, got {method!r}")
    return method


def check_frames(frames: object, name: str = "temporal_frames") -> int:
    """`frames` (K, TSS's ring) as an int in RING_FRAMES; a ValueError naming `name` and the range otherwise."""
    lo, hi = RING_FRAMES
    if isinstance(frames, bool) or not isinstance(frames, Integral) or not lo <= frames <= hi:
        raise ValueError(f"{name}: expected an integer from {lo} to {hi}, got {frames!r}")
    return int(frames)


def make_stage(method: str, context, *, bgr: bool, frames: int | None = None, mode: str = "adaptive",
               k: float | None = None, show: str | None = None, regions_from=None, motion=None, lookahead: int = 0,
               linear_input: bool = False, dense_samples: bool = False, transfer: str | None = None):
    """A new temporal stage (fresh state) on `context` (the filter's OpenCL context). `regions_from`: the
    Filter(keep_regions=True) whose frames the stage gets ("auto" reads its last_regions). `motion`: known
    motion for the blend's dense frames instead of DIS (stage.TemporalStage's `motion`; methods with a blend).
    `lookahead`: N frames after the current one that TSS also reads (the stage's `lookahead`; the caller hands
    them in as `future`: mlaa_stream.pipeline does); not for the blend alone, which reads the past only.
    `linear_input`: the frames are linear light (EXR; the spatial Filter's linear_input). `dense_samples`: TSS tracks
    per-tile motion on dense frames (tss.TSSStage's; slow, off by default). `transfer`: "pq" / "hlg", the frames are
    codes of HDR video (the spatial Filter's transfer): TSS averages the light they stand for; the blend (history
    reprojection) keeps blending the codes, as TAA resolves in a perceptual space (docs/temporal.md, "HDR video")."""
    check(method)
    if lookahead and method == "blend":
        raise ValueError("lookahead: the blend method reads the past only; use a method with TSS")
    if dense_samples and method == "blend":
        raise ValueError("dense_samples: a TSS option; use a method with TSS")
    kw = {} if k is None else {"k": k}
    if motion is not None:
        if method == "tss":
            raise ValueError("motion: the tss method estimates its own; give it to a method with a blend")
        kw["motion"] = motion
    if method == "blend":
        from mlaa_stream.temporal.stage import TemporalStage
        return TemporalStage(context=context, mode=mode, bgr=bgr, show=show, linear_input=linear_input, **kw)
    from mlaa_stream.temporal.tss import DEFAULT_FRAMES, TSSStage, TSSThenBlend
    ring = DEFAULT_FRAMES if frames is None else check_frames(frames, "frames")   # 0 is refused, not made the default
    if method == "tss":
        return TSSStage(context=context, frames=ring, mode=mode, bgr=bgr, show=show, lookahead=lookahead,
                        linear_input=linear_input, dense_samples=dense_samples, transfer=transfer)
    if method == "auto":   # docs/temporal.md: dense flow follows a dolly's zoom, which one translation does not;
        # the blob test makes the forward-backward check redundant
        kw.update(where="render", regions_from=regions_from, fb_check=False,
                  blend_mode="dense" if mode == "adaptive" else mode)
    return TSSThenBlend(context=context, frames=ring, mode=mode, bgr=bgr, show=show, lookahead=lookahead,
                        linear_input=linear_input, dense_samples=dense_samples, transfer=transfer, **kw)


def stats_lists(stage) -> list[list]:
    """The lists a temporal stage appends its per-frame rows to: its own `stats`, or (TSSThenBlend, whose `stats`
    zips them into new rows) its two stages'. Trimming them trims the stage's rows; [] for a stage without any."""
    parts = [getattr(getattr(stage, name, None), "stats", None) for name in ("tss", "blend")]
    if all(isinstance(rows, list) for rows in parts):
        return parts
    rows = getattr(stage, "stats", None)
    return [rows] if isinstance(rows, list) else []
