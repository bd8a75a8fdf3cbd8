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
`--slam`: the slam node maps while the wall follower explores (`--map-out DIR`: DIR/map.yaml +
DIR/map.pgm at the end, Ctrl-C included); the report gains the `slam` figures and the SLAM pose.

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
  .venv/bin/python scripts/run_sim.py --world lab02 --goal inner_far \
      --localizer examples.likelihood_mcl:LikelihoodFieldMcl \
      --planner examples.wavefront_planner:WavefrontPlanner \
      --follower examples.plain_pursuit:PlainPursuit          # bring your own algorithm
  .venv/bin/python scripts/run_sim.py --profile turtlebot3 --slam --map-out maps/lab02 \
      --duration 300 --plot out/slam.png                  # map it: maps/lab02/map.yaml + .pgm
  .venv/bin/python scripts/run_sim.py --profile turtlebot3 --realtime --slam --teleop \
      --map-out maps/mine           # drive with scripts/teleop.py (same ROS_DOMAIN_ID)
  .venv/bin/python scripts/run_sim.py --world evaluations/worlds/lab02_box.yaml --map lab02 \
      --goal inner_far --profile turtlebot3_clean --plot out/box.png   # a box the map lacks
`--map`: the particle filter, the planner and /map use this map while the simulator drives in
`--world` (default: the world): a map SLAM built, or an old map of a changed room.
Local runs are isolated: loopback discovery and a free ROS_DOMAIN_ID (printed at startup).
Ctrl-C (or SIGTERM) ends the whole run: the controller commands zero and the partial report is
written, marked "interrupted": true (exit code 130); a closed terminal (SIGHUP) likewise, exit
code 129. A closed output (`| head`, `| tee` ended first) drops the rest of the output and
loses nothing else. A link (--controller, --localizer, --planner, --follower, --mapper) that
raises or returns what its interface forbids ends the run too: the robot stops, the report says
why (`link_failure`), exit code 3, as evaluate.py's failed episode. Exit code 1: a collision or
no path to the goal; 3: the map of --slam --map-out could not be written (said, and
`map_saved: false` with the reason in the report).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shlex
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

from amr_common.plugins.link_failure import LINK_FAILED  # noqa: E402
from amr_common.ros.ros_env import describe_graph_settings, isolate_local_graph  # noqa: E402
from cli_checks import (  # noqa: E402
    OneLineArgumentParser,
    add_domain_id_option,
    check_output_file,
    join_negative_values,
    per_start_path,
    plot_file,
    recording_file,
)
from launch_common import (  # noqa: E402
    ROBOT_PARAMS,
    SIM_PARAMS,
    add_controller_options,
    add_foxglove_options,
    check_common_options,
)
from launch_slam import (  # noqa: E402
    MAP_NOT_WRITTEN,
    add_slam_options,
    check_slam_options,
    lidar_parameters,
    map_prefix,
)

# Node parameters run_sim sets from its own options: a -p / --pf-param would contradict them.
WALL_FOLLOWER_SET = {"dt": "from --dt", "simulation": "from --realtime and --profile",
                     "enable_localization": "from --enable-localization, --localize and --goal",
                     "controller": "from --controller"}
FILTER_SET = {"world": "from --map (default --world)",
              "lidar_offset_x_m": "from --profile (where the simulated LiDAR sits)"}
SLAM_SET = {"lidar_offset_x_m": FILTER_SET["lidar_offset_x_m"], "output_prefix": "from --map-out",
            "map_start_pose": "from --start (the map is built in the world's frame)"}


