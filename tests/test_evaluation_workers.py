"""evaluate.py's worker pool and verdict against controllers that end their process or command
garbage (issue 10, B8): a dead worker is that episode's error and the others still run; NaN or
non-number commands are counted per episode and fail the verdict."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from amr_evaluation.evaluation import EpisodeSpec, run_episodes
from amr_evaluation.evaluation_report import format_table, outcome_row, verdict

REPO = Path(__file__).resolve().parent.parent
HERE = "tests.test_evaluation_workers"


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


def spec(controller: str, **params) -> EpisodeSpec:
    return EpisodeSpec("lab02", "outer", duration=1.0, controller=f"{HERE}:{controller}",
                       params=params)


def test_a_worker_that_dies_is_its_episodes_error_and_the_others_still_run():
    specs = [spec("Standing"), spec("ExitsTheProcess", how="os._exit"), spec("Standing"),
             spec("ExitsTheProcess", how="sys.exit"), spec("Standing"), spec("Standing")]
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
    (outcome,) = run_episodes([spec("ExitsTheProcess", how="sys.exit")], jobs=1)
    assert "sys.exit(4)" in outcome.error


@pytest.mark.parametrize("kind", ["nan", "inf", "text"])
def test_invalid_commands_are_counted_and_fail_the_verdict(kind):
    outcomes = run_episodes([spec("Standing"), spec("Garbage", kind=kind)], jobs=1)
    clean, garbage = outcomes
    assert clean.error is None and clean.result.invalid_commands == 0
    assert garbage.error is None and garbage.result.invalid_commands == 10   # 20 steps
    assert garbage.result.collisions == 0
    row = outcome_row(garbage)
    assert row["invalid_commands"] == 10
    assert "10" in format_table([outcome_row(clean), row]).splitlines()[-1]
    line, code = verdict(outcomes)
    assert code == 1, line
    assert "INVALID COMMANDS in 1/2 episodes: lab02/outer/ideal/seed 0 (10)" in line
    assert verdict(outcomes[:1])[1] == 0


@pytest.mark.slow
def test_evaluate_script_finishes_when_a_worker_dies(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "evaluate.py"), "--worlds", "lab02",
         "--starts", "outer,inner", "--duration", "1", "--jobs", "2", "--no-sheet",
         "--controller", f"{HERE}:ExitsTheProcess", "--out", str(out)],
        capture_output=True, text=True, timeout=100, cwd=REPO)
    assert proc.returncode == 3, proc.stdout + proc.stderr
    episodes = json.loads((out / "results.json").read_text())["episodes"]
    assert [("worker process died" in (e["error"] or "")) for e in episodes] == [True, True]
