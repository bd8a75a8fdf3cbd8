"""Test harness: every test process gets its own ROS domain on loopback, log folder and Ray token.

Fixtures:
- `course_map`: a map JSON file as the course gives them (a room with a box, no named starts).
- `big_floor`: a generated 60 x 60 m office floor with a named goal, too big for the particle
  filter's default max_memory_mb (it would need about 1,050 MB).
- `ray_cluster`: a Ray cluster on loopback (head + one worker node), this process its driver;
  one per test session (tests/ray_cluster.py). A test on it ends with its Ray work ended (its
  warm workers too) and none of its Ray processes left (`ray_processes_end`).
- `ray_processes_end`: for a test that starts Ray itself (`evaluate.py --ray`, `ray start`):
  when it ends, waits until none of its Ray processes runs, and fails it if one still does
  after 30 s (tests/ray_processes.py).
- `ros`: an initialised rclpy context with an executor; `ros.node(name)` creates a plain node,
  `ros.add(node)` spins an existing one, `ros.spin_until(cond, timeout)` spins until `cond()` is
  true or fails the test, `ros.spin_for(seconds)` spins for a while. Everything is destroyed and
  rclpy is shut down after the test.
"""
from __future__ import annotations

import atexit
import json
import os
import shutil
import tempfile

from amr_common.ros.ros_env import isolate_local_graph

# Before any rclpy import in the tests: a private domain (file-locked, so parallel xdist workers
# and concurrent runs never share one), loopback discovery, logs in a temporary folder.
os.environ.pop("ROS_DOMAIN_ID", None)  # never the user's domain, even if exported
_log_dir = tempfile.mkdtemp(prefix="amr-test-ros-log-")
atexit.register(shutil.rmtree, _log_dir, ignore_errors=True)
isolate_local_graph(log_dir=_log_dir)

import pytest  # noqa: E402

from tests import ray_processes  # noqa: E402
from tests.ray_cluster import use_session_ray_token  # noqa: E402
from tests.ros_harness import RosHarness  # noqa: E402

# Before any Ray import: the session's Ray instances use a token of their own, not ~/.ray's,
# and every process started from here carries the session's id (its Ray processes are found).
_ray_dir = tempfile.mkdtemp(prefix="amr-test-ray-")
atexit.register(shutil.rmtree, _ray_dir, ignore_errors=True)
use_session_ray_token(_ray_dir)
ray_processes.mark_session()


@pytest.fixture
def ros():
    harness = RosHarness()
    try:
        yield harness
    finally:
        harness.close()


@pytest.fixture
def course_map(tmp_path):
    path = tmp_path / "course_map.json"
    path.write_text(json.dumps({"metric": {
        "boundary": [[-2, -2], [2, -2], [2, 2], [-2, 2]],
        "holes": [[[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]]]}}))
    return path


@pytest.fixture
def big_floor(tmp_path):
    from tools.make_building_world import building, to_yaml
    world = building(60, 18)
    x, y, _ = world["starts"]["corridor_west"]
    path = tmp_path / "building_60m.yaml"
    path.write_text(to_yaml(world) + f"goals:\n  along: [{x + 2:g}, {y:g}]\n")
    return path


@pytest.fixture
def ray_processes_end():
    """The test ends with none of its Ray processes left: waited for, and checked."""
    yield
    left = ray_processes.wait_until_ended()
    if left:
        pytest.fail("Ray processes still running after the test (now killed): "
                    + "; ".join(f"{pid} {command[:80]}" for pid, command in left.items()))


@pytest.fixture(scope="session")
def _session_ray_cluster():
    """A Ray cluster on loopback (tests/ray_cluster.py), one per session: start-up is slow."""
    from tests.ray_cluster import LoopbackCluster
    cluster = LoopbackCluster()
    try:
        yield cluster
    finally:
        cluster.close()
        left = ray_processes.wait_until_ended()
        assert not left, f"the session's Ray cluster left processes running: {left}"


@pytest.fixture
def ray_cluster(_session_ray_cluster, ray_processes_end):
    """The session's Ray cluster; the test's Ray work ends with it (its warm workers too)."""
    yield _session_ray_cluster
    _session_ray_cluster.end_test_work()
