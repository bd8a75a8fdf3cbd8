"""evaluate.py's command line: start poses, integer parameters, bad input.

Start poses with negative numbers on a map without named starts, integer parameters; bad files,
controllers and output folders are one-line errors with exit code 2. (The grids and config
files themselves: test_evaluation.py.)
"""
from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import evaluate  # noqa: E402


def _evaluate(capsys, *argv):
    code = evaluate.main([*argv, "--duration", "1", "--jobs", "1", "--no-sheet"])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_evaluate_runs_a_course_map_from_a_negative_pose(capsys, tmp_path, course_map):
    code, out, err = _evaluate(capsys, "--worlds", str(course_map), "--starts", "-1.0,-1.0,1.57",
                               "-p", "kp:=5", "--out", str(tmp_path / "out"))
    assert code == 0, err
    rows = json.loads((tmp_path / "out" / "results.json").read_text())["episodes"]
    assert [(r["world"], r["start"], r["error"]) for r in rows] == [
        ("course_map", "-1,-1,1.57", None)]


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
                                                 "SyntaxError"),
             (["--ray-keep-workers", "30"], "--ray-keep-workers needs --ray"),
             (["--ray", "127.0.0.1:1", "--ray-keep-workers", "-1"],
              "--ray-keep-workers must be a number of seconds >= 0, got -1"),
             (["--ray", "127.0.0.1:1", "--ray-keep-workers", "nan"],
              "--ray-keep-workers must be a number of seconds >= 0, got nan"),
             # --jobs with a cluster's address was once silently ignored.
             (["--ray", "127.0.0.1:1"], "--jobs 1 sets the CPUs of a local Ray instance (--ray "
                                        "without an address): with --ray ADDRESS"),
             (["--ray", "auto"], "with --ray ADDRESS the cluster's CPUs run the episodes")]
    for argv, message in cases:
        code, out, err = _evaluate(capsys, "--worlds", "lab02", *argv)
        assert code == 2, (argv, err)
        assert len(err.strip().splitlines()) == 1 and message in err, (argv, err)
        assert "episodes" not in out  # nothing ran


def test_evaluate_finishes_when_worker_processes_die(capsys, tmp_path):
    """It used to wait forever for the episode of a worker that died."""
    out = tmp_path / "out"
    code = evaluate.main(["--worlds", "lab02", "--starts", "outer,inner", "--duration", "1",
                          "--jobs", "2", "--no-sheet", "--out", str(out),
                          "--controller", "tests.test_evaluation:ExitsTheProcess"])
    assert code == 3, capsys.readouterr()
    episodes = json.loads((out / "results.json").read_text())["episodes"]
    assert ["worker process died" in (e["error"] or "") for e in episodes] == [True, True]
    assert "2 episode(s) FAILED" in capsys.readouterr().out


