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
    """--foxglove and its --foxglove-* options: a live Foxglove view (amr_foxglove_bridge)."""
    parser.add_argument("--foxglove", action="store_true", help="serve the graph's topics to "
                        "Foxglove (Open connection -> Foxglove WebSocket -> ws://HOST:PORT)")
    parser.add_argument("--foxglove-port", type=int, default=8765,
                        help="Foxglove WebSocket port (default 8765, as foxglove_bridge)")
    parser.add_argument("--foxglove-host", default="127.0.0.1", help="address to listen on "
                        "(default 127.0.0.1: this machine only; 0.0.0.0 for other machines)")
    parser.add_argument("--foxglove-origin", action="append", default=[], type=_origin,
                        metavar="ORIGIN", help="also accept WebSocket handshakes from this web "
                        "page origin, e.g. https://lichtblick.example.org (repeatable; built in: "
                        "none, https://app.foxglove.dev, file://, http(s)://localhost)")
    parser.add_argument("--foxglove-teleop", action="store_true", help="let Foxglove clients "
                        "publish /cmd_vel (the Teleop panel drives the robot)")


def _origin(text: str) -> str:
    import argparse

    from amr_tools.foxglove_gate import normalize_origin
    try:
        return normalize_origin(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def make_viewer_nodes(context, args, *, use_sim_time: bool = False) -> list:
    """The Foxglove bridge node when args.foxglove, else nothing.

    Lifecycle nodes to start before the rest of the graph.
    """
    if not getattr(args, "foxglove", False):
        return []
    from amr_tools.foxglove_bridge import FoxgloveBridgeNode
    values = {"port": args.foxglove_port, "host": args.foxglove_host,
              "client_teleop": getattr(args, "foxglove_teleop", False),
              "use_sim_time": use_sim_time}
    if getattr(args, "foxglove_origin", None):
        values["allowed_origins"] = list(args.foxglove_origin)
    return [FoxgloveBridgeNode(context=context,
                               parameter_overrides=overrides_to_parameters(values))]


def make_map_publisher(context, map_source: str, *, use_sim_time: bool = False):
    """amr_map_publisher with `map_source` (any world source) as /map and /map_markers.

    The robot's /map, and the simulation's when the map is not the world.
    """
    from amr_tools.map_publisher import MapPublisherNode
    return MapPublisherNode(context=context, parameter_overrides=overrides_to_parameters(
        {"world": str(map_source), "use_sim_time": use_sim_time}))


def check_common_options(parser, args, script: str, wall_follower_set: dict[str, str],
                         filter_set: dict[str, str]) -> None:
    """Check dt, the Foxglove port, -p, --pf-param, the params file and the controller now.

    Everything the nodes would refuse once started is refused here, before any node exists
    (argparse error: one line, exit code 2). `wall_follower_set` and `filter_set` name the
    parameters `script` sets itself from its options ({"dt": "from --dt"}): a -p or --pf-param
    for them would contradict the option, so it is refused naming the option.
    Sets args.overrides and args.pf_overrides (typed as the nodes declare them) and
    args.controller_spec (the MODULE:CLASS the wall follower will run).
    """
    from link_options import check_link_options, check_particle_filter

    from amr_common.plugins.loader import PluginSpecError, parse_overrides
    from amr_common.plugins.parameter_table import check_value
    from amr_control.wall_follower_node import node_parameters
    from amr_tools.foxglove_bridge import PARAMETERS as FOXGLOVE_PARAMETERS
    # The options that stand for node parameters: by the rules of those parameters.
    for option, name, table, value in (
            ("--dt", "dt", node_parameters(), args.dt),
            ("--foxglove-port", "port", FOXGLOVE_PARAMETERS,
             getattr(args, "foxglove_port", None))):
        problem = check_value(name, table[name], value)[1] if value is not None else None
        if problem:
            parser.error(f"{option} {value:g}: {problem}")
    if (getattr(args, "foxglove_teleop", False) or getattr(args, "foxglove_origin", [])) \
            and not args.foxglove:
        parser.error("--foxglove-teleop and --foxglove-origin need --foxglove")
    if getattr(args, "foxglove", False):
        problem = _listen_problem(args.foxglove_host, args.foxglove_port)
        if problem:
            parser.error(problem)
    pf_param = getattr(args, "pf_param", [])
    for option, attribute, items in (("-p", "overrides", args.param),
                                     ("--pf-param", "pf_overrides", pf_param)):
        try:
            setattr(args, attribute, parse_overrides(items))
        except PluginSpecError as exc:
            parser.error(f"{option}: {exc}")
    localize = bool(getattr(args, "localize", False) or getattr(args, "goal", None) is not None)
    try:
        args.links = check_link_options(args, {"localizer": localize, "planner": localize and
                                               getattr(args, "goal", None) is not None,
                                               "follower": getattr(args, "goal", None)
                                               is not None})
        _check_wall_follower(args, script, wall_follower_set)
        check_particle_filter(args, script, filter_set)
    except ValueError as exc:  # one-line messages
        parser.error(str(exc))


def _refused(option: str, overrides: dict, script: str, set_by_script: dict[str, str]) -> None:
    """ValueError for an override of a parameter the script sets itself (naming the option)."""
    for name in overrides:
        if name in set_by_script:
            raise ValueError(f"{option} {name}: {script} sets it {set_by_script[name]}")


def _check_wall_follower(args, script: str, set_by_script: dict[str, str]) -> None:
    """-p names and values, the params file and the controller; ValueError (one line)."""
    from amr_common.plugins.loader import DEFAULT_CONTROLLER, load_controller_class
    from amr_common.ros.parameters import typed_values
    from amr_control.wall_follower_node import (
        node_parameter_problems,
        parameter_table,
        tuning_table,
    )
    _refused("-p", args.overrides, script, set_by_script)
    in_file = read_params_file(args.params_file) if args.params_file else {}
    spec = args.controller or in_file.get("controller") or DEFAULT_CONTROLLER
    args.controller_spec = str(spec)
    controller_class = load_controller_class(args.controller_spec)
    table = parameter_table(controller_class)
    unknown = [name for name in args.overrides if name not in table]
    if unknown:
        raise ValueError(f"-p {', '.join(unknown)}: no such wall follower parameter with "
                         f"controller {spec}; known: {', '.join(sorted(table))}")
    args.overrides, problems = typed_values(table, args.overrides)
    # What the node will read: defaults, the params file, -p, the script's dt.
    values, file_problems = typed_values(
        table, {name: value for name, value in in_file.items() if name in table})
    problems += file_problems
    values = {**{name: default for name, (default, _) in table.items()}, **values,
              **args.overrides}
    if args.dt is not None:
        values["dt"] = float(args.dt)
    if not problems:
        problems = node_parameter_problems(values)
    if problems:
        raise ValueError(f"wall follower parameters (-p, --params-file): {'; '.join(problems)}")
    # Build the controller once with what the node will give it: a bad value fails now, before
    # any node exists (and its compiled kernels load here, not while the graph starts).
    tuning = {name: values[name] for name in tuning_table(controller_class)}
    try:
        controller_class(values["dt"], **tuning)
    except Exception as exc:  # a user's controller may raise anything
        raise ValueError(f"controller {spec} rejects its parameters: {exc}") from None


def _listen_problem(host: str, port: int) -> str | None:
    """Why a server (the Foxglove bridge) could not listen on host:port now, or None."""
    import socket
    try:
        family, kind, proto, _, address = socket.getaddrinfo(
            host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)[0]
    except (socket.gaierror, UnicodeError) as exc:
        return f"--foxglove-host {host}: not an address of this machine ({exc})"
    with socket.socket(family, kind, proto) as probe:
        # As the bridge binds (SO_REUSEADDR: a port left in TIME_WAIT is free, one in use not).
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(address)
        except OSError as exc:
            return f"--foxglove-port {port}: cannot listen on {host}:{port}: " \
                   f"{exc.strerror or exc}"
    return None


def read_params_file(path: Path | str) -> dict[str, Any]:
    """Every parameter of a ROS 2 params file, after rcl (the nodes' own parser) has read it.

    ValueError with a one-line reason for a missing, binary, malformed or unusable file.
    """
    from amr_evaluation.evaluation import load_ros_params_file
    target = Path(path)
    if not target.is_file():
        raise ValueError(f"--params-file '{path}': no such file")
    _parse_with_rcl(target)
    return load_ros_params_file(target)


def _parse_with_rcl(path: Path) -> None:
    """Have rcl parse the params file now, instead of a node's constructor failing later."""
    import os
    import re

    import rclpy
    context = rclpy.Context()
    sys.stderr.flush()
    saved_stderr = os.dup(2)  # rcl logs a second, less clear line: keep the message one line
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 2)
            rclpy.init(args=["params_check", "--ros-args", "--params-file", str(path)],
                       context=context, domain_id=0)
    except Exception as exc:  # rclpy's RCLError carries rcl's message
        detail = str(exc).split("Error: ", 1)[-1]
        detail = re.sub(r",? at /\S+:\d+", "", detail).strip()
        raise ValueError(f"--params-file '{path}': not a ROS 2 params file the nodes can read: "
                         f"{detail}") from None
    finally:
        os.dup2(saved_stderr, 2)
        os.close(saved_stderr)
    rclpy.shutdown(context=context)


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


