"""Option checks (cli_checks.py, launch_common.py) as run_sim.py and run_robot.py use them.

Start poses, -p names and values, output paths, domain ids (also topic.py's, lifecycle.py's and
ros_graph.py's), params files and controllers: every mistake is a one-line error with exit code
2, found before anything runs.
"""
from __future__ import annotations

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
        code = run_sim.main([*argv, "--duration", "2"])
    except SystemExit as exc:  # argparse errors
        code = exc.code
    out, err = capsys.readouterr()
    assert code == 2, err
    assert message in err.strip().splitlines()[-1], err
    assert "Traceback" not in err
    assert "simulated in" not in out  # checked up front: no run
    return err


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
    _fails_with(capsys, ["-p", "kp:=-1"], "rejects its parameters: WallFollower: kp must be")


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
