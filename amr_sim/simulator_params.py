"""The `amr_simulator` node's parameters: names, defaults, descriptions and checks.

Plain Python, no rclpy.
"""
from __future__ import annotations

from typing import Any

from amr_common.plugins.parameter_table import (
    MAX_SEED,
    Param,
    between,
    check_values,
    one_of,
    ruled,
    vector,
)
from amr_common.world.world import parse_start

DEFAULT_START = "outer"  # the course's "outer corridor" start in lab02
# name: (default, description); the default's type is the parameter's ([] = a double array).
# Numbers accept ints or doubles (`-p dt:=1` must not kill the process): amr_common.ros.parameters
# declares them with dynamic typing, on_configure checks.
_TABLE: dict[str, tuple[Any, str]] = {
    "world": ("lab02", "Bundled world name or path to a world .yaml / course map .json / Nav2 "
                       "map .yaml"),
    "start": (DEFAULT_START, "Start pose: a name from the world file or 'x,y,theta' "
                             "(m, m, rad); '' or the default 'outer' in a world without "
                             "it = the world's first start"),
    "profile": ("ideal", "Sensor profile: 'ideal' (CoppeliaSim robot), 'turtlebot3' (the "
                         "real Burger: LDS-01 at 5 Hz, /odom pose at 20 Hz, the reality-gap "
                         "effects at typical values), 'turtlebot3_clean' (the same without "
                         "effects) or 'turtlebot3_lds02' (+ effects, LDS-02); options after "
                         "colons: ':randomized' draws the effects from the seed, "
                         "':EFFECT=VALUE' sets one (docs/reality-gap.md)"),
    "dt": (0.05, "Simulation step in seconds (0 < dt <= 1)"),
    "seed": (0, "Seed of the sensor noise (and of the drawn effects): the same seed gives "
                "the same run"),
    "mode": ("lockstep", "'lockstep': each /cmd_vel advances one dt; 'realtime': a "
                         "wall-clock timer advances one dt with the newest command"),
    "cmd_vel_stamped": (True, "Subscribe /cmd_vel as geometry_msgs/TwistStamped (Jazzy); "
                              "false = geometry_msgs/Twist as a Humble robot"),
    "command_timeout": (0.5, "Realtime mode: a command older than this (s) counts as zero; "
                             "0 = never (the real turtlebot3_node keeps the last command)"),
    "goal": ([], "Goal [x, y] in metres; [] = the world's goal, if it has one"),
    "goal_rest_time": (0.5, "Once the goal is reached, the run ends when the robot has been "
                            "commanded to rest (zero) this long (s), so the final error is "
                            "measured where it stops; 0 = end at once (the course "
                            "template)"),
    "goal_tolerance": (0.15, "Distance (m) of the true position to the goal that counts "
                             "as reached"),
    "enable_localization": (False, "Synchronize /pose (amr_msgs/PoseStamped) with /cmd_vel, "
                                   "log its error and finish at the goal once localized"),
    "kidnap": ([], "Kidnapping event [t, x, y, theta] (s, m, m, rad): at simulated time t "
                   "the robot is teleported to (x, y, theta); encoders and odometry see no "
                   "motion (tests a localization node's recovery); [] = none"),
    "odom_frame": ("odom", "Frame of the odometry pose"),
    "base_frame": ("base_footprint", "Robot frame (child frame of odometry)"),
    "scan_frame": ("base_scan", "Frame of the LaserScan"),
    "world_frame": ("map", "Frame of /ground_truth and /map"),
    "publish_ground_truth": (True, "Publish the true pose and velocities on /ground_truth"),
    "truth_frame": ("base_footprint_truth", "Frame of the true robot pose on /tf "
                                            "(world_frame -> truth_frame, for comparison)"),
    "map_to_odom_from_truth": (False, "Publish world_frame -> odom_frame on /tf from the "
                                      "true pose (perfect localization, for viewers when "
                                      "no localization node sends it)"),
    "publish_map": (True, "Publish the world as /map (nav_msgs/OccupancyGrid) and "
                          "/map_markers (walls) once, latched"),
    "map_resolution": (0.05, "Cell size of /map in metres (0.005 to 1)"),
    "publish_world_markers": (True, "Publish /world_markers (visualization_msgs/MarkerArray, "
                                    "latched): the walls navigation_map lacks and the "
                                    "movers where they are (updated at up to 10 Hz of "
                                    "simulated time while anyone subscribes)"),
    "navigation_map": ("", "The map the robot navigates on, as `world` takes it (run_sim's "
                           "--map): /world_markers shows the world's walls it lacks; '' = "
                           "the world itself (none lacked)"),
}
PARAMETERS: dict[str, Param] = ruled(
    _TABLE, dt=between(1e-4, 1.0), seed=between(0, MAX_SEED), mode=one_of("lockstep", "realtime"),
    command_timeout=between(0.0, 3600.0), goal=vector(0, 2), goal_rest_time=between(0.0, 3600.0),
    goal_tolerance=between(1e-3, 100.0), kidnap=vector(0, 4), map_resolution=between(0.005, 1.0))


def check_parameters(values: dict[str, Any]) -> dict[str, Any]:
    """The node's parameter values (name -> value as declared), checked and normalised.

    Each against its rule in PARAMETERS; floats, the goal and kidnap as tuples or None, the
    start parsed; raises ValueError naming every bad one.
    """
    p, problems = check_values(PARAMETERS, {**values, **{
        name: [] for name in ("goal", "kidnap") if values[name] is None}})
    if isinstance(p["kidnap"], tuple) and p["kidnap"] and p["kidnap"][0] < 0:
        problems.append(f"kidnap time must be >= 0 (got {p['kidnap'][0]!r})")
    p["goal"] = p["goal"] or None
    p["kidnap"] = p["kidnap"] or None
    try:
        p["start"] = parse_start(p["start"])
    except ValueError as exc:
        problems.append(str(exc))
    if problems:
        raise ValueError("; ".join(problems))
    return p
