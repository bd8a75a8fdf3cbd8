#!/usr/bin/env python3
"""Measure your LiDAR unit's range error against a tape measure: the slam node's range_correction.

Every LDS-01 has its own systematic range error (up to 15 mm below 0.5 m, up to 5 % of the
range above): a map built from its scans is scaled by as much, and no odometry can reveal it.
Stand the Burger facing a flat wall at a few distances measured with a tape from the LiDAR's
centre; at each, the script pools --scans scans of the wall within +-10 deg straight ahead
(amr_common.sensors.range_calibration), prints what the unit reads and its error, and at the end
the correction (true = measured + correction, piecewise linear) for the slam node.

  .venv/bin/python scripts/calibrate_lidar.py --domain-id 30                 # the real robot
  .venv/bin/python scripts/calibrate_lidar.py --domain-id 30 --out ~/lds01.yaml
  .venv/bin/python scripts/calibrate_lidar.py --simulate turtlebot3:randomized --seed 3
Then: run_robot.py --slam --slam-param 'range_correction:=[...]' (the line printed), or
`amr_slam --ros-args --params-file ~/lds01.yaml` (the file --out writes).
--simulate calibrates a simulated unit instead (the one run_sim.py --profile P --seed N drives),
no ROS and no prompts: a rehearsal. On the robot, each wall waits for Enter (when the input is
not a terminal, each line is an Enter). Discovery is left to you (the robot's network, like
run_robot.py) unless --local: loopback only and the --domain-id given, else $ROS_DOMAIN_ID if
not 0, else a free one (printed).
Exit codes: 0 calibrated, 1 a wall not measured (no /scan, no straight wall ahead, an absurd
reading: nothing is written), 130 after Ctrl-C or SIGTERM, 129 after SIGHUP (the terminal
closed), 2 for a mistake in the command line.
"""
from __future__ import annotations

import argparse
import shlex
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

sys.path.insert(0, str(Path(__file__).resolve().parent))
from script_endings import interruptible, run_script  # noqa: E402

from amr_common.plugins.parameter_table import MAX_SEED  # noqa: E402
from amr_common.ros.ros_env import (  # noqa: E402
    describe_graph_settings,
    environment_domain_id,
    isolate_local_graph,
)
from cli_checks import (  # noqa: E402
    OneLineArgumentParser,
    add_domain_id_option,
    check_output_file,
    join_negative_values,
    number_argument,
    ros_name_argument,
    use_domain_id,
)

PROG = "calibrate_lidar"
INTERRUPTED = 130  # exit code after Ctrl-C / SIGTERM, as a shell reports it
SLAM_NODE = "slam"  # the slam node's name (amr_slam's default, run_robot.py's --slam)
DEFAULT_TIMEOUT_S = 10.0
PROMPT = ("Put the Burger so its LiDAR centre is {distance:g} m from a flat wall, facing it "
          "(measure with a tape); press Enter")


class CalibrationError(Exception):
    """A wall that could not be measured: the one-line reason (exit code 1, nothing written)."""


# --- the command line -----------------------------------------------------------------------

def distances_argument(text: str) -> tuple[float, ...]:
    """The argparse type of --distances: 'D1,D2,...', at least two distinct positive metres."""
    positive = number_argument(float, 0.0, above=True)
    items = [item.strip() for item in text.split(",")]
    distances = tuple(positive(item) for item in items)
    if len(distances) < 2:
        raise argparse.ArgumentTypeError(
            f"give at least 2 distances (a scale needs two), got '{text}'")
    if len(set(distances)) < len(distances):
        raise argparse.ArgumentTypeError(f"a distance is given twice in '{text}'")
    most = max_distances()
    if len(distances) > most:
        raise argparse.ArgumentTypeError(f"at most {most} distances (the slam node's "
                                         f"range_correction takes {most} pairs), got '{text}'")
    return distances


# 200 s of scans per wall at the LDS-01's 5 Hz; the default 25 already pool about 1,200 returns.
MAX_SCANS = 1000


def scans_argument(text: str) -> int:
    """The argparse type of --scans: an integer from 1 to MAX_SCANS."""
    scans = number_argument(int, 1)(text)
    if scans > MAX_SCANS:
        raise argparse.ArgumentTypeError(
            f"at most {MAX_SCANS} (got '{text}'): that is {MAX_SCANS / 5:.0f} s of scans per "
            "wall at the LDS-01's 5 Hz, and the default 25 already pool about 1,200 returns")
    return scans


