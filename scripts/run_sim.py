#!/usr/bin/env python3
"""Run the simulator and the wall follower on a maze (stands in for the course's launch file).

With `--goal`, also the particle filter, the planner and the pure pursuit: explore until
localized, plan, follow the path and stop at the goal.

Lockstep (default): the simulator advances one dt per /cmd_vel, as fast as the loop turns.
`--realtime`: the simulator runs on a wall-clock timer; with `--profile turtlebot3` this is the
rehearsal of the real robot: /odom (pose only) + 5 Hz /scan, the amr_odometry node and the wall
follower in robot (timer) mode with params/turtlebot3.yaml - the graph run_robot.py starts.

Examples:
  .venv/bin/python scripts/run_sim.py                                  # lab02, outer, ideal
  .venv/bin/python scripts/run_sim.py --world maze_deadends --start all --duration 120
  .venv/bin/python scripts/run_sim.py --profile turtlebot3 --realtime --duration 60
  .venv/bin/python scripts/run_sim.py --controller my_pkg.my_ctrl:MyController -p kp:=5.0
  .venv/bin/python scripts/run_sim.py --report out/run.json --plot out/run.png
  .venv/bin/python scripts/run_sim.py --record out/run.mcap --duration 60
  .venv/bin/python scripts/run_sim.py --profile turtlebot3 --realtime --foxglove   # live
  .venv/bin/python scripts/run_sim.py --world lab02 --goal inner_far --plot out/nav.png
  .venv/bin/python scripts/run_sim.py --world lab02 --goal -1.0,0.6   # walls + filter + planner
Local runs are isolated: loopback discovery and a free ROS_DOMAIN_ID (printed at startup).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from amr_common.ros_env import describe_graph_settings, isolate_local_graph  # noqa: E402
from launch_common import (  # noqa: E402
    add_controller_options,
    add_foxglove_options,
    check_common_options,
    goal_value_joined,
)


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--world", default="lab02", help="bundled world name or a path to a "
                        "world YAML / course map JSON (default lab02)")
    parser.add_argument("--start", default=None, help="named start, X,Y,THETA, or 'all' to run "
                        "every named start in turn (default: the world's first start)")
    parser.add_argument("--profile", default="ideal", choices=["ideal", "turtlebot3"])
    parser.add_argument("--duration", type=float, default=600.0,
                        help="simulated seconds to run (default 600)")
    parser.add_argument("--dt", type=float, default=0.05)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--realtime", action="store_true",
                        help="advance on a wall-clock timer instead of lockstep")
    add_controller_options(parser, None, "wall follower ROS params YAML (default "
                           "params/sim.yaml, or params/turtlebot3.yaml for the realtime "
                           "turtlebot3 rehearsal)")
    parser.add_argument("--goal", default=None, help="navigate to X,Y (metres, negative "
                        "numbers typed as is) or a named goal of the world: adds the particle "
                        "filter, planner and pure pursuit; the run ends when the robot rests "
                        "at the goal")
    parser.add_argument("--enable-localization", action="store_true")
    parser.add_argument("--report", default=None, help="write a JSON report here")
    parser.add_argument("--plot", default=None, help="write a PNG of the trajectory here")
    parser.add_argument("--record", default=None, help="record topics to this .mcap file")
    parser.add_argument("--gui", action="store_true", help="live view window (pygame)")
    add_foxglove_options(parser)
    parser.add_argument("--domain-id", type=int, default=None,
                        help="ROS_DOMAIN_ID (default: $ROS_DOMAIN_ID if set, else a free one)")
    args = parser.parse_args(goal_value_joined(sys.argv[1:] if argv is None else argv))
    if not (math.isfinite(args.duration) and args.duration > 0):
        parser.error("--duration must be > 0")
    check_common_options(parser, args)
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    isolate_local_graph(args.domain_id)
    from amr_common.world import World, WorldError
    try:
        world = World.load(args.world)
        starts = list(world.starts) if args.start == "all" else [args.start]
        for start in starts:
            world.resolve_start(start)  # fail early with the world's own message
        if args.goal is not None:  # a name or X,Y, checked against the walls
            args.goal = world.resolve_goal(args.goal)
    except WorldError as exc:
        print(f"run_sim: {exc}", file=sys.stderr)
        return 2
    print(f"run_sim: {describe_graph_settings()}")
    from sim_session import SimSession
    exit_code = 0
    reports = []
    for start in starts:
        session = SimSession(args, world, start)
        try:
            report = session.run()
        finally:
            session.close()
        reports.append(report)
        print(session.summary_line(report))
        if report["collisions"] > 0:
            exit_code = 1
    _write_outputs(args, world, reports)
    return exit_code


def _write_outputs(args, world, reports) -> None:
    if args.report:
        path = Path(args.report)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(reports[0] if len(reports) == 1 else reports, indent=1))
        print(f"run_sim: report written to {path}")
    if args.plot:
        from amr_evaluation.plot import plot_episode
        path = Path(args.plot)
        path.parent.mkdir(parents=True, exist_ok=True)
        for index, report in enumerate(reports):
            target = path if len(reports) == 1 else path.with_name(
                f"{path.stem}-{report['start']}{path.suffix}")
            title = f"{report['world']} / {report['start']} / {report['profile']}"
            if report.get("goal") is not None:
                reached = report["goal_reached_time_s"]
                title += (f" -> goal ({report['goal'][0]:g}, {report['goal'][1]:g}): "
                          + ("not reached" if reached is None else
                             f"reached {reached:.1f} s, final error "
                             f"{report['final_position_error_m'] * 100:.1f} cm"))
            plot_episode(world, report["trajectory"], report["collision_points"], path=str(target),
                         title=title, planned_path=report.get("path"), goal=report.get("goal"))
            print(f"run_sim: plot written to {target}")


if __name__ == "__main__":
    sys.exit(main())
