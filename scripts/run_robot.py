#!/usr/bin/env python3
"""Drive a real TurtleBot3 Burger: amr_odometry + wall follower (robot mode) + lifecycle manager.

Runs on the laptop; the robot runs its own bringup
(`ros2 launch turtlebot3_bringup robot.launch.py`). Both sides must use the same ROS_DOMAIN_ID,
the same RMW and a discovery range that reaches the robot (SUBNET, the default): this script
does not change discovery, it prints what it uses.

  .venv/bin/python scripts/run_robot.py --domain-id 30 --cmd-vel stamped   # Jazzy bringup
  .venv/bin/python scripts/run_robot.py --domain-id 30 --cmd-vel twist     # Humble bringup
Ctrl-C stops the robot: the wall follower publishes a zero command before exiting.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from amr_common.ros_env import describe_graph_settings  # noqa: E402
from launch_common import (
    ROBOT_PARAMS,
    add_controller_options,
    check_common_options,
    make_robot_graph,  # noqa: E402
)


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--domain-id", type=int, default=None,
                        help="ROS_DOMAIN_ID shared with the robot (default: $ROS_DOMAIN_ID)")
    parser.add_argument("--cmd-vel", choices=["stamped", "twist"], default=None,
                        help="/cmd_vel type: stamped = TwistStamped (Jazzy bringup), twist = "
                        "Twist (Humble); default from the params file")
    add_controller_options(parser, str(ROBOT_PARAMS), "wall follower ROS params YAML "
                           "(default params/turtlebot3.yaml)")
    parser.add_argument("--dt", type=float, default=None, help="control period in seconds")
    args = parser.parse_args(argv)
    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        parser.error("--domain-id must be within 0-232")
    check_common_options(parser, args)
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.domain_id is not None:
        os.environ["ROS_DOMAIN_ID"] = str(args.domain_id)
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from amr_common.lifecycle_manager import LifecycleManager, run_managed
    from amr_common.node_runner import StopFlag

    # Own signal handling: the final zero command must go out before the context shuts down.
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    stop = StopFlag().install()
    stamped = None if args.cmd_vel is None else args.cmd_vel == "stamped"
    nodes = make_robot_graph(None, params_file=args.params_file, dt=args.dt,
                             cmd_vel_stamped=stamped, controller=args.controller,
                             tuning=args.overrides)
    manager = LifecycleManager([node.get_name() for node in nodes])
    manager.get_logger().info(f"run_robot: {describe_graph_settings()}; Ctrl-C stops the robot")
    return run_managed(manager, stop, nodes)


if __name__ == "__main__":
    sys.exit(main())
