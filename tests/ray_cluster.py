"""A Ray cluster on loopback for the tests (the `ray_cluster` fixture in conftest.py).

A head node without CPUs (it only coordinates, as on a real cluster) and one worker node with two
CPUs, every Ray process bound to 127.0.0.1; this test process is connected to it as the driver. Its
node processes are children of this process, started from this venv's Python: the workers import
the project from the same venv path, the set-up docs/tune.md "Sweep on a cluster" describes. Nodes
are declared dead after ~2 s of missed health checks (Ray's default ~15 s), so node-loss tests stay
short. Ray start-up takes a few seconds: one cluster per test session.

Every Ray instance of the test session (this cluster, `evaluate.py --ray` in a subprocess)
authenticates with the session's own token (use_session_ray_token, called by conftest.py
before any Ray import), never with the user's `~/.ray/auth_token`: the suite passes with an
empty HOME and leaves HOME as it found it.
"""
from __future__ import annotations

import os
import secrets
from pathlib import Path

import pytest

from amr_evaluation.ray_executor import LOCAL_RAY_ENV

FAST_NODE_DEATH = {"health_check_initial_delay_ms": 0, "health_check_period_ms": 500,
                   "health_check_failure_threshold": 3, "health_check_timeout_ms": 500}


# Ray's documented variables for token authentication; RAY_ADDRESS would join the user's cluster.
RAY_AUTH_VARIABLES = ("RAY_AUTH_MODE", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH", "RAY_ADDRESS")


def use_session_ray_token(folder: str | Path) -> Path:
    """Token authentication for this process and its children with a new token in `folder`.

    Ray 2.60 enables token authentication for a new local instance: `ray.init()` writes
    `~/.ray/auth_token` when it finds no token, and a cluster started node by node (this
    module's, `ray start`) needs one already, or its GCS aborts ("Ray couldn't find an
    authentication token"): the first run on a fresh machine failed. The token file is named
    by RAY_AUTH_TOKEN_PATH (read before `~/.ray/auth_token`; RAY_AUTH_TOKEN, which would win,
    and RAY_ADDRESS are dropped). Returns the token file.
    """
    for name in RAY_AUTH_VARIABLES:
        os.environ.pop(name, None)
    path = Path(folder) / "ray_auth_token"
    path.touch(mode=0o600)
    path.write_text(secrets.token_hex(32), encoding="utf-8")
    os.environ["RAY_AUTH_MODE"] = "token"
    os.environ["RAY_AUTH_TOKEN_PATH"] = str(path)
    return path


def import_ray():
    """ray, with the loopback settings applied first (Ray reads them at import).

    Never skipped: `make test` installs the cluster extra, and a test that skips cannot fail.
    """
    for name, value in LOCAL_RAY_ENV.items():
        os.environ.setdefault(name, value)
    try:
        import ray
    except ImportError as exc:
        pytest.fail(f"Ray is missing ({exc}): install the cluster extra, "
                    "`.venv/bin/pip install -r requirements-cluster.lock -c requirements.lock` "
                    "(make test does)")
    return ray


class LoopbackCluster:
    """Head (0 CPUs) + worker nodes on 127.0.0.1; this process is the driver."""

    def __init__(self, worker_cpus: int = 2) -> None:
        self.ray = import_ray()
        from ray.cluster_utils import Cluster
        self.cluster = Cluster(initialize_head=True, head_node_args={
            "num_cpus": 0, "node_ip_address": "127.0.0.1", "include_dashboard": False,
            "_system_config": FAST_NODE_DEATH})
        self.workers = [self.add_worker(worker_cpus)]
        # The workers' output stays in their log files: forwarded, it would be printed into
        # whichever test runs when it arrives (a worker ended by a test prints as it goes).
        self.ray.init(address=self.address, logging_level="WARNING", log_to_driver=False)

    @property
    def address(self) -> str:
        """HOST:PORT of the head's GCS, as `evaluate.py --ray ADDRESS` takes it."""
        return self.cluster.address

    def add_worker(self, cpus: int):
        """Start one more worker node with `cpus` CPUs; its Ray Node object."""
        return self.cluster.add_node(num_cpus=cpus, node_ip_address="127.0.0.1")

    def kill_worker(self, node) -> None:
        """SIGKILL every process of a worker node (no graceful drain: a lost machine)."""
        self.cluster.remove_node(node, allow_graceful=False)
        if node in self.workers:
            self.workers.remove(node)

    def end_test_work(self) -> None:
        """End what a test left on the cluster: its idle warm episode workers."""
        from amr_evaluation.ray_workers import release_idle_warm_workers
        release_idle_warm_workers(self.ray)

    def close(self) -> None:
        """Disconnect and stop every node."""
        self.ray.shutdown()
        self.cluster.shutdown()
