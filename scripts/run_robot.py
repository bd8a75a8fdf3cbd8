#!/usr/bin/env python3
"""Drive a real TurtleBot3 Burger: amr_odometry + wall follower (robot mode) + lifecycle manager.

Runs on the laptop; the robot runs its own bringup
(`ros2 launch turtlebot3_bringup robot.launch.py`). Both sides must use the same ROS_DOMAIN_ID,
the same RMW and a discovery range that reaches the robot (SUBNET, the default): this script
does not change discovery, it prints what it uses.

  .venv/bin/python scripts/run_robot.py --domain-id 30 --cmd-vel stamped   # Jazzy bringup
  .venv/bin/python scripts/run_robot.py --domain-id 30 --cmd-vel twist     # Humble bringup
  .venv/bin/python scripts/run_robot.py --domain-id 30 --foxglove --map course_map.json
  .venv/bin/python scripts/run_robot.py --domain-id 30 --localize --world lab02  # + localization
  .venv/bin/python scripts/run_robot.py --domain-id 30 --world lab02 --goal -1.0,0.6
With --world and --goal: also the particle filter, the planner and the pure pursuit (robot
mode): explore until localized, then drive to the goal and stop there.
Ctrl-C stops the robot: the controllers publish a zero command before exiting.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from amr_common.ros_env import describe_graph_settings, environment_domain_id  # noqa: E402
from cli_checks import (  # noqa: E402
    OneLineArgumentParser,
    add_domain_id_option,
    join_negative_values,
    use_domain_id,
)
from launch_common import (  # noqa: E402
    ROBOT_PARAMS,
    add_controller_options,
    add_foxglove_options,
    add_localization_options,
    check_common_options,
    make_robot_graph,
    make_viewer_nodes,
)

# Node parameters run_robot sets itself: a -p / --pf-param would contradict them.
WALL_FOLLOWER_SET = {"simulation": "(robot mode)", "dt": "from --dt",
                     "cmd_vel_stamped": "from --cmd-vel", "controller": "from --controller"}
FILTER_SET = {"world": "from --world",
              "lidar_offset_x_m": "(the Burger's LiDAR position; the robot's /tf_static gives it)"}


def parse_args(argv=None) -> argparse.Namespace:
    parser = OneLineArgumentParser(description=__doc__.split("\n\n")[0],
                                   formatter_class=argparse.RawDescriptionHelpFormatter,
                                   epilog=__doc__.split("\n\n", 1)[1])
    add_domain_id_option(parser, "ROS_DOMAIN_ID shared with the robot, 0-232 (default: "
                         "$ROS_DOMAIN_ID)")
    parser.add_argument("--cmd-vel", choices=["stamped", "twist"], default=None,
                        help="/cmd_vel type: stamped = TwistStamped (Jazzy bringup), twist = "
                        "Twist (Humble); default from the params file")
    add_controller_options(parser, str(ROBOT_PARAMS), "wall follower ROS params YAML "
                           "(default params/turtlebot3.yaml)")
    parser.add_argument("--dt", type=float, default=None, help="control period in seconds")
    parser.add_argument("--map", default=None, metavar="MAP", help="also publish this course "
                        "map JSON / world YAML / Nav2 map YAML as /map and /map_markers "
                        "(amr_map_publisher)")
    add_foxglove_options(parser)
    add_localization_options(parser)
    parser.add_argument("--world", default=None, help="with --localize or --goal: the map the "
                        "robot is in (bundled world name or world YAML / course map JSON / Nav2 "
                        "map YAML; default --map)")
    parser.add_argument("--goal", default=None, help="navigate to X,Y (metres, negative numbers "
                        "typed as is) or a named goal of --world: also the particle filter, the "
                        "planner and the pure pursuit")
    args = parser.parse_args(join_negative_values(argv, ["--goal"]))
    if args.domain_id is None:
        try:
            environment_domain_id()
        except ValueError as exc:
            parser.error(str(exc))
    check_common_options(parser, args, "run_robot", WALL_FOLLOWER_SET, FILTER_SET)
    args.localize = args.localize or args.goal is not None  # navigation needs the filter
    if args.localize and args.world is None:
        args.world = args.map
    if args.localize and args.world is None:
        parser.error(f"{'--goal' if args.goal else '--localize'} needs --world (the map the "
                     f"robot drives in)")
    if args.world is not None:
        from amr_common.world import World, WorldError
        try:
            world = World.load(args.world)
            if args.goal is not None:
                args.goal = world.resolve_goal(args.goal)
        except WorldError as exc:
            parser.error(str(exc))
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    use_domain_id(args)
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from amr_common.lifecycle_manager import LifecycleManager, run_managed
    from amr_common.node_runner import StopFlag

    # Own signal handling: the final zero command must go out before the context shuts down.
    # No arguments for rcl: it would read the script's own command line (a '__ns:=...' value
    # as a remapping of every node).
    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
    stop = StopFlag().install()
    stamped = None if args.cmd_vel is None else args.cmd_vel == "stamped"
    nodes = make_robot_graph(None, params_file=args.params_file, dt=args.dt,
                             cmd_vel_stamped=stamped, controller=args.controller,
                             tuning=args.overrides,
                             localize_world=args.world if args.localize else None,
                             filter_overrides=args.pf_overrides, goal=args.goal)
    if args.map:
        from amr_tools.map_publisher import MapPublisherNode
        from launch_common import overrides_to_parameters
        nodes.insert(0, MapPublisherNode(parameter_overrides=overrides_to_parameters(
            {"world": args.map})))
    nodes = make_viewer_nodes(None, args) + nodes  # shut down last (reverse order)
    manager = LifecycleManager([node.get_name() for node in nodes])
    manager.get_logger().info(f"run_robot: {describe_graph_settings()}; Ctrl-C stops the robot")
    return run_managed(manager, stop, nodes)


if __name__ == "__main__":
    sys.exit(main())
