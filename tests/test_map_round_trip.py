"""The SLAM round trip (amr_evaluation.map_round_trip): a map built by SLAM, saved, read back.

It serves the particle filter and the planner while the simulator drives the true world.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from amr_common.world import World
from amr_evaluation.map_round_trip import round_trip_summary, run_round_trip
from amr_evaluation.mapping_metrics import occupied_centres

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import slam_round_trip  # noqa: E402


def test_a_slam_map_of_twin_maze_small_localizes_and_navigates_the_true_world(tmp_path):
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
