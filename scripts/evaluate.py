#!/usr/bin/env python3
"""Score a controller on many episodes at once: worlds x starts x profiles x seeds, in parallel.

Each episode runs headless with the same Simulator and controller class as the ROS path
(amr_evaluation.episode.run_episode). With --goals, navigation episodes (worlds x starts x goals
x profiles x seeds): the controller explores until the particle filter is localized, then the
planner and the pure pursuit drive to the goal (amr_evaluation.navigation_episode). Writes
results.json (with the set's kind and links, for compare.py), results.csv and sheet.png (every
episode's trajectory; --slam: every map, each also saved in maps/) to --out, prints a table and
a one-line verdict.
Exit code: 0 no collision (and every goal reached), 1 some episode collided or missed its goal,
2 bad options, 3 some episode failed: a link failed (raised, or commanded NaN/inf/non-numbers:
amr_common.plugins.link_failure, as in run_sim.py), an exception, sys.exit, its worker process
died, or it ran past --episode-timeout; or a map could not be saved; 130 / 129 stopped by Ctrl-C or
SIGTERM / SIGHUP (the terminal closed).

Examples:
  .venv/bin/python scripts/evaluate.py --worlds lab02 --seeds 0,1,2 --duration 120
  .venv/bin/python scripts/evaluate.py --worlds all --starts all --profiles ideal,turtlebot3
  .venv/bin/python scripts/evaluate.py --config evaluations/example.yaml -p kp:=4.0
  .venv/bin/python scripts/evaluate.py --worlds lab02 --controller my_pkg.ctrl:MyController
  .venv/bin/python scripts/evaluate.py --localize --worlds all --profiles ideal,turtlebot3 \
      --seeds 0-4 --duration 60                      # the particle filter's figures
  .venv/bin/python scripts/evaluate.py --localize --worlds twin_maze --seeds 0-9 --kidnap-at 25
  .venv/bin/python scripts/evaluate.py --worlds lab02,maze_deadends --goals all \
      --profiles ideal,turtlebot3 --seeds 0-2 --duration 300   # navigation to named goals
  .venv/bin/python scripts/evaluate.py --worlds evaluations/worlds/lab02_box.yaml --map lab02 \
      --goals inner_far --profiles turtlebot3_clean --seeds 0-4 --duration 200  # box not on map
  .venv/bin/python scripts/evaluate.py --worlds lab02 --goals all --seeds 0-2 --duration 200 \
      --localizer examples.likelihood_mcl:LikelihoodFieldMcl --out out/mine   # your own link
  .venv/bin/python scripts/evaluate.py --slam --worlds all --profiles turtlebot3_clean \
      --seeds 0-4 --starts south_west,outer,south,south_east --duration 300   # SLAM figures
  .venv/bin/python scripts/evaluate.py --slam --worlds lab02 --profiles turtlebot3 \
      --duration 120 --mapper examples.odometry_mapper:OdometryMapper   # your own mapper
Options given on the command line override the same keys of --config.
"""
from __future__ import annotations

import argparse
import datetime as dt_module
import math
import platform
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(REPO))

from evaluate_executors import (  # noqa: E402
    add_executor_options,
    check_ray_options,
    make_executor,
)
from link_options import add_link_options, check_filter_map, links_ran  # noqa: E402
from script_endings import interruptible, run_script  # noqa: E402

from amr_common.plugins.loader import DEFAULT_LOCALIZER, PluginSpecError, load_controller_class
from amr_evaluation.evaluation import (  # noqa: E402
    DEFAULT_CONTROLLER,
    EvaluationError,
    check_controller,
    expand_grid,
    load_config,
    load_ros_params_file,
    parse_overrides,
    run_episodes,
)
from amr_evaluation.evaluation_report import (  # noqa: E402
    ProgressBar,
    format_table,
    outcome_row,
    verdict,
    write_csv,
    write_json,
)
from amr_evaluation.executors import episode_time_limit  # noqa: E402
from cli_checks import check_output_folder, join_negative_values  # noqa: E402

