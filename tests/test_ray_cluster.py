"""The test session's Ray cluster (tests/ray_cluster.py) on a machine where Ray never ran.

With an empty HOME (no `~/.ray/auth_token`), every test on the `ray_cluster` fixture once
errored at set-up (Ray's GCS aborts without a token); it passed only where an earlier
`evaluate.py --ray` had written one. The session now brings its own token, and never reads or
writes the user's `~/.ray`.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.ray_cluster import RAY_AUTH_VARIABLES

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parent.parent


def _node_of_a_task(ray) -> str:
    @ray.remote(num_cpus=1)
    def node_id():
        return ray.get_runtime_context().get_node_id()

    return ray.get(node_id.remote(), timeout=120)


def test_tasks_run_on_the_worker_node_with_the_sessions_token(ray_cluster):
    ray = ray_cluster.ray
    (worker,) = ray_cluster.workers
    assert _node_of_a_task(ray) == worker.node_id  # the head has no CPUs
    token = Path(os.environ["RAY_AUTH_TOKEN_PATH"])
    assert os.environ["RAY_AUTH_MODE"] == "token" and "RAY_AUTH_TOKEN" not in os.environ
    assert len(token.read_text()) == 64 and not token.is_relative_to(Path.home())


def test_a_newcomer_with_an_empty_home_gets_the_cluster_and_a_home_left_alone(
        tmp_path, ray_processes_end):
    home = tmp_path / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in RAY_AUTH_VARIABLES}
    env["HOME"] = str(home)
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
         f"{__file__}::test_tasks_run_on_the_worker_node_with_the_sessions_token"],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "1 passed" in proc.stdout
    assert sorted(p.name for p in home.iterdir()) == []  # no ~/.ray/auth_token, nothing


def test_a_ray_worker_left_running_is_found_and_its_end_waited_for(ray_cluster):
    """The check every Ray test ends with (tests/ray_processes.py) sees a test's own worker.

    A Tune trial's worker outlived its test by seconds and printed into a later test's output
    as it ended; the session cluster's own processes are not counted.
    """
    from tests import ray_processes
    ray = ray_cluster.ray

    @ray.remote(num_cpus=1)
    class Lingers:
        def pid(self) -> int:
            return os.getpid()

    actor = Lingers.remote()
    pid = ray.get(actor.pid.remote())
    left = ray_processes.leftovers()
    assert list(left) == [pid] and left[pid].startswith("ray::Lingers"), left
    ray.kill(actor)
    assert ray_processes.wait_until_ended() == {}
