"""The SLAM round trip (amr_evaluation.map_round_trip): a map built by SLAM, saved, read back.

It serves the particle filter and the planner while the simulator drives the true world.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from amr_common.world.world import World
from amr_evaluation.map_round_trip import round_trip_summary, run_round_trip
from amr_evaluation.mapping_metrics import occupied_centres

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import slam_round_trip  # noqa: E402


def test_a_slam_map_of_twin_maze_small_localizes_and_navigates_the_true_world(tmp_path):
    # On the filter's own defaults (no filter_params): it expects the map's walls inside the
    # occupied cells. Expecting them on the cells' free edges it never localized here with the
    # defaults, and the round trip widened its check (8 cm, 90 %).
    row = run_round_trip("twin_maze_small", 1, tmp_path, map_duration=60.0,
                         navigation_duration=60.0)
    # The map: Nav2 files, read back as a world, lying on the true walls (the world's frame).
    map_world = World.load(row["map_file"])
    distance = World.load("twin_maze_small").clearances(occupied_centres(map_world.raster))
    assert np.mean(distance <= 0.03) >= 0.95
    # From another start than the mapping one (south_east), the filter must find itself on
    # the SLAM map (global localization), then drive.
    assert row["start"] != "south_east"
    assert row["time_to_localized_s"] is not None and row["false_localizations"] == 0
    assert row["goal_reached"] and row["final_position_error_m"] <= 0.05
    assert row["navigation_collisions"] == 0 == row["collisions"]
    summary = round_trip_summary([row])
    assert summary["goal_share"] == 1.0 and summary["false_localizations"] == 0


@pytest.mark.parametrize("argv, message", [
    (["--worlds", "no_such_world"], "no_such_world"),
    (["--seeds", "x"], "seed"),
    (["--pf-param", "beams:=0"], "beams"),
    (["--duration", "0"], "--duration"),
])
def test_round_trip_option_mistakes_are_one_line_errors(capsys, tmp_path, argv, message):
    with pytest.raises(SystemExit) as exit_info:
        slam_round_trip.parse_args([*argv, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and len(err.strip().splitlines()) == 1, err
    assert message in err, err


@pytest.mark.slow
def test_ctrl_c_or_a_closed_terminal_ends_the_round_trips_without_a_traceback(tmp_path):
    """Ctrl-C printed a KeyboardInterrupt traceback; SIGHUP (the terminal closed) killed it."""
    import os
    import signal
    import subprocess

    from tests.processes import terminate, wait_for
    runs = {}
    for signum in (signal.SIGINT, signal.SIGHUP):
        log = tmp_path / f"{signum.name}.log"
        with open(log, "w") as stream:
            runs[signum] = (subprocess.Popen(
                [sys.executable, str(SCRIPTS / "slam_round_trip.py"), "--worlds", "lab02",
                 "--seeds", "0", "--jobs", "1", "--map-duration", "3000", "--out",
                 str(tmp_path / signum.name)], stdout=stream, stderr=subprocess.STDOUT,
                env=dict(os.environ)), log)
    try:
        for process, log in runs.values():
            wait_for(lambda: "1 episodes" in log.read_text() or process.poll() is not None,
                     60.0, "the episodes to start")
        for signum, (process, log) in runs.items():
            assert process.poll() is None, log.read_text()
            process.send_signal(signum)
        for process, _ in runs.values():
            process.wait(30.0)
    finally:
        for process, _ in runs.values():
            terminate(process, 5.0)
    for signum, (process, log) in runs.items():
        output = log.read_text()
        assert process.returncode == (129 if signum == signal.SIGHUP else 130), output
        assert "slam_round_trip: interrupted" in output and "Traceback" not in output, output
