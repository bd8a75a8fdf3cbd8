"""scripts/teleop.py: keys to /cmd_vel within the Burger's limits, and zero on every way out.

The script runs as its own process, as a user starts it, with its keys on a pipe or on a
pseudo-terminal; an in-test subscriber (this test's private domain, conftest.py) checks what it
publishes. Processes that do not depend on each other run side by side: discovery between
processes takes 1-3 s here.
"""
from __future__ import annotations

import argparse
import errno
import os
import pty
import signal
import subprocess
import sys
import termios

import pytest
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry

from amr_common.robot import MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED
from amr_common.ros.qos import RELIABLE_10
from amr_common.ros.ros_conversions import command_from_twist
from tests.processes import REPO, terminate

sys.path.insert(0, str(REPO / "scripts"))
import terminal_keys  # noqa: E402
from teleop import (  # noqa: E402
    ARROWS,
    INTERRUPTED,
    STAMPED,
    TWIST,
    TeleopState,
    choose_message_type,
    detect_message_type,
    drive,
    parse_args,
)
from terminal_keys import KeyReader, StatusLine, keys_in  # noqa: E402

TELEOP = REPO / "scripts" / "teleop.py"
STARTUP = 20.0  # s: interpreter + rclpy start + discovery on a loaded 2-core machine


class Teleop:
    """scripts/teleop.py on its own topic, and what a subscriber of that topic receives."""

    def __init__(self, ros, topic: str, *options: str, kind: type = TwistStamped,
                 stdin=subprocess.PIPE, env: dict | None = None) -> None:
        self.ros = ros
        self.kind = kind
        self.messages: list = []
        node = ros.node(f"listener{topic.replace('/', '_')}")
        node.create_subscription(kind, topic, self.messages.append, RELIABLE_10)
        self.process = subprocess.Popen(
            [sys.executable, str(TELEOP), "--local", "--topic", topic, *options],
            stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
            env=env)

    @property
    def commands(self) -> list[tuple[float, float]]:
        return [command_from_twist(m) for m in self.messages]

    def last_is(self, v: float, w: float) -> bool:
        return bool(self.messages) and self.commands[-1] == pytest.approx((v, w), abs=1e-9)

    def keys(self, text: str) -> None:
        self.process.stdin.write(text + "\n")
        self.process.stdin.flush()

    def end_input(self) -> None:
        self.process.stdin.close()
        self.process.stdin = None  # communicate() must not flush it

    def wait_for(self, v: float, w: float, timeout: float = 5.0) -> None:
        self.ros.spin_until(lambda: self.last_is(v, w), timeout, f"command ({v}, {w})")

    def finish(self, timeout: float = 10.0) -> tuple[int, str, str]:
        """Wait for the exit (spinning: the final zeros come last); (code, stdout, stderr)."""
        try:
            self.ros.spin_until(lambda: self.process.poll() is not None, timeout, "the exit")
        finally:
            terminate(self.process, 2.0)
        out, err = self.process.communicate()
        self.ros.spin_for(0.1)
        return self.process.returncode, out, err


def wait_for_all(ros, teleops: list[Teleop]) -> None:
    """Until each subscriber has its first message (the script sends zero at 10 Hz)."""
    ros.spin_until(lambda: all(t.messages for t in teleops), STARTUP, "discovery")
    assert all(t.last_is(0.0, 0.0) for t in teleops)


def assert_stopped_at_exit(teleop: Teleop) -> None:
    commands = teleop.commands
    assert commands[-3:] == [(0.0, 0.0)] * 3, commands[-6:]  # a few zeros, the last word
    assert all(abs(v) <= MAX_LINEAR_SPEED and abs(w) <= MAX_ANGULAR_SPEED for v, w in commands)


