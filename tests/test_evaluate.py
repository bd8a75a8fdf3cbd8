"""evaluate.py options and config files: start poses, integer parameters, bad input.

Start poses with negative numbers, worlds without named starts, integer parameters, bad files
and output folders (one-line errors, exit code 2).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from amr_evaluation.evaluation import EvaluationError, expand_grid, load_config, parse_start_list

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import evaluate  # noqa: E402


def _evaluate(capsys, *argv):
    code = evaluate.main([*argv, "--duration", "1", "--jobs", "1", "--no-sheet"])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_start_lists_mix_names_and_poses():
    assert parse_start_list("outer,-1,-1.5,1.57,inner") == ["outer", (-1.0, -1.5, 1.57), "inner"]
    assert parse_start_list([-1, -1, 1.57]) == [(-1.0, -1.0, 1.57)]  # YAML: [-1, -1, 1.57]
    assert parse_start_list(["outer", [0.6, -0.6, 4.71]]) == ["outer", (0.6, -0.6, 4.71)]
    for bad in ("1,2", [[1, 2]], [True], "a,1,2,3,4", "1,nan,0"):
        with pytest.raises(EvaluationError, match=r"x,y,theta|\[x, y, theta\]|neither"):
            parse_start_list(bad)


def test_a_pose_applies_to_every_world_and_maps_without_starts_need_one(course_map):
    specs = expand_grid(f"lab02,{course_map}", "all,-1.0,-1.0,1.57", "ideal", "0", duration=1)
    labels = [spec.label for spec in specs]
    assert labels == ["lab02/outer/ideal/seed 0", "lab02/inner/ideal/seed 0",
                      "lab02/-1,-1,1.57/ideal/seed 0", "course_map/-1,-1,1.57/ideal/seed 0"]
    with pytest.raises(EvaluationError, match="names no start poses, so 'all' is none"):
        expand_grid(str(course_map), "all")
    with pytest.raises(EvaluationError, match="inside obstacle"):
        expand_grid(str(course_map), "0,0,0")


def test_evaluate_runs_a_course_map_from_a_negative_pose(capsys, tmp_path, course_map):
    code, out, err = _evaluate(capsys, "--worlds", str(course_map), "--starts", "-1.0,-1.0,1.57",
                               "-p", "kp:=5", "--out", str(tmp_path / "out"))
    assert code == 0, err
    rows = json.loads((tmp_path / "out" / "results.json").read_text())["episodes"]
    assert [(r["world"], r["start"], r["error"]) for r in rows] == [
        ("course_map", "-1,-1,1.57", None)]


def test_config_files_take_poses_and_refuse_wrong_types(tmp_path):
    config = tmp_path / "poses.yaml"
    config.write_text("worlds: [lab02]\nstarts: [outer, [1.0, -1.0, 1.57], '-0.6,-0.6,4.71']\n"
                      "params: {kp: 5}\n")
    loaded = load_config(config)
    assert [s.start for s in expand_grid(loaded["worlds"], loaded["starts"])] == [
        "outer", (1.0, -1.0, 1.57), (-0.6, -0.6, 4.71)]
    cases = {"worlds: 5\n": "'worlds' must be a name, a list of names or 'all', got 5",
             "worlds: lab02\nprofiles: {a: 1}\n": "'profiles' must be a name",
             "worlds: lab02\nstarts: [[1, 2]]\n": r"'starts': start pose \[1, 2\]",
             "worlds: lab02\ncontroller: 3\n": "'controller' must be MODULE:CLASS",
             "worlds: [lab02\n": "not valid YAML: .* at line 2, column 1"}
    for text, message in cases.items():
        config.write_text(text)
        with pytest.raises(EvaluationError, match=message):
            load_config(config)
    config.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe" * 20)
    with pytest.raises(EvaluationError, match="not a text file"):
        load_config(config)


def test_bad_inputs_are_one_line_errors_with_exit_code_2(capsys, tmp_path, monkeypatch):
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    numbers = tmp_path / "numbers.yaml"
    numbers.write_text("worlds: 5\n")
    broken = tmp_path / "broken.yaml"
    broken.write_text("wall_follower:\n  ros__parameters:\n    kp: [1\n")
    (tmp_path / "broken_ctrl.py").write_text("class C:\n    def compute_commands(self)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    cases = [(["--out", str(a_file)], "--out '%s' is a file, not a folder" % a_file),
             (["--out", str(a_file / "sub")], "cannot be written"),
             (["--config", str(numbers)], "'worlds' must be a name"),
             (["--config", str(tmp_path)], "cannot read config"),
             (["--params-file", str(broken)], "not valid YAML"),
             (["--controller", "broken_ctrl:C"], "cannot import module 'broken_ctrl': "
                                                 "SyntaxError")]
    for argv, message in cases:
        code, out, err = _evaluate(capsys, "--worlds", "lab02", *argv)
        assert code == 2, (argv, err)
        assert len(err.strip().splitlines()) == 1 and message in err, (argv, err)
        assert "episodes" not in out  # nothing ran
