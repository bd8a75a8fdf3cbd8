"""The SLAM part of the run scripts (run_sim.py, run_robot.py): options, their checks, the node.

    --slam                  the slam node maps (amr_mapping.slam_node) while the robot explores
    --map-out DIR           ... and writes DIR/map.yaml + DIR/map.pgm (Nav2 map files) at the
                            end, on Ctrl-C too (run_robot without it: maps/DATE-TIME/)
    --slam-param NAME:=VALUE  a slam node / Mapper parameter (repeatable)
    --mapper MODULE:CLASS   the slam node's mapper (amr_common.plugins.interfaces.Mapper)
    --no-controller         no controller runs: drive with scripts/teleop.py (alias --teleop)

--slam with --localize or --goal is refused: the particle filter and the planner need the map
SLAM is still building; map first, then localize and navigate on the saved map
(run_sim.py `--world DIR/map.yaml`, run_robot.py `--map DIR/map.yaml`). --slam with --kidnap
too: the mapper cannot know the robot was carried. Every check runs before anything starts (one
line, exit code 2).
A map that could not be written (the folder gone, a full disk) fails the run: MAP_NOT_WRITTEN.
"""
from __future__ import annotations

import datetime
from pathlib import Path
from typing import Any

MAP_NAME = "map"  # DIR/map.yaml + DIR/map.pgm, as map_saver_cli -f DIR/map
MAP_NOT_WRITTEN = 3  # exit code of a run whose map could not be written


def add_slam_options(parser, script: str) -> None:
    """--slam, --map-out, --slam-param and --no-controller (--teleop)."""
    parser.add_argument("--slam", action="store_true", help="also run the slam node: it maps "
                        "while the robot explores (/map, map -> odom, /slam_pose)")
    parser.add_argument("--map-out", default=None, metavar="DIR", help="with --slam: write the "
                        "map as DIR/map.yaml + DIR/map.pgm (Nav2 map files) when the run ends, "
                        "Ctrl-C included" + (" (default: maps/DATE-TIME/ in the current folder, "
                                             "named at start-up)" if script == "run_robot"
                                             else ""))
    parser.add_argument("--slam-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="slam node or Mapper parameter override (repeatable), e.g. "
                        "--slam-param loop_closure:=false")
    parser.add_argument("--mapper", default=None, metavar="MODULE:CLASS", help="with --slam: "
                        "a mapper (amr_common.plugins.interfaces.Mapper) for the slam node "
                        "(default amr_mapping.mapper:Mapper)")
    parser.add_argument("--no-controller", "--teleop", dest="no_controller",
                        action="store_true", help="start no controller: drive the robot with "
                        "scripts/teleop.py" + (" (needs --realtime: lockstep advances on the "
                                               "controller's commands)"
                                               if script == "run_sim" else ""))


def check_slam_options(args, script: str, set_by_script: dict[str, str]) -> None:
    """The SLAM options now, before anything runs; ValueError with a one-line reason.

    Sets args.slam_overrides (typed as the node declares them) and args.map_out (a Path of a
    writable folder, or None).
    """
    args.slam_overrides = {}
    if not args.slam:
        for option, given in (("--map-out", args.map_out is not None),
                              ("--slam-param", bool(args.slam_param)),
                              ("--mapper", getattr(args, "mapper", None) is not None)):
            if given:
                raise ValueError(f"{option} needs --slam")
        return
    for option in ("localize", "goal", "enable_localization"):
        if getattr(args, option, None):
            on_map = "--map" if script == "run_robot" else "--world"  # the robot's is its map
            raise ValueError(f"--slam and --{option.replace('_', '-')} exclude each other: "
                             "map first, then localize and navigate on the saved map "
                             f"({on_map} DIR/{MAP_NAME}.yaml)")
    if getattr(args, "map", None):
        raise ValueError("--slam and --map exclude each other: both would publish /map")
    if getattr(args, "kidnap", None) is not None:  # (a robot's SLAM has no kidnapping either)
        raise ValueError("--slam and --kidnap exclude each other: the mapper is not told that "
                         "the robot was carried, so it would go on mapping from a wrong pose "
                         "(--kidnap tests a localizer's recovery: --localize or --goal)")
    if args.map_out is not None:
        if not str(args.map_out).strip():
            raise ValueError(f"--map-out {args.map_out!r}: give a folder (an empty name would "
                             "write into the current folder)")
        args.map_out = check_map_folder(args.map_out)
    args.slam_overrides = slam_overrides(args.slam_param, set_by_script,
                                         getattr(args, "mapper", None))


def check_map_folder(path: str | Path) -> Path:
    """`path` as a folder the map files can be written to (created); ValueError if not."""
    from cli_checks import check_output_file, check_output_folder
    folder = check_output_folder(path, "--map-out")
    for suffix in (".yaml", ".pgm"):
        check_output_file(folder / f"{MAP_NAME}{suffix}", "--map-out")
    return folder


def default_map_folder(now: datetime.datetime | None = None) -> Path:
    """maps/<YYYY-MM-DD>-<HHMMSS>/ in the current folder (-2, -3 ... if it exists already)."""
    base = Path.cwd() / "maps" / f"{now or datetime.datetime.now():%Y-%m-%d-%H%M%S}"
    folder, count = base, 1
    while folder.exists():
        count += 1
        folder = base.with_name(f"{base.name}-{count}")
    return folder


