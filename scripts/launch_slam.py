"""The SLAM part of the run scripts (run_sim.py, run_robot.py): options, their checks, the node.

    --slam                  the slam node maps (amr_mapping.slam_node) while the robot explores
    --map-out DIR           ... and writes DIR/map.yaml + DIR/map.pgm (Nav2 map files) at the
                            end, on Ctrl-C too
    --slam-param NAME:=VALUE  a slam node / Mapper parameter (repeatable)
    --no-controller         no controller runs: drive with scripts/teleop.py (alias --teleop)

--slam with --localize or --goal is refused: the particle filter and the planner need the map
SLAM is still building; map first, then localize and navigate on the saved map
(`--world DIR/map.yaml`). Every check runs before anything starts (one line, exit code 2).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

MAP_NAME = "map"  # DIR/map.yaml + DIR/map.pgm, as map_saver_cli -f DIR/map


def add_slam_options(parser, script: str) -> None:
    """--slam, --map-out, --slam-param and --no-controller (--teleop)."""
    parser.add_argument("--slam", action="store_true", help="also run the slam node: it maps "
                        "while the robot explores (/map, map -> odom, /slam_pose)")
    parser.add_argument("--map-out", default=None, metavar="DIR", help="with --slam: write the "
                        "map as DIR/map.yaml + DIR/map.pgm (Nav2 map files) when the run ends, "
                        "Ctrl-C included")
    parser.add_argument("--slam-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="slam node or Mapper parameter override (repeatable), e.g. "
                        "--slam-param loop_closure:=false")
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
                              ("--slam-param", bool(args.slam_param))):
            if given:
                raise ValueError(f"{option} needs --slam")
        return
    for option in ("localize", "goal", "enable_localization"):
        if getattr(args, option, None):
            raise ValueError(f"--slam and --{option.replace('_', '-')} exclude each other: "
                             "map first, then localize and navigate on the saved map "
                             "(--world DIR/map.yaml)")
    if getattr(args, "map", None):
        raise ValueError("--slam and --map exclude each other: both would publish /map")
    if args.map_out is not None:
        from cli_checks import check_output_file, check_output_folder
        folder = check_output_folder(args.map_out, "--map-out")
        for suffix in (".yaml", ".pgm"):
            check_output_file(folder / f"{MAP_NAME}{suffix}", "--map-out")
        args.map_out = folder
    args.slam_overrides = slam_overrides(args.slam_param, set_by_script)


def slam_overrides(items: list[str], set_by_script: dict[str, str]) -> dict[str, Any]:
    """--slam-param NAME:=VALUE items, typed and checked by the node's and the Mapper's checks."""
    from amr_common.controller_loader import ControllerSpecError, parse_overrides
    from amr_common.parameters import typed_values
    from amr_mapping.mapper_params import PARAMETERS, check_parameters
    from amr_mapping.slam_node_params import NODE_PARAMETERS, node_parameter_problems
    try:
        overrides = parse_overrides(items)
    except ControllerSpecError as exc:
        raise ValueError(f"--slam-param: {exc}") from None
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
        try:
            check_parameters({k: v for k, v in overrides.items() if k in PARAMETERS})
        except ValueError as exc:
            problems.append(str(exc))
    if problems:
        raise ValueError(f"--slam-param: {'; '.join(problems)}")
    return overrides


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
