"""The lifecycle manager brings nodes up in order and names the node that is missing or fails."""
import pytest
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn

from amr_common.ros.lifecycle_manager import LifecycleManager, LifecycleStartupError


class RecordingNode(LifecycleNode):
    """A lifecycle node that records the transitions it went through into a shared journal."""

    def __init__(self, name, journal, context, fail_on=None):
        super().__init__(name, context=context)
        self.journal = journal
        self.fail_on = fail_on

    def _record(self, transition):
        self.journal.append((self.get_name(), transition))
        if transition == self.fail_on:
            self.get_logger().error(f"refusing to {transition} (test)")
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn.SUCCESS

    def on_configure(self, state):
        return self._record("configure")

    def on_activate(self, state):
        result = self._record("activate")
        return super().on_activate(state) if result == TransitionCallbackReturn.SUCCESS else result


def _manager(ros, order, **params):
    from rclpy.parameter import Parameter
    overrides = [Parameter(k, value=v) for k, v in params.items()]
    return ros.add(LifecycleManager(order, context=ros.context, parameter_overrides=overrides))


def test_manager_configures_all_then_activates_all_in_order(ros):
    journal = []
    controller = ros.add(RecordingNode("controller", journal, ros.context))
    simulator = ros.add(RecordingNode("simulator", journal, ros.context))
    manager = _manager(ros, ["controller", "simulator"])
    manager.startup(ros.executor,
                    before_activation=lambda: journal.append(("all configured", "hook")))
    assert journal == [("controller", "configure"), ("simulator", "configure"),
                       ("all configured", "hook"),
                       ("controller", "activate"), ("simulator", "activate")]
    assert manager.get_state("controller", ros.executor) == "active"
    assert manager.get_state("simulator", ros.executor) == "active"
    assert controller._state_machine.current_state[1] == "active"
    assert simulator._state_machine.current_state[1] == "active"


def test_manager_names_the_missing_node(ros):
    journal = []
    ros.add(RecordingNode("present", journal, ros.context))
    manager = _manager(ros, ["present", "absent_node"], service_timeout=0.5)
    with pytest.raises(LifecycleStartupError, match="'absent_node' not found"):
        manager.startup(ros.executor)
    assert journal == []  # nothing is configured while a node is missing


def test_manager_reports_a_failing_node_and_stops_the_rest(ros):
    journal = []
    ros.add(RecordingNode("first", journal, ros.context))
    ros.add(RecordingNode("broken", journal, ros.context, fail_on="configure"))
    ros.add(RecordingNode("last", journal, ros.context))
    manager = _manager(ros, ["first", "broken", "last"])
    with pytest.raises(LifecycleStartupError, match="'broken' failed to configure"):
        manager.startup(ros.executor)
    assert journal == [("first", "configure"), ("broken", "configure")]
    assert manager.get_state("last", ros.executor) == "unconfigured"
    assert manager.get_state("first", ros.executor) == "inactive"  # never activated


def test_manager_skips_nodes_already_active(ros):
    journal = []
    node = ros.add(RecordingNode("autostarted", journal, ros.context))
    node.trigger_configure()
    node.trigger_activate()
    manager = _manager(ros, ["autostarted"])
    manager.startup(ros.executor)
    assert journal == [("autostarted", "configure"), ("autostarted", "activate")]


def test_manager_executable_brings_up_nodes_in_another_process(ros):
    import os
    import subprocess
    import sys
    from pathlib import Path

    journal = []
    ros.add(RecordingNode("remote_a", journal, ros.context))
    ros.add(RecordingNode("remote_b", journal, ros.context))
    executable = Path(sys.executable).parent / "amr_lifecycle_manager"
    process = subprocess.Popen(
        [str(executable), "--ros-args", "-p", "node_startup_order:=['remote_a', 'remote_b']"],
        env=dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        ros.spin_until(lambda: len(journal) == 4, timeout=20.0,
                       message="the manager process to configure and activate both nodes")
    finally:
        process.terminate()
        output = process.communicate(timeout=10)[0]
    assert journal == [("remote_a", "configure"), ("remote_b", "configure"),
                       ("remote_a", "activate"), ("remote_b", "activate")], output