def _parser() -> OneLineArgumentParser:
    """run_sim's options (checked by parse_args)."""
    parser = OneLineArgumentParser(description=__doc__.split("\n\n")[0],
                                   formatter_class=argparse.RawDescriptionHelpFormatter,
                                   epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--world", default="lab02", help="bundled world name or a path to a "
                        "world YAML / course map JSON / Nav2 map YAML (default lab02)")
    parser.add_argument("--map", default=None, help="the map of the particle filter, the "
                        "planner and /map, as --world takes it (default: the world itself); "
                        "the robot drives in --world")
    parser.add_argument("--start", default=None, help="named start, X,Y,THETA (m, m, rad; e.g. "
                        "--start -1.0,-1.0,1.57), or 'all' to run every named start in turn "
                        "(default: the world's first start)")
    parser.add_argument("--profile", default="ideal", help="ideal (default), turtlebot3 or "
                        "turtlebot3_lds02 (the Burger with the reality-gap effects; options "
                        "after colons: turtlebot3:command_latency_s=0.1, see "
                        "docs/reality-gap.md) or turtlebot3_clean (the Burger without them)")
    parser.add_argument("--randomize", action="store_true", help="draw every reality-gap "
                        "effect within its documented range from --seed (the report lists the "
                        "drawn values)")
    parser.add_argument("--duration", type=float, default=600.0,
                        help="simulated seconds to run (default 600)")
    parser.add_argument("--dt", type=float, default=0.05)
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulator's noise "
                        "and of the particle filter (as the headless episodes; --pf-param "
                        "seed:=N wins)")
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
    add_link_options(parser)
    add_slam_options(parser, "run_sim")
    parser.add_argument("--kidnap", default=None, metavar="T,X,Y,THETA",
                        help="teleport the robot at simulated time T (s) to (X, Y, THETA): "
                        "the encoders see no motion; tests the filter's recovery")
    parser.add_argument("--report", default=None, help="write a JSON report here")
    parser.add_argument("--plot", default=None, help="write a picture of the trajectory here "
                        "(PNG unless the name says .svg, .pdf, ...; one per start with --start "
                        "all)")
    parser.add_argument("--record", default=None, help="record every topic to this .mcap file, "
                        "as `ros2 bag record -a` (one file per start with --start all: "
                        "NAME-START.mcap; .mcap is added to a name without a suffix)")
    parser.add_argument("--gui", action="store_true", help="live view window (pygame)")
    add_foxglove_options(parser)
    add_domain_id_option(parser, "ROS_DOMAIN_ID, 0-232 (default: $ROS_DOMAIN_ID if set and not "
                         "0, else a free one)")
    return parser


def parse_args(argv=None) -> argparse.Namespace:
    """The options, checked: one line and exit code 2 for a mistake, before anything runs."""
    parser = _parser()
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
    _check_simulator_options(parser, args)
    check_common_options(parser, args, "run_sim", WALL_FOLLOWER_SET, FILTER_SET)
    try:
        check_slam_options(args, "run_sim", SLAM_SET)
        if args.slam:  # the simulated unit calibrated now: one that cannot be is refused here
            args.slam_lidar = lidar_parameters(args, args.profile)
    except ValueError as exc:
        parser.error(str(exc))
    if args.no_controller and not args.realtime:
        parser.error("--no-controller needs --realtime: lockstep advances on the controller's "
                     "commands")
    if args.no_controller and args.goal is not None:
        parser.error("--no-controller and --goal exclude each other: the pure pursuit drives "
                     "to the goal")
    _check_start_outputs_kidnap(parser, args)
    return args


def _check_start_outputs_kidnap(parser, args) -> None:
    """--start parsed, --plot and --record file names, --kidnap within the run."""
    from amr_common.world.world import parse_start
    try:
        if args.start != "all":
            args.start = parse_start(args.start or "")
        if args.plot:
            args.plot = str(plot_file(args.plot))
        if args.record:
            args.record = str(recording_file(args.record))
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
        if args.kidnap[0] >= args.duration:
            parser.error(f"--kidnap at {args.kidnap[0]:g} s comes after the run ends "
                         f"(--duration {args.duration:g} s)")