def simulated_robot_parameters(tuning: dict, params_file, profile_name: str) -> dict:
    """The simulated robot's values for the controller (where its LiDAR sits), unless set.

    Only those neither the -p overrides nor the params file set (the rehearsal's
    turtlebot3.yaml sets them itself), but for the scan time: that is the simulated scanner's
    (the robot's file states the real LiDAR's 0.2 s, which turtlebot3_clean does not skew:
    de-skewing its scans would smear them); -p still sets it.
    """
    from amr_common.plugins.loader import DEFAULT_CONTROLLER, load_controller_class
    from amr_evaluation.episode import robot_parameters
    from amr_evaluation.evaluation import load_ros_params_file
    from amr_sim.profiles import get_profile
    try:
        in_file = load_ros_params_file(params_file)
        controller_class = load_controller_class(
            tuning.get("controller", in_file.get("controller", DEFAULT_CONTROLLER)))
    except Exception:  # a bad file or class: the node reports it when it configures
        return {}
    defaults = robot_parameters(controller_class, get_profile(profile_name))
    return {k: v for k, v in defaults.items()
            if k not in tuning and (k not in in_file or k in _SIMULATED_SCANNER)}


_SIMULATED_SCANNER = {"scan_revolution_s"}  # robot_parameters' values a params file cannot set


