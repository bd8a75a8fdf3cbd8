"""What the run scripts share (they stand in for launch files): the node graphs and parameters.

run_robot.py and the rehearsal of run_sim.py (`--profile turtlebot3 --realtime`) build the
robot graph with the same function, so the rehearsal runs exactly the nodes and parameters that
drive the real robot.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(REPO))

PARAMS_DIR = REPO / "amr_control" / "params"
SIM_PARAMS = PARAMS_DIR / "sim.yaml"
ROBOT_PARAMS = PARAMS_DIR / "turtlebot3.yaml"


def add_controller_options(parser, params_file_default, params_file_help: str) -> None:
    """--controller, -p NAME:=VALUE and --params-file, shared by the run scripts."""
    parser.add_argument("--controller", default=None, help="MODULE:CLASS of a controller with "
                        "compute_commands(z_scan, z_v, z_w) (default the project's WallFollower)")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="wall follower parameter override (repeatable)")
    parser.add_argument("--params-file", default=params_file_default, help=params_file_help)


def add_foxglove_options(parser) -> None:
    """--foxglove, --foxglove-port, --foxglove-host: a live Foxglove view (amr_foxglove_bridge)."""
    parser.add_argument("--foxglove", action="store_true", help="serve the graph's topics to "
                        "Foxglove (Open connection -> Foxglove WebSocket -> ws://HOST:PORT)")
    parser.add_argument("--foxglove-port", type=int, default=8765,
                        help="Foxglove WebSocket port (default 8765, as foxglove_bridge)")
    parser.add_argument("--foxglove-host", default="127.0.0.1", help="address to listen on "
                        "(default 127.0.0.1: this machine only; 0.0.0.0 for other machines)")


def make_viewer_nodes(context, args, *, use_sim_time: bool = False) -> list:
    """The Foxglove bridge node when args.foxglove, else nothing.

    Lifecycle nodes to start before the rest of the graph.
    """
    if not getattr(args, "foxglove", False):
        return []
    from amr_common.foxglove_bridge import FoxgloveBridgeNode
    return [FoxgloveBridgeNode(context=context, parameter_overrides=overrides_to_parameters({
        "port": args.foxglove_port, "host": args.foxglove_host, "use_sim_time": use_sim_time}))]


def check_common_options(parser, args) -> None:
    """Validate dt and parse the -p overrides into args.overrides (argparse errors on failure)."""
    import math

    from amr_common.controller_loader import ControllerSpecError, parse_overrides
    if args.dt is not None and not (math.isfinite(args.dt) and args.dt > 0):
        parser.error("--dt must be > 0")
    if getattr(args, "foxglove_port", 0) is not None and \
            not 0 <= getattr(args, "foxglove_port", 0) <= 65535:
        parser.error("--foxglove-port must be within 0-65535")
    try:
        args.overrides = parse_overrides(args.param)
    except ControllerSpecError as exc:
        parser.error(str(exc))


def overrides_to_parameters(values: dict[str, Any]) -> list:
    """{"kp": 4.0} -> [rclpy Parameter], for Node(parameter_overrides=...)."""
    from rclpy.parameter import Parameter
    return [Parameter(name, value=value) for name, value in values.items()]


def node_args(params_file: Path | str | None) -> list[str] | None:
    """Node cli_args that load a --params-file (ROS 2 YAML keyed by node name)."""
    if params_file is None:
        return None
    path = Path(params_file)
    if not path.is_file():
        raise SystemExit(f"params file not found: {path}")
    return ["--ros-args", "--params-file", str(path)]


def make_wall_follower(context, *, params_file, overrides: dict[str, Any]):
    """The wall follower with a params file and overrides.

    use_sim_time is left to them: in simulation mode the node stamps each command with its
    measurement's stamp and needs no clock, so following /clock (one more message per lockstep
    step) is opt-in.
    """
    from amr_control.wall_follower_node import WallFollowerNode
    return WallFollowerNode(context=context, cli_args=node_args(params_file),
                            parameter_overrides=overrides_to_parameters(dict(overrides)))


def goal_value_joined(argv: list[str]) -> list[str]:
    """The command line with `--goal -1,0.6` turned into `--goal=-1,0.6`.

    argparse takes a value starting with '-' for an option; goals are typed with their signs.
    """
    out: list[str] = []
    args = list(argv)
    while args:
        arg = args.pop(0)
        if arg == "--goal" and args and args[0].startswith("-"):
            arg = f"--goal={args.pop(0)}"
        out.append(arg)
    return out


def make_navigation_nodes(context, *, world: str, goal: tuple[float, float], simulation: bool,
                          params_file=None, lidar_offset_x: float | None = None,
                          dt: float | None = None, cmd_vel_stamped: bool | None = None,
                          angular_sign: int | None = None) -> list:
    """The nodes that navigate once localized: particle filter, planner, pure pursuit.

    They follow the wall follower in the startup order (the simulator, if any, comes last).
    Each reads its own section of `params_file`; the values given here win over it.
    """
    try:
        from amr_localization.particle_filter_node import ParticleFilterNode
    except ImportError as exc:
        raise SystemExit(f"navigation needs the particle filter (amr_localization): {exc}")
    from amr_control.pure_pursuit_node import PurePursuitNode
    from amr_planning.planner_node import PlannerNode
    located = {"lidar_offset_x_m": lidar_offset_x} if lidar_offset_x is not None else {}
    pursuit = {"simulation": simulation, **located}
    for name, value in (("dt", dt), ("cmd_vel_stamped", cmd_vel_stamped),
                        ("angular_sign", angular_sign)):
        if value is not None:
            pursuit[name] = value
    cli = node_args(params_file)
    return [
        ParticleFilterNode(context=context, cli_args=cli, parameter_overrides=(
            overrides_to_parameters({"world": world, **located}))),
        PlannerNode(context=context, cli_args=cli, parameter_overrides=overrides_to_parameters(
            {"world": world, "goal": [float(goal[0]), float(goal[1])]})),
        PurePursuitNode(context=context, cli_args=cli,
                        parameter_overrides=overrides_to_parameters(pursuit)),
    ]


def make_robot_graph(context, *, params_file=ROBOT_PARAMS, dt: float | None = None,
                     cmd_vel_stamped: bool | None = None, controller: str | None = None,
                     tuning: dict[str, Any] | None = None) -> list:
    """The real-robot graph: /odom -> amr_odometry -> /odometry, wall follower in robot mode.

    Returns the lifecycle nodes in startup order.
    """
    from amr_turtlebot3.odometry_node import OdometryNode
    overrides: dict[str, Any] = dict(tuning or {})
    overrides["simulation"] = False
    if dt is not None:
        overrides["dt"] = dt
    if cmd_vel_stamped is not None:
        overrides["cmd_vel_stamped"] = cmd_vel_stamped
    if controller is not None:
        overrides["controller"] = controller
    odometry = OdometryNode(context=context)
    wall_follower = make_wall_follower(context, params_file=params_file, overrides=overrides)
    return [odometry, wall_follower]
