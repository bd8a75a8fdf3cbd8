"""evaluate.py, amr_evaluation.evaluation and evaluation_report.

Grids, overrides, controllers, result files.
"""
from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from amr_evaluation.evaluation import (
    EpisodeOutcome,
    EpisodeSpec,
    EvaluationError,
    PluginSpecError,
    check_controller,
    expand_grid,
    load_config,
    parse_seeds,
    parse_start_list,
    run_episodes,
)
from amr_evaluation.evaluation_report import (
    ProgressBar,
    format_table,
    outcome_row,
    verdict,
    write_csv,
    write_json,
)
from amr_evaluation.executors import LocalPoolExecutor, episode_time_limit

REPO = Path(__file__).resolve().parent.parent
EVALUATE = REPO / "scripts" / "evaluate.py"


# --- grids and options ---------------------------------------------------------------------

def test_grid_is_worlds_x_starts_x_profiles_x_seeds():
    specs = expand_grid("lab02,corridor_loop", "all", "ideal,turtlebot3", "0,1", duration=30.0)
    from amr_common.world.world import World
    starts = {w: list(World.load(w).starts) for w in ("lab02", "corridor_loop")}
    expected = [(w, s, p, seed) for w in ("lab02", "corridor_loop") for s in starts[w]
                for p in ("ideal", "turtlebot3") for seed in (0, 1)]
    assert [(s.world, s.start, s.profile, s.seed) for s in specs] == expected
    assert all(s.duration == 30.0 for s in specs)
    assert len({s.label for s in specs}) == len(specs)


def test_named_starts_apply_to_the_worlds_that_have_them():
    specs = expand_grid(["lab02", "corridor_loop"], "outer,south", "ideal", [3])
    assert [(s.world, s.start) for s in specs] == [("lab02", "outer"), ("corridor_loop", "south")]
    with pytest.raises(EvaluationError, match="nowhere_start.*exist in none"):
        expand_grid("lab02,corridor_loop", "outer,south,nowhere_start", "ideal", [0])
    with pytest.raises(EvaluationError,
                       match="world 'corridor_loop' has none of the starts outer"):
        expand_grid("lab02,corridor_loop", "outer", "ideal", [0])


def test_all_worlds_and_bad_names():
    from amr_common.world.world import bundled_worlds
    assert {s.world for s in expand_grid("all", "all", "ideal", "0")} == set(bundled_worlds())
    with pytest.raises(EvaluationError, match="unknown world 'atlantis'"):
        expand_grid("atlantis")
    with pytest.raises(EvaluationError, match="profile 'gazebo'"):
        expand_grid("lab02", profiles="gazebo")
    with pytest.raises(EvaluationError, match="no worlds"):
        expand_grid(" , ")
    for duration in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(EvaluationError, match="duration"):
            expand_grid("lab02", duration=duration)
    with pytest.raises(EvaluationError, match="dt"):
        expand_grid("lab02", dt=0.0)


def test_seeds_parse_lists_and_ranges():
    assert parse_seeds("0,1,2") == [0, 1, 2]
    assert parse_seeds("3-6, 1") == [3, 4, 5, 6, 1]
    assert parse_seeds([0, "2-3", 2]) == [0, 2, 3]
    assert parse_seeds(7) == [7]
    for bad in ("x", "-1", "5-2", "1.5", [True]):
        with pytest.raises(EvaluationError, match="seed"):
            parse_seeds(bad)