def _check_simulator_options(parser, args) -> None:
    """--dt and --seed by the simulator's own checks (its node would refuse them later)."""
    from amr_sim.simulator_params import PARAMETERS, check_parameters
    defaults = {name: default for name, (default, _) in PARAMETERS.items()}
    for option, name, value in (("--dt", "dt", args.dt), ("--seed", "seed", args.seed)):
        try:
            check_parameters({**defaults, name: value})
        except ValueError as exc:
            parser.error(f"{option} {value:g}: {exc}" if isinstance(value, float) else
                         f"{option} {value}: {exc}")  # a seed in full


def main(argv=None) -> int:
    # Ctrl-C (SIGTERM, SIGHUP) only sets the flag, whenever it comes: the options are checked,
    # then the run ends at its next check and writes what it has (if it came before the graph
    # ran, a report of the start pose, marked interrupted), instead of a KeyboardInterrupt
    # tearing through imports or ROS callbacks.
    stop = _STOP if _STOP is not None else StopFlag().install()
    try:
        args = parse_args(argv)
        prepared = _prepare(args)
        if isinstance(prepared, int):
            return prepared
        return _simulate(args, *prepared, stop)
    finally:
        stop.uninstall()


def _prepare(args):
    """(world, map, starts, outputs) with every start and output checked, or exit code 2.

    The starts and the kidnap pose are checked against the world (where the robot is), the goal
    against the map (where the planner plans); what the world and the map disagree on is
    printed as a warning and kept in args.map_warnings for the report.
    """
    import sim_session  # noqa: F401  (the slow imports, while Ctrl-C can still simply abort)

    from amr_common.world.map_vs_world import load_map, resolve_goal_on_map, start_warning
    from amr_common.world.world import World, WorldError, start_label
    try:
        isolate_local_graph(args.domain_id, program="run_sim")  # teleop.py --local finds it
        world = World.load(args.world)
        try:
            map_world = load_map(args.map, world)
        except WorldError as exc:
            raise WorldError(f"--map {exc}") from None
        if args.start in ("all", None) and not world.starts:
            raise WorldError(f"{world.source} names no start poses"
                             + (", so '--start all' runs nothing" if args.start else "")
                             + ": give one with --start X,Y,THETA")
        starts = list(world.starts) if args.start == "all" else [args.start]
        warnings = [start_warning(world.resolve_start(start), map_world, world)
                    for start in starts]  # fail early with the world's own message
        if args.kidnap is not None:
            world.resolve_start(args.kidnap[1:], what="kidnap pose")
        if args.goal is not None:  # a name or X,Y, checked against the map's walls
            args.goal, goal_warning = resolve_goal_on_map(args.goal, map_world, world)
            warnings.append(goal_warning)
        if args.localize or args.goal is not None:  # the particle filter runs on the map
            check_filter_map(map_world, args.pf_overrides, args.links.get("localizer"))
        starts = [next(iter(world.starts)) if s is None else s for s in starts]
        outputs = _check_outputs(args, [start_label(s) for s in starts])
    except ValueError as exc:  # WorldError, a bad domain id or output path, a map too big
        print(f"run_sim: {exc}", file=sys.stderr)
        return 2
    args.map_warnings = [w for w in warnings if w is not None]
    for warning in args.map_warnings:
        print(f"run_sim: warning: {warning}", file=sys.stderr)
    return world, map_world, starts, outputs


