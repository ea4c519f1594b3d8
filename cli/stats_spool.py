"""The temporal stage's per-frame stats rows, moved to a temporary file as a run goes.

A stage appends one row a frame (1-2.5 KB: the motion model, timings, the ring), which the command line reads at
the end for `--stats` and the model summary; kept in memory, a long video grew the process without bound (about
1 KB a frame with the default method). The spool keeps the newest rows with the stage -- a stage may still amend
its latest row -- and pickles the older ones (their values as the stage made them: the CSV is the same)."""
from __future__ import annotations

import pickle
import tempfile
from typing import Any, Iterator

from mlaa_stream.temporal.methods import stats_lists

SPOOL_EVERY = 256  # rows with the stage before the older ones move to the file
KEEP = 8           # the newest rows left with the stage


class StatsSpool:
    """Wraps a temporal stage (called as the stage, every other attribute the stage's); `rows()` yields every
    frame's row in order, the spooled ones first."""

    def __init__(self, stage: Any):
        self.stage = stage
        self._file = None
        self.spooled = 0

    def __call__(self, *args, **kwargs):
        out = self.stage(*args, **kwargs)
        self.drain()
        return out

    def __getattr__(self, name: str):
        return getattr(self.stage, name)

    def drain(self, keep: int | None = None) -> None:
        """Move all but the newest `keep` (KEEP) rows to the file once SPOOL_EVERY have gathered."""
        keep = KEEP if keep is None else keep
        lists = stats_lists(self.stage)
        rows = self.stage.stats if lists else []
        n = len(rows) - keep
        if n < SPOOL_EVERY:
            return
        if self._file is None:
            self._file = tempfile.TemporaryFile(prefix="mlaa-stream-stats-")
        for row in rows[:n]:
            pickle.dump(row, self._file, protocol=pickle.HIGHEST_PROTOCOL)
        for rows_of in lists:
            del rows_of[:n]
        self.spooled += n

    def rows(self) -> Iterator[dict]:
        if self._file is not None:
            self._file.seek(0)
            for _ in range(self.spooled):
                yield pickle.load(self._file)
        yield from self.stage.stats

    def close(self) -> None:
        self.stage.close()
        if self._file is not None:
            self._file.close()
            self._file = None