def test_config_file_is_validated(tmp_path):
    config = load_config(REPO / "evaluations" / "example.yaml")
    specs = expand_grid(config["worlds"], config["starts"], config["profiles"], config["seeds"],
                        duration=config["duration"], dt=config["dt"],
                        controller=config["controller"], params=config["params"])
    assert len(specs) == 8 and {s.world for s in specs} == {"lab02", "corridor_loop"}
    bad = tmp_path / "bad.yaml"
    cases = {"worlds: [lab02]\nspeed: 3\n": "unknown key.*speed",
             "starts: all\n": "'worlds' is required",
             "worlds: [lab02]\nduration: long\n": "'duration' must be a number",
             "worlds: [lab02]\njobs: 0\n": "'jobs' must be a positive integer",
             "worlds: [lab02]\nparams: [1, 2]\n": "'params' must map",
             "- just a list\n": "expected a mapping",
             "worlds: [lab02\n": "not valid YAML: .* at line 2, column 1",
             "worlds: 5\n": "'worlds' must be a name, a list of names or 'all', got 5",
             "worlds: lab02\nprofiles: {a: 1}\n": "'profiles' must be a name",
             "worlds: lab02\nstarts: [[1, 2]]\n": r"'starts': start pose \[1, 2\]",
             "worlds: lab02\ncontroller: 3\n": "'controller' must be MODULE:CLASS"}
    for text, message in cases.items():
        bad.write_text(text)
        with pytest.raises(EvaluationError, match=message):
            load_config(bad)
    with pytest.raises(EvaluationError, match="cannot read"):
        load_config(tmp_path / "missing.yaml")
    bad.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe" * 20)
    with pytest.raises(EvaluationError, match="not a text file"):
        load_config(bad)


def test_start_lists_mix_names_and_poses():
    assert parse_start_list("outer,-1,-1.5,1.57,inner") == ["outer", (-1.0, -1.5, 1.57), "inner"]
    assert parse_start_list([-1, -1, 1.57]) == [(-1.0, -1.0, 1.57)]  # YAML: [-1, -1, 1.57]
    assert parse_start_list(["outer", [0.6, -0.6, 4.71]]) == ["outer", (0.6, -0.6, 4.71)]
    for bad in ("1,2", [[1, 2]], [True], "a,1,2,3,4", "1,nan,0"):
        with pytest.raises(EvaluationError, match=r"x,y,theta|\[x, y, theta\]|neither"):
            parse_start_list(bad)


def test_a_pose_applies_to_every_world_and_maps_without_starts_need_one(course_map, tmp_path):
    specs = expand_grid(f"lab02,{course_map}", "all,-1.0,-1.0,1.57", "ideal", "0", duration=1)
    assert [spec.label for spec in specs] == [
        "lab02/outer/ideal/seed 0", "lab02/inner/ideal/seed 0", "lab02/-1,-1,1.57/ideal/seed 0",
        "course_map/-1,-1,1.57/ideal/seed 0"]
    with pytest.raises(EvaluationError, match="names no start poses, so 'all' is none"):
        expand_grid(str(course_map), "all")
    with pytest.raises(EvaluationError, match="inside obstacle"):
        expand_grid(str(course_map), "0,0,0")
    config = tmp_path / "poses.yaml"
    config.write_text("worlds: [lab02]\nstarts: [outer, [1.0, -1.0, 1.57], '-0.6,-0.6,4.71']\n")
    loaded = load_config(config)
    assert [s.start for s in expand_grid(loaded["worlds"], loaded["starts"])] == [
        "outer", (1.0, -1.0, 1.57), (-0.6, -0.6, 4.71)]


# --- controller loading ---------------------------------------------------------------------

class RecordingController:
    """A user's controller: constructor takes dt and gains."""

    def __init__(self, dt, gain=1.0):
        if gain <= 0:
            raise ValueError("gain must be positive")
        self.dt, self.gain = dt, gain

    def compute_commands(self, z_scan, z_v, z_w):
        return 0.0, 0.0


def test_controller_loading_errors_are_clear():
    spec = f"{__name__}:RecordingController"
    assert check_controller(spec, {"gain": 2.0}, 0.05) is RecordingController
    cases = {"no_colon_here": "must look like MODULE:CLASS",
             "amr_sim.no_such_module:X": "cannot import module 'amr_sim.no_such_module'",
             f"{__name__}:Missing": "has no 'Missing'",
             "json:JSONDecoder": "has no compute_commands"}
    for bad, message in cases.items():
        with pytest.raises(PluginSpecError, match=message):
            check_controller(bad, {}, 0.05)
    with pytest.raises(PluginSpecError, match="rejected its parameters.*unknown_gain"):
        check_controller(spec, {"unknown_gain": 1}, 0.05)
    with pytest.raises(PluginSpecError, match="gain must be positive"):
        check_controller(spec, {"gain": -1.0}, 0.05)