def _simulate(args, world, map_world, starts, outputs, stop) -> int:
    """Run each start in turn until done or stopped; write the outputs; the exit code."""
    from sim_report import map_lost, report_before_start
    from sim_session import SimSession

    from amr_common.ros.lifecycle_manager import StartupInterrupted
    from amr_common.world.world import start_label
    print(f"run_sim: {describe_graph_settings()}", flush=True)  # the graph starts now
    if args.no_controller:
        print(f"run_sim: no controller runs: drive from another terminal with "
              f"{teleop_command()}", flush=True)
    reports, rasters = [], {}  # rasters: the SLAM map of each start (for the plot)
    for start in starts:
        if stop.requested:
            if not reports:  # stopped before any node existed: nothing moved, nothing to stop
                reports.append(report_before_start(args, world, start, map_world))
            break
        label = start_label(start) if len(starts) > 1 else None
        session = SimSession(args, world, start, stop=stop,
                             record_path=outputs["record"].get(start_label(start)),
                             map_world=map_world,
                             map_prefix=map_prefix(args.map_out, label) if args.slam else "")
        try:
            report = session.run()
        except StartupInterrupted:  # before the graph ran (or while a node configured)
            report = report_before_start(args, world, start, map_world)
        finally:
            session.close()
        reports.append(report)
        rasters[report["start"]] = getattr(session, "slam_raster", None)
        print(session.summary_line(report))
        if session.recording_line() is not None:
            print(f"run_sim: {session.recording_line()}")
    _write_outputs(world, map_world, reports, outputs, several_starts=len(starts) > 1,
                   rasters=rasters)
    if stop.requested:
        print("run_sim: interrupted", file=sys.stderr)
    lost = [report["slam"]["map_error"] for report in reports if map_lost(report)]
    for reason in lost:
        print(f"run_sim: the map was not written: {reason}", file=sys.stderr)
    if lost:  # a mapping session lost: above everything else
        return MAP_NOT_WRITTEN
    if stop.requested:
        return stop.exit_code  # 130 after Ctrl-C or SIGTERM, 129 after SIGHUP
    if any(report["link_failure"] for report in reports):
        return LINK_FAILED  # the run ended then, said why
    # 1: a run collided, or its goal had no path (the planner said why; the run ended then).
    return 1 if any(report["collisions"] > 0 or report.get("planning_error")
                    for report in reports) else 0


def teleop_command() -> str:
    """The command line of scripts/teleop.py that drives this run (paths as typed from here)."""
    def typed(path: str) -> str:
        relative = os.path.relpath(path)
        return shlex.quote(path if relative.startswith("..") else relative)

    return (f"{typed(sys.executable)} {typed(str(Path(__file__).with_name('teleop.py')))} "
            f"--local --domain-id {os.environ['ROS_DOMAIN_ID']}")


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


def _write_outputs(world, map_world, reports, outputs, several_starts: bool,
                   rasters=None) -> None:
    """The report (a list for several starts, even if stopped after one) and the plots.

    A map that is not the world is drawn as its cells (or walls) under the world's true walls;
    a map SLAM built (`rasters`, one per start) over them.
    """
    if outputs["report"] is not None:
        path = outputs["report"]
        path.write_text(json.dumps(reports if several_starts else reports[0], indent=1))
        print(f"run_sim: report written to {path}")
    if outputs["plot"]:
        from sim_report import world_label

        from amr_evaluation.plot import plot_episode
        for report in reports:
            title = f"{world_label(report)} / {report['start']} / {report['profile']}" + \
                (" (interrupted)" if report["interrupted"] else "")
            if report.get("goal") is not None:
                reached = report["goal_reached_time_s"]
                title += (f" -> goal ({report['goal'][0]:g}, {report['goal'][1]:g}): "
                          + ("not reached" if reached is None else
                             f"reached {reached:.1f} s, final error "
                             f"{report['final_position_error_m'] * 100:.1f} cm"))
            if "slam" in report:
                from amr_evaluation.mapping_plot import plot_mapping
                written = plot_mapping(world, report, (rasters or {}).get(report["start"]),
                                       path=str(outputs["plot"][report["start"]]), title=title)
            elif "estimate" in report:
                from amr_evaluation.localization_plot import plot_localization
                written = plot_localization(world, report,
                                            path=str(outputs["plot"][report["start"]]),
                                            title=title, map_world=map_world)
            else:
                written = plot_episode(world, report["trajectory"], report["collision_points"],
                                       path=str(outputs["plot"][report["start"]]), title=title,
                                       map_world=map_world,
                                       mover_waits=report.get("mover_waits"))
            print(f"run_sim: plot written to {written}")


if __name__ == "__main__":
    sys.exit(run_script(main))
