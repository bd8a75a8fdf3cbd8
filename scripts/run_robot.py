#!/usr/bin/env python3
"""Drive a real TurtleBot3 Burger: amr_odometry + wall follower (robot mode) + lifecycle manager.

Runs on the laptop; the robot runs its own bringup
(`ros2 launch turtlebot3_bringup robot.launch.py`). Both sides must use the same ROS_DOMAIN_ID,
the same RMW and a discovery range that reaches the robot (SUBNET, the default): this script
does not change discovery, it prints what it uses.

  .venv/bin/python scripts/run_robot.py --domain-id 30 --cmd-vel stamped   # Jazzy bringup
  .venv/bin/python scripts/run_robot.py --domain-id 30 --cmd-vel twist     # Humble bringup
  .venv/bin/python scripts/run_robot.py --domain-id 30 --foxglove --map course_map.json
  .venv/bin/python scripts/run_robot.py --domain-id 30 --localize --map lab02  # + localization
  .venv/bin/python scripts/run_robot.py --domain-id 30 --map ~/map.yaml --goal -1.0,0.6
--map is THE map, as Nav2's `map:=`: published as /map (amr_map_publisher), the particle
filter's with --localize, the planner's with --goal. With --goal: also the particle filter, the
planner and the pure pursuit (robot mode): explore until localized, then drive to the goal and
stop there. (--world is an old name of --map: on the robot there is no simulated world.)
  .venv/bin/python scripts/run_robot.py --domain-id 30 --slam --map-out ~/maps/room  # map it
  .venv/bin/python scripts/run_robot.py --domain-id 30 --slam --teleop --map-out ~/maps/room
With --slam: the slam node maps while the wall follower explores (or, with --teleop, while you
drive with scripts/teleop.py); --map-out DIR writes DIR/map.yaml + DIR/map.pgm on Ctrl-C; without
it the map goes to maps/<YYYY-MM-DD>-<HHMMSS>/ in the current folder (named at start-up and at
the end): a mapping session is never thrown away.
Ctrl-C (or SIGTERM) stops the robot: the controllers publish a zero command before exiting (exit
code 130), at any moment, start-up included; a dropped SSH session or a closed terminal (SIGHUP)
too, exit code 129. Exit code 3: the map could not be written (said, with the reason).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from amr_common.stop_flag import StopFlag  # noqa: E402

# Run as a script, Ctrl-C (SIGTERM, SIGHUP) only sets a flag from the first moment on: see main().
_STOP = StopFlag().install() if __name__ == "__main__" else None

from link_options import (  # noqa: E402
    add_link_options,
    add_localization_options,
    check_filter_map,
)
from script_endings import run_script  # noqa: E402

from amr_common.ros.ros_env import describe_graph_settings, environment_domain_id  # noqa: E402
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
    check_common_options,
    make_robot_graph,
    make_viewer_nodes,
)
from launch_slam import (  # noqa: E402
    MAP_NOT_WRITTEN,
    add_slam_options,
    check_map_folder,
    check_slam_options,
    default_map_folder,
    lidar_parameters,
    make_slam_node,
    map_prefix,
    without_controller,
)

# Node parameters run_robot sets itself: a -p / --pf-param would contradict them.
WALL_FOLLOWER_SET = {"simulation": "(robot mode)", "dt": "from --dt",
                     "cmd_vel_stamped": "from --cmd-vel", "controller": "from --controller"}
FILTER_SET = {"world": "from --map",
              "lidar_offset_x_m": "(the Burger's LiDAR position; the robot's /tf_static gives it)"}
SLAM_SET = {"lidar_offset_x_m": FILTER_SET["lidar_offset_x_m"], "output_prefix": "from --map-out"}


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
    parser.add_argument("--map", default=None, metavar="MAP", help="the map of the room: "
                        "Nav2 map YAML (map_saver's), course map JSON, world YAML or bundled "
                        "world name; published as /map and /map_markers (amr_map_publisher), "
                        "the particle filter's and the planner's map")
    add_foxglove_options(parser)
    add_localization_options(parser)
    add_link_options(parser)
    parser.add_argument("--world", default=None, metavar="MAP", help="deprecated: the old name "
                        "of --map (there is no simulated world on the robot)")
    parser.add_argument("--goal", default=None, help="navigate to X,Y (metres, negative numbers "
                        "typed as is) or a named goal of --map: also the particle filter, the "
                        "planner and the pure pursuit")
    add_slam_options(parser, "run_robot")
    args = parser.parse_args(join_negative_values(argv, ["--goal"]))
    if args.domain_id is None:
        try:
            environment_domain_id()
        except ValueError as exc:
            parser.error(str(exc))
    check_common_options(parser, args, "run_robot", WALL_FOLLOWER_SET, FILTER_SET)
    try:
        check_slam_options(args, "run_robot", SLAM_SET)
    except ValueError as exc:
        parser.error(str(exc))
    if args.no_controller and args.goal is not None:
        parser.error("--no-controller and --goal exclude each other: the pure pursuit drives "
                     "to the goal")
    args.localize = args.localize or args.goal is not None  # navigation needs the filter
    args.deprecated_world = args.world is not None
    if args.world is not None and args.map is not None and args.world != args.map:
        parser.error("--world and --map name different maps: give --map only (the robot has "
                     "one map; --world is its old name)")
    args.map = args.map or args.world
    if args.localize and args.map is None:
        parser.error(f"{'--goal' if args.goal else '--localize'} needs --map (the map of the "
                     f"room the robot is in)")
    if args.map is not None:
        from amr_common.world.world import World
        try:
            world = World.load(args.map)
            if args.goal is not None:
                args.goal = world.resolve_goal(args.goal)
            if args.localize:  # the particle filter runs on `world`
                check_filter_map(world, args.pf_overrides, args.links.get("localizer"))
        except ValueError as exc:  # WorldError, a map too big for the filter
            parser.error(str(exc))
    return args


def main(argv=None) -> int:
    # Ctrl-C (SIGTERM, SIGHUP) only sets the flag, whenever it comes (own signal handling: the
    # final zero command must go out before the context shuts down): before any node exists the
    # script just ends; once nodes exist the manager stops starting them and every node is
    # shut down (a configured controller sends a zero command), instead of a KeyboardInterrupt
    # tearing through imports or callbacks.
    stop = _STOP if _STOP is not None else StopFlag().install()
    try:
        args = parse_args(argv)
        if args.deprecated_world:
            print("run_robot: --world is deprecated: use --map (the map of the filter, the "
                  "planner and /map; the robot has no simulated world)", file=sys.stderr)
        if args.slam and args.map_out is None:
            try:
                args.map_out = check_map_folder(default_map_folder())
            except ValueError as exc:  # the current folder is not writable
                print(f"run_robot: no --map-out, and {exc}", file=sys.stderr)
                return 2
            print(f"run_robot: no --map-out: the map will be written to "
                  f"{map_prefix(args.map_out)}.yaml when the run ends", flush=True)
        code = 0 if stop.requested else _run(args, stop)
    finally:
        stop.uninstall()
    if stop.requested:
        print("run_robot: interrupted", file=sys.stderr)
        return stop.exit_code if code == 0 else code  # 130 (Ctrl-C, SIGTERM), 129 (SIGHUP)
    return code


def _run(args: argparse.Namespace, stop: StopFlag) -> int:
    """Build the graph and run it until stopped; the exit code (0 after a stop)."""
    use_domain_id(args)
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from amr_common.ros.lifecycle_manager import LifecycleManager, run_managed

    # No arguments for rcl: it would read the script's own command line (a '__ns:=...' value
    # as a remapping of every node).
    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
    stamped = None if args.cmd_vel is None else args.cmd_vel == "stamped"
    nodes = make_robot_graph(None, params_file=args.params_file, dt=args.dt,
                             cmd_vel_stamped=stamped, controller=args.controller,
                             tuning=args.overrides,
                             localize_world=args.map if args.localize else None,
                             filter_overrides=args.pf_overrides, goal=args.goal,
                             links=args.links)
    if args.no_controller:  # the user drives (scripts/teleop.py)
        without_controller(nodes)
    slam_node = None
    if args.slam:
        overrides = lidar_parameters(args)  # the LDS-01, its calibration from --slam-param
        slam_node = make_slam_node(None, lidar_offset_x_m=overrides.pop("lidar_offset_x_m"),
                                   output_prefix=map_prefix(args.map_out), overrides=overrides)
        nodes.append(slam_node)
    if args.map:
        from launch_common import make_map_publisher
        nodes.insert(0, make_map_publisher(None, args.map))
    nodes = make_viewer_nodes(None, args) + nodes  # shut down last (reverse order)
    manager = LifecycleManager([node.get_name() for node in nodes])
    manager.get_logger().info(f"run_robot: {describe_graph_settings()}; Ctrl-C stops the robot")
    code = run_managed(manager, stop, nodes)  # the slam node saves its map on the way down
    ending = 0 if slam_node is None else map_ending(slam_node)
    return code or ending


def map_ending(slam_node) -> int:
    """Say where the map went (or why it did not); MAP_NOT_WRITTEN if it could not be written."""
    if slam_node.map_save_error is not None:
        print(f"run_robot: the map was NOT written: {slam_node.map_save_error}",
              file=sys.stderr)
        return MAP_NOT_WRITTEN
    if slam_node.saved_maps:
        print(f"run_robot: map written to {slam_node.saved_maps[-1]}")
    else:
        print("run_robot: no map written: no scan was mapped")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
