"""Test harness: every test process gets its own ROS domain on loopback and its own log folder.

Fixtures:
- `course_map`: a map JSON file as the course gives them (a room with a box, no named starts).
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

from amr_common.ros_env import isolate_local_graph

# Before any rclpy import in the tests: a private domain (file-locked, so parallel xdist workers
# and concurrent runs never share one), loopback discovery, logs in a temporary folder.
os.environ.pop("ROS_DOMAIN_ID", None)  # never the user's domain, even if exported
_log_dir = tempfile.mkdtemp(prefix="amr-test-ros-log-")
atexit.register(shutil.rmtree, _log_dir, ignore_errors=True)
isolate_local_graph(log_dir=_log_dir)

import pytest  # noqa: E402

from tests.ros_harness import RosHarness  # noqa: E402


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
