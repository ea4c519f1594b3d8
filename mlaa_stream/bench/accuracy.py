"""The benchmark: every method and preset over the scenes -- accuracy per category, speed per 1080p
frame -- written as docs/bench/results.csv, docs/bench/README.md and docs/bench/speed_vs_accuracy.png.

Add a method with one line in METHODS: a name and a factory taking the device spec and returning
an object with `process(frame) -> frame` (and optionally `close()`).

Peer methods: "fxaa" is FXAA 3.11 as an OpenCL kernel (mlaa_stream/spatial/fxaa.py); "smaa" is SMAA 1x ultra
(orthogonal patterns, corner rounding, blended in linear light; no diagonal patterns) in numpy on the host
(mlaa_stream/bench/smaa.py), so its ms column measures numpy on the CPU, not OpenCL nor a GPU shader.
"""
from __future__ import annotations

import csv
import datetime as _dt
import math
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Protocol

import numpy as np

from mlaa_stream.yardstick import metrics as M
from mlaa_stream.spatial.fast_filter import FastFilter
from mlaa_stream.spatial.fxaa import FXAA
from mlaa_stream.bench.smaa import SMAA
from mlaa_stream.spatial.filter import PRESETS, Filter
from mlaa_stream.temporal.methods import DEFAULT_LOOKAHEAD
from mlaa_stream.yardstick.scenes import Scene, generate_scenes, timing_frame


class Processor(Protocol):
    def process(self, frame: np.ndarray) -> np.ndarray: ...


class NoAA:
    """The 'none' baseline: hands the frame back (a copy, like any filter would)."""

    device_name = "host (numpy copy)"

    def process(self, frame: np.ndarray) -> np.ndarray:
        return frame.copy()

    def close(self) -> None:
        pass


class SpatialTemporal:
    """The spatial filter, then a temporal stage with its history kept across frames; `reset()` starts
    a new shot (the bench calls it between scenes). `method`: one of mlaa_stream.temporal.methods.METHODS
    ("auto" is what `--temporal` runs, with `lookahead` DEFAULT_LOOKAHEAD); with `temporal_options` the blend
    (TemporalStage) with them. `process_all` hands the stage each frame's `lookahead` next frames, as the pipeline
    does; `process` (the timing run) reads the past only."""

    def __init__(self, device: str | None, method: str = "auto", lookahead: int = 0, **temporal_options):
        from mlaa_stream.temporal.methods import make_stage, needs_regions
        self.filter = Filter(device=device, keep_regions=needs_regions(method))
        self.lookahead = lookahead
        if temporal_options:   # the blend's own options (mode): TemporalStage itself
            from mlaa_stream.temporal.stage import TemporalStage
            self.stage = TemporalStage(context=self.filter.context, bgr=False, **temporal_options)
        else:
            self.stage = make_stage(method, self.filter.context, bgr=False, regions_from=self.filter,
                                    lookahead=lookahead)
        self.index = 0

    def process(self, frame: np.ndarray, future: list[np.ndarray] = ()) -> np.ndarray:
        ahead = {"future": future} if self.lookahead else {}
        out = self.stage(frame, self.filter.process(frame), self.index, **ahead)
        self.index += 1
        return out

    def process_all(self, frames: np.ndarray) -> np.ndarray:
        """A shot's frames in order, each with the next `lookahead` frames."""
        n = self.lookahead
        return np.stack([self.process(f, list(frames[i + 1:i + 1 + n])) for i, f in enumerate(frames)])

    def reset(self) -> None:
        self.stage.reset()
        self.filter.new_shot()
        self.index = 0

    def close(self) -> None:
        self.stage.close()
        self.filter.close()


# name -> factory(device). One line per method; temporal methods get each scene's frames in order
# from a fresh instance.
METHODS: dict[str, Callable[[str | None], Processor]] = {
    "none": lambda device: NoAA(),
    "fxaa": lambda device: FXAA(device=device),
    "smaa": lambda device: SMAA(),   # SMAA 1x ultra, numpy on the host: its ms column is not a GPU's
    "mlaa": lambda device: Filter(device=device),
    "mlaa+temporal": lambda device: SpatialTemporal(device, "auto", lookahead=DEFAULT_LOOKAHEAD),
    "mlaa+temporal:tss": lambda device: SpatialTemporal(device, "tss", lookahead=DEFAULT_LOOKAHEAD),
    "mlaa+temporal:blend": lambda device: SpatialTemporal(device, "blend", mode="adaptive"),
    "mlaa+temporal:blend-dense": lambda device: SpatialTemporal(device, "blend", mode="dense"),
}
# Every quality preset of the MLAA filter, as "mlaa:<preset>" (one with no options is "mlaa" itself).
# The fast preset as Antialiaser(preset="fast") runs it: FastFilter, without host copies on CPU devices.
METHODS.update({f"mlaa:{name}": (lambda device, kw=kw: (FastFilter if kw.get("fast") else Filter)(device=device, **kw))
                for name, kw in PRESETS.items() if kw})
