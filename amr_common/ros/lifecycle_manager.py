"""Lifecycle manager: brings the project's lifecycle nodes up in a given order.

Given `node_startup_order`, it waits for each node's lifecycle services (failing with an error
that names the missing node), configures every node in order, then activates every node in order
(the simulator last, so the loop starts when everyone listens). A node that fails a transition is
reported and the remaining transitions are not attempted. Nodes already in the target state
(e.g. started with autostart) are left as they are.

In-process (run scripts): `LifecycleManager(order, context=ctx).startup(executor)` with the
executor that spins the managed nodes. As an executable:
    amr_lifecycle_manager --ros-args -p node_startup_order:="['wall_follower', 'simulator']"
"""
from __future__ import annotations

import sys
import time
from typing import Callable, Sequence

import rclpy
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import Executor
from rclpy.lifecycle import LifecycleNode
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from amr_common.plugins.link_failure import LINK_FAILED
from amr_common.ros.lifecycle_node import first_link_failure
from amr_common.ros.node_runner import StopFlag, make_executor, shutdown_node, spin_until_stopped

_TRANSITION_LABELS = {Transition.TRANSITION_CONFIGURE: "configure",
                      Transition.TRANSITION_ACTIVATE: "activate"}
# A transition is skipped when the node is already at or past its goal state.
_ALREADY_DONE = {Transition.TRANSITION_CONFIGURE: {State.PRIMARY_STATE_INACTIVE,
                                                   State.PRIMARY_STATE_ACTIVE},
                 Transition.TRANSITION_ACTIVATE: {State.PRIMARY_STATE_ACTIVE}}


class LifecycleStartupError(RuntimeError):
    """A managed node is missing or failed a transition; the message names it."""


class StartupInterrupted(RuntimeError):
    """The stop flag (Ctrl-C, SIGTERM, SIGHUP) was set during start-up: no further transition."""


