"""Benchmarks, each runnable as `python -m mlaa_stream.bench.NAME` (`accuracy` is `mlaa-stream bench`).

They import the library and the yardstick, never the other way round."""