def slam_overrides(items: list[str], set_by_script: dict[str, str],
                   mapper: str | None = None) -> dict[str, Any]:
    """--slam-param NAME:=VALUE items, typed and checked by the node's and the Mapper's checks.

    mapper: --mapper's MODULE:CLASS (loaded now: ValueError naming what is missing); its
    parameters are the ones --slam-param takes, and it becomes the node's `mapper` parameter.
    """
    from amr_common.plugins.loader import (
        DEFAULT_MAPPER,
        PluginSpecError,
        link_parameters,
        load_class,
        parse_overrides,
    )
    from amr_common.ros.parameters import typed_values
    from amr_mapping.mapper_params import check_parameters
    from amr_mapping.slam_node_params import NODE_PARAMETERS, node_parameter_problems
    try:
        overrides = parse_overrides(items)
        PARAMETERS = link_parameters(load_class(mapper or DEFAULT_MAPPER, "mapper"),
                                     NODE_PARAMETERS)
    except PluginSpecError as exc:
        raise ValueError(str(exc) if mapper and str(exc).startswith("mapper") else
                         f"--slam-param: {exc}") from None
    if "mapper" in overrides:
        raise ValueError("--slam-param mapper: give the class with --mapper MODULE:CLASS")
    for name in overrides:
        if name in set_by_script:
            raise ValueError(f"--slam-param {name}: the script sets it {set_by_script[name]}")
    table = {**NODE_PARAMETERS, **PARAMETERS}
    unknown = [name for name in overrides if name not in table]
    if unknown:
        raise ValueError(f"--slam-param {', '.join(unknown)}: no such slam parameter; known: "
                         f"{', '.join(sorted(table))}")
    overrides, problems = typed_values(table, overrides)
    if not problems:
        node = {name: default for name, (default, _) in NODE_PARAMETERS.items()}
        node.update({k: v for k, v in overrides.items() if k in NODE_PARAMETERS})
        problems = node_parameter_problems(node)
        try:  # the reference's own checks; another class checks when the node builds it
            if mapper in (None, DEFAULT_MAPPER):
                check_parameters({k: v for k, v in overrides.items() if k in PARAMETERS})
        except ValueError as exc:
            problems.append(str(exc))
    if problems:
        raise ValueError(f"--slam-param: {'; '.join(problems)}")
    return {**overrides, "mapper": mapper} if mapper else overrides


def lidar_parameters(args: Any, profile: Any = None) -> dict[str, Any]:
    """The slam node's LiDAR and robot parameters, --slam-param's on top; only those it takes.

    profile: a simulated run's (amr_evaluation.episode.mapper_parameters: the LiDAR's place,
    de-skew, range error and the unit calibrated with --seed, the Burger's speeds); None: the
    Burger's LDS-01 (LDS-02 owners: --slam-param lidar_model:=LDS-02), its place, the
    calibration the user gives (--slam-param range_correction:=[...],
    scripts/calibrate_lidar.py) and the Burger's speeds (episode.burger_mapper_limits).
    """
    from amr_common.plugins.loader import DEFAULT_MAPPER, described_parameters, link_class
    from amr_mapping.mapper_params import range_error_parameters
    given = args.slam_overrides or {}
    mapper = link_class(getattr(args, "mapper", None) or DEFAULT_MAPPER, "mapper")
    if profile is not None:
        from amr_evaluation.episode import mapper_parameters
        from amr_sim.profiles import get_profile
        values = mapper_parameters(get_profile(profile), mapper, seed=args.seed)
    else:
        from amr_common.robot import LIDAR_OFFSET_X
        from amr_evaluation.episode import burger_mapper_limits
        takes = described_parameters(mapper)
        values = {name: value for name, value in {
            **range_error_parameters(str(given.get("lidar_model", "LDS-01"))),
            **burger_mapper_limits()}.items() if takes is None or name in takes}
        values["lidar_offset_x_m"] = LIDAR_OFFSET_X
    return {**values, **given}


def map_prefix(map_out: Path | None, label: str | None = None) -> str:
    """DIR/map (DIR/map-LABEL for one start of several), or '' without --map-out."""
    if map_out is None:
        return ""
    return str(Path(map_out) / (MAP_NAME if label is None else f"{MAP_NAME}-{label}"))


def make_slam_node(context, *, lidar_offset_x_m: float, output_prefix: str = "",
                   start_pose=None, overrides: dict[str, Any] | None = None):
    """The slam node: the LiDAR position (until /tf_static), where to save, the start pose."""
    from amr_mapping.slam_node import SlamNode
    from launch_common import overrides_to_parameters
    values: dict[str, Any] = {"lidar_offset_x_m": float(lidar_offset_x_m),
                              "output_prefix": str(output_prefix)}
    if start_pose is not None:
        values["map_start_pose"] = [float(v) for v in start_pose]
    values.update(overrides or {})
    return SlamNode(context=context, parameter_overrides=overrides_to_parameters(values))


def without_controller(nodes: list) -> list:
    """`nodes` without the wall follower (destroyed): --no-controller, the user drives."""
    for node in [n for n in nodes if n.get_name() == "wall_follower"]:
        nodes.remove(node)
        node.destroy_node()
    return nodes
