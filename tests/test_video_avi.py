"""An AVI output keeps the source's frame rate: AVI stores one index entry per tick of the stream's time base,
so an MP4 source's 1/12288 time base used to give a 600 fps AVI whose gaps were padded with empty frames."""
from __future__ import annotations

import os

import av
from click.testing import CliRunner

from mlaa_stream.cli.main import main

CLIP = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")  # 10 frames at 24 fps


def test_an_avi_output_has_the_source_rate_and_one_entry_per_frame(tmp_path):
    out = tmp_path / "o.avi"
    r = CliRunner().invoke(main, [CLIP, "-o", str(out)])
    assert r.exit_code == 0, r.output
    with av.open(str(out)) as c:
        s = c.streams.video[0]
        assert s.average_rate == 24 and s.frames == 10
        assert len(list(c.decode(s))) == 10