@pytest.mark.slow
def test_keys_step_and_clamp_the_stamped_command_and_q_stops(ros):
    teleop = Teleop(ros, "/teleop_keys")
    wait_for_all(ros, [teleop])
    teleop.keys("www")
    teleop.wait_for(0.03, 0.0)
    teleop.keys("w" * 25)  # beyond the limit: held at 0.22 m/s
    teleop.wait_for(MAX_LINEAR_SPEED, 0.0)
    teleop.keys("xxx" + "a" * 40)
    teleop.wait_for(0.19, MAX_ANGULAR_SPEED)
    teleop.keys("dd")
    teleop.wait_for(0.19, 2.64)
    teleop.keys(" ")
    teleop.wait_for(0.0, 0.0)
    teleop.keys("x" * 30 + "d" * 30 + "W")  # upper case too; the negative limits
    teleop.wait_for(-MAX_LINEAR_SPEED + 0.01, -MAX_ANGULAR_SPEED)
    teleop.keys("q")
    code, out, err = teleop.finish()
    assert code == 0, err
    assert_stopped_at_exit(teleop)
    stamped = teleop.messages[-1]
    assert stamped.header.frame_id == "base_footprint" and stamped.header.stamp.sec > 0
    assert "TwistStamped on /teleop_keys" in err
    assert "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST" in err  # --local: loopback
    # One status line per change (not a terminal): the command as it was sent.
    assert "linear +0.030 m/s  angular +0.00 rad/s" in out.splitlines()
    assert out.splitlines()[-1].endswith("(stopped, exiting)")


@pytest.mark.slow
def test_twist_subscriber_detected_hold_timeout_and_end_of_input_stop(ros):
    auto = Teleop(ros, "/teleop_auto", "--auto", "--hold-timeout", "0.6", kind=Twist)
    plain = Teleop(ros, "/teleop_twist", "--twist", kind=Twist)
    wait_for_all(ros, [auto, plain])
    auto.keys("ww")
    auto.wait_for(0.02, 0.0)
    moving_since = len(auto.messages)
    plain.keys("wa")
    plain.wait_for(0.01, 0.1)
    # No key for 0.6 s: zero, while the script still runs; the other keeps its command.
    took = ros.spin_until(lambda: auto.last_is(0.0, 0.0), 5.0, "the hold timeout")
    assert auto.process.poll() is None
    assert len(auto.messages) - moving_since >= 4  # it kept sending at 10 Hz until then
    assert took + 0.1 * (len(auto.messages) - moving_since) > 0.5
    assert plain.last_is(0.01, 0.1)
    auto.keys("a")
    auto.wait_for(0.0, 0.1)
    for teleop in (auto, plain):  # the pipe closes: end of input
        teleop.end_input()
    outputs = {}
    for teleop, name in ((auto, "auto"), (plain, "twist")):
        code, outputs[name], err = teleop.finish()
        assert code == 0, f"{name}: {err}"
        assert_stopped_at_exit(teleop)
        assert "geometry_msgs/msg/Twist on" in err
    assert "linear +0.000 m/s  angular +0.00 rad/s  (stopped: no key for 0.6 s)" in \
        outputs["auto"].splitlines()