def localizing_wall_follower(tuning: dict[str, Any]) -> dict[str, Any]:
    """Wall follower overrides for a graph with the particle filter.

    Synchronize /pose and keep exploring once localized (no planner to hand over to), unless
    the caller's tuning says otherwise.
    """
    return {"enable_localization": True, "stop_when_localized": False, **tuning}


def make_particle_filter(context, *, world: str, lidar_offset_x_m: float,
                         overrides: dict[str, Any] | None = None, localizer: str | None = None,
                         sensor: dict[str, Any] | None = None):
    """The particle filter node on `world`, told where the LiDAR sits (overrides win).

    localizer: its `localizer` parameter (MODULE:CLASS; None: the node's default).
    sensor: lidar_model, deskew and map_walls of a simulated run, those the localizer takes
    (amr_evaluation.episode.filter_parameters); the robot's are the defaults (auto,
    de-skewed).
    """
    from amr_localization.particle_filter_node import ParticleFilterNode
    values: dict[str, Any] = {"world": str(world), **(sensor or {}),
                              "lidar_offset_x_m": float(lidar_offset_x_m)}
    if localizer:
        values["localizer"] = str(localizer)
    values.update(overrides or {})
    return ParticleFilterNode(context=context, parameter_overrides=overrides_to_parameters(values))


def navigating_wall_follower(tuning: dict[str, Any]) -> dict[str, Any]:
    """Wall follower overrides for a graph that navigates: hand over to the pure pursuit.

    Synchronize /pose and command only while it is not localized (stop_when_localized), unless
    the caller's tuning says otherwise.
    """
    return {"enable_localization": True, "stop_when_localized": True, **tuning}


def make_navigators(context, *, world: str, goal: tuple[float, float], wall_follower,
                    lidar_offset_x_m: float, links: dict[str, str] | None = None) -> list:
    """The planner and the pure pursuit, after the wall follower and the particle filter.

    The pursuit commands like the wall follower (simulation or robot mode, dt, data_timeout,
    /cmd_vel type and angular sign): it takes those from the wall follower node. links: the
    `planner` and `follower` classes (MODULE:CLASS) when not the nodes' defaults.
    """
    links = links or {}
    planner = {"planner": links["planner"]} if links.get("planner") else {}
    follower = {"follower": links["follower"]} if links.get("follower") else {}
    from amr_control.pure_pursuit_node import PurePursuitNode
    from amr_planning.planner_node import PlannerNode
    same = {name: wall_follower.get_parameter(name).value
            for name in ("simulation", "dt", "data_timeout", "cmd_vel_stamped", "angular_sign")}
    return [
        PlannerNode(context=context, parameter_overrides=overrides_to_parameters(
            {"world": str(world), "goal": [float(goal[0]), float(goal[1])], **planner})),
        PurePursuitNode(context=context, parameter_overrides=overrides_to_parameters(
            {**same, "lidar_offset_x_m": float(lidar_offset_x_m), **follower})),
    ]


def make_robot_graph(context, *, params_file=ROBOT_PARAMS, dt: float | None = None,
                     cmd_vel_stamped: bool | None = None, controller: str | None = None,
                     tuning: dict[str, Any] | None = None, localize_world: str | None = None,
                     filter_overrides: dict[str, Any] | None = None,
                     goal: tuple[float, float] | None = None,
                     links: dict[str, str] | None = None) -> list:
    """The real-robot graph: /odom -> amr_odometry -> /odometry, wall follower in robot mode.

    With `localize_world`, also the particle filter on that map (the Burger's LiDAR position),
    and the wall follower synchronizes /pose; with a `goal` too, the planner and the pure
    pursuit, which drive once localized. links: the localizer, planner and follower classes
    (MODULE:CLASS) when not the nodes' defaults. Returns the lifecycle nodes in startup order.
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
    if localize_world is not None:
        overrides = (navigating_wall_follower if goal is not None else
                     localizing_wall_follower)(overrides)
    odometry = OdometryNode(context=context)
    wall_follower = make_wall_follower(context, params_file=params_file, overrides=overrides)
    if localize_world is None:
        return [odometry, wall_follower]
    from amr_common.robot import LIDAR_OFFSET_X
    particle_filter = make_particle_filter(context, world=localize_world,
                                           lidar_offset_x_m=LIDAR_OFFSET_X,
                                           overrides=filter_overrides,
                                           localizer=(links or {}).get("localizer"))
    navigators = [] if goal is None else make_navigators(
        context, world=localize_world, goal=goal, wall_follower=wall_follower,
        lidar_offset_x_m=LIDAR_OFFSET_X, links=links)
    return [odometry, wall_follower, particle_filter, *navigators]
