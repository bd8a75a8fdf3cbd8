"""scripts/compare.py: two evaluate.py result sets side by side, each kind with its figures.

Every kind (wall following, localization, navigation, mapping) shows its own columns, each side
is labelled with the links it ran (the set's own metadata), two kinds in one table are refused,
and only a regular file of sane size is read (one line, exit code 2).
"""
from __future__ import annotations

import json
import os
import re
import resource
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SCRIPTS = REPO / "scripts"
sys.path.insert(0, str(SCRIPTS))
import compare  # noqa: E402
import evaluate  # noqa: E402

ODOMETRY_MAPPER = "examples.odometry_mapper:OdometryMapper"


def write_set(path: Path, rows: list[dict], meta: dict, key: str = "meta") -> Path:
    path.mkdir(parents=True, exist_ok=True)
    (path / "results.json").write_text(json.dumps({key: meta, "episodes": rows}))
    return path


def lines_of(capsys) -> list[str]:
    return capsys.readouterr().out.splitlines()


def table_rows(lines: list[str]) -> list[dict[str, str]]:
    """The table's rows as {header: cell} (cells are 2+ spaces apart, 'A | B' inside one)."""
    header = re.split(r"\s{2,}", lines[0])
    return [dict(zip(header, re.split(r"\s{2,}", line))) for line in lines[1:]]


def test_two_mapping_sets_show_the_mapping_figures_and_the_mapper_each_ran(tmp_path, capsys):
    grid = ["--slam", "--worlds", "lab02", "--starts", "outer", "--profiles",
            "turtlebot3_clean", "--duration", "15", "--jobs", "1", "--no-sheet"]
    assert evaluate.main([*grid, "--out", str(tmp_path / "a")]) == 0
    assert evaluate.main([*grid, "--mapper", ODOMETRY_MAPPER, "--out", str(tmp_path / "b")]) == 0
    summary = json.loads((tmp_path / "b" / "results.json").read_text())["summary"]
    assert summary["kind"] == "mapping" and summary["links"] == {
        "controller": "amr_control.wall_follower:WallFollower", "mapper": ODOMETRY_MAPPER}
    capsys.readouterr()
    assert compare.main([str(tmp_path / "a"), str(tmp_path / "b")]) == 0
    out = lines_of(capsys)
    assert out[0] == "mapping (--slam) sets"
    assert out[1].endswith("(controller amr_control.wall_follower:WallFollower, mapper "
                           "amr_mapping.mapper:Mapper)")
    assert out[2].endswith(f"(controller amr_control.wall_follower:WallFollower, mapper "
                           f"{ODOMETRY_MAPPER})")
    [row] = table_rows(out[3:-1])
    assert (row["world"], row["start"], row["n"]) == ("lab02", "outer", "1|1")

    def both(column: str) -> list[float]:
        return [float(value) for value in row[f"{column} A|B"].split(" | ")]
    # The odometry mapper takes the drifting odometry as the truth: its poses drift with it,
    # and its map is drawn twice where they do; the project's corrects it.
    rmse, precision = both("rmse_cm"), both("precision_%")
    assert rmse[0] < 1.0 < rmse[1] and precision[0] > precision[1]
    assert both("recall_%")[0] > 90.0 and both("update_ms")[0] > 0.0
    assert row["closures A|B"].startswith("0.0 | -")  # the odometry mapper closes no loop


@pytest.mark.parametrize("kind, row, columns", [
    ("wall_following", {"collisions": 1, "min_clearance_m": 0.05, "laps": 2,
                        "explored_fraction": 0.5, "rms_wall_error_m": 0.02},
     ["failed", "collisions", "clear_cm", "laps", "explored_%", "wall_err_cm"]),
    ("localization", {"false_localizations": 0, "time_to_localized_s": 3.0,
                      "tracking_error_mean_m": 0.01, "tracking_error_p95_m": 0.02},
     ["failed", "false", "localized", "time_s", "track_cm", "p95_cm"]),
    ("navigation", {"goal": "inner_far", "goal_reached": True, "goal_reached_time_s": 40.0,
                    "collisions": 0, "false_localizations": 0, "min_clearance_m": 0.07},
     ["goal", "failed", "false", "collisions", "goals", "time_s", "track_cm", "clear_cm"]),
])
def test_each_kind_has_its_columns_and_a_star_where_the_counts_differ(tmp_path, capsys, kind,
                                                                      row, columns):
    base = {"world": "lab02", "start": "outer", "profile": "ideal", "seed": 0}
    a = write_set(tmp_path / "a", [{**base, **row}], {"kind": kind})
    b = write_set(tmp_path / "b", [{**base, **row, "error": "RuntimeError: boom"}],
                  {"kind": kind, "links": {"controller": "my.ctrl:Mine"}})
    assert compare.main([str(a), str(b)]) == 0
    out = lines_of(capsys)
    assert f"B: {b} (controller my.ctrl:Mine" in out[2]
    header = out[3].split()
    assert [h for h in header if h not in ("world", "start", "profile", "n", "A|B")] == columns
    assert out[4].endswith("*")  # one failed on B's side


def test_sets_of_different_kinds_are_refused_in_one_line(tmp_path, capsys):
    base = {"world": "lab02", "start": "outer", "profile": "ideal", "seed": 0}
    navigation = write_set(tmp_path / "nav", [{**base, "goal": "inner_far"}], {"goals": "all"})
    # A set written before evaluate.py recorded its kind: known by its keys.
    mapping = write_set(tmp_path / "slam", [{**base, "trajectory_rmse_m": 0.01}],
                        {"mapper": "amr_mapping.mapper:Mapper"}, key="summary")
    localization = write_set(tmp_path / "loc", [{**base, "time_to_localized_s": 2.0}],
                             {"localizer": "amr_localization.particle_filter:ParticleFilter"},
                             key="summary")
    for a, b, kinds in ((navigation, mapping, ("navigation", "mapping")),
                        (localization, navigation, ("localization", "navigation"))):
        assert compare.main([str(a), str(b)]) == 2
        captured = capsys.readouterr()
        assert captured.out == "" and len(captured.err.strip().splitlines()) == 1
        assert f"is a {kinds[0]}" in captured.err and f"a {kinds[1]}" in captured.err
        assert "compare two sets of one kind" in captured.err


def _limited_memory() -> None:  # a reader that does not stop fails fast instead of swapping
    resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))


def test_only_a_regular_results_file_of_sane_size_is_read(tmp_path, capsys):
    good = write_set(tmp_path / "good", [{"world": "lab02"}], {})
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    # A device or a pipe never ends: refused at once (/dev/zero grew to 24 GB, deaf to Ctrl-C).
    for source in ("/dev/zero", str(fifo)):
        run = subprocess.run([sys.executable, str(SCRIPTS / "compare.py"), source, str(good)],
                             capture_output=True, text=True, timeout=60,
                             preexec_fn=_limited_memory)
        assert run.returncode == 2 and run.stdout == ""
        assert run.stderr == f"compare: {source}: not an evaluate.py result set (not a " \
                             "regular file)\n"
    huge = tmp_path / "huge.json"
    with huge.open("wb") as stream:  # sparse: nothing is written
        stream.truncate(compare.MAX_RESULTS_BYTES + 1)
    assert compare.main([str(huge), str(good)]) == 2
    assert "larger than 100 MB" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert compare.main([str(tmp_path / "empty"), str(good)]) == 2
    assert "results.json: not an evaluate.py result set (no such file)" in \
        capsys.readouterr().err