def max_distances() -> int:
    """How many calibration points the Mapper's range_correction takes (its rule's lengths)."""
    from amr_mapping.mapper_params import PARAMETERS
    return max(PARAMETERS["range_correction"].rule.lengths) // 2


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The options, checked (one line, exit code 2, before anything runs)."""
    from amr_evaluation.lidar_calibration import CALIBRATION_DISTANCES_M, CALIBRATION_SCANS
    parser = OneLineArgumentParser(prog=f"{PROG}.py", description=__doc__.split("\n\n")[0],
                                   formatter_class=argparse.RawDescriptionHelpFormatter,
                                   epilog=__doc__.split("\n\n", 1)[1])
    default_distances = ",".join(f"{d:g}" for d in CALIBRATION_DISTANCES_M)
    parser.add_argument("--distances", type=distances_argument,
                        default=CALIBRATION_DISTANCES_M, metavar="D1,D2,...",
                        help=f"tape distances (m) from the LiDAR's centre to the wall, at least "
                        f"two (default {default_distances}: one below the LDS-01's 0.5 m, two "
                        f"above)")
    parser.add_argument("--scans", type=scans_argument, default=CALIBRATION_SCANS,
                        help=f"scans pooled at each distance, 1-{MAX_SCANS} (default "
                        f"{CALIBRATION_SCANS})")
    parser.add_argument("--out", default=None, metavar="FILE.yaml", help="also write a ROS "
                        f"params file for the slam node ('{SLAM_NODE}': range_correction)")
    parser.add_argument("--simulate", default=None, metavar="PROFILE", help="calibrate a "
                        "simulated unit of this sensor profile (e.g. turtlebot3:randomized) "
                        "instead of the robot: no ROS, no prompts")
    parser.add_argument("--seed", type=number_argument(int, 0, maximum=MAX_SEED), default=None,
                        help="with --simulate: the seed that draws the unit (default 0)")
    parser.add_argument("--topic", type=ros_name_argument("topic"), default=None,
                        help="robot: the LaserScan topic (default /scan)")
    parser.add_argument("--timeout", type=number_argument(float, 0.0, above=True), default=None,
                        metavar="S", help=f"robot: give up after S seconds without a scan "
                        f"(default {DEFAULT_TIMEOUT_S:g})")
    parser.add_argument("--local", action="store_true", help="robot: loopback discovery on a "
                        "private domain (a local simulation) instead of the environment's")
    add_domain_id_option(parser, "robot: ROS_DOMAIN_ID shared with the robot, 0-232 (default: "
                         "$ROS_DOMAIN_ID)")
    args = parser.parse_args(join_negative_values(argv, ["--distances"]))
    try:
        _check_args(args)
    except ValueError as exc:
        parser.error(str(exc))
    return args


def _check_args(args: argparse.Namespace) -> None:
    """The checks between options; ValueError with a one-line reason."""
    if args.simulate is not None:
        robot_only = [option for option, given in (
            ("--topic", args.topic is not None), ("--timeout", args.timeout is not None),
            ("--local", args.local), ("--domain-id", args.domain_id is not None)) if given]
        if robot_only:
            raise ValueError(f"{', '.join(robot_only)}: for the robot; --simulate needs no ROS")
        from amr_sim.profiles import get_profile
        try:
            get_profile(args.simulate)
        except ValueError as exc:
            raise ValueError(f"--simulate: {exc}") from None
        _check_simulated_distances(args.simulate, args.distances)
        args.seed = 0 if args.seed is None else args.seed
    else:
        if args.seed is not None:
            raise ValueError("--seed needs --simulate (the robot's unit is the one it has)")
        if args.domain_id is None and not args.local:
            environment_domain_id()  # ValueError for a bad $ROS_DOMAIN_ID
        args.topic = args.topic or "/scan"
        args.timeout = DEFAULT_TIMEOUT_S if args.timeout is None else args.timeout
    if args.out is not None:
        if Path(args.out).suffix.lower() not in (".yaml", ".yml"):
            raise ValueError(f"--out '{args.out}': a ROS params file is YAML: name it .yaml")
        args.out = check_output_file(args.out, "--out")


def _check_simulated_distances(profile: str, distances: Sequence[float]) -> None:
    """Each distance one the simulated robot can stand at (lidar_calibration.distance_limits)."""
    from amr_evaluation.lidar_calibration import distance_limits
    closest, farthest = distance_limits(profile)
    for distance in distances:
        if distance < closest:
            raise ValueError(f"--distances {distance:g}: too close: the simulated Burger's body "
                             f"keeps its LiDAR's centre at least {closest:g} m from the wall")
        if distance > farthest:
            raise ValueError(f"--distances {distance:g}: too far for the simulated calibration "
                             f"room (at most {farthest:g} m)")


# --- one wall -------------------------------------------------------------------------------

def pooled_wall_points(scans: Sequence[Any]) -> Any:
    """The returns within +-10 deg ahead of every LaserScan in `scans`, pooled: (N, 2) metres.

    Readings that are not returns (amr_common.sensors.scan_returns: 0.0, the LDS-01's "none", NaN,
    outside the scan's [range_min, range_max]) are left out.
    """
    import numpy as np

    from amr_common.sensors.range_calibration import wall_points
    from amr_common.sensors.scan_returns import return_mask
    pooled = [np.empty((0, 2))]
    for scan in scans:
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        ranges = np.where(return_mask(ranges, scan.range_min, scan.range_max), ranges, np.nan)
        pooled.append(wall_points(ranges, scan.angle_min, scan.angle_increment))
    return np.vstack(pooled)


def checked_reading(distance: float, reading: float | None, points: int | None = None) -> float:
    """`reading` of the wall `distance` m away; CalibrationError if none or beyond any LiDAR's."""
    from amr_common.sensors.range_calibration import MIN_WALL_RETURNS, RangeCorrection
    if reading is None:
        if points is None:
            why = "the returns ahead are too few or not on one line"
        elif points < MIN_WALL_RETURNS:
            why = f"only {points} returns there (the wall out of the LiDAR's range?)"
        else:
            why = (f"its {points} returns are not on one straight line (something in front "
                   f"of the wall? the Burger not facing it?)")
        raise CalibrationError(f"no straight wall within +-10 deg ahead at {distance:g} m: {why}")
    try:
        RangeCorrection.from_list([reading, distance - reading])
    except ValueError:
        raise CalibrationError(
            f"the wall {distance:g} m away reads {reading:.3f} m: more than any LiDAR's error "
            f"(the tape from the LiDAR's centre? the wall the nearest thing ahead?)") from None
    return reading


def describe_reading(distance: float, reading: float, detail: str) -> str:
    """'  1 m (tape): reads 1.0310 m, error +31.0 mm (+3.10 %); 25 scans, 1225 returns'."""
    error = reading - distance
    return (f"  {distance:g} m (tape): reads {reading:.4f} m, error {1000 * error:+.1f} mm "
            f"({100 * error / distance:+.2f} %); {detail}")


# --- the two ways of measuring --------------------------------------------------------------

def measure_simulated(args: argparse.Namespace) -> dict[float, float]:
    """The simulated unit's readings at args.distances (amr_evaluation.lidar_calibration)."""
    from amr_evaluation.lidar_calibration import wall_reading
    raw = {}
    for distance in args.distances:  # each where the robot fits (_check_simulated_distances)
        raw[distance] = wall_reading(args.simulate, args.seed, distance, args.scans)
    print(f"Simulated unit: profile {args.simulate}, seed {args.seed}")
    readings = {}
    for distance, reading in raw.items():
        readings[distance] = checked_reading(distance, reading)
        print(describe_reading(distance, reading, f"{args.scans} scans"), flush=True)
    return readings


def measure_robot(args: argparse.Namespace) -> dict[float, float]:
    """The robot's readings at args.distances: a prompt, then args.scans new scans, each."""
    if args.local:
        try:
            isolate_local_graph(args.domain_id)
        except RuntimeError as exc:  # no free local domain
            raise CalibrationError(str(exc)) from None
    else:
        use_domain_id(args)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from amr_common.sensors.range_calibration import wall_distance
    # No rclpy signal handlers: Ctrl-C is a KeyboardInterrupt, answered in main().
    context = rclpy.Context()
    rclpy.init(args=[], context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("calibrate_lidar", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        print(f"{PROG}: {describe_graph_settings()}; scans from {args.topic}", file=sys.stderr)
        readings = {}
        for distance in args.distances:
            wait_for_enter(distance)
            print(f"  collecting {args.scans} scans on {args.topic} ...", flush=True)
            scans = collect_scans(node, executor.spin_once, args.topic, args.scans,
                                  args.timeout)
            points = pooled_wall_points(scans)
            reading = checked_reading(distance, wall_distance(points), len(points))
            readings[distance] = reading
            print(describe_reading(distance, reading,
                                   f"{len(scans)} scans, {len(points)} returns"), flush=True)
        return readings
    finally:
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def wait_for_enter(distance: float) -> None:
    """The prompt for the wall at `distance`, until Enter (a line when not a terminal)."""
    try:
        input(PROMPT.format(distance=distance) + " ")
    except EOFError:
        raise CalibrationError(f"the input ended before the wall at {distance:g} m was "
                               f"measured") from None
    if not sys.stdin.isatty():
        print()  # the piped line was not echoed: end the prompt's line


def collect_scans(node: Any, spin_once: Callable[..., None], topic: str, count: int,
                  timeout: float) -> list:
    """`count` LaserScans arriving from now on; CalibrationError after `timeout` s without one.

    A new best-effort subscription: no scan taken while the Burger was being moved is used.
    """
    from sensor_msgs.msg import LaserScan

    from amr_common.ros.qos import scan_qos
    scans: list = []
    subscription = node.create_subscription(LaserScan, topic, scans.append, scan_qos())
    try:
        received, last = 0, time.monotonic()
        while len(scans) < count:
            spin_once(timeout_sec=0.1)
            if len(scans) > received:
                received, last = len(scans), time.monotonic()
            elif time.monotonic() - last > timeout:
                if not scans:
                    raise CalibrationError(
                        f"no scan on {topic} within {timeout:g} s (robot bringup running? same "
                        f"ROS_DOMAIN_ID, RMW and discovery range? {describe_graph_settings()})")
                raise CalibrationError(f"{topic} stopped after {len(scans)} scans: none for "
                                       f"{timeout:g} s")
    finally:
        node.destroy_subscription(subscription)
    return scans[:count]


# --- the result -----------------------------------------------------------------------------

def slam_param(values: Sequence[float]) -> str:
    """The run scripts' --slam-param item, quoted for a shell (brackets are glob characters)."""
    return shlex.quote(f"range_correction:=[{', '.join(repr(float(v)) for v in values)}]")


def params_yaml(values: Sequence[float], readings: Mapping[float, float], source: str) -> str:
    """A ROS params file for the slam node with `values` as its range_correction."""
    tape = ", ".join(f"{d:g}" for d in readings)
    read = ", ".join(f"{r:.4f}" for r in readings.values())
    return "\n".join([
        f"# The LiDAR unit's range calibration (scripts/calibrate_lidar.py, "
        f"{datetime.now():%Y-%m-%d %H:%M}): {source}.",
        f"# Walls at {tape} m (tape) read {read} m; true = measured + correction.",
        "# amr_slam --ros-args --params-file THIS_FILE",
        f"{SLAM_NODE}:",
        "  ros__parameters:",
        f"    range_correction: [{', '.join(repr(float(v)) for v in values)}]",
        ""])


def report(readings: Mapping[float, float], args: argparse.Namespace, source: str) -> None:
    """Print the correction and the ways to give it to the slam node; write --out."""
    from amr_common.sensors.range_calibration import fit_correction
    from amr_mapping.mapper_params import check_parameters
    try:
        values = fit_correction(readings).as_list()
        check_parameters({"range_correction": values})  # what the slam node will check
    except ValueError as exc:  # readings not ascending with the distances
        raise CalibrationError(f"the readings do not fit one correction: {exc}") from None
    print(f"range_correction (m; true = measured + correction): {values}")
    print(f"For the slam node: run_robot.py --slam --slam-param {slam_param(values)}")
    if args.out is not None:
        args.out.write_text(params_yaml(values, readings, source))
        print(f"Params file: {args.out} (amr_slam --ros-args --params-file {args.out})")


def main(argv: Sequence[str] | None = None) -> int:
    """Calibrate; the exit code (module docstring)."""
    return interruptible(f"\n{PROG}: interrupted; nothing written", lambda: _calibrate(argv))


def _calibrate(argv: Sequence[str] | None) -> int:
    try:
        args = parse_args(argv)
        if args.simulate is not None:
            readings = measure_simulated(args)
            source = f"simulated unit {args.simulate}, seed {args.seed}"
        else:
            readings = measure_robot(args)
            source = f"the robot's {args.topic}"
        report(readings, args, source)
        return 0
    except CalibrationError as exc:
        print(f"{PROG}: {exc}; nothing written", file=sys.stderr)
        return 1


if __name__ == "__main__":
    try:
        sys.exit(run_script(main))
    except KeyboardInterrupt:  # in the instant before main() answers it
        sys.exit(INTERRUPTED)
