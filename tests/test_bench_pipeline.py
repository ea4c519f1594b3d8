"""The end-to-end benchmark (mlaa_stream.bench.pipeline) runs its rows, the temporal stage's included, on a tiny
clip. Only that the rows exist and are positive: timings belong to the benchmark, not to the tests."""
from __future__ import annotations

import pytest

from mlaa_stream.bench import pipeline as P
from mlaa_stream.spatial.filter import Filter


def test_pipeline_bench_rows_with_the_temporal_stage(tmp_path):
    pytest.importorskip("av")
    with Filter() as filt, Filter(bgr=False, keep_regions=True) as tfilt:
        rows = P.bench_size("tiny", 96, 64, 6, filt, str(tmp_path), "libx264", "ultrafast", repeat=1,
                            temporal_filter=tfilt)
    assert P.TEMPORAL_ROW in rows and "transcode (decode+encode)" in rows
    assert all(v > 0 for k, v in rows.items() if k != P.TEMPORAL_SHARE)
    assert 0.0 < rows[P.TEMPORAL_SHARE] <= 1.0


def test_pipeline_bench_without_the_temporal_stage_has_no_temporal_rows(tmp_path):
    pytest.importorskip("av")
    with Filter() as filt:
        rows = P.bench_size("tiny", 96, 64, 4, filt, str(tmp_path), "libx264", "ultrafast", repeat=1)
    assert P.TEMPORAL_ROW not in rows and P.TEMPORAL_SHARE not in rows
