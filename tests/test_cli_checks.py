"""Option checks (cli_checks.py, launch_common.py) as run_sim.py and run_robot.py use them.

Start poses, -p names and values, output paths, domain ids (also topic.py's, lifecycle.py's and
ros_graph.py's), params files and controllers: every mistake is a one-line error with exit code
2, found before anything runs.
"""
from __future__ import annotations

import socket
import sys
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import lifecycle  # noqa: E402
import ros_graph  # noqa: E402
import run_robot  # noqa: E402
import run_sim  # noqa: E402
import topic  # noqa: E402


def _fails_with(capsys, argv, message):
    """run_sim.main(argv) exits 2 with `message` on one line, before simulating anything."""
    try:
        code = run_sim.main([*argv, *([] if "--duration" in argv else ["--duration", "2"])])
    except SystemExit as exc:  # argparse errors
        code = exc.code
    out, err = capsys.readouterr()
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1, f"one line, no usage, no warning:\n{err}"
    assert message in err, err
    assert "Traceback" not in err
    assert "simulated in" not in out and "ROS_DOMAIN_ID=" not in out  # checked up front: no run
    return err


def _robot_fails_with(capsys, argv, message):
    """run_robot.parse_args(argv) exits 2 with `message` on one line."""
    with pytest.raises(SystemExit) as exit_info:
        run_robot.parse_args(["--domain-id", "5", *argv])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2, err
    assert len(err.strip().splitlines()) == 1 and message in err, err


# --- start poses -----------------------------------------------------------------------

def test_pose_options_take_negative_numbers():
    args = run_sim.parse_args(["--start", "-1.0,-1.0,1.57", "--goal", "-0.5,1"])
    # The goal stays text until the world resolves it (a name or X,Y).
    assert args.start == (-1.0, -1.0, 1.57) and args.goal == "-0.5,1"
    assert run_sim.parse_args(["--start", "outer"]).start == "outer"


def test_start_all_on_a_map_without_starts_is_an_error(capsys, course_map):
    _fails_with(capsys, ["--world", str(course_map), "--start", "all"],
                "names no start poses, so '--start all' runs nothing")
    _fails_with(capsys, ["--world", str(course_map)], "give one with --start X,Y,THETA")
    _fails_with(capsys, ["--start", "1,2"], "neither a start name nor 'x,y,theta'")


# --- -p names and types ------------------------------------------------------------------

def test_a_misspelled_parameter_is_an_error_listing_the_known_ones(capsys):
    err = _fails_with(capsys, ["-p", "kpp:=5"], "-p kpp: no such wall follower parameter")
    assert "known: " in err and " kp, " in err and "wall_distance_m" in err


def test_a_bad_parameter_value_is_found_before_the_run(capsys):
    _fails_with(capsys, ["-p", "kp:=-1"], "wall follower parameters (-p, --params-file): kp must "
                                          "be >= 0 (got -1.0)")


# --- output paths --------------------------------------------------------------------------

