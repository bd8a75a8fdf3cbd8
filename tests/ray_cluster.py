"""A Ray cluster on loopback for the tests (the `ray_cluster` fixture in conftest.py).

A head node without CPUs (it only coordinates, as on a real cluster) and one worker node with
two CPUs, every Ray process bound to 127.0.0.1; this test process is connected to it as the
driver. Its node processes are children of this process, started from this venv's Python: the
workers import the project from the same venv path, the set-up README "Sweep on a cluster"
describes. Nodes are declared dead after ~2 s of missed health checks (Ray's default ~15 s), so
node-loss tests stay short. Ray start-up takes a few seconds: one cluster per test session.
"""
from __future__ import annotations

import os

import pytest

from amr_evaluation.ray_executor import LOCAL_RAY_ENV

FAST_NODE_DEATH = {"health_check_initial_delay_ms": 0, "health_check_period_ms": 500,
                   "health_check_failure_threshold": 3, "health_check_timeout_ms": 500}


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
        self.ray.init(address=self.address, logging_level="WARNING")

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

    def close(self) -> None:
        """Disconnect and stop every node."""
        self.ray.shutdown()
        self.cluster.shutdown()
