"""amr_common.ros.node_runner, the main of every lifecycle executable.

`-p autostart:=true` configures and activates, a failing transition gives exit code 1, and
Ctrl-C / SIGTERM / SIGHUP end the spin and run the node's shutdown transition before the process
exits (a node on the robot whose SSH session dropped still sends its final zero).

The executable tests run a small journaling node as its own process, as a user starts one.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.parameter import Parameter

from amr_common.ros.node_runner import (
    StopFlag,
    autostart,
    declare_autostart,
    shutdown_node,
    spin_until_stopped,
)
from tests.processes import wait_for

REPO = Path(__file__).resolve().parent.parent


class JournalNode(LifecycleNode):
    """A lifecycle node that journals its transitions and refuses the one named by `fail_on`.

    Each transition goes to `self.journal` and to the file named by the `journal` parameter.
    """

    def __init__(self, node_name: str = "journal_node", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        self.declare_parameter("journal", "")
        self.declare_parameter("fail_on", "")
        self.declare_parameter("fail_in_constructor", False)
        if self.get_parameter("fail_in_constructor").value:
            raise RuntimeError("constructor failed (test)")
        self.journal: list[str] = []
        self._write("created")

    def _record(self, transition: str) -> TransitionCallbackReturn:
        self.journal.append(transition)
        self._write(transition)
        if transition == self.get_parameter("fail_on").value:
            self.get_logger().error(f"refusing to {transition} (test)")
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn.SUCCESS

    def _write(self, event: str) -> None:
        path = self.get_parameter("journal").value
        if path:
            with open(path, "a") as stream:
                stream.write(event + "\n")

    def on_configure(self, state):
        return self._record("configure")

    def on_activate(self, state):
        result = self._record("activate")
        return super().on_activate(state) if result == TransitionCallbackReturn.SUCCESS else result

    def on_deactivate(self, state):
        self._record("deactivate")
        return super().on_deactivate(state)

    def on_shutdown(self, state):
        return self._record(f"shutdown from {state.label}")


def main() -> int:
    from amr_common.ros.node_runner import run_lifecycle_node
    return run_lifecycle_node(JournalNode)


# --- the executable ------------------------------------------------------------------------
def _start(tmp_path: Path, *params: str) -> tuple[subprocess.Popen, Path]:
    journal = tmp_path / "journal.txt"
    ros_args = ["--ros-args", "-p", f"journal:={journal}"]
    for param in params:
        ros_args += ["-p", param]
    process = subprocess.Popen(
        [sys.executable, "-c", "import sys; from tests.test_node_runner import main; "
                               "sys.exit(main())", *ros_args],
        cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True)
    return process, journal


def _journal(path: Path) -> list[str]:
    return path.read_text().splitlines() if path.exists() else []


def _finish(process: subprocess.Popen, timeout: float = 20.0) -> str:
    try:
        return process.communicate(timeout=timeout)[0]
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_autostart_activates_and_a_signal_runs_the_shutdown_transition(tmp_path, signum):
    process, journal = _start(tmp_path, "autostart:=true")
    try:
        wait_for(lambda: "activate" in _journal(journal) or process.poll() is not None, 30.0,
                  "the node to activate")
        assert process.poll() is None, _finish(process)
        time.sleep(0.3)  # spinning now; the signal must end the spin, not the startup
        process.send_signal(signum)
        output = _finish(process)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, output
    assert _journal(journal) == ["created", "configure", "activate", "shutdown from active"], \
        output


def test_without_autostart_the_node_waits_unconfigured(tmp_path):
    process, journal = _start(tmp_path)
    try:
        wait_for(lambda: _journal(journal) or process.poll() is not None, 30.0,
                  "the node to be created")
        time.sleep(0.5)  # an autostart would follow the creation at once
        assert process.poll() is None, _finish(process)
        assert _journal(journal) == ["created"]
        process.send_signal(signal.SIGINT)
        output = _finish(process)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, output
    assert _journal(journal) == ["created", "shutdown from unconfigured"], output


def test_a_failing_autostart_exits_1_naming_the_transition(tmp_path):
    process, journal = _start(tmp_path, "autostart:=true", "fail_on:=configure")
    output = _finish(process, timeout=30.0)
    assert process.returncode == 1, output
    assert "autostart: 'configure' returned FAILURE" in output
    assert _journal(journal) == ["created", "configure", "shutdown from unconfigured"]


def test_a_node_that_cannot_be_built_exits_1(tmp_path):
    process, journal = _start(tmp_path, "fail_in_constructor:=true")
    output = _finish(process, timeout=30.0)
    assert process.returncode == 1, output
    assert "fatal: RuntimeError('constructor failed (test)')" in output
    assert _journal(journal) == []


# --- the pieces, in-process ----------------------------------------------------------------
def _node(ros, **params) -> JournalNode:
    overrides = [Parameter(name, value=value) for name, value in params.items()]
    return ros.add(JournalNode(context=ros.context, parameter_overrides=overrides))


def _state(node: LifecycleNode) -> str:
    return node._state_machine.current_state[1]


def test_autostart_configures_then_activates(ros):
    node = _node(ros)
    assert autostart(node) is True
    assert node.journal == ["configure", "activate"] and _state(node) == "active"


@pytest.mark.parametrize("fail_on, state", [("configure", "unconfigured"),
                                            ("activate", "inactive")])
def test_autostart_stops_at_the_failing_transition(ros, fail_on, state):
    node = _node(ros, fail_on=fail_on)
    assert autostart(node) is False
    assert node.journal[-1] == fail_on and _state(node) == state


def test_autostart_parameter_defaults_to_false(ros):
    assert declare_autostart(_node(ros)) is False
    node = _node(ros, autostart=True)
    assert declare_autostart(node) is True
    assert declare_autostart(node) is True  # declaring twice is harmless


@pytest.mark.parametrize("steps, expected", [
    ((), "shutdown from unconfigured"),
    (("configure",), "shutdown from inactive"),
    (("configure", "activate"), "shutdown from active"),
])
def test_shutdown_node_runs_the_shutdown_transition_once(ros, steps, expected):
    node = _node(ros)
    for step in steps:
        getattr(node, f"trigger_{step}")()
    shutdown_node(node)
    shutdown_node(node)  # already finalized: nothing more happens
    assert node.journal == [*steps, expected] and _state(node) == "finalized"


_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _harmless_signals() -> dict:
    """Handlers that ignore SIGTERM and SIGHUP (one the flag missed fails the test, not pytest).

    Returns the handlers to restore.
    """
    previous = {s: signal.getsignal(s) for s in _STOP_SIGNALS}
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, lambda *_: None)
    return previous


def test_stop_flag_is_set_by_sigint_sigterm_and_sighup_and_remembers_which_came():
    previous = _harmless_signals()
    codes = {}
    try:
        for signum in _STOP_SIGNALS:
            before = signal.getsignal(signum)
            stop = StopFlag().install()
            assert stop.requested is False
            os.kill(os.getpid(), signum)
            wait_for(lambda: stop.requested, 2.0, "the signal handler")
            os.kill(os.getpid(), signal.SIGINT)  # a second signal: the first one stopped it
            time.sleep(0.05)
            assert stop.signum == signum
            codes[signum] = stop.exit_code
            stop.uninstall()
            assert signal.getsignal(signum) is before
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    # As a shell reports them (128 + the signal), SIGTERM as the scripts document it.
    assert codes == {signal.SIGINT: 130, signal.SIGTERM: 130, signal.SIGHUP: 129}


def test_a_stop_flag_that_raises_interrupts_like_ctrl_c_for_each_signal():
    previous = _harmless_signals()
    try:
        for signum in _STOP_SIGNALS:
            stop = StopFlag(raise_interrupt=True).install()
            with pytest.raises(KeyboardInterrupt):
                os.kill(os.getpid(), signum)
                time.sleep(2.0)  # the handler raises here, at once
            assert stop.requested and stop.exit_code == (129 if signum == signal.SIGHUP
                                                         else 130)
            stop.uninstall()
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def test_the_spin_ends_when_the_flag_is_set(ros):
    stop = StopFlag()
    node = ros.node("stopper")
    started = time.monotonic()
    node.create_timer(0.2, lambda: setattr(stop, "requested", True))
    spin_until_stopped(ros.executor, stop, ros.context)
    assert stop.requested
    assert time.monotonic() - started < 5.0