def test_bad_output_paths_are_found_before_simulating(capsys, tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    _fails_with(capsys, ["--report", str(tmp_path)], "is a folder: give a file name")
    _fails_with(capsys, ["--record", str(tmp_path)], "is a folder: give a file name")
    _fails_with(capsys, ["--report", str(a_file / "r.json")], "is a file, not a folder")
    _fails_with(capsys, ["--plot", str(tmp_path / "p.xyz")], "matplotlib cannot write '.xyz'")
    _fails_with(capsys, ["--world", "corridor_loop", "--start", "all", "--plot",
                         str(a_file / "p.png")], "is a file, not a folder")


# --- domain ids and bad files -------------------------------------------------------------

@pytest.mark.parametrize("script", [run_sim, run_robot, topic, lifecycle, ros_graph])
@pytest.mark.parametrize("domain_id", ["-1", "233", "500", "x"])
def test_domain_ids_outside_0_232_are_refused(capsys, script, domain_id):
    with pytest.raises(SystemExit) as exit_info:
        script.parse_args([f"--domain-id={domain_id}", "list"])  # `list`: topic, lifecycle
    assert exit_info.value.code == 2
    assert "0-232" in capsys.readouterr().err


def test_domain_id_from_the_environment_is_checked(capsys, monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "500")
    _fails_with(capsys, [], "ROS_DOMAIN_ID in the environment must be within")
    with pytest.raises(SystemExit):
        run_robot.parse_args([])
    assert "0-232" in capsys.readouterr().err


def test_bad_params_files_and_controllers_are_one_line_errors(capsys, tmp_path, monkeypatch):
    cases = {"broken.yaml": ("wall_follower:\n  ros__parameters:\n    kp: [1\n",
                             "not a ROS 2 params file the nodes can read"),
             "binary.yaml": (b"\x89PNG\r\n\x1a\n\x00\xff\xfe" * 20,
                             "not a ROS 2 params file the nodes can read"),
             "mixed.yaml": ("wall_follower:\n  ros__parameters:\n    kp: [1, a]\n",
                            "Sequence should be of same type"),
             "flat.yaml": ("kp: 5\n", "Cannot have a value before ros__parameters")}
    for name, (content, message) in cases.items():
        path = tmp_path / name
        path.write_bytes(content) if isinstance(content, bytes) else path.write_text(content)
        _fails_with(capsys, ["--params-file", str(path)], message)
    (tmp_path / "broken_ctrl.py").write_text("class C:\n    def compute_commands(self)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    _fails_with(capsys, ["--controller", "broken_ctrl:C"],
                "cannot import module 'broken_ctrl': SyntaxError")
    with pytest.raises(SystemExit):
        run_robot.parse_args(["--controller", "broken_ctrl:C"])
    assert "SyntaxError" in capsys.readouterr().err


# --- the run's own options: one line each, before anything runs ----------------------------

@pytest.mark.parametrize("argv, message", [
    (["--no-such-option"], "unrecognized arguments: --no-such-option"),
    (["--duration", "0"], "--duration must be > 0"),
    (["--duration", "nan"], "--duration must be > 0"),
    (["--kidnap", "5,1,1"], "--kidnap must be T,X,Y,THETA"),
    (["--kidnap", "30,1,-1,0", "--duration", "10"],
     "--kidnap at 30 s comes after the run ends (--duration 10 s)"),
    (["--kidnap", "1,0,0,0"], "kidnap pose (0, 0) touches a wall"),
    (["--goal", "1e308,1e308"], "goal (1e+308, 1e+308) is outside the boundary"),
    (["--goal", "1.094,-0.2", "--profile", "turtlebot3"],
     "goal (1.094, -0.2) is too close to a wall: clearance 0.106 m < 0.135 m"),
    (["--dt", "10"], "--dt 10: dt must be in [0.0001, 1] (got 10.0)"),
    (["--seed", "-1"], "--seed -1: seed must be in [0, 4294967295] (got -1)"),
    (["--pf-param", "beams:=90"], "--pf-param needs --localize or --goal"),
])
def test_bad_run_options_are_one_line_errors(capsys, argv, message):
    _fails_with(capsys, argv, message)


def test_a_recording_must_be_an_mcap_file(capsys, tmp_path):
    _fails_with(capsys, ["--record", str(tmp_path / "x.txt")],
                "--record '" + str(tmp_path / "x.txt") + "': recordings are MCAP files")
    args = run_sim.parse_args(["--record", str(tmp_path / "run")])
    assert args.record == str(tmp_path / "run.mcap")


def test_a_foxglove_port_in_use_is_found_before_the_run(capsys):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        _fails_with(capsys, ["--foxglove", "--foxglove-port", str(port)],
                    f"--foxglove-port {port}: cannot listen on 127.0.0.1:{port}")


# --- --pf-param and -p: names, values, what the script sets itself -------------------------

@pytest.mark.parametrize("override, message", [
    ("beamz:=3", "--pf-param beamz: no such particle filter parameter; known: "),
    ("max_particles:=0", "max_particles must be in [1, 200000] (got 0)"),
    ("beams:=0", "beams must be in [1, 4096] (got 0)"),
    ("sigma_hit_m:=-0.03", "sigma_hit_m must be > 0 (got -0.03)"),
    ("z_random:=2", "z_random must be in (0, 1) (got 2.0)"),
    ("max_particles:=100000000", "max_particles must be in [1, 200000] (got 100000000)"),
    ("initial_pose:=[0.0,0.0]", "initial_pose must be [] or 3 finite numbers"),
    ("sigma_hit_m:=nan", "--pf-param: override 'sigma_hit_m:=nan': value 'nan' is not finite"),
    ("slop:=-1", "slop must be >= 0 (got -1.0)"),
    ("pose_topic:=5", "pose_topic must be a string"),
    ("world:=twin_maze", "--pf-param world: run_sim sets it from --map (default --world)"),
    ("lidar_offset_x_m:=0.1", "--pf-param lidar_offset_x_m: run_sim sets it from --profile"),
    ("__node:=evil", "'__node' is not a parameter name"),
    ("__ns:=/evil", "'__ns' is not a parameter name"),
    ("a/b:=1", "'a/b' is not a parameter name"),
])
def test_particle_filter_overrides_are_checked_before_the_run(capsys, override, message):
    _fails_with(capsys, ["--localize", "--pf-param", override], message)


def test_particle_filter_overrides_take_lists_and_typed_values():
    args = run_sim.parse_args(["--goal", "inner_far", "--pf-param", "initial_pose:=[1.0,-1,1.57]",
                               "--pf-param", "max_particles:=2000", "--pf-param", "slop:=1"])
    assert args.pf_overrides == {"initial_pose": [1.0, -1.0, 1.57], "max_particles": 2000,
                                 "slop": 1.0}
    assert all(type(v) is float for v in args.pf_overrides["initial_pose"])


@pytest.mark.parametrize("override, message", [
    ("dt:=0.1", "-p dt: run_sim sets it from --dt"),
    ("simulation:=false", "-p simulation: run_sim sets it from --realtime and --profile"),
    ("enable_localization:=true", "-p enable_localization: run_sim sets it from "
                                  "--enable-localization, --localize and --goal"),
    ("controller:=tests.controllers:ConstantController", "-p controller: run_sim sets it "
                                                         "from --controller"),
    ("queue_size:=0", "queue_size must be >= 1"),
    ("angular_sign:=2", "angular_sign must be 1 or -1"),
    ("scan_topic:=5", "scan_topic must be a string"),
    ("stop_when_localized:=1", "stop_when_localized must be true or false"),
    ("__ns:=/evil", "'__ns' is not a parameter name"),
])
def test_wall_follower_overrides_are_checked_like_the_filters(capsys, override, message):
    _fails_with(capsys, ["-p", override], message)


@pytest.mark.parametrize("argv, message", [
    (["--no-such-option"], "unrecognized arguments"),
    (["--localize", "--map", "lab02", "--pf-param", "__ns:=/evil"],
     "'__ns' is not a parameter name"),
    (["--localize", "--map", "lab02", "--pf-param", "world:=twin_maze"],
     "--pf-param world: run_robot sets it from --map"),
    (["--pf-param", "beams:=90"], "--pf-param needs --localize or --goal"),
    (["-p", "simulation:=true"], "-p simulation: run_robot sets it (robot mode)"),
    (["--dt", "0"], "--dt 0: dt must be > 0 (got 0.0)"),
])
def test_run_robot_checks_the_same_way(capsys, argv, message):
    _robot_fails_with(capsys, argv, message)


# --- a map too big for the particle filter ----------------------------------------------------
# Refused only when the filter configured (exit 1, after the nodes started); now one line, exit
# code 2, before anything runs, saying what it would need; with the filter's own parameters
# (a node parameter such as slop is not the filter's); a run without the filter is not refused.
TOO_BIG = "60.0 x 60.0 m map is too big for the particle filter: it would need 1,0"


@pytest.mark.parametrize("options", [["--localize"], ["--goal", "along"],
                                     ["--localize", "--pf-param", "slop:=0.2"]])
def test_a_map_too_big_for_the_filter_is_refused_before_anything_runs(capsys, big_floor,
                                                                      options):
    _fails_with(capsys, ["--world", str(big_floor), *options], TOO_BIG)
    _robot_fails_with(capsys, ["--world", str(big_floor), *options], TOO_BIG)


def test_a_map_whose_table_would_take_too_long_is_refused_before_anything_runs(capsys,
                                                                              tmp_path):
    """A map whose table would take minutes to build: refused in one line, exit 2, how long."""
    from tools.make_speckled_map import write_speckled_map
    path = write_speckled_map(tmp_path / "specks", 100, 0.02)
    options = ["--localize", "--pf-param", "max_table_build_s:=0.0001"]
    err = _fails_with(capsys, ["--world", str(path), *options], "m map would take about")
    assert "max_table_build_s is 0.0001" in err and "MB" in err
    # Another file (a table this process built is cached: it takes no time any more).
    path = write_speckled_map(tmp_path / "specks_robot", 100, 0.02)
    _robot_fails_with(capsys, ["--map", str(path), *options], "would take about")


def test_a_big_map_is_the_filters_concern_only(capsys, big_floor):
    _fails_with(capsys, ["--world", str(big_floor), "--localize", "--pf-param",
                         "max_memory_mb:=2"], "max_memory_mb is 2")
    args = run_sim.parse_args(["--world", str(big_floor), "--duration", "1"])
    assert isinstance(run_sim._prepare(args), tuple)  # wall following: no filter, no refusal
    args = run_robot.parse_args(["--domain-id", "5", "--map", str(big_floor)])
    assert args.map == str(big_floor) and not args.localize
