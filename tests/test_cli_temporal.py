"""The temporal options of the filter command: --temporal on video, --stats, refusal elsewhere."""
from __future__ import annotations

import csv
from pathlib import Path

from click.testing import CliRunner

from mlaa_stream.cli.main import main

DEMO = Path(__file__).resolve().parent.parent / "fixtures" / "demo"


def test_video_gets_the_temporal_stage_and_stats(tmp_path):
    out, stats = tmp_path / "out.mp4", tmp_path / "stats.csv"
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(out), "--temporal",
                                    "--stats", str(stats), "-q"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(stats.open()))
    assert len(rows) == 10 and rows[0]["model"] == "reset"
    assert {r["model"] for r in rows[1:]} <= {"static", "global", "dense"}


def test_temporal_is_off_by_default_and_stats_imply_it(tmp_path):
    out = tmp_path / "out.mp4"
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(out), "-v"])
    assert res.exit_code == 0, res.output
    assert out.exists() and "temporal models" not in res.output
    stats = tmp_path / "stats.csv"
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(tmp_path / "b.mp4"),
                                    "--stats", str(stats), "-q"])
    assert res.exit_code == 0 and stats.exists()
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(tmp_path / "c.mp4"),
                                    "--no-temporal", "--stats", str(tmp_path / "none.csv"), "-q"])
    assert res.exit_code == 0 and not (tmp_path / "none.csv").exists()


def test_temporal_on_a_folder_is_refused(tmp_path):
    res = CliRunner().invoke(main, [str(DEMO / "images"), "-o", str(tmp_path / "x"), "--temporal"])
    assert res.exit_code == 2
    assert "--temporal works on video input" in res.output
    assert not (tmp_path / "x").exists()
