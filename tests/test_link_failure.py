"""A link that fails at run time fails the run: one rule for run_sim.py and evaluate.py.

A class given with --controller, --follower, --localizer, --planner or --mapper that raises
(from its 20th call, say) or returns what its interface forbids (None, NaN, a wrong shape):
run_sim.py logged one error and exited 0 with the robot standing ("map written"), or crashed the
graph with a traceback and no map, while evaluate.py called the same episodes failed. Now its
node logs it once and stops the robot, the run ends there with exit code 3 and the reason in
the summary line and the report, and evaluate.py's episode fails with the same reason.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from amr_common.plugins.link_failure import (
    LinkFailure,
    checked_commands,
    checked_estimate,
    checked_localization,
    checked_path,
    checked_raster,
    checked_statistics,
    link_call,
)
from amr_common.world.map_raster import Raster

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import evaluate  # noqa: E402
import run_sim  # noqa: E402

LINKS = "tests.failing_links"


# --- the rule -------------------------------------------------------------------------------

def test_what_a_link_may_return_and_what_is_its_failure():
    assert checked_commands("controller", (np.float32(0.1), 1)) == (pytest.approx(0.1), 1.0)
    for bad, shown in [(None, "None"), ((math.nan, 0.0), "(nan, 0.0)"), ((0.1,), "(0.1,)"),
                       (("fast", 0.0), "('fast', 0.0)"), ((True, 0.0), "(True, 0.0)")]:
        with pytest.raises(LinkFailure, match=rf"^controller failed: compute_commands returned "
                                              rf"{__import__('re').escape(shown)}, not \(v, w\)"):
            checked_commands("controller", bad)
    assert checked_path(SimpleNamespace(points=[[0, 0], [1, 1]])).shape == (2, 2)
    for plan, why in [(None, "plan returned None, not a path with points"),
                      (SimpleNamespace(points=np.zeros((3, 7))), r"shape \(3, 7\), not \(K, 2\)"),
                      (SimpleNamespace(points=np.zeros((0, 2))), r"shape \(0, 2\)"),
                      (SimpleNamespace(points=[[0, math.nan]]), "not all finite")]:
        with pytest.raises(LinkFailure, match=why):
            checked_path(plan)
    rejected = SimpleNamespace(status="rejected: too few points", pose=(math.nan,) * 3)
    assert checked_estimate(rejected) is rejected  # the interface's way to skip a scan
    for estimate in (None, SimpleNamespace(status="matched", pose=(0.0, math.nan, 0.0)),
                     SimpleNamespace(status="matched", pose=(0.0, 0.0))):
        with pytest.raises(LinkFailure, match="^mapper failed: update"):
            checked_estimate(estimate)
    raster = Raster(np.zeros((2, 3), dtype=np.int8), 0.05, (0.0, 0.0))
    assert checked_raster(raster) is raster
    for bad in (None, Raster(np.zeros(3, dtype=np.int8), 0.05, (0.0, 0.0)),
                Raster(np.zeros((2, 2), dtype=np.int8), 0.0, (0.0, 0.0)),
                Raster(np.zeros((2, 2), dtype=np.int8), 0.05, (math.nan, 0.0))):
        with pytest.raises(LinkFailure, match="^mapper failed: occupancy_raster returned"):
            checked_raster(bad)
    with pytest.raises(LinkFailure, match="statistics returned None, not a dict"):
        checked_statistics(None)
    assert checked_localization((math.nan,) * 3, False)[1] is False  # no estimate yet: fine
    with pytest.raises(LinkFailure, match="localized is True with the estimate"):
        checked_localization((math.nan, 0.0, 0.0), True)


def test_a_call_that_raises_is_the_links_failure_but_what_its_interface_allows():
    def plan(start, goal):
        raise ValueError("goal (9, 9) is unreachable")

    with pytest.raises(ValueError, match="unreachable"):  # the planner's "no path"
        link_call("planner", "plan", plan, (0, 0), (9, 9), allowed=(ValueError,))
    with pytest.raises(LinkFailure) as info:
        link_call("planner", "plan", lambda s, g: 1 / 0, (0, 0), (9, 9), allowed=(ValueError,))
    failure = info.value.placed(12.3456, "my_planner:Wave")
    assert str(failure) == ("planner 'my_planner:Wave' failed at t=12.35 s: plan raised "
                            "ZeroDivisionError: division by zero")


# --- run_sim.py and evaluate.py -------------------------------------------------------------

NAVIGATION = ["--goal", "inner_far"]
CASES = {  # name: (options, the reason; run_sim's report and evaluate's episode say it)
    "controller raises": (["--controller", f"{LINKS}:RaisingController"],
                          "controller '{L}:RaisingController' failed at t=0.95 s: "
                          "compute_commands raised RuntimeError: compute_commands broke"),
    "controller NaN": (["--controller", f"{LINKS}:NanController"],
                       "controller '{L}:NanController' failed at t=0.95 s: compute_commands "
                       "returned (nan, 0.0), not (v, w) as two finite numbers"),
    "controller None": (["--controller", f"{LINKS}:NoneController"],
                        "controller '{L}:NoneController' failed at t=0.95 s: compute_commands "
                        "returned None, not (v, w) as two finite numbers"),
    "follower raises": (["--follower", f"{LINKS}:RaisingFollower", *NAVIGATION],
                        "follower '{L}:RaisingFollower' failed at t=26.15 s: compute_commands "
                        "raised RuntimeError: compute_commands broke"),
    "follower inf": (["--follower", f"{LINKS}:InfFollower", *NAVIGATION],
                     "follower '{L}:InfFollower' failed at t=26.15 s: compute_commands "
                     "returned (0.1, inf), not (v, w) as two finite numbers"),
    "localizer raises": (["--localizer", f"{LINKS}:RaisingLocalizer", *NAVIGATION],
                         "localizer '{L}:RaisingLocalizer' failed at t=0.95 s: correct raised "
                         "RuntimeError: correct broke"),
    "planner None": (["--planner", f"{LINKS}:NonePlanner", *NAVIGATION],
                     "planner '{L}:NonePlanner' failed at t=25.95 s: plan returned None, not "
                     "a path with points"),
    "planner (3, 7)": (["--planner", f"{LINKS}:ShapePlanner", *NAVIGATION],
                       "planner '{L}:ShapePlanner' failed at t=25.95 s: plan's points have "
                       "shape (3, 7), not (K, 2) with K >= 1"),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_a_link_that_fails_fails_the_run_sim_run_and_the_evaluate_episode_alike(
        case, tmp_path, capsys):
    options, reason = CASES[case]
    reason = reason.format(L=LINKS)
    report_path = tmp_path / "run.json"
    code = run_sim.main([*options, "--duration", "30", "--report", str(report_path)])
    captured = capsys.readouterr()
    report = json.loads(report_path.read_text())
    assert code == 3, captured.err
    assert report["link_failure"] == reason
    summary = next(line for line in captured.out.splitlines() if line.startswith("run_sim: lab02"))
    assert summary.endswith(f"; FAILED: {reason}")
    assert report["sim_time_s"] == pytest.approx(float(reason.split("t=")[1].split(" s")[0]))
    assert "Traceback" not in captured.err
    # evaluate.py: the same episode fails with the same reason (exit code 3).
    goal = ["--goals", options[options.index("--goal") + 1]] if "--goal" in options else []
    out = tmp_path / "evaluate"
    assert evaluate.main(["--worlds", "lab02", "--starts", "outer", "--duration", "30",
                          "--no-sheet", "--jobs", "1", "--out", str(out), *goal,
                          *options[:2]]) == 3
    (episode,) = json.loads((out / "results.json").read_text())["episodes"]
    assert episode["error"] == reason


MAPPER_CASES = {  # mapper class: the reason (run_sim's report)
    "NoneUpdateMapper": "update returned None, not an estimate with a status text and a pose",
    "NanPoseMapper": "update's pose (status 'first') is (nan, nan, nan), not three finite "
                     "numbers",
    "NoneRasterMapper": "occupancy_raster returned None, not a Raster "
                        "(amr_common.world.map_raster) with 2-D integer values",
    "RaisingStatisticsMapper": "statistics raised RuntimeError: statistics broke",
}


@pytest.mark.slow
@pytest.mark.parametrize("mapper", list(MAPPER_CASES))
def test_a_mapper_that_fails_fails_the_slam_run_and_keeps_the_map_saved_before(
        mapper, tmp_path, capsys):
    # Such a mapper crashed the graph with a traceback (None, a raster or statistics of None),
    # or gave "SLAM: nothing mapped" and exit 0 (NaN poses).
    maps = tmp_path / "maps"
    maps.mkdir()
    before = {name: f"an earlier save's {name}" for name in ("map.yaml", "map.pgm")}
    for name, text in before.items():
        (maps / name).write_text(text)
    report_path = tmp_path / "run.json"
    code = run_sim.main(["--slam", "--mapper", f"{LINKS}:{mapper}", "--map-out", str(maps),
                         "--duration", "5", "--report", str(report_path)])
    captured = capsys.readouterr()
    report = json.loads(report_path.read_text())
    assert code == 3, captured.err
    assert report["link_failure"].startswith(f"mapper '{LINKS}:{mapper}' failed at t=")
    assert report["link_failure"].endswith(MAPPER_CASES[mapper])
    assert f"; FAILED: {report['link_failure']}" in captured.out
    assert "Traceback" not in captured.err and report["slam"]["map_file"] is None
    assert {name: (maps / name).read_text() for name in before} == before


@pytest.mark.slow
def test_evaluate_slam_counts_a_mapper_whose_poses_are_all_nan_as_failed(tmp_path, capsys):
    # Its episodes were "RMSE n/a", exit code 0.
    out = tmp_path / "out"
    assert evaluate.main(["--slam", "--worlds", "lab02", "--starts", "outer", "--duration",
                          "5", "--profiles", "turtlebot3_clean", "--jobs", "1", "--out",
                          str(out), "--mapper", f"{LINKS}:NanPoseMapper"]) == 3
    (episode,) = json.loads((out / "results.json").read_text())["episodes"]
    assert episode["error"] == (f"mapper '{LINKS}:NanPoseMapper' failed at t=0.00 s: "
                                f"{MAPPER_CASES['NanPoseMapper']}")
    assert "1 failed" in capsys.readouterr().out


@pytest.mark.slow
def test_run_robot_ends_failed_with_a_final_zero_when_its_controller_fails(ros, tmp_path):
    # It logged one error and stayed up: the Burger stood still and the run went on as if well.
    from tests.emulator_process import commands_in, running_emulator
    from tests.processes import terminate
    log_path = tmp_path / "run_robot.log"
    with running_emulator(tmp_path, "--wall-ahead-at", "2.0", "--corridor-width", "0.8",
                          "--seed", "1") as (emulator, log), open(log_path, "w") as output:
        robot = subprocess.Popen(
            [sys.executable, str(SCRIPTS / "run_robot.py"), "--domain-id",
             os.environ["ROS_DOMAIN_ID"], "--cmd-vel", "stamped", "--controller",
             f"{LINKS}:RaisingController"], stdout=output, stderr=subprocess.STDOUT)
        try:
            code = robot.wait(timeout=60)  # it ends by itself
        finally:
            terminate(robot, timeout=10)
    text = log_path.read_text()
    commands = commands_in(log)
    assert code == 3, text
    assert f"the run failed: controller '{LINKS}:RaisingController' failed: compute_commands " \
           "raised RuntimeError: compute_commands broke" in text
    assert "Traceback" not in text
    moving = [c for c in commands if c["linear"][0] != 0.0]
    assert moving, "it drove before its 20th call"
    last = commands[-1]
    assert (last["linear"][0], last["angular"][2]) == (0.0, 0.0)
