"""Out-of-order lifecycle requests are refused and logged; the node keeps running.

Activate before configure, configure twice, cleanup while active, ...: each is answered
`success: false` with a log line; the node keeps its state and keeps answering. Checked through
the real lifecycle services, in-process and against each node's executable.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter

from amr_common.ros.lifecycle_node import GuardedLifecycleNode
from amr_control.pure_pursuit_node import PurePursuitNode
from amr_control.wall_follower_node import WallFollowerNode
from amr_localization.particle_filter_node import ParticleFilterNode
from amr_planning.planner_node import PlannerNode
from amr_sim.simulator_node import SimulatorNode
from amr_tools.foxglove_bridge import FoxgloveBridgeNode
from amr_tools.map_publisher import MapPublisherNode
from amr_turtlebot3.odometry_node import OdometryNode
from tests.processes import terminate, wait_for

REPO = Path(__file__).resolve().parent.parent
# Every lifecycle node of the project: (class, parameter overrides) by node name ...
NODES = {"amr_simulator": (SimulatorNode, {}), "wall_follower": (WallFollowerNode, {}),
         "amr_odometry": (OdometryNode, {}), "map_publisher": (MapPublisherNode, {}),
         "foxglove_bridge": (FoxgloveBridgeNode, {"port": 0}),  # any free port
         "particle_filter": (ParticleFilterNode, {}), "planner": (PlannerNode, {}),
         "pure_pursuit": (PurePursuitNode, {})}
# ... and its executable with its arguments.
EXECUTABLES = {"amr_simulator": ["amr_simulator"], "wall_follower": ["amr_wall_follower"],
               "amr_odometry": ["amr_odometry"], "map_publisher": ["amr_map_publisher"],
               "foxglove_bridge": ["amr_foxglove_bridge", "--ros-args", "-p", "port:=0"],
               "particle_filter": ["amr_particle_filter"], "planner": ["amr_planner"],
               "pure_pursuit": ["amr_pure_pursuit"]}


class LifecycleClient:
    """change_state / get_state clients of one node, called from a separate test node."""

    def __init__(self, ros, client_node, target: str) -> None:
        self.ros = ros
        self.change = client_node.create_client(ChangeState, f"/{target}/change_state")
        self.get = client_node.create_client(GetState, f"/{target}/get_state")
        ros.spin_until(lambda: self.change.service_is_ready() and self.get.service_is_ready(),
                       60.0, f"{target}'s lifecycle services")
        self.wait_until_answering(60.0)

    def _call(self, client, request, timeout: float = 20.0):
        future = client.call_async(request)
        self.ros.spin_until(future.done, timeout, "a lifecycle service answer")
        return future.result()

    def request(self, transition_id: int = 0, label: str = "") -> bool:
        request = ChangeState.Request()
        request.transition.id, request.transition.label = transition_id, label
        return self._call(self.change, request).success

    def state(self, timeout: float = 20.0) -> str:
        return self._call(self.get, GetState.Request(), timeout).current_state.label

    def wait_until_answering(self, timeout: float) -> None:
        """Ask get_state once a second until the node answers.

        A request sent before the server's endpoints matched (or to a node of the same name
        that an earlier test destroyed) is lost, so one call is not enough here.
        """
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            future = self.get.call_async(GetState.Request())
            end = min(time.monotonic() + 1.0, deadline)
            while not future.done() and time.monotonic() < end:
                self.ros.executor.spin_once(timeout_sec=0.05)
            if future.done():
                return
            self.get.remove_pending_request(future)
        pytest.fail(f"{self.get.srv_name} did not answer within {timeout} s")


def out_of_order_sequence(client: LifecycleClient) -> None:
    """Every refused request leaves the node where it was; valid ones still work after."""
    assert client.state() == "unconfigured"
    assert client.request(Transition.TRANSITION_ACTIVATE) is False   # before configure
    assert client.request(label="deactivate") is False
    assert client.request(label="no_such_transition") is False
    assert client.state() == "unconfigured"
    assert client.request(Transition.TRANSITION_CONFIGURE) is True
    assert client.request(Transition.TRANSITION_CONFIGURE) is False  # twice
    assert client.request(label="configure") is False
    assert client.state() == "inactive"
    assert client.request(Transition.TRANSITION_ACTIVATE) is True
    assert client.request(Transition.TRANSITION_CLEANUP) is False    # while active
    assert client.request(Transition.TRANSITION_ACTIVATE) is False
    assert client.request(99) is False
    assert client.state() == "active"
    assert client.request(Transition.TRANSITION_DEACTIVATE) is True
    assert client.request(Transition.TRANSITION_CLEANUP) is True
    assert client.state() == "unconfigured"


def make_node(ros, name: str) -> GuardedLifecycleNode:
    node_class, overrides = NODES[name]
    return ros.add(node_class(context=ros.context, parameter_overrides=[
        Parameter(key, value=value) for key, value in overrides.items()]))


@pytest.mark.parametrize("name", list(NODES))
def test_out_of_order_requests_through_the_service_are_refused_and_logged(ros, name):
    node = make_node(ros, name)
    assert isinstance(node, GuardedLifecycleNode)
    refused = []
    node._log_refusal = lambda text, original=node._log_refusal: (refused.append(text),
                                                                  original(text))
    client = LifecycleClient(ros, ros.node("lifecycle_client"), name)
    out_of_order_sequence(client)
    assert len(refused) == 8, refused
    assert "'activate' refused: it is not possible in state 'unconfigured'" in refused[0]
    assert any("'cleanup' refused: it is not possible in state 'active'" in t for t in refused)


@pytest.mark.parametrize("name", list(NODES))
def test_out_of_order_triggers_in_process_return_failure_without_raising(ros, name):
    node = make_node(ros, name)
    assert node.trigger_activate() == TransitionCallbackReturn.FAILURE
    assert node.trigger_cleanup() == TransitionCallbackReturn.FAILURE
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_cleanup() == TransitionCallbackReturn.FAILURE
    assert node._state_machine.current_state[1] == "active"
    assert node.trigger_shutdown() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_shutdown() == TransitionCallbackReturn.FAILURE  # finalized already
    assert node.trigger_configure() == TransitionCallbackReturn.FAILURE


def test_a_raising_transition_callback_is_logged_and_answered_error(ros):
    class Raising(GuardedLifecycleNode):
        def on_configure(self, state):
            raise RuntimeError("broken on purpose")

    node = ros.add(Raising("raising", context=ros.context))
    logged = []
    node._log_error = logged.append
    assert node.trigger_configure() == TransitionCallbackReturn.ERROR
    assert any("broken on purpose" in text for text in logged), logged
    assert node._state_machine.current_state[1] == "unconfigured"  # on_error recovered


def test_warn_every_throttles_each_kind_on_its_own(ros, monkeypatch):
    # rclpy's throttle keys on the call site: one helper logging every kind let a frequent
    # kind (a bad scan) silence a rare one (odometry ignored).
    node = ros.add(GuardedLifecycleNode("warning", context=ros.context))
    logged = []

    class Logger:
        def warning(self, text):
            logged.append(("warning", text))

        def error(self, text):
            logged.append(("error", text))

    monkeypatch.setattr(node, "get_logger", lambda: Logger())
    assert node.warn_every("scan", "bad scan 1") and not node.warn_every("scan", "bad scan 2")
    assert node.warn_every("odometry", "odometry ignored", error=True)
    assert not node.warn_every("scan", "bad scan 3", period_s=60.0)
    assert node.warn_every("scan", "bad scan 4", period_s=0.0)
    assert logged == [("warning", "bad scan 1"), ("error", "odometry ignored"),
                      ("warning", "bad scan 4")]


def test_is_active_follows_the_transitions_and_cleanup_and_shutdown_release(ros):
    class Recording(GuardedLifecycleNode):
        released = 0

        def release(self):
            self.released += 1

    node = ros.add(Recording("recording", context=ros.context))
    assert node.is_active is False
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.is_active is False
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    assert node.is_active is True
    assert node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
    assert (node.is_active, node.released) == (False, 0)  # kept for a later activate
    assert node.trigger_cleanup() == TransitionCallbackReturn.SUCCESS
    assert (node.is_active, node.released) == (False, 1)
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_shutdown() == TransitionCallbackReturn.SUCCESS  # from active
    assert (node.is_active, node.released) == (False, 2)


@pytest.mark.slow
def test_every_executable_survives_out_of_order_requests(ros):
    """The process keeps running and answering after each refused request."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    bin_dir = Path(sys.executable).parent
    processes = {name: subprocess.Popen(
        [str(bin_dir / command[0]), *command[1:]],
        cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        for name, command in EXECUTABLES.items()}
    client_node = ros.node("lifecycle_client")
    try:
        for name, process in processes.items():
            client = LifecycleClient(ros, client_node, name)
            out_of_order_sequence(client)
            assert process.poll() is None, f"{name} died"
            assert client.request(Transition.TRANSITION_CONFIGURE) is True
            assert client.state() == "inactive"
        for process in processes.values():
            process.send_signal(signal.SIGINT)
        wait_for(lambda: all(p.poll() is not None for p in processes.values()), 15.0,
                 "every node to exit on SIGINT")
    finally:
        outputs = {}
        for name, process in processes.items():
            terminate(process, timeout=5.0)
            outputs[name] = process.communicate(timeout=10)[0]
    for name, process in processes.items():
        assert process.returncode == 0, f"{name}:\n{outputs[name]}"
        assert "is not possible in state" in outputs[name], outputs[name]