# What a method's row means beyond its name, printed under the tables of README.md when the method ran.
METHOD_NOTES: dict[str, str] = {
    "smaa": "SMAA 1x ultra (luma edges 0.05, contrast adaptation 2.0, 32 search steps, corner rounding 25 %; "
            "orthogonal patterns only, no diagonal ones), blended in linear light: `mlaa_stream/bench/smaa.py`, "
            "numpy on the host CPU -- its ms is numpy's, not an OpenCL kernel's nor a GPU shader's",
}
TRUTH = "truth"  # a reference row: the supersampled truth itself (no timing)
# Categories whose input already equals the truth almost everywhere: they measure damage, and their
# (ill-conditioned) error-removed ratios stay out of the all-category means.
DAMAGE_ONLY = {"photo", "antialiased"}

METRIC_COLUMNS = ["error_removed", "edge_error_removed", "damage", "broken_wires", "flip",
                  "temporal_error", "flicker", "rmse"]
CSV_COLUMNS = ["method", "scene", "category", "frames", *METRIC_COLUMNS, "ms_per_1080p_frame",
               "device", "error"]


@dataclass
class Timing:
    median_ms: float
    frames: int
    device: str


@dataclass
class BenchResult:
    rows: list[dict] = field(default_factory=list)  # one per (method, scene)
    timings: dict[str, Timing] = field(default_factory=dict)
    failures: dict[str, str] = field(default_factory=dict)
    device: str = ""
    command: str = ""
    date: str = ""
    methods: list[str] = field(default_factory=list)
    categories: list[str] = field(default_factory=list)


def time_method(proc: Processor, frames: list[np.ndarray], n: int = 20, warmup: int = 3) -> float:
    """Median wall-clock milliseconds of proc.process over n frames (cycling `frames`), after
    `warmup` untimed ones (kernel builds, buffer allocation)."""
    for k in range(warmup):
        proc.process(frames[k % len(frames)])
    times = []
    for k in range(n):
        f = frames[k % len(frames)]
        t0 = time.perf_counter()
        proc.process(f)
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def close_processor(proc) -> None:
    """Releases a method's device resources where it holds any."""
    close = getattr(proc, "close", None)
    if close is not None:
        close()


def new_shot(proc: object) -> None:
    """What follows is a shot of its own (or a still judged alone): a temporal method starts afresh, a filter holds no
    render verdict from before (Filter.new_shot)."""
    for hook in ("reset", "new_shot"):
        if callable(getattr(proc, hook, None)):
            getattr(proc, hook)()


def run_scene(proc: Processor, scene: Scene) -> np.ndarray:
    """All frames of a scene through one method, in order, as a shot of its own (new_shot)."""
    return run_frames(proc, scene.inputs)


def run_frames(proc: Processor, frames) -> np.ndarray:
    """Frames of one shot through one method, in order, as a shot of its own (new_shot)."""
    new_shot(proc)
    if hasattr(proc, "process_all"):   # a temporal method reading frames ahead
        return proc.process_all(frames)
    return np.stack([proc.process(f) for f in frames])


def score_scene(outs: np.ndarray, scene: Scene, with_flip: bool) -> dict[str, float]:
    return M.score(outs, scene.inputs, scene.truths, scene.edges, scene.wires, scene.backgrounds,
                   with_flip=with_flip)


