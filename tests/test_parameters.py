"""amr_common.ros.parameters: integers where a double is expected (`-p kp:=5`).

Accepted by every node, by -p, --ros-args and params files alike; other wrong types fail
configure with a reason instead of a crash.
"""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter

from amr_common.ros.parameters import declare_parameters, read_parameters
from tests.processes import terminate

REPO = Path(__file__).resolve().parent.parent
TABLE = {"gain": (10.0, "a double"), "count": (3, "an integer"), "side": ("right", "a string"),
         "goal": ([], "a double array")}


def _node(ros, name, *cli):
    return ros.add(Node(name, context=ros.context, cli_args=["--ros-args", *cli] if cli else None))


def test_integers_are_stored_and_read_as_doubles(ros):
    node = _node(ros, "typed", "-p", "gain:=5", "-p", "goal:=[1, 2]")
    declare_parameters(node, TABLE)
    assert node.get_parameter("gain").value == 5.0
    assert isinstance(node.get_parameter("gain").value, float)
    values, problems = read_parameters(node, TABLE)
    assert problems == []
    assert values == {"gain": 5.0, "count": 3, "side": "right", "goal": [1.0, 2.0]}
    assert all(isinstance(v, float) for v in values["goal"])


def test_wrong_types_are_problems_not_exceptions(ros):
    node = _node(ros, "wrong", "-p", "gain:=fast", "-p", "count:=2.5", "-p", "goal:=[a, b]")
    declare_parameters(node, TABLE)  # must not raise
    values, problems = read_parameters(node, TABLE)
    assert problems == ["gain must be a number (got 'fast')",
                        "count must be an integer (got 2.5)",
                        "goal must be a list of numbers (got ['a', 'b'])"]


def test_wall_follower_takes_integers_for_its_doubles_and_tuning(ros, tmp_path):
    from amr_control.wall_follower_node import WallFollowerNode
    params = tmp_path / "ints.yaml"
    params.write_text("wall_follower:\n  ros__parameters:\n    kd: 3\n    data_timeout: 1\n")
    node = ros.add(WallFollowerNode(context=ros.context, cli_args=[
        "--ros-args", "--params-file", str(params), "-p", "dt:=1"], parameter_overrides=[
        Parameter("kp", value=5), Parameter("wall_distance_m", value=0)]))
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    controller = node.controller
    assert (controller.kp, controller.kd, controller.wall_distance_m) == (5.0, 3.0, 0.0)
    assert node.dt == 1.0 and node.data_timeout == 1.0


def test_wall_follower_refuses_a_word_for_a_number_with_a_reason(ros):
    from amr_control.wall_follower_node import WallFollowerNode
    node = ros.add(WallFollowerNode(context=ros.context, parameter_overrides=[
        Parameter("kp", value="strong"), Parameter("slop", value="wide")]))
    assert node.trigger_configure() == TransitionCallbackReturn.FAILURE


def test_simulator_and_odometry_take_integers(ros):
    from amr_sim.simulator_node import SimulatorNode
    from amr_turtlebot3.odometry_node import OdometryNode
    simulator = ros.add(SimulatorNode(context=ros.context, parameter_overrides=[
        Parameter("dt", value=1), Parameter("goal", value=[1, -1]),
        Parameter("command_timeout", value=2)]))
    assert simulator.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert simulator.simulator.dt == 1.0 and simulator.goal == (1.0, -1.0)
    odometry = ros.add(OdometryNode(context=ros.context, parameter_overrides=[
        Parameter("max_gap", value=2)]))
    assert odometry.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert odometry.estimator.max_gap == 2.0


def test_ranges_are_on_the_descriptors_and_a_value_outside_fails_configure(ros):
    """`ros2 param describe` shows each rule; a start-up value outside one fails configure.

    rclpy enforces a descriptor's range already when -p gives the value: declared with it
    from the start, `-p kp:=-1` would raise in the constructor and kill the process.
    """
    from amr_control.wall_follower_node import WallFollowerNode
    node = ros.add(WallFollowerNode(context=ros.context, parameter_overrides=[
        Parameter("kd", value=-1.0)]))
    kp = node.describe_parameter("kp")
    assert (kp.floating_point_range[0].from_value, kp.floating_point_range[0].to_value) == \
        (0.0, math.inf) and kp.additional_constraints == ">= 0"
    queue = node.describe_parameter("queue_size").integer_range[0]
    assert (queue.from_value, queue.to_value) == (1, 2 ** 63 - 1)
    sector = node.describe_parameter("sector_half_width_rad")
    assert sector.floating_point_range[0].to_value == pytest.approx(math.pi / 2)
    assert sector.additional_constraints == "in (0, 1.5708)"
    assert node.describe_parameter("follow_side").additional_constraints == \
        "one of: right, left"
    assert not node.describe_parameter("kd").floating_point_range  # -1 stays, for configure
    assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
    assert not node.set_parameters([Parameter("kp", value=-2.0)])[0].successful
    assert node.set_parameters([Parameter("kp", value=4.0)])[0].successful


def test_wall_follower_executable_survives_an_integer_gain():
    """`amr_wall_follower --ros-args -p kp:=5` used to die in its constructor."""
    process = subprocess.Popen(
        [str(Path(sys.executable).parent / "amr_wall_follower"), "--ros-args",
         "-p", "kp:=5", "-p", "max_linear_speed_mps:=0", "-p", "autostart:=true"],
        cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 30.0
        lines = []
        while time.monotonic() < deadline:
            line = process.stdout.readline()
            lines.append(line)
            if "configured:" in line or not line:
                break
        process.send_signal(signal.SIGINT)
        output = "".join(lines) + process.communicate(timeout=20)[0]
    finally:
        terminate(process, 5.0)
    assert "configured:" in output, output
    assert process.returncode == 0, output
    assert "Traceback" not in output and "InvalidParameterType" not in output
