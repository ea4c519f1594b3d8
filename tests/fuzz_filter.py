"""Fuzz the spatial filter with hypothesis (run by test_reliability.py in a subprocess, so that a native
crash fails that test instead of killing pytest): shapes, dtypes, channels, presets, linear input, HDR transfers and
special values (NaN, ±Inf, negative, huge). Prints one summary line: `examples N seconds S`.

    python tests/fuzz_filter.py [MAX_EXAMPLES]
"""
from __future__ import annotations

import sys
import time

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from mlaa_stream.device.transfer import TRANSFERS
from mlaa_stream.spatial.filter import PRESETS, Filter
from mlaa_stream.spatial.nonfinite import SAMPLE_LIMIT

# Few distinct frame sizes and formats: each new (size, format, options) is a PoCL kernel build of seconds.
SHAPES = [(3, 5), (24, 31)]
CASES = ([(preset, np.uint8, 3) for preset in PRESETS]
         + [("default", dt, c) for dt in (np.uint8, np.uint16, np.float16, np.float32) for c in (0, 1, 4)]
         + [("linear_input", dt, c) for dt in (np.float16, np.float32) for c in (0, 1, 3, 4)]
         + [(transfer, dt, c) for transfer in TRANSFERS for dt in (np.uint8, np.uint16) for c in (0, 3, 4)])
FLOAT_SPECIALS = [np.nan, np.inf, -np.inf, -5.0, -1e30, 1e30, 3e38, -3e38, 0.0, 1.0, 65504.0]
_filters: dict[str, Filter] = {}
examples = 0


def filter_for(options: str) -> Filter:
    if options not in _filters:
        kwargs = ({"linear_input": True} if options == "linear_input" else
                  {"transfer": options} if options in TRANSFERS else PRESETS[options])
        _filters[options] = Filter(**kwargs)
    return _filters[options]


def make_frame(rng: np.random.Generator, shape, dtype, channels: int, special_rate: float) -> np.ndarray:
    full = shape if channels == 0 else (*shape, channels)
    if np.dtype(dtype).kind == "f":
        frame = rng.random(full, dtype=np.float32)
        mask = rng.random(full) < special_rate
        frame[mask] = rng.choice(np.array(FLOAT_SPECIALS, np.float32), size=int(mask.sum()))
        with np.errstate(over="ignore"):
            return frame.astype(dtype)
    top = np.iinfo(dtype).max
    frame = rng.integers(0, top, full, endpoint=True, dtype=np.int64)
    mask = rng.random(full) < special_rate
    frame[mask] = rng.choice([0, top], size=int(mask.sum()))
    return frame.astype(dtype)


@settings(max_examples=int(sys.argv[1]) if len(sys.argv) > 1 else 60, deadline=None, derandomize=True,
          database=None, suppress_health_check=list(HealthCheck))
@given(case=st.sampled_from(CASES), shape=st.sampled_from(SHAPES), seed=st.integers(0, 2**32 - 1),
       special_rate=st.sampled_from([0.0, 0.01, 0.2, 1.0]))
def check_filter(case, shape, seed, special_rate) -> None:
    global examples
    options, dtype, channels = case
    frame = make_frame(np.random.default_rng(seed), shape, dtype, channels, special_rate)
    out = filter_for(options).process(frame)
    examples += 1
    assert out.shape == frame.shape and out.dtype == frame.dtype, (out.shape, out.dtype)
    if frame.dtype.kind == "f":
        finite = np.isfinite(frame)
        assert np.isfinite(out[finite]).all(), f"{case} {shape}: finite input gave non-finite output"
        kept = ~finite | (np.abs(frame.astype(np.float32)) > SAMPLE_LIMIT)
        same = (out[kept] == frame[kept]) | (np.isnan(out[kept]) & np.isnan(frame[kept]))
        assert same.all(), f"{case} {shape}: a non-finite or out-of-range sample was changed"
        same = (out[~finite] == frame[~finite]) | (np.isnan(out[~finite]) & np.isnan(frame[~finite]))
        assert same.all(), f"{case} {shape}: a non-finite sample was changed"


if __name__ == "__main__":
    t0 = time.perf_counter()
    check_filter()
    print(f"examples {examples} seconds {time.perf_counter() - t0:.1f}")
