#!/usr/bin/env python3
"""Run the simulator and the wall follower on a maze (stands in for the course's launch file).

With `--goal`, also the particle filter, the planner and the pure pursuit: explore until
localized, plan, follow the path and stop at the goal.

Lockstep (default): the simulator advances one dt per /cmd_vel, as fast as the loop turns.
`--realtime`: the simulator runs on a wall-clock timer; with `--profile turtlebot3` this is the
rehearsal of the real robot: /odom (pose only) + 5 Hz /scan, the amr_odometry node and the wall
follower in robot (timer) mode with params/turtlebot3.yaml - the graph run_robot.py starts.
`--localize`: the particle filter joins the graph (/pose with `localized`); the simulator
synchronizes /cmd_vel with /pose and the report gains the localization figures and the
estimate at every /pose.

Examples:
  .venv/bin/python scripts/run_sim.py                                  # lab02, outer, ideal
  .venv/bin/python scripts/run_sim.py --world maze_deadends --start all --duration 120
  .venv/bin/python scripts/run_sim.py --profile turtlebot3 --realtime --duration 60
  .venv/bin/python scripts/run_sim.py --controller my_pkg.my_ctrl:MyController -p kp:=5.0
  .venv/bin/python scripts/run_sim.py --report out/run.json --plot out/run.png
  .venv/bin/python scripts/run_sim.py --record out/run.mcap --duration 60
  .venv/bin/python scripts/run_sim.py --profile turtlebot3 --realtime --foxglove   # live
  .venv/bin/python scripts/run_sim.py --world course_map.json --start -1.0,-1.0,1.57
  .venv/bin/python scripts/run_sim.py --world twin_maze --localize --plot out/loc.png
  .venv/bin/python scripts/run_sim.py --world maze_deadends --localize --kidnap 25,1.4,1,0
  .venv/bin/python scripts/run_sim.py --world lab02 --goal inner_far --plot out/nav.png
  .venv/bin/python scripts/run_sim.py --world lab02 --goal -1.0,0.6 --kidnap 40,0.2,1,3.14
Local runs are isolated: loopback discovery and a free ROS_DOMAIN_ID (printed at startup).
Ctrl-C ends the whole run: the controller commands zero and the partial report is written,
marked "interrupted": true (exit code 130).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from amr_common.ros_env import describe_graph_settings, isolate_local_graph  # noqa: E402
from cli_checks import (  # noqa: E402
    add_domain_id_option,
    check_output_file,
    join_negative_values,
    per_start_path,
    plot_file,
)
from launch_common import (  # noqa: E402
    ROBOT_PARAMS,
    SIM_PARAMS,
    add_controller_options,
    add_foxglove_options,
    add_localization_options,
    check_common_options,
)

INTERRUPTED = 130  # exit code after Ctrl-C / SIGTERM, as a shell reports it


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--world", default="lab02", help="bundled world name or a path to a "
                        "world YAML / course map JSON (default lab02)")
    parser.add_argument("--start", default=None, help="named start, X,Y,THETA (m, m, rad; e.g. "
                        "--start -1.0,-1.0,1.57), or 'all' to run every named start in turn "
                        "(default: the world's first start)")
    parser.add_argument("--profile", default="ideal", help="ideal (default), turtlebot3, "
                        "turtlebot3_real or turtlebot3_lds02 (the Burger with the reality-gap "
                        "effects; options after colons: turtlebot3_real:command_latency_s=0.1, "
                        "see docs/reality-gap.md)")
    parser.add_argument("--randomize", action="store_true", help="draw every reality-gap "
                        "effect within its documented range from --seed (the report lists the "
                        "drawn values)")
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
                        "filter, the planner and the pure pursuit; the run ends when the robot "
                        "rests at the goal")
    parser.add_argument("--enable-localization", action="store_true",
                        help="the simulator synchronizes /cmd_vel with /pose from a "
                        "localization node of yours (--localize starts the project's)")
    add_localization_options(parser)
    parser.add_argument("--kidnap", default=None, metavar="T,X,Y,THETA",
                        help="teleport the robot at simulated time T (s) to (X, Y, THETA): "
                        "the encoders see no motion; tests the filter's recovery")
    parser.add_argument("--report", default=None, help="write a JSON report here")
    parser.add_argument("--plot", default=None, help="write a picture of the trajectory here "
                        "(PNG unless the name says .svg, .pdf, ...; one per start with --start "
                        "all)")
    parser.add_argument("--record", default=None, help="record topics to this .mcap file (one "
                        "file per start with --start all: NAME-START.mcap)")
    parser.add_argument("--gui", action="store_true", help="live view window (pygame)")
    add_foxglove_options(parser)
    add_domain_id_option(parser, "ROS_DOMAIN_ID, 0-232 (default: $ROS_DOMAIN_ID if set and not "
                         "0, else a free one)")
    args = parser.parse_args(join_negative_values(argv, ["--start", "--goal", "--kidnap"]))
    if not (math.isfinite(args.duration) and args.duration > 0):
        parser.error("--duration must be > 0")
    from amr_sim.profiles import get_profile, randomized_profile_name
    try:
        if args.randomize:
            args.profile = randomized_profile_name(args.profile)
        args.profile = get_profile(args.profile).name
    except ValueError as exc:
        parser.error(str(exc))
    if args.params_file is None:
        rehearsal = args.realtime and get_profile(args.profile).odom_topic == "/odom"
        args.params_file = str(ROBOT_PARAMS if rehearsal else SIM_PARAMS)
    check_common_options(parser, args)
    from amr_common.world import parse_start
    try:
        if args.start != "all":
            args.start = parse_start(args.start or "")
        if args.plot:
            args.plot = str(plot_file(args.plot))
    except ValueError as exc:
        parser.error(str(exc))
    if args.kidnap is not None:
        try:
            args.kidnap = [float(v) for v in args.kidnap.split(",")]
        except ValueError:
            args.kidnap = []
        if len(args.kidnap) != 4 or not all(math.isfinite(v) for v in args.kidnap) or \
                args.kidnap[0] < 0:
            parser.error("--kidnap must be T,X,Y,THETA (s, m, m, rad) with T >= 0")
    return args


def main(argv=None) -> int:
    try:
        args = parse_args(argv)
        prepared = _prepare(args)
        if isinstance(prepared, int):
            return prepared
        from amr_common.node_runner import StopFlag
        # From here on Ctrl-C (or SIGTERM) only sets the flag: the run ends at the next check
        # and writes what it has, instead of a KeyboardInterrupt tearing through ROS callbacks.
        stop = StopFlag().install()
    except KeyboardInterrupt:  # still checking options and loading: no node exists yet
        print("run_sim: interrupted before the simulation started (no report)", file=sys.stderr)
        return INTERRUPTED
    try:
        return _simulate(args, *prepared, stop)
    finally:
        stop.uninstall()


def _prepare(args):
    """(world, starts, outputs) with every start and output path checked, or exit code 2."""
    import sim_session  # noqa: F401  (the slow imports, while Ctrl-C can still simply abort)

    from amr_common.world import World, WorldError, start_label
    try:
        isolate_local_graph(args.domain_id)
        world = World.load(args.world)
        if args.start in ("all", None) and not world.starts:
            raise WorldError(f"{world.source} names no start poses"
                             + (", so '--start all' runs nothing" if args.start else "")
                             + ": give one with --start X,Y,THETA")
        starts = list(world.starts) if args.start == "all" else [args.start]
        for start in starts:
            world.resolve_start(start)  # fail early with the world's own message
        if args.kidnap is not None:
            world.resolve_start(args.kidnap[1:])
        if args.goal is not None:  # a name or X,Y, checked against the walls
            args.goal = world.resolve_goal(args.goal)
        starts = [next(iter(world.starts)) if s is None else s for s in starts]
        outputs = _check_outputs(args, [start_label(s) for s in starts])
    except ValueError as exc:  # WorldError, a bad domain id or output path
        print(f"run_sim: {exc}", file=sys.stderr)
        return 2
    return world, starts, outputs


def _simulate(args, world, starts, outputs, stop) -> int:
    """Run each start in turn until done or stopped; write the outputs; the exit code."""
    from sim_session import SimSession, report_before_start

    from amr_common.world import start_label
    print(f"run_sim: {describe_graph_settings()}")
    reports = []
    for start in starts:
        if stop.requested:
            if not reports:  # stopped before any node existed: nothing moved, nothing to stop
                reports.append(report_before_start(args, world, start))
            break
        session = SimSession(args, world, start, stop=stop,
                             record_path=outputs["record"].get(start_label(start)))
        try:
            report = session.run()
        finally:
            session.close()
        reports.append(report)
        print(session.summary_line(report))
    _write_outputs(world, reports, outputs, several_starts=len(starts) > 1)
    if stop.requested:
        print("run_sim: interrupted", file=sys.stderr)
        return INTERRUPTED
    return 1 if any(report["collisions"] > 0 for report in reports) else 0


def _check_outputs(args, labels: list[str]) -> dict:
    """Every output file of the run, checked writable now (ValueError) instead of after it.

    Plots and recordings are per start ({label: path}); the report holds every start.
    """
    def per_start(path, what: str) -> dict:
        if len(labels) == 1:
            return {labels[0]: check_output_file(path, what)}
        return {label: check_output_file(per_start_path(path, label), what) for label in labels}

    return {"report": check_output_file(args.report, "--report") if args.report else None,
            "plot": per_start(args.plot, "--plot") if args.plot else {},
            "record": per_start(args.record, "--record") if args.record else {}}


def _write_outputs(world, reports, outputs, several_starts: bool) -> None:
    """The report (a list for several starts, even if stopped after one) and the plots."""
    if outputs["report"] is not None:
        path = outputs["report"]
        path.write_text(json.dumps(reports if several_starts else reports[0], indent=1))
        print(f"run_sim: report written to {path}")
    if outputs["plot"]:
        from amr_evaluation.plot import plot_episode
        for report in reports:
            title = f"{report['world']} / {report['start']} / {report['profile']}" + \
                (" (interrupted)" if report["interrupted"] else "")
            if report.get("goal") is not None:
                reached = report["goal_reached_time_s"]
                title += (f" -> goal ({report['goal'][0]:g}, {report['goal'][1]:g}): "
                          + ("not reached" if reached is None else
                             f"reached {reached:.1f} s, final error "
                             f"{report['final_position_error_m'] * 100:.1f} cm"))
            if "estimate" in report:
                from amr_evaluation.localization_plot import plot_localization
                written = plot_localization(world, report,
                                            path=str(outputs["plot"][report["start"]]),
                                            title=title)
            else:
                written = plot_episode(world, report["trajectory"], report["collision_points"],
                                       path=str(outputs["plot"][report["start"]]), title=title)
            print(f"run_sim: plot written to {written}")


if __name__ == "__main__":
    sys.exit(main())