@pytest.mark.slow
def test_sigint_sigterm_and_sighup_stop_the_robot(ros):
    teleops = {signum: Teleop(ros, f"/teleop_{signum.name.lower()}")
               for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    wait_for_all(ros, list(teleops.values()))
    for teleop in teleops.values():
        teleop.keys("wwwaa")
    for signum, teleop in teleops.items():
        teleop.wait_for(0.03, 0.2)
        teleop.process.send_signal(signum)
    for signum, teleop in teleops.items():
        code, _, err = teleop.finish()
        # As a shell reports them: 128 + SIGHUP for a hang-up, 130 for Ctrl-C and SIGTERM.
        assert code == (129 if signum == signal.SIGHUP else INTERRUPTED), f"{signum.name}: {err}"
        assert_stopped_at_exit(teleop)


@pytest.mark.slow
def test_terminal_raw_keys_ctrl_c_and_hang_up_stop_and_restore(ros):
    """On a terminal: keys act without Enter, Ctrl-C quits; a hung-up terminal stops too."""
    terminals = [pty.openpty() for _ in range(2)]
    settings = [termios.tcgetattr(slave) for _, slave in terminals]
    quits, hangs_up = (Teleop(ros, topic, stdin=slave)
                       for topic, (_, slave) in zip(("/teleop_tty", "/teleop_hangup"),
                                                    terminals))
    try:
        wait_for_all(ros, [quits, hangs_up])
        os.write(terminals[0][0], b"w")  # no line end: only raw mode delivers it
        os.write(terminals[1][0], b"a")
        quits.wait_for(0.01, 0.0)
        hangs_up.wait_for(0.0, 0.1)
        os.write(terminals[0][0], b"\x1b[A")  # arrow up
        quits.wait_for(0.02, 0.0)
        os.write(terminals[0][0], b"\x03")  # Ctrl-C in raw mode is a key, not a signal
        os.close(terminals[1][0])  # the terminal window closes
        code, _, err = quits.finish()
        assert code == 0, err
        assert_stopped_at_exit(quits)
        assert "space / s  stop" in err  # the key help, on a terminal only
        assert termios.tcgetattr(terminals[0][1]) == settings[0]
        code, _, err = hangs_up.finish()
        assert code == 0, err
        assert_stopped_at_exit(hangs_up)
    finally:
        for master, slave in terminals:
            for fd in (master, slave):
                try:
                    os.close(fd)
                except OSError as exc:
                    assert exc.errno == errno.EBADF


# --- without a process ---------------------------------------------------------------------

def test_steps_limits_and_ramp():
    state = TeleopState()
    for _ in range(25):
        state.press("w")
    assert (state.v, state.w) == (MAX_LINEAR_SPEED, 0.0)  # exactly the limit, no drift
    for _ in range(30):
        state.press("a")
    assert state.w == MAX_ANGULAR_SPEED
    state.press("d")
    assert state.w == pytest.approx(MAX_ANGULAR_SPEED - 0.1, abs=1e-12)
    assert state.press("s") and (state.v, state.w) == (0.0, 0.0) and not state.moving
    assert not state.press("\x03") and not state.press("Q")
    ramped = TeleopState(ramp=True)
    for key in "wwwwwaaaaa":
        ramped.press(key)
    assert (ramped.target_v, ramped.target_w) == pytest.approx((0.05, 0.5))
    assert (ramped.v, ramped.w) == (0.0, 0.0)
    ramped.advance(0.1)  # turtlebot3_teleop's half step per 0.1 s
    assert (ramped.v, ramped.w) == pytest.approx((0.005, 0.05))
    assert "(target +0.050, +0.50)" in ramped.describe()
    ramped.advance(10.0)
    assert (ramped.v, ramped.w) == pytest.approx((0.05, 0.5))
    ramped.press(" ")  # stopping is never ramped
    assert (ramped.v, ramped.w) == (0.0, 0.0)


def test_keys_from_bytes():
    assert keys_in(b"ww\n", ARROWS) == "ww"
    assert keys_in(b"\x1b[A\x1b[B\x1b[C\x1b[D\x1bOA", ARROWS) == "wxdaw"  # arrows, both modes
    assert keys_in(b"\x1b[5~\x1b[1;5Cq", ARROWS) == "q"  # page up, ctrl-right: ignored
    assert keys_in(b"\x1b", ARROWS) == "" and keys_in(b"\x1b[Aw") == "w"


def test_a_terminal_that_fails_to_read_is_the_end_of_input(monkeypatch):
    """EIO: a background process reading its terminal, a hung-up line. Other errors raise."""
    read_fd, write_fd = os.pipe()
    try:
        os.write(write_fd, b"w")
        with open(read_fd, closefd=False) as stream:
            keys = KeyReader(ARROWS, stream)
            assert not keys.is_tty and keys.read(1.0) == "w"
            os.write(write_fd, b"w")

            def fail(fd: int, size: int, error: int = errno.EIO) -> bytes:
                raise OSError(error, os.strerror(error))

            monkeypatch.setattr(terminal_keys.os, "read", fail)
            assert keys.read(1.0) is None
            monkeypatch.setattr(terminal_keys.os, "read",
                                lambda fd, size: fail(fd, size, errno.EBADF))
            with pytest.raises(OSError):
                keys.read(1.0)
    finally:
        os.close(read_fd)
        os.close(write_fd)
    assert KeyReader(ARROWS, None).read(0.0) is None  # no stdin at all: nothing to read


class _Keys:
    """Keys for drive(), then a failure (as a terminal read can fail)."""

    def __init__(self, keys: str, error: Exception) -> None:
        self.batches = list(keys)
        self.error = error

    def read(self, timeout: float) -> str:
        if self.batches:
            return self.batches.pop(0)
        raise self.error


class _Stop:
    requested = False


def _options(**values) -> argparse.Namespace:
    options = {"rate": 10.0, "ramp": False, "hold_timeout": None, "topic": "/cmd_vel"}
    options.update(values)
    return argparse.Namespace(**options)


def test_an_error_in_the_loop_still_sends_zero(capsys):
    sent = []
    code = drive(_Keys("wwa", OSError(errno.EBADF, "Bad file descriptor")),
                 lambda v, w: sent.append((v, w)), _options(), _Stop(), StatusLine())
    assert code == 1
    assert (0.02, 0.1) in sent and sent[-3:] == [(0.0, 0.0)] * 3
    assert "stopping the robot" in capsys.readouterr().err


def test_a_failing_zero_does_not_prevent_the_others(capsys):
    sent = []

    def send(v: float, w: float) -> None:
        if (v, w) == (0.0, 0.0) and not sent:
            sent.append("failed")
            raise RuntimeError("publisher gone")
        sent.append((v, w))

    code = drive(_Keys("", ValueError("boom")), send, _options(), _Stop(), StatusLine())
    assert code == 1 and sent == ["failed", (0.0, 0.0), (0.0, 0.0)]
    assert "the zero command failed: publisher gone" in capsys.readouterr().err


def test_message_type_from_the_subscribers(ros):
    node = ros.node("teleop_type_probe")
    stop = _Stop()
    node.create_subscription(Twist, "/probe_twist", lambda m: None, RELIABLE_10)
    assert detect_message_type(node, "/probe_twist", 5.0, stop) == TWIST
    node.create_subscription(TwistStamped, "/probe_stamped", lambda m: None, RELIABLE_10)
    assert detect_message_type(node, "/probe_stamped", 5.0, stop) == STAMPED
    node.create_subscription(Odometry, "/probe_odom", lambda m: None, RELIABLE_10)
    with pytest.raises(LookupError, match="nav_msgs/msg/Odometry, not Twist"):
        detect_message_type(node, "/probe_odom", 5.0, stop)
    with pytest.raises(LookupError, match="no subscriber on /probe_none within 0.2 s"):
        detect_message_type(node, "/probe_none", 0.2, stop)
    # A Humble and a Jazzy robot on one topic (one process cannot hold both types).
    with pytest.raises(LookupError, match=r"disagree \(geometry_msgs/msg/Twist, geometry_"):
        choose_message_type({STAMPED, TWIST}, "/cmd_vel", 5.0)


@pytest.mark.parametrize("options, message", [
    (["--rate", "0"], "--rate: must be > 0 and <= 100 (got '0')"),
    (["--rate", "nan"], "--rate: must be > 0"),
    (["--hold-timeout", "-1"], "--hold-timeout: must be > 0"),
    (["--hold-timeout", "inf"], "--hold-timeout: must be > 0"),
    (["--topic", "cmd vel"], "--topic: 'cmd vel' is not a topic name"),
    (["--stamped", "--twist"], "argument --twist: not allowed with argument --stamped"),
    (["--wait", "2"], "--wait is only used with --auto"),
    (["--auto", "--wait", "0"], "--wait: must be > 0"),
    (["--domain-id", "300"], "must be within 0-232"),
    (["--ramp", "1"], "unrecognized arguments: 1"),
])
def test_option_errors(options, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        parse_args(options)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    # One line, as the other scripts' errors: the usage text buried it.
    assert len(err.splitlines()) == 1 and message in err and len(err) < 200, err


def test_bad_environment_domain_is_an_option_error(monkeypatch, capsys):
    monkeypatch.setenv("ROS_DOMAIN_ID", "abc")
    with pytest.raises(SystemExit) as exit_info:
        parse_args([])
    assert exit_info.value.code == 2
    assert "ROS_DOMAIN_ID in the environment must be an integer" in capsys.readouterr().err


def test_option_error_exits_2_before_anything_runs():
    result = subprocess.run([sys.executable, str(TELEOP), "--hold-timeout", "0"],
                            capture_output=True, text=True, cwd=REPO, timeout=30,
                            stdin=subprocess.DEVNULL)
    assert result.returncode == 2
    assert result.stderr == ("teleop.py: error: argument --hold-timeout: must be > 0 (got '0') "
                             "(--help lists the options)\n")
    assert "RMW=" not in result.stderr and result.stdout == ""


class _ClosedOutput:
    """stdout piped into a program that has exited (`teleop.py | head -1`)."""

    def isatty(self) -> bool:
        return False

    def write(self, text: str) -> int:
        raise BrokenPipeError(errno.EPIPE, "Broken pipe")

    def flush(self) -> None:
        raise BrokenPipeError(errno.EPIPE, "Broken pipe")


def test_a_script_endings_does_not_stop_the_driving_nor_the_final_zeros():
    sent = []
    code = drive(_Keys("wwq", AssertionError("read after q")),
                 lambda v, w: sent.append((v, w)), _options(), _Stop(),
                 StatusLine(_ClosedOutput()))
    assert code == 0
    assert (0.02, 0.0) in sent and sent[-3:] == [(0.0, 0.0)] * 3


# --- which local simulator ----------------------------------------------------------------

class FakeSimulator:
    """A process holding a domain lock as run_sim.py does (run_sim's own registration)."""

    def __init__(self, env: dict, domain_id: int | None = None) -> None:
        code = ("import sys; from amr_common.ros.ros_env import isolate_local_graph; "
                f"print(isolate_local_graph({domain_id}, program='run_sim'), flush=True); "
                "sys.stdin.read()")
        self.process = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, text=True, cwd=REPO, env=env)
        self.domain_id = int(self.process.stdout.readline())

    def stop(self) -> None:
        self.process.stdin.close()  # the end of its input: it exits, the lock is free
        self.process.wait(timeout=10)


def _without_a_domain(tmp_path) -> dict:
    """The environment of a new terminal (no ROS_DOMAIN_ID), with its own folder of locks."""
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    env["AMR_DOMAIN_LOCK_DIR"] = str(tmp_path / "locks")
    return env


@pytest.mark.slow
def test_local_teleop_drives_the_one_local_simulator_without_being_told_its_domain(ros,
                                                                                   tmp_path):
    """teleop.py --local took a free domain of its own: it drove nothing."""
    env = _without_a_domain(tmp_path)
    # The simulator runs on this test's domain, where the test's subscriber listens.
    simulator = FakeSimulator(env, int(os.environ["ROS_DOMAIN_ID"]))
    try:
        teleop = Teleop(ros, "/teleop_found", env=env)
        wait_for_all(ros, [teleop])
        teleop.keys("w")
        teleop.wait_for(0.01, 0.0)
        teleop.keys("q")
        code, _, err = teleop.finish()
    finally:
        simulator.stop()
    assert code == 0, err
    assert f"teleop: driving the local simulator on ROS_DOMAIN_ID {simulator.domain_id}" in err


def test_local_teleop_asks_which_domain_unless_exactly_one_simulator_runs(tmp_path):
    env = _without_a_domain(tmp_path)

    def teleop() -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, str(TELEOP), "--local"], capture_output=True,
                              text=True, cwd=REPO, env=env, timeout=60,
                              stdin=subprocess.DEVNULL)

    alone = teleop()
    assert alone.returncode == 2 and alone.stderr.startswith("teleop: no local simulator runs")
    assert alone.stderr.rstrip().endswith("give --domain-id")
    simulators = [FakeSimulator(env), FakeSimulator(env)]
    try:
        several = teleop()
    finally:
        for simulator in simulators:
            simulator.stop()
    assert several.returncode == 2, several.stderr
    assert len(several.stderr.splitlines()) == 1 and "2 local simulators run" in several.stderr
    for simulator in simulators:
        assert f"{simulator.domain_id} (pid {simulator.process.pid})" in several.stderr
    gone = teleop()  # the simulators ended: their locks are free again
    assert gone.returncode == 2 and "no local simulator runs" in gone.stderr