def run_bench(scenes: list[Scene], method_names: list[str] | None = None, device: str | None = None,
              timed_frames: int = 20, warmup: int = 3, with_flip: bool = False,
              log: Callable[[str], None] | None = None, command: str = "") -> BenchResult:
    """Score every method on every scene and time it on a 1080p frame; a method that fails is
    recorded with its error and the others go on."""
    from mlaa_stream.device.context import default_context

    log = log or (lambda msg: None)
    names = list(METHODS) if method_names is None else list(method_names)
    unknown = [n for n in names if n not in METHODS and n != TRUTH]
    if unknown:
        raise ValueError(f"expected methods from {', '.join([*METHODS, TRUTH])}, got {', '.join(unknown)}")
    if TRUTH not in names:
        names.append(TRUTH)
    res = BenchResult(device=default_context(device).name, command=command,
                      date=_dt.datetime.now().strftime("%Y-%m-%d %H:%M"), methods=names)
    res.categories = list(dict.fromkeys(s.category for s in scenes))
    timing = [timing_frame(), timing_frame(shift=0.5)] if timed_frames > 0 else []
    for name in names:
        if name == TRUTH:
            for s in scenes:
                res.rows.append(_row(name, s, score_scene(s.truths, s, with_flip), math.nan, "", ""))
            continue
        try:
            proc = METHODS[name](device)
            try:
                dev = getattr(proc, "device_name", res.device)
                ms = time_method(proc, timing, timed_frames, warmup) if timing else math.nan
            finally:
                close_processor(proc)
            res.timings[name] = Timing(ms, timed_frames, dev)
            log(f"{name}: {ms:.1f} ms per 1080p frame on {dev}")
            for s in scenes:
                proc = METHODS[name](device)
                try:
                    outs = run_scene(proc, s)
                finally:
                    close_processor(proc)
                sc = score_scene(outs, s, with_flip)
                res.rows.append(_row(name, s, sc, ms, dev, ""))
                log(f"  {s.name}: error removed {_pct(sc['error_removed'])}, "
                    f"damage {_num(sc['damage'])}")
        except Exception as exc:  # one broken method must not sink the run: record and go on
            res.failures[name] = f"{type(exc).__name__}: {exc}"
            log(f"{name}: FAILED {res.failures[name]}")
            res.rows = [r for r in res.rows if r["method"] != name]
    return res


def _row(method: str, s: Scene, sc: dict, ms: float, dev: str, err: str) -> dict:
    return {"method": method, "scene": s.name, "category": s.category, "frames": s.frames, **sc,
            "ms_per_1080p_frame": ms, "device": dev, "error": err}


# --- aggregation ------------------------------------------------------------------------------------
def _nanmean(values) -> float:
    v = [x for x in values if x is not None and not math.isnan(x)]
    return sum(v) / len(v) if v else math.nan


def per_category(res: BenchResult) -> dict[str, dict[str, dict[str, float]]]:
    """category -> method -> metric (mean over the category's scenes)."""
    out: dict = {}
    for cat in res.categories:
        out[cat] = {}
        for m in res.methods:
            rows = [r for r in res.rows if r["method"] == m and r["category"] == cat]
            if rows:
                out[cat][m] = {k: _nanmean(r[k] for r in rows) for k in METRIC_COLUMNS}
    return out


def summary(res: BenchResult) -> dict[str, dict[str, float]]:
    """method -> metric, the mean over categories (each category weighs the same); error removed
    leaves out the DAMAGE_ONLY categories."""
    cats = per_category(res)
    out = {}
    ratio = {"error_removed", "edge_error_removed"}
    for m in res.methods:
        per = [(c, cats[c][m]) for c in cats if m in cats[c]]
        if per:
            out[m] = {k: _nanmean(p[k] for c, p in per if not (k in ratio and c in DAMAGE_ONLY))
                      for k in METRIC_COLUMNS}
            t = res.timings.get(m)
            out[m]["ms"] = t.median_ms if t else math.nan
    return out


# --- outputs ----------------------------------------------------------------------------------------
def _pct(v: float) -> str:
    return "–" if v is None or math.isnan(v) else f"{100 * v:.1f} %"


def _num(v: float, digits: int = 2) -> str:
    return "–" if v is None or math.isnan(v) else f"{v:.{digits}f}"


def write_csv(res: BenchResult, path: Path) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
        w.writeheader()
        for r in res.rows:
            w.writerow({k: (f"{r[k]:.6g}" if isinstance(r.get(k), float) else r.get(k, ""))
                        for k in CSV_COLUMNS})
        for name, err in res.failures.items():
            w.writerow({"method": name, "error": err})