def test_the_local_pool_imports_no_ray(tmp_path):
    """The default path needs no cluster extra: Ray is imported only with --ray."""
    import subprocess
    code = ("import sys; sys.path.insert(0, 'scripts'); import evaluate; "
            f"code = evaluate.main(['--worlds', 'lab02', '--duration', '1', '--jobs', '2', "
            f"'--no-sheet', '--out', {str(tmp_path / 'out')!r}]); "
            "assert 'ray' not in sys.modules, 'ray imported'; sys.exit(code)")
    proc = subprocess.run([sys.executable, "-c", code], cwd=SCRIPTS.parent, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "on 2 local process(es)" in proc.stdout


def test_options_that_would_be_ignored_or_mean_nothing_are_one_line_errors(capsys, tmp_path,
                                                                          course_map):
    """Each was once accepted (and ignored, or read as 'all'/'none') or crashed."""
    cases = [(["--localize", "--kidnap-at", "-5"], "--kidnap-at must be a time within the "
                                                   "episode (0 < T < 1 s), got -5"),
             (["--localize", "--kidnap-at", "0"], "(0 < T < 1 s), got 0"),
             (["--localize", "--kidnap-at", "1"], "(0 < T < 1 s), got 1"),
             (["--localize", "--kidnap-at", "nan"], "(0 < T < 1 s), got nan"),
             (["--localize", "--kidnap-at", "0.5", "--worlds", str(course_map), "--starts",
               "1,1,0"], "--kidnap-at: world 'course_map' has fewer than two named starts"),
             (["--kidnap-at", "0.5"], "--kidnap-at needs --localize"),
             (["--pf-param", "beams:=30"], "--pf-param needs --localize"),
             (["--localize", "--pf-param", "beams:=0"],
              "--pf-param: beams must be in [1, 4096] (got 0)"),
             (["--localize", "--pf-param", "bemas:=30"], "unknown parameter(s) ['bemas']"),
             (["--localize", "--pf-param", "beams"], "'beams' must look like name:=value"),
             (["--goals", ""], "no goals given (an empty list)"),
             (["--goals", " , "], "no goals given (an empty list)"),
             (["--starts", ""], "no starts given (an empty list)"),
             (["--profiles", ""], "no profiles given (an empty list)"),
             (["--pose-source", "truth"], "--pose-source needs --goals"),
             (["--episode-timeout", "-1"], "--episode-timeout must be a number of seconds > 0"),
             (["--episode-timeout", "nan"], "(0: no limit), got nan")]
    for argv, message in cases:
        argv = ["--worlds", "lab02", *argv, "--out", str(tmp_path / "out")]
        code, out, err = _evaluate(capsys, *argv)
        assert code == 2, (argv, out, err)
        assert len(err.strip().splitlines()) == 1 and message in err, (argv, err)
        assert "episodes" not in out and not (tmp_path / "out").exists()  # nothing ran


def test_a_hanging_or_crashing_controller_is_its_episodes_error_with_the_results_written(
        capsys, tmp_path):
    """A sleeping controller used to hang evaluate.py (--out stayed empty).

    And a single episode ran in evaluate.py's own process, which the controller's os._exit
    ended: no results at all.
    """
    misbehaves = ["--worlds", "lab02", "--controller", "tests.controllers:Misbehaves",
                  "--params-file", "none", "--no-sheet"]
    code = evaluate.main([*misbehaves, "--starts", "outer", "-p", "how:=exit",
                          "--duration", "1", "--out", str(tmp_path / "exit")])
    out = capsys.readouterr().out
    assert code == 3 and "1 episode(s) FAILED" in out
    (episode,) = json.loads((tmp_path / "exit" / "results.json").read_text())["episodes"]
    assert "worker process died (exit code 7)" in episode["error"]

    # Two episodes in parallel, the first to start sleeps for good: it ends at the limit.
    code = evaluate.main([*misbehaves, "--starts", "outer,inner", "-p", "how:=sleep",
                          "-p", f"marker:={tmp_path / 'first'}", "--duration", "1",
                          "--jobs", "2", "--episode-timeout", "3", "--out",
                          str(tmp_path / "sleep")])
    out = capsys.readouterr().out
    assert code == 3 and "1 episode(s) FAILED" in out
    data = json.loads((tmp_path / "sleep" / "results.json").read_text())
    errors = [e["error"] for e in data["episodes"]]
    assert sum(e is None for e in errors) == 1, errors
    assert any(e and "ran past its wall-clock limit of 3 s" in e for e in errors), errors
    assert data["meta"]["episode_timeout_s"] == 3.0
    assert (tmp_path / "sleep" / "results.csv").read_text().count("\n") == 3


@pytest.mark.parametrize("options", [["--localize"], ["--goals", "along"],
                                     ["--localize", "--pf-param", "initial_pose:=[0.05,20,0]"]])
def test_a_map_too_big_for_the_filter_is_refused_before_anything_runs(capsys, tmp_path,
                                                                      big_floor, options):
    """A map too big for the filter: the episodes used to fail one by one as it was built."""
    code, out, err = _evaluate(capsys, "--worlds", str(big_floor), *options, "--out",
                               str(tmp_path / "out"))
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    message = "initial_pose [0.05, 20.0, 0.0]: (0.050, 20.000) is on or too close to a wall" \
        if "--pf-param" in options else \
        "60.0 x 60.0 m map is too big for the particle filter: it would need 1,0"
    assert message in err and not (tmp_path / "out").exists(), err


def test_navigation_on_the_true_pose_runs_no_filter(big_floor):
    specs = evaluate.episode_specs(evaluate.resolve_settings(evaluate.parse_args(
        ["--worlds", str(big_floor), "--goals", "along", "--pose-source", "truth"])))
    evaluate.check_filter_maps(specs, {})  # no filter: no refusal
    with pytest.raises(ValueError, match="too big"):
        evaluate.check_filter_maps([replace(spec, pose_source="filter") for spec in specs], {})


@pytest.mark.slow
def test_a_closed_terminal_or_sigterm_ends_evaluate_as_ctrl_c_does(tmp_path):
    """SIGHUP and SIGTERM end it as Ctrl-C does: "interrupted", exit code 129 / 130.

    SIGHUP (the terminal closed) and SIGTERM killed it at once (-1, -15); Ctrl-C during --slam
    episodes ended in a traceback.
    """
    import os
    import signal
    import subprocess

    from tests.processes import terminate, wait_for
    runs = {}
    for signum, options in ((signal.SIGHUP, []), (signal.SIGTERM, ["--slam"]),
                            (signal.SIGINT, ["--slam"])):
        log = tmp_path / f"{signum.name}.log"
        with open(log, "w") as stream:
            runs[signum] = (subprocess.Popen(
                [sys.executable, str(SCRIPTS / "evaluate.py"), "--worlds", "lab02", "--starts",
                 "outer", "--profiles", "ideal", "--seeds", "0", "--duration", "3000",
                 "--jobs", "1", "--no-sheet", "--out", str(tmp_path / signum.name), *options],
                stdout=stream, stderr=subprocess.STDOUT, cwd=SCRIPTS.parent,
                env=dict(os.environ)), log)
    try:
        for process, log in runs.values():
            wait_for(lambda: "episodes of" in log.read_text() or process.poll() is not None,
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
        assert "evaluate: interrupted" in output and "Traceback" not in output, output
