#!/usr/bin/env python3
"""Drive the TurtleBot3 Burger from the keyboard, as turtlebot3_teleop's teleop_keyboard does.

Keys (arrow keys work too):
        w
   a    s    d
        x
  w / x      linear speed +- 0.01 m/s   (Burger limit 0.22 m/s)
  a / d      angular speed +- 0.1 rad/s (Burger limit 2.84 rad/s; a turns left)
  space / s  stop
  q, Ctrl-C  quit (Ctrl-D too on a terminal)
The limits are the official ones, as turtlebot3_teleop's (the OpenCR firmware itself clamps
the wheels at ~0.21 m/s, ~2.64 rad/s).

The command goes out on /cmd_vel every 1/--rate s and at each key. Every way out - q, Ctrl-C,
SIGTERM or SIGHUP, a lost terminal (end of input), an error - publishes zero velocity a few times
(reliable, keep last 10, as turtlebot3_node subscribes) and restores the terminal: the robot
has no command timeout of its own and would keep the last command. When stdin is not a
terminal (a pipe, a test), each character of its lines is a key and the end of input quits.

Examples:
  .venv/bin/python scripts/teleop.py --domain-id 30                # Jazzy bringup on the LAN
  .venv/bin/python scripts/teleop.py --domain-id 30 --twist        # Humble bringup
  .venv/bin/python scripts/teleop.py --domain-id 30 --auto --hold-timeout 1 --ramp
  .venv/bin/python scripts/teleop.py --local                       # the local simulation
Discovery is left to you (the robot's network, like run_robot.py) unless --local: loopback only
and the --domain-id given, else $ROS_DOMAIN_ID if not 0, else the domain of the one run_sim.py
running on this machine (with none or several, say which with --domain-id).
Exit codes: 0 after q or the end of input, 130 after Ctrl-C or SIGTERM, 129 after SIGHUP, 1
after an error, 2 for a mistake in the command line.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

sys.path.insert(0, str(Path(__file__).resolve().parent))
from script_endings import run_script  # noqa: E402
from terminal_keys import KeyReader, StatusLine  # noqa: E402

from amr_common.robot import MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED  # noqa: E402
from amr_common.ros.ros_env import (  # noqa: E402
    describe_graph_settings,
    environment_domain_id,
    isolate_local_graph,
    local_graphs,
)
from cli_checks import (  # noqa: E402
    OneLineArgumentParser,
    add_domain_id_option,
    number_argument,
    ros_name_argument,
    use_domain_id,
)

LINEAR_STEP = 0.01  # m/s per key, as turtlebot3_teleop (also the firmware's resolution)
ANGULAR_STEP = 0.1  # rad/s per key
# --ramp: turtlebot3_teleop moves the sent command half a step per 0.1 s loop towards the target.
LINEAR_ACCELERATION = LINEAR_STEP / 2 / 0.1  # 0.05 m/s^2
ANGULAR_ACCELERATION = ANGULAR_STEP / 2 / 0.1  # 0.5 rad/s^2
FINAL_ZEROS = 3  # zero commands sent on the way out
ACK_TIMEOUT = 3.5  # s: Fast DDS's default heartbeat period is 3 s (see teleop_fastdds.xml)
INTERRUPTED = 130  # exit code after Ctrl-C or SIGTERM, as a shell reports Ctrl-C
QUIT_KEYS = {"q", "\x03", "\x04", "\x1c"}  # q, Ctrl-C, Ctrl-D, Ctrl-\ (raw mode: no signals)
STOP_KEYS = {" ", "s"}
STAMPED, TWIST = "geometry_msgs/msg/TwistStamped", "geometry_msgs/msg/Twist"
ARROWS = {"up": "w", "down": "x", "left": "a", "right": "d"}


def parse_args(argv=None) -> argparse.Namespace:
    parser = OneLineArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    kind = parser.add_mutually_exclusive_group()
    kind.add_argument("--stamped", dest="cmd_vel", action="store_const", const="stamped",
                      help="publish geometry_msgs/TwistStamped, as the Jazzy bringup takes "
                      "(default)")
    kind.add_argument("--twist", dest="cmd_vel", action="store_const", const="twist",
                      help="publish geometry_msgs/Twist, as a Humble bringup takes")
    kind.add_argument("--auto", dest="cmd_vel", action="store_const", const="auto",
                      help="the type the /cmd_vel subscriber advertises (waits --wait s for it)")
    parser.set_defaults(cmd_vel="stamped")
    parser.add_argument("--wait", type=number_argument(float, 0.0, above=True), default=None,
                        metavar="S", help="with --auto: seconds to wait for a subscriber "
                        "(default 5)")
    parser.add_argument("--topic", type=ros_name_argument("topic"), default="/cmd_vel",
                        help="velocity command topic (default /cmd_vel)")
    parser.add_argument("--rate", type=number_argument(float, 0.0, above=True, maximum=100.0),
                        default=10.0, metavar="HZ", help="publishing rate (default 10, as "
                        "turtlebot3_teleop's 0.1 s key poll)")
    parser.add_argument("--ramp", action="store_true", help="smooth the sent command towards "
                        "the keys' target like turtlebot3_teleop (0.05 m/s^2, 0.5 rad/s^2); "
                        "stop and quit stay immediate")
    parser.add_argument("--hold-timeout", type=number_argument(float, 0.0, above=True),
                        default=None, metavar="S", help="stop after S seconds without a key. "
                        "turtlebot3_teleop has no such timeout: it republishes the last command "
                        "until a stop key, and the robot keeps it even after the teleop dies "
                        "(default: none, as the original)")
    parser.add_argument("--local", action="store_true", help="loopback discovery (a local "
                        "simulation) instead of the environment's settings; without --domain-id "
                        "or $ROS_DOMAIN_ID, the domain of the one run_sim.py running here")
    add_domain_id_option(parser, "ROS_DOMAIN_ID shared with the robot, 0-232 (default: "
                         "$ROS_DOMAIN_ID)")
    args = parser.parse_args(argv)
    if args.domain_id is None:
        try:
            environment_domain_id()
        except ValueError as exc:
            parser.error(str(exc))
    if args.wait is not None and args.cmd_vel != "auto":
        parser.error("--wait is only used with --auto")
    args.wait = 5.0 if args.wait is None else args.wait
    return args


# --- what the keys do (no ROS) -------------------------------------------------------------

def _clamp(value: float, limit: float) -> float:
    # Rounded: sums of 0.01 steps drift (0.22 - 0.03 = 0.19000000000000003).
    return round(min(max(value, -limit), limit), 9)


def _towards(current: float, target: float, step: float) -> float:
    return min(target, current + step) if target > current else max(target, current - step)


@dataclass
class TeleopState:
    """The keys' target (v m/s, w rad/s) and the command sent, within the Burger's limits."""

    ramp: bool = False
    target_v: float = 0.0
    target_w: float = 0.0
    v: float = 0.0
    w: float = 0.0

    def press(self, key: str) -> bool:
        """Apply one key; False for a quit key (the command is zero then)."""
        key = key.lower()
        if key in QUIT_KEYS:
            self.stop()
            return False
        if key in STOP_KEYS:
            self.stop()
        elif key in ("w", "x"):
            step = LINEAR_STEP if key == "w" else -LINEAR_STEP
            self.target_v = _clamp(self.target_v + step, MAX_LINEAR_SPEED)
        elif key in ("a", "d"):
            step = ANGULAR_STEP if key == "a" else -ANGULAR_STEP
            self.target_w = _clamp(self.target_w + step, MAX_ANGULAR_SPEED)
        if not self.ramp:
            self.v, self.w = self.target_v, self.target_w
        return True

    def stop(self) -> None:
        """Zero target and command at once (no ramp down)."""
        self.target_v = self.target_w = self.v = self.w = 0.0

    def advance(self, dt: float) -> None:
        """Move the sent command towards the target over dt seconds (with ramp)."""
        self.v = _towards(self.v, self.target_v, LINEAR_ACCELERATION * dt)
        self.w = _towards(self.w, self.target_w, ANGULAR_ACCELERATION * dt)

    @property
    def moving(self) -> bool:
        """True while the target or the command is not zero."""
        return any((self.target_v, self.target_w, self.v, self.w))

    def describe(self) -> str:
        """The status line: the command sent (and the target while ramping to it)."""
        text = f"linear {self.v:+.3f} m/s  angular {self.w:+.2f} rad/s"
        if (self.v, self.w) != (self.target_v, self.target_w):
            text += f"  (target {self.target_v:+.3f}, {self.target_w:+.2f})"
        return text


# --- the loop -------------------------------------------------------------------------------

def drive(keys: KeyReader, send: Callable[[float, float], None], args: argparse.Namespace,
          stop, status: StatusLine, listeners: Callable[[], int] = lambda: 1) -> int:
    """Run the keyboard loop until quit, end of input or `stop.requested`; the exit code.

    `listeners()`: how many subscribers the commands reach (the status line says when none).
    Whatever ends the loop, an exception included, zero velocity is sent FINAL_ZEROS times.
    """
    state = TeleopState(ramp=args.ramp)
    try:
        return _loop(keys, send, state, args, stop, status, listeners)
    except Exception as exc:  # noqa: BLE001 - any failure must still stop the robot
        status.close()
        print(f"teleop: {type(exc).__name__}: {exc}: stopping the robot", file=sys.stderr)
        return 1
    finally:
        state.stop()
        for attempt in range(FINAL_ZEROS):
            try:
                send(0.0, 0.0)
            except Exception as exc:  # noqa: BLE001 - try the others, never mask the exit
                print(f"teleop: the zero command failed: {exc}", file=sys.stderr)
            if attempt + 1 < FINAL_ZEROS:
                time.sleep(0.02)
        status.show(f"{state.describe()}  (stopped, exiting)")
        status.close()


def _loop(keys: KeyReader, send: Callable[[float, float], None], state: TeleopState,
          args: argparse.Namespace, stop, status: StatusLine,
          listeners: Callable[[], int]) -> int:
    period = 1.0 / args.rate
    last_key = last_tick = next_send = time.monotonic()
    note = ""
    while not stop.requested:
        pressed = keys.read(next_send - time.monotonic())
        now = time.monotonic()
        if pressed is None:  # end of input: a pipe closed or the terminal gone
            return 0
        if pressed:
            last_key, note = now, ""
            for key in pressed:
                if not state.press(key):
                    return 0
        if args.hold_timeout is not None and state.moving and \
                now - last_key >= args.hold_timeout:
            state.stop()
            note = f"  (stopped: no key for {args.hold_timeout:g} s)"
        if state.ramp:
            state.advance(now - last_tick)
        last_tick = now
        if pressed or now >= next_send:
            send(state.v, state.w)
            next_send = now + period
        alone = "" if listeners() else f"  [no subscriber on {args.topic} yet]"
        status.show(state.describe() + note + alone)
    return INTERRUPTED


# --- ROS ------------------------------------------------------------------------------------

FASTDDS_PROFILE = Path(__file__).with_name("teleop_fastdds.xml")


def use_fast_heartbeats() -> None:
    """Fast DDS: load teleop_fastdds.xml (a heartbeat every 0.1 s) unless a profile is set.

    With the default 3 s heartbeat a reliable writer learns only seconds later that a command
    was lost (and resends it), and the final zero is acknowledged up to 3 s after quitting.
    """
    rmw = os.environ.get("RMW_IMPLEMENTATION", "") or "rmw_fastrtps_cpp"
    names = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")  # 2.x, 3.x
    if rmw.startswith("rmw_fastrtps") and not any(os.environ.get(name) for name in names):
        for name in names:
            os.environ[name] = str(FASTDDS_PROFILE)


def detect_message_type(node, topic: str, wait: float, stop) -> str:
    """The type the subscribers of `topic` take, waiting up to `wait` s for one to appear."""
    deadline = time.monotonic() + wait
    while True:
        types = {info.topic_type for info in node.get_subscriptions_info_by_topic(topic)}
        if types or stop.requested or time.monotonic() > deadline:
            return choose_message_type(types, topic, wait)
        time.sleep(0.1)


def choose_message_type(types: set[str], topic: str, wait: float) -> str:
    """Twist or TwistStamped, the one type in `types`; LookupError (one line) if unclear."""
    if not types:
        raise LookupError(f"no subscriber on {topic} within {wait:g} s (robot up? same "
                          f"ROS_DOMAIN_ID and RMW?): give --stamped or --twist")
    if len(types) > 1:
        raise LookupError(f"the subscribers of {topic} disagree ({', '.join(sorted(types))}): "
                          f"give --stamped or --twist")
    (found,) = types
    if found not in (STAMPED, TWIST):
        raise LookupError(f"{topic} is subscribed as {found}, not Twist or TwistStamped")
    return found


def make_sender(node, topic: str, stamped: bool) -> tuple[Callable[[float, float], None], object]:
    """(send(v, w), publisher): commands on `topic`, reliable keep last 10 as turtlebot3_node."""
    from geometry_msgs.msg import Twist, TwistStamped

    from amr_common.ros.qos import RELIABLE_10
    from amr_common.ros.ros_conversions import twist_stamped

    publisher = node.create_publisher(TwistStamped if stamped else Twist, topic, RELIABLE_10)

    def send(v: float, w: float) -> None:
        if stamped:
            publisher.publish(twist_stamped(v, w, node.get_clock().now().to_msg()))
        else:
            message = Twist()
            message.linear.x, message.angular.z = float(v), float(w)
            publisher.publish(message)

    return send, publisher


def simulator_domain_id() -> int:
    """The ROS_DOMAIN_ID of the one run_sim.py running here; LookupError (one line) if not one."""
    simulators = local_graphs("run_sim")
    if len(simulators) == 1:
        return simulators[0][0]
    if not simulators:
        raise LookupError("no local simulator runs (run_sim.py --realtime --teleop prints the "
                          "command that drives it): give --domain-id")
    running = ", ".join(f"{domain} (pid {pid})" for domain, pid in simulators)
    raise LookupError(f"{len(simulators)} local simulators run, on ROS_DOMAIN_ID {running}: "
                      f"say which with --domain-id")


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        if args.local:
            domain_id = args.domain_id
            if domain_id is None and not environment_domain_id():
                domain_id = simulator_domain_id()
                print(f"teleop: driving the local simulator on ROS_DOMAIN_ID {domain_id}",
                      file=sys.stderr)
            isolate_local_graph(domain_id)
        else:
            use_domain_id(args)
        import rclpy
        from rclpy.signals import SignalHandlerOptions

        from amr_common.ros.node_runner import StopFlag
    except KeyboardInterrupt:
        return INTERRUPTED
    except LookupError as exc:  # not one local simulator: the user says which
        print(f"teleop: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:  # no free local domain
        print(f"teleop: {exc}", file=sys.stderr)
        return 1
    use_fast_heartbeats()
    # Our own signal handling: rclpy's would shut the context down before the final zeros.
    stop = StopFlag().install()  # Ctrl-C, SIGTERM, SIGHUP
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("teleop_keyboard")
    try:
        code = _run(node, args, stop)
        return stop.exit_code if code == INTERRUPTED else code  # 129 after SIGHUP
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        stop.uninstall()


def _run(node, args: argparse.Namespace, stop) -> int:
    """Pick the message type, then drive; the exit code."""
    from rclpy.duration import Duration

    print(f"teleop: {describe_graph_settings()}", file=sys.stderr)
    kind = {"stamped": STAMPED, "twist": TWIST}.get(args.cmd_vel)
    if kind is None:
        try:
            kind = detect_message_type(node, args.topic, args.wait, stop)
        except LookupError as exc:
            if stop.requested:
                return INTERRUPTED
            print(f"teleop: {exc}", file=sys.stderr)
            return 1
    send, publisher = make_sender(node, args.topic, kind == STAMPED)
    keys = KeyReader(ARROWS)
    print(f"teleop: {kind} on {args.topic} at {args.rate:g} Hz"
          + (f", stop after {args.hold_timeout:g} s without a key" if args.hold_timeout else ""),
          file=sys.stderr)
    if keys.is_tty:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
    with keys:
        code = drive(keys, send, args, stop, StatusLine(), publisher.get_subscription_count)
    # Reliable: the node stays until the zeros are acknowledged (or resent if lost).
    if not publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT)):
        print(f"teleop: WARNING: the zero command on {args.topic} was not acknowledged within "
              f"{ACK_TIMEOUT:g} s: make sure the robot has stopped", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(run_script(main))