def test_evaluate_reports_a_bad_controller_and_exits_2(tmp_path):
    out = subprocess.run([sys.executable, str(EVALUATE), "--worlds", "lab02", "--controller",
                          "amr_sim.nothing_here:Ctrl", "--out", str(tmp_path / "o")],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert "cannot import module 'amr_sim.nothing_here'" in out.stderr
    assert "Traceback" not in out.stderr


# --- result files and summaries --------------------------------------------------------------

def _result(spec, **metrics):
    from amr_evaluation.episode import EpisodeResult
    return EpisodeResult(world=spec.world, start=spec.start, profile=spec.profile, seed=spec.seed,
                         steps=1200, sim_time_s=60.0, wall_time_s=1.0, **metrics)


def _outcomes():
    a = EpisodeSpec("lab02", "outer", "ideal", 0, duration=60.0)
    b = EpisodeSpec("lab02", "inner", "turtlebot3", 1, duration=60.0)
    c = EpisodeSpec("corridor_loop", "south", "ideal", 2, duration=60.0)
    return [
        EpisodeOutcome(a, _result(a, collisions=0, first_collision_time_s=None,
                                  min_clearance_m=0.0421, distance_m=11.5, laps=2,
                                  explored_fraction=0.5,
                                  rms_wall_error_m=0.012), wall_time_s=1.234),
        EpisodeOutcome(b, _result(b, collisions=3, first_collision_time_s=12.5,
                                  min_clearance_m=0.0, distance_m=4.0, laps=0,
                                  explored_fraction=0.2,
                                  rms_wall_error_m=math.nan), wall_time_s=2.0),
        EpisodeOutcome(c, error="RuntimeError: controller exploded", wall_time_s=0.1),
    ]


def test_json_and_csv_hold_every_episode(tmp_path):
    outcomes = _outcomes()
    write_json(tmp_path / "r.json", outcomes, {"controller": "x:Y", "params": {"kp": 4.0}})
    write_csv(tmp_path / "r.csv", outcomes)
    data = json.loads((tmp_path / "r.json").read_text())  # strict JSON: NaN would not parse back
    assert data["meta"]["params"] == {"kp": 4.0}
    first, second, third = data["episodes"]
    assert first == {"world": "lab02", "start": "outer", "profile": "ideal", "seed": 0,
                     "sim_time_s": 60.0, "collisions": 0, "first_collision_time_s": None,
                     "min_clearance_m": 0.0421, "distance_m": 11.5, "laps": 2,
                     "explored_fraction": 0.5, "rms_wall_error_m": 0.012, "invalid_commands": 0,
                     "wall_time_s": 1.234, "error": None}
    assert second["rms_wall_error_m"] is None and second["first_collision_time_s"] == 12.5
    assert third["error"] == "RuntimeError: controller exploded" and third["collisions"] is None
    with open(tmp_path / "r.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert [r["world"] for r in rows] == ["lab02", "lab02", "corridor_loop"]
    assert rows[1]["collisions"] == "3" and float(rows[1]["first_collision_time_s"]) == 12.5
    assert rows[0]["first_collision_time_s"] == "" and rows[2]["error"].startswith("RuntimeError")


def test_table_is_aligned_and_verdict_counts_collisions():
    outcomes = _outcomes()
    table = format_table(outcome_row(o) for o in outcomes).splitlines()
    header, rule, *body = table
    assert header.split()[:4] == ["world", "start", "profile", "seed"]
    assert len({len(line) for line in [rule] + body[:3]}) <= 2  # rows as wide as the rule (rstrip)
    end = header.index("collisions") + len("collisions")  # numbers right-aligned under headers
    assert body[1][end - 2:end + 1] == " 3 " and body[0][end - 2:end + 1] == " 0 "
    assert "4.2" in body[0] and "controller exploded" in table[-1]
    line, code = verdict(outcomes)
    assert code == 3  # an episode failed: worse than a collision
    assert "COLLISIONS in 1/3" in line and "lab02/inner/turtlebot3/seed 1" in line
    assert "worst clearance 0.0 cm" in line and "1 episode(s) FAILED" in line
    line, code = verdict(outcomes[:1])
    assert code == 0 and line.startswith("verdict: no collisions in 1/1") and "4.2 cm" in line
    assert verdict(outcomes[:2])[1] == 1


def test_progress_bar_only_on_a_terminal():
    import io

    class Tty(io.StringIO):
        def isatty(self):
            return True

    plain, tty = io.StringIO(), Tty()
    for stream in (plain, tty):
        bar = ProgressBar(4, stream=stream)
        for done in range(1, 5):
            bar(done, 4)
        bar.finish()
    assert plain.getvalue() == ""
    assert "\r[" in tty.getvalue() and "4/4 episodes" in tty.getvalue()


# --- real runs -------------------------------------------------------------------------------

class DriveStraight:
    """Drives straight ahead at `speed` whatever it sees: it must hit the wall in front."""

    def __init__(self, dt, speed=0.1):
        self.speed = speed

    def compute_commands(self, z_scan, z_v, z_w):
        return self.speed, 0.0


class Exploding:
    def __init__(self, dt):
        self.calls = 0

    def compute_commands(self, z_scan, z_v, z_w):
        self.calls += 1
        if self.calls == 3:
            raise RuntimeError("controller exploded on call 3")
        return 0.0, 0.0


def _evaluate(tmp_path: Path, *args: str) -> tuple[subprocess.CompletedProcess, Path]:
    out_dir = tmp_path / "out"
    proc = subprocess.run([sys.executable, str(EVALUATE), "--out", str(out_dir), *args],
                          capture_output=True, text=True, timeout=300, cwd=REPO)
    return proc, out_dir


@pytest.mark.slow
def test_two_episodes_in_two_processes_write_readable_results(tmp_path):
    proc, out = _evaluate(tmp_path, "--worlds", "lab02", "--starts", "outer,inner",
                          "--duration", "20", "--jobs", "2")
    assert proc.returncode in (0, 1), proc.stderr
    data = json.loads((out / "results.json").read_text())
    episodes = data["episodes"]
    assert [(e["start"], e["error"]) for e in episodes] == [("outer", None), ("inner", None)]
    assert data["meta"]["jobs"] == 2
    assert data["meta"]["controller"] == "amr_control.wall_follower:WallFollower"
    assert data["meta"]["kind"] == "wall_following"  # for compare.py: what the set ran
    assert data["meta"]["links"] == {"controller": "amr_control.wall_follower:WallFollower"}
    for e in episodes:
        assert e["sim_time_s"] == pytest.approx(20.0)
        assert 0.5 < e["distance_m"] < 20.0 * 0.22 + 1e-6  # it moved, within the speed limit
        assert 0.0 < e["explored_fraction"] <= 1.0
    assert proc.returncode == (1 if any(e["collisions"] for e in episodes) else 0)
    with open(out / "results.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert ([float(r["distance_m"]) for r in rows]
            == pytest.approx([e["distance_m"] for e in episodes]))
    assert "verdict:" in proc.stdout and "lab02  outer" in proc.stdout
    assert (out / "sheet.png").stat().st_size > 10_000
    assert "\r[" not in proc.stderr  # no progress bar when not on a terminal


@pytest.mark.slow
def test_a_collision_gives_exit_code_1_and_its_time(tmp_path):
    # Straight north from lab02 "outer" (1, -1): the wall at y = 1.2 is 2.2 - 0.105 m ahead.
    proc, out = _evaluate(tmp_path, "--worlds", "lab02", "--starts", "outer", "--duration", "14",
                          "--controller", "tests.test_evaluation:DriveStraight",
                          "-p", "speed:=0.2", "--no-sheet")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    (episode,) = json.loads((out / "results.json").read_text())["episodes"]
    assert episode["collisions"] >= 1
    assert episode["first_collision_time_s"] == pytest.approx((2.2 - 0.105) / 0.2, abs=0.5)
    assert "COLLISIONS in 1/1 episodes: lab02/outer/ideal/seed 0" in proc.stdout


def test_a_failing_controller_is_reported_not_fatal():
    specs = [EpisodeSpec("lab02", "outer", duration=1.0,
                         controller="tests.test_evaluation:Exploding"),
             EpisodeSpec("lab02", "outer", duration=1.0,
                         controller="tests.test_evaluation:DriveStraight")]
    seen = []
    outcomes = run_episodes(specs, jobs=1,
                            progress=lambda done, total, o: seen.append((done, total)))
    assert seen == [(1, 2), (2, 2)]
    assert "RuntimeError: controller exploded on call 3" in outcomes[0].error
    assert outcomes[1].error is None
    assert outcomes[1].result.distance_m == pytest.approx(0.1, abs=0.01)
    assert verdict(outcomes)[1] == 3


def test_ros_params_file_gives_the_controller_what_the_node_gets(tmp_path):
    from amr_control.wall_follower import WallFollower
    from amr_evaluation.evaluation import load_ros_params_file
    params = tmp_path / "sim.yaml"
    params.write_text("wall_follower:\n  ros__parameters:\n    kp: 2.5\n    use_sim_time: true\n"
                      "    controller: amr_control.wall_follower:WallFollower\n"
                      "/**:\n  ros__parameters:\n    kd: 0.5\n"
                      "pure_pursuit:\n  ros__parameters:\n    max_linear_speed_mps: 0.1\n")
    assert load_ros_params_file(params, WallFollower) == {"kp": 2.5, "kd": 0.5}
    assert load_ros_params_file(params, RecordingController)["use_sim_time"] is True
    params.write_text("kp: 2.5\n")
    with pytest.raises(EvaluationError, match="no '<node>: ros__parameters:' section"):
        load_ros_params_file(params, WallFollower)
    config = tmp_path / "set.yaml"  # a config's params_file is relative to the config
    config.write_text("worlds: [lab02]\nparams_file: sim.yaml\n")
    assert load_config(config)["params_file"] == str(params)


class LidarAwareController(RecordingController):
    """A controller that, like WallFollower, has a lidar_offset_x_m parameter."""

    received: list = []

    def __init__(self, dt, lidar_offset_x_m=0.0):
        super().__init__(dt)
        LidarAwareController.received.append(lidar_offset_x_m)

    @classmethod
    def parameter_descriptions(cls):
        return {"lidar_offset_x_m": (0.0, "Forward position of the LiDAR [m].")}


@pytest.mark.parametrize("profile, params, expected", [
    ("ideal", {}, 0.0),                                  # the course robot scans from its centre
    ("turtlebot3", {}, -0.032),                          # the Burger's base_scan
    ("turtlebot3", {"lidar_offset_x_m": -0.05}, -0.05),  # the user's value wins
])
def test_episodes_tell_the_controller_where_the_profiles_lidar_is(profile, params, expected):
    from amr_evaluation.evaluation import run_one
    LidarAwareController.received.clear()
    spec = EpisodeSpec(world="lab02", start="outer", profile=profile, seed=0, duration=0.1,
                       controller=f"{__name__}:LidarAwareController", params=params)
    outcome = run_one(spec)
    assert outcome.error is None
    assert LidarAwareController.received == [expected]

# --- controllers that end their process or command garbage ---------------------------------
# A dead worker is that episode's error and the others still run; NaN or non-number commands
# are counted per episode and fail the verdict.

_HERE = "tests.test_evaluation"


class Standing:
    """Commands zero: a clean episode."""

    def __init__(self, dt):
        pass

    def compute_commands(self, z_scan, z_v, z_w):
        return 0.0, 0.0


class ExitsTheProcess(Standing):
    """Ends its process on the 5th call: os._exit (no cleanup) or sys.exit."""

    def __init__(self, dt, how="os._exit"):
        self.how, self.calls = how, 0

    def compute_commands(self, z_scan, z_v, z_w):
        self.calls += 1
        if self.calls == 5:
            if self.how == "os._exit":
                os._exit(7)
            sys.exit(4)
        return 0.0, 0.0


class Garbage(Standing):
    """Every other command is NaN, inf or not a number at all."""

    def __init__(self, dt, kind="nan"):
        self.kind, self.calls = kind, 0

    def compute_commands(self, z_scan, z_v, z_w):
        self.calls += 1
        if self.calls % 2:
            return 0.0, 0.0
        return {"nan": (math.nan, 0.0), "inf": (0.1, -math.inf), "text": ("fast", None)}[self.kind]


def _pool_spec(controller: str, **params) -> EpisodeSpec:
    return EpisodeSpec("lab02", "outer", duration=1.0, controller=f"{_HERE}:{controller}",
                       params=params)


def test_a_worker_that_dies_is_its_episodes_error_and_the_others_still_run():
    specs = [_pool_spec("Standing"), _pool_spec("ExitsTheProcess", how="os._exit"),
             _pool_spec("Standing"), _pool_spec("ExitsTheProcess", how="sys.exit"),
             _pool_spec("Standing"), _pool_spec("Standing")]
    seen = []
    outcomes = run_episodes(specs, jobs=2, progress=lambda done, total, o: seen.append(done))
    assert seen == [1, 2, 3, 4, 5, 6]
    errors = [o.error for o in outcomes]
    assert errors[0] is None and errors[2] is None and errors[4] is None and errors[5] is None
    assert "worker process died" in errors[1] and "exit code 7" in errors[1]
    assert "sys.exit(4)" in errors[3]
    assert all(o.result.steps == 20 for i, o in enumerate(outcomes) if i not in (1, 3))
    line, code = verdict(outcomes)
    assert code == 3 and "2 episode(s) FAILED" in line


def test_sys_exit_in_a_controller_does_not_end_a_single_process_evaluation():
    (outcome,) = run_episodes([_pool_spec("ExitsTheProcess", how="sys.exit")], jobs=1)
    assert "sys.exit(4)" in outcome.error


def _misbehaving(how: str) -> EpisodeSpec:
    return EpisodeSpec("lab02", "outer", duration=1.0, controller="tests.controllers:Misbehaves",
                       params={"how": how})


def test_an_episode_past_its_time_limit_is_its_error_and_the_others_still_run():
    """A controller that sleeps forever used to hang the whole evaluation."""
    specs = [_misbehaving("none"), _misbehaving("sleep"), _misbehaving("exit"),
             _misbehaving("none"), _misbehaving("sleep"), _misbehaving("none")]
    seen = []
    outcomes = run_episodes(specs, jobs=2, episode_timeout_s=3.0,
                            progress=lambda done, total, o: seen.append(done))
    assert seen == [1, 2, 3, 4, 5, 6]
    errors = [o.error for o in outcomes]
    for k in (1, 4):
        assert "ran past its wall-clock limit of 3 s" in errors[k], errors[k]
        assert 3.0 <= outcomes[k].wall_time_s < 60.0
    assert "worker process died (exit code 7)" in errors[2]
    assert all(outcomes[k].error is None and outcomes[k].result.steps == 20 for k in (0, 3, 5))


@pytest.mark.parametrize("how, error", [("sleep", "ran past its wall-clock limit of 2 s"),
                                        ("exit", "worker process died (exit code 7)")])
def test_a_single_episode_is_protected_too(how, error):
    """One episode (or --jobs 1) used to run in this process: os._exit ended it."""
    (outcome,) = run_episodes([_misbehaving(how)], jobs=1, episode_timeout_s=2.0)
    assert outcome.result is None and error in outcome.error
    assert os.getpid() == _PID  # still here


_PID = os.getpid()  # this test process


def test_the_default_time_limit_is_the_larger_of_60_s_and_twice_the_simulated_time():
    assert episode_time_limit(1.0) == 60.0 and episode_time_limit(600.0) == 1200.0
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="episode timeout must be a number of seconds > 0"):
            LocalPoolExecutor(2, bad)
    assert LocalPoolExecutor(2, 0).episode_timeout_s is None  # 0: no limit


@pytest.mark.parametrize("kind, shown", [("nan", "(nan, 0.0)"), ("inf", "(0.1, -inf)"),
                                         ("text", "('fast', None)")])
def test_a_controller_commanding_nan_inf_or_text_fails_its_episode_with_the_reason(kind, shown):
    # One rule with run_sim.py (amr_common.plugins.link_failure): such a controller has failed; its
    # episodes were counted as run with "invalid commands" (exit 1), its run_sim.py runs as
    # clean (exit 0).
    outcomes = run_episodes([_pool_spec("Standing"), _pool_spec("Garbage", kind=kind)], jobs=1)
    clean, garbage = outcomes
    assert clean.error is None and clean.result.invalid_commands == 0
    assert garbage.result is None and garbage.error == (
        f"controller '{_HERE}:Garbage' failed at t=0.05 s: compute_commands returned {shown}, "
        "not (v, w) as two finite numbers")  # its second call
    line, code = verdict(outcomes)
    assert code == 3 and "1 episode(s) FAILED to run" in line, line
    assert verdict(outcomes[:1])[1] == 0


# --- navigation episodes -------------------------------------------------------------------

def test_navigation_grid_is_worlds_x_starts_x_goals():
    from amr_common.world.world import World
    specs = expand_grid("lab02,maze_deadends", "outer,south_west",
                        goals="inner_far,north_east", pose_source="truth")
    assert [(s.world, s.start, s.goal, s.pose_source) for s in specs] == [
        ("lab02", "outer", "inner_far", "truth"),
        ("maze_deadends", "south_west", "north_east", "truth")]
    assert specs[0].label == "lab02/outer->inner_far/ideal/seed 0"
    assert [s.goal for s in expand_grid("lab02", "outer", goals="all")] == \
        list(World.load("lab02").goals)
    assert expand_grid("lab02", "outer")[0].goal is None  # no goals: wall following
    with pytest.raises(EvaluationError, match=r"goal\(s\) kitchen exist in none"):
        expand_grid("lab02", goals="kitchen,inner_far")
    with pytest.raises(EvaluationError, match="world 'lab02' has none of the goals kitchen"):
        expand_grid("lab02", goals="kitchen")
    with pytest.raises(EvaluationError, match="pose_source must be one of filter, truth"):
        expand_grid("lab02", goals="all", pose_source="oracle")


@pytest.mark.slow
def test_navigation_episodes_report_goals_and_exit_1_when_one_is_missed(tmp_path):
    proc, out = _evaluate(tmp_path, "--worlds", "lab02", "--starts", "outer", "--goals",
                          "inner_far,north_west", "--pose-source", "truth", "--duration", "30",
                          "--jobs", "1")
    assert proc.returncode == 1, proc.stdout + proc.stderr  # inner_far needs 42 s
    data = json.loads((out / "results.json").read_text())
    far, near = data["episodes"]
    assert (far["goal"], far["goal_reached"], far["stopped_time_s"]) == ("inner_far", False, None)
    assert near["goal"] == "north_west" and near["goal_reached"]
    assert near["final_position_error_m"] < 0.01 and near["path_length_m"] == pytest.approx(
        3.9, abs=0.1)
    assert data["meta"]["goals"] == "inner_far,north_west"
    with open(out / "results.csv", newline="") as stream:
        assert [r["goal"] for r in csv.DictReader(stream)] == ["inner_far", "north_west"]
    assert "goal reached in 1/2 episodes" in proc.stdout
    assert "NOT reached: lab02/outer->inner_far/ideal/seed 0" in proc.stdout
    assert "final err. cm" in proc.stdout


def test_one_episode_or_one_job_runs_in_a_worker_process_and_bad_jobs_are_refused():
    from amr_evaluation.executors import local_executor
    for jobs, episodes, workers in ((4, 1, 1), (1, 5, 1), (2, 5, 2), (2, None, 2)):
        executor = local_executor(jobs, episodes, 30.0)
        assert isinstance(executor, LocalPoolExecutor) and executor.episode_timeout_s == 30.0
        assert executor.workers(episodes or 10) == workers
    with pytest.raises(ValueError, match="jobs must be >= 1"):
        local_executor(0, 1)
