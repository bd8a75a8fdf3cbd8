"""scripts/bench_realdata.py: a real log through the Mapper, the field's measures out.

On the first 120 scans of the shipped Intel slice (a second or so), and its refusals: a log,
relations or parameter that cannot be used is one line and exit status 2, before any work.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "scripts"))

import bench_realdata  # noqa: E402

DATA = REPO / "tests" / "data"
LOG = DATA / "intel-1000-1399.clf.gz"
RELATIONS = DATA / "intel-1000-1399.relations"


def test_the_figures_maps_and_report_of_a_log(tmp_path, capsys):
    report = tmp_path / "report.json"
    assert bench_realdata.main([str(LOG), "--relations", str(RELATIONS), "--scans", "120",
                                "--quiet", "--map-out", str(tmp_path / "map"), "--plot",
                                str(tmp_path / "map.png"), "--report", str(report)]) == 0
    out = capsys.readouterr().out
    assert "scans with a pose: 120 of 120" in out and "relation error (SLAM)" in out
    figures = json.loads(report.read_text())
    assert figures["scans_with_pose"] == 120 and len(figures["trajectory"]) == 120
    assert figures["relation_error"]["relations_used"] > 10
    assert figures["relation_error"]["translation_m"][0] < 0.03
    assert figures["self_consistency"] > 0.9
    assert figures["x_real_time"] > 0 and figures["update_cpu_ms"]["p99"] > 0
    assert (tmp_path / "map" / "map.yaml").is_file() and (tmp_path / "map.png").is_file()


@pytest.mark.parametrize("extra,message", [
    (["--relations", "missing.relations"], "cannot read relations"),
    (["--param", "no_such:=1"], "unknown parameter"),
    (["--param", "resolution_m:=-1"], "resolution_m must be > 0"),
])
def test_bad_options_are_one_line_and_status_2(tmp_path, capsys, extra, message):
    assert bench_realdata.main([str(LOG), "--scans", "5", "--quiet", *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_a_log_without_scans_or_no_log_at_all(tmp_path, capsys):
    empty = tmp_path / "empty.clf"
    empty.write_text("PARAM robot_frontlaser_offset 0.0\nODOM 0 0 0 0 0 0 1.0 host 1.0\n")
    assert bench_realdata.main([str(empty)]) == 2
    assert "no FLASER or ROBOTLASER1 scan" in capsys.readouterr().err
    assert bench_realdata.main([str(tmp_path / "missing.clf")]) == 2
    assert "cannot read CARMEN log" in capsys.readouterr().err