class LifecycleManager(Node):
    """A plain node that configures, then activates, lifecycle nodes in a given order.

    Creates in __init__ its parameters (node_startup_order, service_timeout,
    transition_timeout); the get_state / change_state clients are created on first use, one
    pair per managed node. It is not a lifecycle node itself: it has nothing to release on the
    way down and sends nothing; the nodes it manages run their own shutdown transitions
    (`run_managed` drives those of in-process nodes, controllers first).
    """

    def __init__(self, node_startup_order: Sequence[str] | None = None,
                 node_name: str = "lifecycle_manager", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        self.declare_parameter(
            "node_startup_order", list(node_startup_order or [""]),
            ParameterDescriptor(description="Lifecycle nodes to configure, then activate, in "
                                            "this order"))
        self.declare_parameter("service_timeout", 10.0, ParameterDescriptor(
            description="Seconds to wait for a node's lifecycle services to appear"))
        # 60 s: the first configure after an install compiles the numba kernels (10-20 s on a
        # slow laptop; more on a loaded machine), which is slow but not a failure.
        self.declare_parameter("transition_timeout", 60.0, ParameterDescriptor(
            description="Seconds to wait for a node to answer one transition request"))
        self.node_startup_order = [n for n in self.get_parameter("node_startup_order").value
                                   if n]
        self._lifecycle_clients: dict[str, tuple] = {}
        self._stop: StopFlag | None = None

    def startup(self, executor: Executor, stop: StopFlag | None = None,
                before_activation: Callable[[], None] | None = None) -> None:
        """Configure, then activate, every node in order. Raises LifecycleStartupError.

        With `stop`: StartupInterrupted as soon as it is set (between transitions, or while
        waiting for a node), the nodes left in the states they reached. `before_activation`
        runs once every node is configured, before the first activation (the publishers exist,
        nothing was published yet: e.g. a recorder subscribes then).
        """
        if not self.node_startup_order:
            raise LifecycleStartupError("node_startup_order is empty: nothing to start")
        self._stop = stop
        for name in self.node_startup_order:
            self._wait_for_services(name, executor)
        for transition in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
            if transition == Transition.TRANSITION_ACTIVATE and before_activation is not None:
                before_activation()
            for name in self.node_startup_order:
                self._transition(name, transition, executor)
        self.get_logger().info("all nodes active: " + ", ".join(self.node_startup_order))

    def get_state(self, name: str, executor: Executor) -> str:
        """The node's current primary state label (e.g. 'active')."""
        response = self._call(name, self._clients_for(name)[0], GetState.Request(), executor,
                              "get_state")
        return response.current_state.label

    def _clients_for(self, name: str) -> tuple:
        if name not in self._lifecycle_clients:
            self._lifecycle_clients[name] = (
                self.create_client(GetState, f"{name}/get_state"),
                self.create_client(ChangeState, f"{name}/change_state"))
        return self._lifecycle_clients[name]

    def _wait_for_services(self, name: str, executor: Executor) -> None:
        timeout = self.get_parameter("service_timeout").value
        deadline = time.monotonic() + timeout
        clients = self._clients_for(name)
        while not all(client.service_is_ready() for client in clients):
            self._check_stop()
            if time.monotonic() > deadline:
                raise LifecycleStartupError(
                    f"lifecycle node '{name}' not found: its services {name}/get_state and "
                    f"{name}/change_state did not appear within {timeout:.1f} s (is the node "
                    f"running, with this name, in this ROS_DOMAIN_ID?)")
            executor.spin_once(timeout_sec=0.05)

    def _call(self, name: str, client, request, executor: Executor, what: str):
        timeout = self.get_parameter("transition_timeout").value
        self._check_stop()
        future = client.call_async(request)
        deadline = time.monotonic() + timeout
        while not future.done():
            if self._stop is not None and self._stop.requested:
                client.remove_pending_request(future)
                self._check_stop()
            if time.monotonic() > deadline:
                client.remove_pending_request(future)
                raise LifecycleStartupError(
                    f"lifecycle node '{name}' did not answer '{what}' within {timeout:.1f} s")
            executor.spin_once(timeout_sec=0.05)
        if future.exception() is not None:
            raise LifecycleStartupError(f"lifecycle node '{name}': '{what}' raised "
                                        f"{future.exception()!r}")
        return future.result()

    def _check_stop(self) -> None:
        if self._stop is not None and self._stop.requested:
            raise StartupInterrupted("start-up interrupted")

    def _transition(self, name: str, transition: int, executor: Executor) -> None:
        label = _TRANSITION_LABELS[transition]
        get_state, change_state = self._clients_for(name)
        state = self._call(name, get_state, GetState.Request(), executor, "get_state")
        if state.current_state.id in _ALREADY_DONE.get(transition, ()):
            self.get_logger().info(f"'{name}' already {state.current_state.label}")
            return
        request = ChangeState.Request()
        request.transition.id = transition
        response = self._call(name, change_state, request, executor, label)
        if not response.success:
            after = self._call(name, get_state, GetState.Request(), executor, "get_state")
            raise LifecycleStartupError(
                f"lifecycle node '{name}' failed to {label} (now "
                f"'{after.current_state.label}'; see its log for the reason); nodes after it "
                f"in the startup order were not started")
        self.get_logger().info(f"'{name}': {label} OK")


def run_managed(manager: LifecycleManager, stop: StopFlag,
                nodes: Sequence[LifecycleNode] = ()) -> int:
    """Spin `manager` and the in-process `nodes`, bring the graph up, run until stopped.

    Then the in-process nodes go through their shutdown transition in reverse startup order
    (controllers first: their final zero command goes out while DDS is still up), everything is
    destroyed and rclpy shut down. The caller has run rclpy.init(signal_handler_options=NO) and
    installed `stop` (Ctrl-C, SIGTERM, SIGHUP); a stop during start-up ends it there (no further
    transition). A link of a node that failed (amr_common.plugins.link_failure) ends the run too.
    Returns the process exit code (0 after a stop: the caller knows it from `stop`; LINK_FAILED
    after a failed link).
    """
    executor = make_executor()
    for node in [*nodes, manager]:
        executor.add_node(node)
    exit_code = 0
    try:
        manager.startup(executor, stop)
        # Stay up, as a launch file's manager would; a link that failed ends the run.
        spin_until_stopped(executor, stop, until=lambda: first_link_failure(nodes) is not None)
        if first_link_failure(nodes) is not None:  # its node logged it and stopped the robot
            manager.get_logger().error(f"the run failed: {first_link_failure(nodes)}")
            exit_code = LINK_FAILED
    except StartupInterrupted:
        manager.get_logger().info("start-up interrupted: shutting the nodes down")
    except LifecycleStartupError as exc:
        manager.get_logger().error(str(exc))
        exit_code = 1
    finally:
        for node in reversed(nodes):
            shutdown_node(node)
        for node in [*nodes, manager]:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return exit_code


def main(args: Sequence[str] | None = None) -> int:
    rclpy.init(args=list(sys.argv if args is None else args),
               signal_handler_options=SignalHandlerOptions.NO)
    stop = StopFlag().install()
    return run_managed(LifecycleManager(), stop)


if __name__ == "__main__":
    sys.exit(main())