def _table(head: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(" --- " for _ in head) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


HEAD = ["method", "error removed", "edge error removed", "damage (RMSE, levels)", "broken wires",
        "FLIP", "temporal error", "flicker energy", "ms / 1080p frame"]


def _cells(m: str, v: dict, ms: float) -> list[str]:
    return [m, _pct(v["error_removed"]), _pct(v["edge_error_removed"]), _num(v["damage"]),
            _pct(v["broken_wires"]), _num(v["flip"], 4), _num(v["temporal_error"]),
            _num(v["flicker"]), _num(ms, 1)]


def write_readme(res: BenchResult, path: Path, chart_name: str, scenes: list[Scene]) -> None:
    summ, cats = summary(res), per_category(res)
    ms = {m: (res.timings[m].median_ms if m in res.timings else math.nan) for m in res.methods}
    parts = [
        "# Benchmark: speed against accuracy",
        "",
        "Generated by `mlaa_stream.bench.accuracy`; do not edit by hand -- rerun the command.",
        "",
        f"- command: `{res.command or 'mlaa-stream bench'}`",
        f"- date: {res.date}",
        f"- device: {res.device}",
        f"- timing: median ms per 1920x1080 RGB8 frame over "
        f"{next(iter(res.timings.values())).frames if res.timings else 0} frames after warm-up, "
        "host to host (upload, kernels, download); machines here are noisy, compare ratios within one run",
        "",
        f"![speed against accuracy]({chart_name})",
        "",
        "## Metrics",
        "",
        "- **error removed** = 1 − MSE(out, truth) / MSE(in, truth); 100 % is the 8×8 supersampled truth, "
        "0 % is doing nothing, negative is worse than the input.",
        "- **edge error removed**: the same over edge pixels only (input differs from truth by > 3 levels).",
        "- **damage**: RMSE in 8-bit levels over pixels where the input already equals the truth (±1) "
        "and no edge pixel is next to them; 0 is ideal.",
        "- **broken wires**: share of thin-feature pixels whose contrast against the background is under "
        "a third of the truth's.",
        "- **FLIP**: NVIDIA FLIP (LDR), mean over the frames, each a centre crop ≤ 256×256; lower is better; "
        "– when flip-evaluator is not installed or not asked for.",
        "- **temporal error**: mean |Δout − Δtruth| / mean |Δin − Δtruth| over consecutive frames; "
        "< 1 is steadier than the input. **flicker energy**: Σ Δout² / Σ Δtruth²; 1 ideal, above "
        "flickers, below smears.",
        "",
        f"## All categories (mean over categories; error removed leaves out {', '.join(sorted(DAMAGE_ONLY))}, "
        "whose input already equals the truth almost everywhere)",
        "",
        _table(HEAD, [_cells(m, summ[m], ms[m]) for m in res.methods if m in summ]),
        "",
    ]
    notes = [f"- `{m}`: {METHOD_NOTES[m]}" for m in res.methods if m in METHOD_NOTES and m in summ]
    if notes:
        parts += notes + [""]
    if res.failures:
        parts += ["Methods that failed:", ""]
        parts += [f"- `{m}`: {e}" for m, e in res.failures.items()] + [""]
    by_cat = {}
    for s in scenes:
        by_cat.setdefault(s.category, []).append(s)
    for cat in res.categories:
        desc = "; ".join(f"`{s.name}` {s.size[0]}×{s.size[1]}×{s.frames}: {s.notes}" for s in by_cat.get(cat, []))
        parts += [f"## {cat}", "", desc, "",
                  _table(HEAD, [_cells(m, cats[cat][m], ms[m]) for m in res.methods if m in cats[cat]]), ""]
    path.write_text("\n".join(parts))


def _label_points(ax, shown: list[tuple[str, float, float]], colours: dict[str, str]) -> None:
    """Label each point where its text box overlaps no point, no other label and stays in the
    axes: greedy over candidate offsets around the point (display pixels), leader line if moved."""
    pts = {m: ax.transData.transform((x, y)) for m, x, y in shown}
    bbox = ax.get_window_extent()
    boxes: list[tuple[float, float, float, float]] = []
    cands = [(8, -4), (8, 9), (8, -17), (8, 22), (8, -30), (8, 35), (8, -43), (8, 48)]

    def free(b) -> bool:
        x0, y0, x1, y1 = b
        if x0 < bbox.x0 + 2 or x1 > bbox.x1 - 2 or y0 < bbox.y0 + 2 or y1 > bbox.y1 - 2:
            return False
        if any(x0 - 6 < px < x1 + 6 and y0 - 6 < py < y1 + 6 for px, py in pts.values()):
            return False
        return not any(x0 < c1 and c0 < x1 and y0 < d1 and d0 < y1 for c0, d0, c1, d1 in boxes)

    for m, x, y in sorted(shown, key=lambda p: p[2]):
        px, py = pts[m]
        w, h = 6.0 * len(m) + 2, 10.0
        options = cands + [(-8 - w, dy) for _, dy in cands]
        chosen = options[0]
        for dx, dy in options:
            if free((px + dx, py + dy, px + dx + w, py + dy + h)):
                chosen = (dx, dy)
                break
        dx, dy = chosen
        boxes.append((px + dx, py + dy, px + dx + w, py + dy + h))
        moved = (dx, dy) not in ((8, -4), (-8 - w, -4))
        ax.annotate(m, (x, y), xytext=(dx, dy), textcoords="offset pixels", fontsize=8, color=colours[m],
                    arrowprops={"arrowstyle": "-", "color": "0.6", "lw": 0.5} if moved else None)


def plot_chart(res: BenchResult, path: Path) -> None:
    """x: ms per 1080p frame (log); y: error removed; second panel FLIP (or damage without FLIP)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    summ = summary(res)
    pts = [(m, v) for m, v in summ.items() if m != TRUTH and not math.isnan(v["ms"])]
    use_flip = any(not math.isnan(v["flip"]) for _, v in pts)
    second = "flip" if use_flip else "damage"
    colours = {m: f"C{k % 10}" for k, (m, _) in enumerate(pts)}  # one colour per method, both panels
    fig = Figure(figsize=(12, 5), dpi=110)
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 2)
    panels = [("error_removed", "error removed (mean over categories, %)", 100.0),
              (second, "FLIP (lower is better)" if use_flip else "damage away from edges (RMSE, 8-bit levels)", 1.0)]
    labels = []
    for ax, (key, label, scale) in zip(axes, panels):
        shown = [(m, v["ms"], v[key] * scale) for m, v in pts if not math.isnan(v[key])]
        for m, x, y in shown:
            ax.scatter([x], [y], s=40, zorder=3, color=colours[m])
        ax.set_xscale("log")
        xs = [x for _, x, _ in shown]
        if xs:
            ax.set_xlim(min(xs) / 2, max(xs) * 6)  # room for labels right of the slowest point
        labels.append((ax, shown))
        if TRUTH in summ and not math.isnan(summ[TRUTH][key]):
            ty = summ[TRUTH][key] * scale
            ax.axhline(ty, color="0.5", ls="--", lw=1)
            ax.text(0.99, ty, "truth (8×8 supersampled) ", transform=ax.get_yaxis_transform(),
                    va="bottom", ha="right", fontsize=8, color="0.35")
        ax.set_xlabel("ms per 1920×1080 frame (log)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_title("accuracy against speed")
    axes[1].set_title("perceptual error" if use_flip else "damage")
    fig.suptitle(f"{res.device} — {res.date}", fontsize=9)
    fig.tight_layout()
    for ax, shown in labels:  # after layout, so label spacing is computed in final pixels
        _label_points(ax, shown, colours)
    fig.savefig(path)


OUTPUT_NAMES = ("results.csv", "README.md", "speed_vs_accuracy.png")


def write_outputs(res: BenchResult, out_dir: Path, scenes: list[Scene]) -> list[Path]:
    """results.csv, README.md and speed_vs_accuracy.png (OUTPUT_NAMES) under out_dir (replaced on every run)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / name for name in OUTPUT_NAMES]
    write_csv(res, paths[0])
    write_readme(res, paths[1], paths[2].name, scenes)
    plot_chart(res, paths[2])
    return paths


def bench(out_dir: Path | str = "docs/bench", quick: bool = False, device: str | None = None,
          method_names: list[str] | None = None, frames: int | None = None, flip: bool | None = None,
          seed: int = 0, scene_names: list[str] | None = None, log: Callable[[str], None] | None = None,
          command: str = "") -> BenchResult:
    """The whole benchmark: scenes (small ones when quick), every method, the three outputs."""
    scenes = generate_scenes(small=quick, seed=seed, names=scene_names, warn=log)
    with_flip = (not quick and M.flip_available()) if flip is None else bool(flip and M.flip_available())
    n = frames if frames is not None else (5 if quick else 20)
    res = run_bench(scenes, method_names, device, timed_frames=n, warmup=2 if quick else 3,
                    with_flip=with_flip, log=log, command=command)
    write_outputs(res, Path(out_dir), scenes)
    return res


if __name__ == "__main__":  # python -m mlaa_stream.bench.accuracy [OPTIONS]: the same as `mlaa-stream bench`
    from mlaa_stream.cli.bench_cmd import bench_command

    bench_command(prog_name="python -m mlaa_stream.bench.accuracy")