# run_sim.py gives the wall follower node this file: the same gains here keep both paths equal.
SIM_PARAMS = REPO / "amr_control" / "params" / "sim.yaml"


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n", 1)[1])
    parser.add_argument("--config", default=None, help="episode-set YAML (keys: worlds, map, "
                        "starts, profiles, seeds, duration, dt, controller, params_file, params, "
                        "jobs, localizer, planner, follower, mapper)")
    parser.add_argument("--worlds", default=None, help="comma-separated world names or paths, "
                        "or 'all' (default lab02)")
    parser.add_argument("--map", default=None, help="with --goals or --localize: the map of "
                        "the particle filter and the planner (a Nav2 map YAML or any world "
                        "source) while the episodes drive in the one world of --worlds "
                        "(default: the world)")
    parser.add_argument("--starts", default=None, help="'all', or comma-separated start names "
                        "and X,Y,THETA poses (m, m, rad; a pose applies to every world; default "
                        "all)")
    parser.add_argument("--goals", default=None, help="navigation episodes: 'all' or "
                        "comma-separated named goals of the worlds (default: none, wall "
                        "following)")
    parser.add_argument("--pose-source", default=None, choices=["filter", "truth"],
                        help="navigation: the particle filter (default) or the true pose")
    parser.add_argument("--profiles", default=None, help="comma-separated sensor profiles: ideal, "
                        "turtlebot3, turtlebot3_clean, turtlebot3_lds02 (default ideal)")
    parser.add_argument("--randomize", action="store_true", help="draw every reality-gap "
                        "effect within its documented range from each episode's seed "
                        "(profiles turtlebot3, turtlebot3_lds02; listed under the table)")
    parser.add_argument("--seeds", default=None, help="comma-separated seeds or ranges, e.g. "
                        "0,1,2 or 0-9 (default 0)")
    parser.add_argument("--duration", type=float, default=None,
                        help="simulated seconds per episode (default 600)")
    parser.add_argument("--dt", type=float, default=None,
                        help="control period in s (default 0.05)")
    parser.add_argument("--controller", default=None, metavar="MODULE:CLASS",
                        help=f"controller class (default {DEFAULT_CONTROLLER})")
    add_link_options(parser, EVALUATE_NEEDS)
    parser.add_argument("--params-file", default=None,
                        help="ROS 2 params YAML for the controller (default, like run_sim.py: "
                        "amr_control/params/sim.yaml when it exists; 'none' for class defaults)")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="controller constructor parameter override (repeatable; typed "
                        "bool/int/float/str like ROS)")
    add_executor_options(parser)
    parser.add_argument("--out", default=None,
                        help="output folder (default out/evaluate-<UTC time>)")
    parser.add_argument("--no-sheet", action="store_true", help="skip sheet.png")
    parser.add_argument("--localize", action="store_true", help="localization episodes: the "
                        "particle filter rides along; columns: time to localized, false "
                        "localizations, tracking errors, relocalizations")
    parser.add_argument("--kidnap-at", type=float, default=None, metavar="T",
                        help="with --localize: teleport the robot at T s to the world's next "
                        "named start, turned by 90 deg")
    parser.add_argument("--pf-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="with --localize: particle filter parameter override")
    parser.add_argument("--slam", action="store_true", help="mapping episodes: the controller "
                        "explores while SLAM maps; columns: trajectory RMSE / max, map "
                        "precision and recall, loop closures, timings (the odometry drifts "
                        "like a real Burger's: amr_evaluation.mapping_episode)")
    parser.add_argument("--slam-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="with --slam: Mapper parameter override, e.g. loop_closure:=false")
    return parser.parse_args(join_negative_values(argv, ["--starts"]))


def resolve_settings(args: argparse.Namespace) -> dict:
    """Config-file values, overridden by the command-line options that were given."""
    settings: dict = {"worlds": "lab02", "map": None, "starts": "all", "goals": None,
                      "pose_source": "filter", "profiles": "ideal", "seeds": "0",
                      "duration": 600.0, "dt": 0.05, "controller": DEFAULT_CONTROLLER,
                      "params": {}, "jobs": None}
    if args.config:
        settings.update(load_config(args.config))
    for key in ("worlds", "map", "starts", "goals", "pose_source", "profiles", "seeds",
                "duration", "dt", "controller", "params_file", "jobs", *EVALUATE_NEEDS):
        value = getattr(args, key)
        if value is not None:
            settings[key] = value
    params_file = settings.get("params_file")
    if (params_file is None and SIM_PARAMS.is_file()
            and settings["controller"] == DEFAULT_CONTROLLER):
        params_file = SIM_PARAMS
    from_file = {}
    if params_file and str(params_file).lower() != "none":
        from_file = load_ros_params_file(params_file,
                                         load_controller_class(settings["controller"]))
        settings["params_file"] = str(params_file)
    else:
        settings["params_file"] = None
    # Lowest to highest priority: params file, config `params`, -p overrides.
    settings["params"] = {**from_file, **(settings.get("params") or {}),
                          **parse_overrides(args.param)}
    if settings["jobs"] is not None and settings["jobs"] < 1:
        raise EvaluationError(f"--jobs must be >= 1, got {settings['jobs']}")
    if args.randomize:
        from amr_evaluation.evaluation_config import parse_name_list
        from amr_sim.profiles import randomized_profile_name
        settings["profiles"] = [randomized_profile_name(name)
                                for name in parse_name_list(settings["profiles"])]
    timeout = args.episode_timeout
    if timeout is not None and not 0 <= timeout < math.inf:  # also NaN
        raise EvaluationError(f"--episode-timeout must be a number of seconds > 0 (0: no "
                              f"limit), got {timeout:g}")
    if timeout is None:  # a bad duration is refused with the episodes
        duration = settings["duration"]
        timeout = episode_time_limit(duration) if math.isfinite(duration) else 0.0
    settings["episode_timeout"] = timeout
    check_option_pairs(args, settings)
    settings["links"] = check_links(args, settings)
    kind = settings["kind"] = ("localization" if args.localize else "mapping" if args.slam
                               else "navigation" if settings["goals"] else "wall_following")
    settings["links_ran"] = links_ran(kind, {"controller": settings["controller"],  # compare.py
                                             **settings["links"]}, settings["pose_source"])
    if args.slam:
        args.mapper_params = check_slam_params(args.slam_param, settings["links"].get("mapper"))
    return settings


# --localizer, --planner, --follower, --mapper (and the config keys): what each goes with.
EVALUATE_NEEDS = {"localizer": "--localize or --goals with the filter's pose",
                  "planner": "--goals", "follower": "--goals", "mapper": "--slam"}


def check_links(args: argparse.Namespace, settings: dict) -> dict[str, str]:
    """The --localizer / --planner / --follower / --mapper classes, loaded now: {link: spec}.

    PluginSpecError (one line) naming what a class lacks; EvaluationError for a link the
    episodes do not run (a planner without --goals).
    """
    from link_options import check_links as load_links
    runs = {"localizer": bool(args.localize or (settings["goals"]
                                                 and settings["pose_source"] == "filter")),
            "planner": bool(settings["goals"]), "follower": bool(settings["goals"]),
            "mapper": bool(args.slam)}
    try:
        return load_links({link: settings.get(link) for link in EVALUATE_NEEDS}, runs,
                          EVALUATE_NEEDS)
    except PluginSpecError:
        raise
    except ValueError as exc:
        raise EvaluationError(str(exc)) from None


def check_option_pairs(args: argparse.Namespace, settings: dict) -> None:
    """Options that mean something only with another one: an error rather than ignored."""
    if not args.localize:
        for option, given in (("--kidnap-at", args.kidnap_at is not None),
                              ("--pf-param", bool(args.pf_param))):
            if given:
                raise EvaluationError(f"{option} needs --localize")
    if args.pose_source is not None and settings["goals"] is None:
        raise EvaluationError("--pose-source needs --goals (navigation episodes)")
    if args.slam_param and not args.slam:
        raise EvaluationError("--slam-param needs --slam")
    if args.slam and (args.localize or settings["goals"]):
        raise EvaluationError("--slam (mapping) excludes --localize and --goals")
    if args.ray is not None:
        check_ray_options(args.ray, settings["jobs"],
                          60.0 if args.ray_keep_workers is None else args.ray_keep_workers)


def check_slam_params(items: list[str], mapper: str | None) -> dict:
    """--slam-param for the mapper's class (link_options.check_mapper_params); EvaluationError."""
    from link_options import check_mapper_params
    try:
        return check_mapper_params(items, mapper)
    except ValueError as exc:
        raise EvaluationError(f"--slam-param: {exc}") from None


def check_localization_options(args: argparse.Namespace, settings: dict, specs) -> None:
    """--localize: --kidnap-at within the episodes, in worlds with a start to carry it to.

    And --pf-param: names and values the particle filter takes.
    """
    if args.kidnap_at is not None:
        duration = settings["duration"]
        if not 0.0 < args.kidnap_at < duration:  # also NaN
            raise EvaluationError(f"--kidnap-at must be a time within the episode (0 < T < "
                                  f"{duration:g} s), got {args.kidnap_at:g}")
        from amr_evaluation.localization_evaluation import kidnap_pose
        for world in dict.fromkeys(spec.world for spec in specs):
            if kidnap_pose(world, None, args.kidnap_at) is None:
                raise EvaluationError(f"--kidnap-at: world '{Path(world).stem}' has fewer "
                                      "than two named starts (the robot is carried to the "
                                      "next one)")
    from amr_localization.particle_filter_params import check_parameters
    try:
        overrides = parse_overrides(args.pf_param)
        if settings.get("links", {}).get("localizer", DEFAULT_LOCALIZER) == DEFAULT_LOCALIZER:
            check_parameters(overrides)  # another class checks them when an episode builds it
    except ValueError as exc:
        raise EvaluationError(f"--pf-param: {exc}") from None


def check_filter_maps(specs, overrides: dict, localize: bool = False) -> None:
    """The particle filter's checks against every map it will run on, before anything runs.

    Its episodes: all with `localize`, else the navigation ones on the filter's pose. A map too
    big for its memory budget (saying what it would need) or whose table would take too long to
    build (saying how long), an initial pose where the robot cannot be: EvaluationError (one
    line). Up to ~0.5 s per map: only a sample of its table is built.
    """
    from amr_common.world.map_vs_world import load_map
    from amr_common.world.world import World
    maps = [(spec.map, spec.world, spec.localizer) for spec in specs  # on the map, if one
            if localize or (spec.goal is not None and spec.pose_source == "filter")]
    for map_source, world, localizer in dict.fromkeys(maps):
        try:  # (another localizer class checks its map itself)
            check_filter_map(load_map(map_source, World.load(world)), overrides, localizer)
        except ValueError as exc:
            raise EvaluationError(str(exc)) from None


def episode_specs(settings: dict) -> list:
    """The episodes of resolved settings; the controller built once with its parameters."""
    warnings: list[str] = []
    specs = expand_grid(settings["worlds"], settings["starts"], settings["profiles"],
                        settings["seeds"], duration=settings["duration"], dt=settings["dt"],
                        controller=settings["controller"], params=settings["params"],
                        goals=settings["goals"], pose_source=settings["pose_source"],
                        map=settings["map"], warnings=warnings,
                        links={link: spec for link, spec in settings.get("links", {}).items()
                               if link != "mapper"})
    check_controller(settings["controller"], settings["params"], settings["dt"])
    for warning in warnings:  # the map and the world disagree: allowed, said
        print(f"evaluate: warning: {warning}", file=sys.stderr)
    return specs


def main(argv: list[str] | None = None) -> int:
    return interruptible("evaluate: interrupted", lambda: _evaluate(argv))


def _evaluate(argv: list[str] | None) -> int:
    args = parse_args(argv)
    try:
        settings = resolve_settings(args)
        if args.localize and settings["goals"]:
            raise EvaluationError("--goals (navigation) and --localize exclude each other")
        if settings["map"] and not (args.localize or settings["goals"]):
            raise EvaluationError("--map needs --goals or --localize (wall following uses no "
                                  "map)")
        specs = episode_specs(settings)
        if args.localize:
            check_localization_options(args, settings, specs)
        if args.slam:  # each episode's simulated LiDAR unit is calibrated for the mapper
            from amr_evaluation.mapping_evaluation import check_lidar_units
            check_lidar_units(((s.profile, s.seed) for s in specs),
                              settings["links"].get("mapper"))
        check_filter_maps(specs, parse_overrides(args.pf_param), args.localize)
        started = dt_module.datetime.now(dt_module.timezone.utc)
        out = check_output_folder(args.out or Path("out") / f"evaluate-{started:%Y%m%d-%H%M%S}",
                                  "--out")
        executor = make_executor(args, settings["jobs"], len(specs),
                                 settings["episode_timeout"])
    except ValueError as exc:  # EvaluationError, PluginSpecError, a bad --out
        print(f"evaluate: {exc}", file=sys.stderr)
        return 2
    try:
        return run_and_report(args, settings, specs, executor, out, started)
    finally:
        close = getattr(executor, "close", None)
        if close:
            close()


def run_and_report(args, settings: dict, specs, executor, out: Path, started) -> int:
    """Run the episodes on the executor; write and print the results; the exit code."""
    if args.localize:
        from amr_evaluation.localization_evaluation import evaluate_main
        return evaluate_main(specs, settings, args, out, executor=executor)
    if args.slam:
        from amr_evaluation.mapping_evaluation import evaluate_main as evaluate_mapping
        return evaluate_mapping(specs, settings, args.mapper_params, out, executor=executor,
                                sheet=not args.no_sheet)
    print(f"evaluate: {len(specs)} episodes of {settings['duration']:g} s on "
          f"{executor.describe()}, controller {settings['controller']}"
          + (f" {settings['params']}" if settings["params"] else ""), flush=True)

    bar = ProgressBar(len(specs))
    try:
        # Trajectories only for the sheet: without it, workers send summaries back.
        outcomes = run_episodes(specs, progress=bar, executor=executor,
                                trajectory=not args.no_sheet)
    except KeyboardInterrupt:
        bar.finish()
        raise
    bar.finish()
    wall = (dt_module.datetime.now(dt_module.timezone.utc) - started).total_seconds()

    meta = {"started_utc": started.isoformat(timespec="seconds"), "wall_time_s": round(wall, 2),
            "jobs": executor.workers(len(specs)), "executor": executor.describe(),
            "kind": settings["kind"], "controller": settings["controller"],
            "links": settings["links_ran"],
            "params": settings["params"], "params_file": settings["params_file"],
            "duration_s": settings["duration"], "dt_s": settings["dt"],
            "episode_timeout_s": settings["episode_timeout"],
            "goals": settings["goals"], "pose_source": settings["pose_source"],
            "map": settings["map"],
            "config": args.config, "command": " ".join(sys.argv),
            "python": platform.python_version(), "host": platform.node()}
    write_json(out / "results.json", outcomes, meta)
    write_csv(out / "results.csv", outcomes)
    if not args.no_sheet:
        ran = [o.result for o in outcomes if o.result is not None]
        if ran:
            from amr_evaluation.plot import plot_episodes_sheet
            # Title: the controller and what differs from its params file (all would not fit).
            changed = " ".join(f"{k}={v}" for k, v in parse_overrides(args.param).items())
            sheet = plot_episodes_sheet(ran, out / "sheet.png", title=textwrap.shorten(
                f"{settings['controller']} {changed}", width=150, placeholder=" ..."))
            print(f"evaluate: trajectories drawn in {sheet}")

    print(format_table(outcome_row(o) for o in outcomes))
    line, code = verdict(outcomes)
    print(line)
    print(f"evaluate: {len(specs)} episodes in {wall:.1f} s; results in {out}")
    return code


if __name__ == "__main__":
    sys.exit(run_script(main))
