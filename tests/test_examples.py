"""Bring your own algorithm: the course-style examples run in place of the project's links.

Headless (the episodes), through evaluate.py and through the ROS graph (run_sim.py); a class
that cannot be loaded is one line and exit code 2 before anything runs; compare.py sets two
result sets side by side. Short episodes on lab02 (the examples localize, drive and map there).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from amr_common.plugins import interfaces
from amr_common.plugins.loader import load_class
from amr_common.world.world import World

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import compare  # noqa: E402
import evaluate  # noqa: E402
import run_sim  # noqa: E402
import tune  # noqa: E402

MCL = "examples.likelihood_mcl:LikelihoodFieldMcl"
WAVEFRONT = "examples.wavefront_planner:WavefrontPlanner"
PURSUIT = "examples.plain_pursuit:PlainPursuit"
ODOMETRY_MAPPER = "examples.odometry_mapper:OdometryMapper"
EXAMPLES = ["--localizer", MCL, "--planner", WAVEFRONT, "--follower", PURSUIT]


def test_the_examples_implement_their_interfaces():
    world = World.load("lab02")
    built = {"localizer": load_class(MCL, "localizer")(world, particles=100),
             "planner": load_class(WAVEFRONT, "planner")(world),
             "follower": load_class(PURSUIT, "follower")(0.05),
             "mapper": load_class(ODOMETRY_MAPPER, "mapper")({})}
    assert isinstance(built["mapper"], interfaces.Mapper)
    assert isinstance(built["localizer"], interfaces.Localizer)
    assert isinstance(built["planner"], interfaces.Planner)
    assert isinstance(built["follower"], interfaces.PathFollower)
    plan = built["planner"].plan(world.starts["outer"][:2], world.goals["inner_far"])
    assert isinstance(plan, interfaces.PlannedPath)
    # The wavefront keeps its clearance: every cell centre of the path is clearance_m off.
    assert world.clearances(plan.points[1:-1]).min() >= 0.15 - 1e-9


def test_the_likelihood_field_mcl_localizes_headless():
    from amr_evaluation.localization_episode import run_localization_episode
    # The clean Burger: the example weighs each scan as taken at its stamp (no de-skew); under
    # the reality gap (turtlebot3) its heading error p95 is 8.3 degrees here.
    result = run_localization_episode("lab02", "inner", profile="turtlebot3_clean", seed=0,
                                      duration=8.0, record=False, localizer=MCL)
    assert result.time_to_localized_s is not None and result.time_to_localized_s < 4.0
    assert result.false_localizations == 0
    assert result.tracking_error_p95_m < 0.03 and result.heading_error_p95_deg < 3.0


def test_the_three_examples_drive_to_the_goal_headless():
    from amr_evaluation.navigation_episode import run_navigation_episode
    result = run_navigation_episode("lab02", "inner", "north_west", profile="turtlebot3",
                                    duration=60.0, pose_source="filter", localizer=MCL,
                                    planner_class=WAVEFRONT, follower=PURSUIT,
                                    record_trajectory=False)
    assert result.goal_reached and result.collisions == 0 and result.stalled is False
    assert result.false_localizations == 0 and result.final_position_error_m < 0.03


def test_the_odometry_mapper_maps_at_known_poses_and_smears_as_the_odometry_drifts():
    from amr_evaluation.mapping_episode import TYPICAL_DRIFT, run_mapping_episode
    exact, drifting = (run_mapping_episode("lab02", profile="turtlebot3_clean", seed=0,
                                           duration=40.0, drift=drift, mapper=ODOMETRY_MAPPER)
                       for drift in (None, TYPICAL_DRIFT))
    for result in (exact, drifting):
        assert result.mapper == ODOMETRY_MAPPER and result.collisions == 0
        assert result.loop_closure is False and result.loop_closures is None  # not reported
        assert result.update_ms_median > 0.0 and result.scans == 201
    # Exact poses: every wall it saw is in the map (range noise leaves a few cells behind it).
    assert exact.trajectory_rmse_m < 1e-9
    assert exact.recall >= 0.95 and exact.precision >= 0.75
    # Drift: its poses are the odometry's, and the walls drawn again land beside the first.
    assert drifting.trajectory_max_m == pytest.approx(drifting.odometry_max_error_m)
    assert drifting.trajectory_max_m > 0.03
    assert drifting.precision < exact.precision - 0.1


def test_evaluate_maps_with_the_odometry_mapper(tmp_path, capsys):
    out = tmp_path / "slam"
    assert evaluate.main(["--slam", "--worlds", "lab02", "--profiles", "turtlebot3_clean",
                          "--duration", "20", "--jobs", "1", "--mapper", ODOMETRY_MAPPER,
                          "--slam-param", "resolution_m:=0.03", "--out", str(out)]) == 0
    assert f"mapper {ODOMETRY_MAPPER} {{'resolution_m': 0.03}}" in capsys.readouterr().out
    data = json.loads((out / "results.json").read_text())
    assert data["summary"]["mapper"] == ODOMETRY_MAPPER and data["summary"]["failed"] == 0
    episode = data["episodes"][0]
    assert episode["mapper"] == ODOMETRY_MAPPER and episode["loop_closure"] is False
    assert 0.5 < episode["precision"] <= 1.0 and episode["recall"] > 0.8


def test_evaluate_takes_the_mapper_from_its_config(tmp_path, capsys):
    config = tmp_path / "set.yaml"
    config.write_text(f"worlds: [lab02]\nmapper: {PURSUIT}\n")
    assert evaluate.main(["--config", str(config), "--slam", "--duration", "1"]) == 2
    assert evaluate.main(["--config", str(config), "--duration", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert f"mapper '{PURSUIT}' has no update" in err[0] and "--mapper needs --slam" in err[1]


def test_evaluate_runs_the_examples_and_compare_sets_them_side_by_side(tmp_path, capsys):
    grid = ["--worlds", "lab02", "--starts", "inner", "--goals", "north_west", "--profiles",
            "turtlebot3", "--duration", "45", "--jobs", "1", "--no-sheet"]
    assert evaluate.main([*grid, "--pose-source", "truth", "--out", str(tmp_path / "a")]) == 0
    assert evaluate.main([*grid, *EXAMPLES, "--out", str(tmp_path / "b")]) == 0
    meta = json.loads((tmp_path / "b" / "results.json").read_text())["meta"]
    assert meta["kind"] == "navigation" and meta["links"] == {
        "controller": "amr_control.wall_follower:WallFollower", "localizer": MCL,
        "planner": WAVEFRONT, "follower": PURSUIT}
    assert evaluate.main(["--localize", "--worlds", "lab02", "--starts", "inner", "--profiles",
                          "turtlebot3", "--duration", "5", "--jobs", "1", "--localizer", MCL,
                          "--out", str(tmp_path / "c")]) == 0
    capsys.readouterr()
    assert compare.main([str(tmp_path / "a"), str(tmp_path / "b" / "results.json")]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("lab02"))
    assert row.split()[:5] == ["lab02", "inner", "north_west", "turtlebot3", "1|1"]
    assert "1/1 | 1/1" in row and "0 | 0" in row  # both reached the goal, neither was false
    assert f"follower {PURSUIT}" in out
    # A: the true pose, no localizer ran; B: every link named, the project's included.
    assert "planner amr_planning.planner:Planner" in out and "localizer" not in \
        out.splitlines()[1]
    summary = json.loads((tmp_path / "c" / "results.json").read_text())["summary"]
    assert summary["kind"] == "localization" and summary["links"]["localizer"] == MCL
    assert compare.main([str(tmp_path / "a"), str(tmp_path / "c")]) == 2  # a --localize set
    assert "compare two sets of one kind" in capsys.readouterr().err


def test_compare_refuses_what_is_not_a_result_set(tmp_path, capsys):
    (tmp_path / "x.json").write_text('{"rows": []}')
    assert compare.main([str(tmp_path / "x.json"), str(tmp_path / "x.json")]) == 2
    assert compare.main([str(tmp_path / "missing.json"), str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "not an evaluate.py result set" in err[0]


@pytest.mark.slow
def test_run_sim_runs_the_examples_in_the_ros_graph(tmp_path):
    report = tmp_path / "run.json"
    assert run_sim.main(["--world", "lab02", "--start", "inner", "--goal", "north_west",
                         "--profile", "turtlebot3", "--duration", "60", *EXAMPLES,
                         "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    assert data["goal_reached_time_s"] is not None and data["collisions"] == 0
    assert data["localization"]["false_localizations"] == 0


@pytest.mark.parametrize("script, argv, message", [
    (run_sim, ["--goal", "inner_far", "--planner", "examples.no_such:Planner"],
     "planner 'examples.no_such:Planner': cannot import module 'examples.no_such'"),
    (run_sim, ["--localize", "--localizer", "examples.likelihood_mcl:Mcl"],
     "module 'examples.likelihood_mcl' has no 'Mcl'"),
    (run_sim, ["--goal", "inner_far", "--follower", WAVEFRONT],
     f"follower '{WAVEFRONT}' has no set_path, clear_path, compute_commands"),
    (run_sim, ["--localizer", MCL], "--localizer needs --localize or --goal"),
    (run_sim, ["--slam", "--mapper", PURSUIT], f"mapper '{PURSUIT}' has no update"),
    (evaluate, ["--worlds", "lab02", "--goals", "inner_far", "--localizer", PURSUIT],
     f"localizer '{PURSUIT}' has no set_scan_geometry"),
    (evaluate, ["--worlds", "lab02", "--follower", PURSUIT], "--follower needs --goals"),
    (evaluate, ["--worlds", "lab02", "--slam", "--mapper", PURSUIT],
     f"mapper '{PURSUIT}' has no update"),
    (evaluate, ["--worlds", "lab02", "--slam", "--mapper", "examples.odometry_mapper:Mapper"],
     "module 'examples.odometry_mapper' has no 'Mapper'"),
    (evaluate, ["--worlds", "lab02", "--mapper", ODOMETRY_MAPPER], "--mapper needs --slam"),
    (evaluate, ["--worlds", "lab02", "--slam", "--mapper", ODOMETRY_MAPPER, "--slam-param",
                "loop_closure:=false"], "--slam-param: loop_closure: no such parameter of "
                                       f"mapper {ODOMETRY_MAPPER}"),
    (tune, ["--worlds", "lab02", "--goals", "inner_far", "--space", "kp=1,2", "--planner",
            MCL], f"planner '{MCL}' has no plan, warm_up"),
])
def test_a_class_that_cannot_be_loaded_is_one_line_and_exit_2(capsys, script, argv, message):
    try:
        code = script.main([*argv, "--duration", "1"])
    except SystemExit as exc:  # argparse's error
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len([line for line in err if not line.startswith("usage")]) == 1
    assert message in err[-1]


@pytest.mark.parametrize("node_module, node_class, link, spec, tuning", [
    ("amr_localization.particle_filter_node", "ParticleFilterNode", "localizer", MCL,
     "particles"),
    ("amr_planning.planner_node", "PlannerNode", "planner", WAVEFRONT, "clearance_m"),
    ("amr_control.pure_pursuit_node", "PurePursuitNode", "follower", PURSUIT, "lookahead_m"),
])
def test_each_node_loads_its_link_from_its_parameter(ros, node_module, node_class, link,
                                                     spec, tuning):
    import importlib

    from rclpy.parameter import Parameter
    cls = getattr(importlib.import_module(node_module), node_class)
    node = ros.add(cls(f"{link}_node", context=ros.context, parameter_overrides=[
        Parameter(link, value=spec), Parameter(tuning, value=0.5 if tuning != "particles"
                                               else 200)]))
    assert node.get_parameter(tuning).value in (0.5, 200)  # the class's own, declared
    assert node.trigger_configure().name == "SUCCESS"
    wrong = ros.add(cls(f"{link}_wrong", context=ros.context, parameter_overrides=[
        Parameter(link, value="amr_mapping.mapper:Mapper")]))
    assert wrong.trigger_configure().name == "FAILURE"  # logged: what the class lacks


def test_the_slam_node_refuses_a_mapper_without_the_interface(ros):
    from rclpy.parameter import Parameter

    from amr_mapping.slam_node import SlamNode
    node = ros.add(SlamNode("slam_wrong", context=ros.context, parameter_overrides=[
        Parameter("mapper", value=MCL)]))
    assert node.trigger_configure().name == "FAILURE"
    mine = ros.add(SlamNode("slam_mine", context=ros.context, parameter_overrides=[
        Parameter("mapper", value=ODOMETRY_MAPPER), Parameter("map_size_m", value=8.0)]))
    assert mine.trigger_configure().name == "SUCCESS"  # its own parameters, declared
    assert mine.mapper.log_odds.shape == (400, 400)


@pytest.mark.slow
def test_run_sim_maps_with_the_odometry_mapper_in_the_ros_graph(tmp_path):
    report = tmp_path / "run.json"
    assert run_sim.main(["--world", "lab02", "--profile", "turtlebot3_clean", "--duration",
                         "20", "--slam", "--mapper", ODOMETRY_MAPPER, "--map-out",
                         str(tmp_path / "map"), "--report", str(report)]) == 0
    slam = json.loads(report.read_text())["slam"]
    assert slam["scans"] >= 90 and slam["trajectory_rmse_m"] < 1e-9  # the simulator's odometry
    assert slam["precision"] >= 0.75 and slam["recall"] >= 0.95
    assert World.load(str(tmp_path / "map" / "map.yaml")).starts  # a map a run can use
