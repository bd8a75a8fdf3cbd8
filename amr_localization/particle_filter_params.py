"""The ParticleFilter's parameters and their checking.

The ParticleFilter's parameters: name -> (default, description with units), and their
checking. No rclpy import; the particle_filter node declares each as a ROS parameter.

Run scripts check `--pf-param` values before anything runs with the same two functions the
filter uses: check_parameters(overrides) (the values alone) and check_world(world, values)
(against the map: its size, memory and table build time, the initial pose); both raise
ValueError naming every problem.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from amr_common.plugins.parameter_table import (
    MAX_SEED,
    Param,
    above,
    at_least,
    between,
    check_values,
    one_of,
    ruled,
    table_values,
    vector,
)
from amr_common.robot import ROBOT_RADIUS
from amr_common.world.map_raster import likely_wall_segments
from amr_common.world.world import World
from amr_localization.expected_ranges import estimated_build_s, forget_started_builds
from amr_localization.range_sensor import MODEL_NAMES
from amr_localization.table_memory import MemoryPlan, choose_table

# A particle's centre may be this much closer to a wall than the robot radius before it counts
# as inside the wall: the table's cells are 2 cm, and the simulated robot rests ~0.5 mm deep.
WALL_SLACK_M = 0.02
# The most particles of any count (max_particles, min_particles, tracking_particles), for the
# filter, its node and the run scripts' checks: the node stays responsive. Measured at 200,000
# (lab02, 60 beams, 2-core machine, CPU time): the first scan of a global search (pose search
# seeding 180,000 particles, then weighing them) 0.21 s, later global-search updates 0.1 s or
# less, +40 MB beside the table; a million took ~0.3 s per update and ~2 s to build. 8000
# localize the mazes.
MAX_PARTICLES = 200_000

MAP_WALLS = ("likely", "edges")  # where a map's walls are: map_walls
# name: (default, description). The defaults localize in both simulator profiles.
_TABLE: dict[str, tuple[Any, str]] = {
    "lidar_offset_x_m": (0.0, "Forward position of the LiDAR relative to the robot centre [m] "
                              "(-0.032 on a real Burger; the run scripts set the profile's)."),
    "initial_pose": ([], "Tracking start [x, y, theta] (m, m, rad); [] = global localization "
                         "(uniform over the free space, all headings)."),
    "initial_pose_sigma": ([0.1, 0.1, 0.2], "Standard deviations [x m, y m, theta rad] of the "
                                            "particles drawn around initial_pose or "
                                            "/initialpose."),
    "seed": (0, "Seed of the filter's random numbers: the same seed and inputs give the same "
                "run."),
    "max_particles": (8000, "Particles of a global search (and the most the adaptive count "
                            "uses)."),
    "min_particles": (300, "Fewest particles the adaptive (KLD) count goes down to."),
    "tracking_particles": (2000, "Particles drawn around an initial pose (/initialpose, "
                                 "initial_pose)."),
    "beams": (60, "Beams of each scan weighed per particle, evenly spread over the rays."),
    "lidar_model": ("auto", "The range sensor (range_sensor.py): 'LDS-01' or 'LDS-02' (each "
                            "reading's tolerance and sigma grow with the range by the "
                            "datasheet's bands; a missing return is unknown; the rays are "
                            "de-skewed), 'exact' (the simulator's clean profiles: the fixed "
                            "tolerance and sigma), 'auto' (LDS-02 if the scan's range_max is "
                            "beyond 10 m, else LDS-01)."),
    "deskew": (True, "Move each ray to the LiDAR's pose now with the odometry (rays measured "
                     "clockwise over the revolution before the stamp, as the LDS drivers stamp "
                     "them); false for scans taken at one instant (a simulated scanner without "
                     "skew). Not used by the 'exact' model."),
    "map_walls": ("likely", "Where a map's walls are (a Nav2 or SLAM map; a polygon world's are "
                            "its own): 'likely' inside the occupied cells (the middle of a "
                            "two-cell band, as SLAM marks a wall, else the first cell's centre), "
                            "known to half a cell: a map of a real room; 'edges' on the free "
                            "cells' edges, where the simulator puts the walls of a world built "
                            "from this map (the run scripts set it when the simulated world is "
                            "the filter's map)."),
    "sigma_hit_m": (0.03, "Standard deviation of a beam's range around the expected range [m] "
                          "(the nearest readings' with an LDS model)."),
    "z_random": (0.05, "Weight of the uniform part of a beam's likelihood: a beam that misses "
                       "costs log(z_random), whatever the miss (robust to clutter)."),
    "table_resolution_m": (0.02, "Cell size of the expected-range table [m] (the finest: "
                                 "see max_memory_mb)."),
    "table_angles": (360, "Directions of the expected-range table over 360 degrees (the "
                          "most: see max_memory_mb)."),
    "max_memory_mb": (600.0, "Most memory for the map's data [MB] (expected-range table, "
                             "grids): a bigger map gets half the table's directions, then "
                             "twice its cell size (up to 4 cm); a map too big even then is "
                             "refused, saying what it would need."),
    "max_table_build_s": (60.0, "Longest the expected-range table of a map may take to build "
                                "[s]: estimated from a sample of it before anything runs (on "
                                "this machine, at its present load); a map whose table would "
                                "take longer is refused, saying how long."),
    "noise_v_per_v": (0.1, "Linear-speed noise per unit of linear speed [(m/s)/(m/s)]."),
    "noise_v_per_w": (0.01, "Linear-speed noise per unit of turn rate [(m/s)/(rad/s)]."),
    "noise_w_per_w": (0.1, "Turn-rate noise per unit of turn rate [(rad/s)/(rad/s)]."),
    "noise_w_per_v": (0.5, "Turn-rate noise per unit of linear speed [(rad/s)/(m/s)]."),
    "update_min_distance_m": (0.02, "Weigh a new scan once the robot drove this far since the "
                                    "last measurement update [m] ..."),
    "update_min_angle_rad": (0.05, "... or turned this much [rad] ..."),
    "update_max_interval_s": (0.5, "... or this long passed (also while standing still) [s]."),
    "seed_uniform_share": (0.1, "Share of a global search's particles drawn uniformly; the "
                                "others at the poses an exhaustive search finds fitting the "
                                "first scan."),
    "search_ess_fraction": (0.2, "While not localized, the likelihood is flattened so that the "
                                 "effective sample size stays at least this share of the "
                                 "particles (no premature collapse on a lucky rotated pose)."),
    "resample_ess_fraction": (0.5, "Resample when the effective sample size falls below this "
                                   "share of the particle count."),
    "kld_epsilon": (0.05, "KLD sampling: bound on the K-L divergence of the particle set."),
    "kld_z": (2.33, "KLD sampling: standard normal quantile of the bound's confidence (2.33 = "
                    "99 %)."),
    "kld_bin_xy_m": (0.05, "KLD histogram bin size in x and y [m] (sized for 2-3 m mazes)."),
    "kld_bin_theta_rad": (0.1745, "KLD histogram bin size in heading [rad]."),
    "cluster_radius_m": (0.1, "Particles within this distance of the heaviest region form the "
                              "dominant cluster [m]."),
    "cluster_angle_rad": (0.35, "... and within this heading difference [rad]."),
    "cluster_min_share": (0.9, "Localized needs the dominant cluster to carry this share of the "
                               "weight."),
    "match_tolerance_m": (0.03, "A ray matches when reading and exact expectation at the "
                                "estimate differ by at most this [m] (plus the datasheet's "
                                "error at the reading's range with an LDS model)."),
    "localize_match_fraction": (0.97, "Localized needs this share of ALL rays to match ..."),
    "localize_updates": (10, "... at this many consecutive measurement updates."),
    "ambiguity_match_fraction": (0.9, "Localized needs that no pose elsewhere (> 15 cm or "
                                      "> 15 degrees away, exhaustive search) explains this share "
                                      "of the rays."),
    "inject_share": (0.2, "Share of the particles moved to the rival poses of an ambiguous "
                          "scan."),
    "keep_match_fraction": (0.8, "Once localized, fewer matching rays than this share ..."),
    "lost_updates": (3, "... at this many consecutive updates = lost: localized false and a "
                        "global search."),
    "reinit_match_fraction": (0.75, "A dominant cluster matching fewer rays than this share ..."),
    "reinit_updates": (10, "... at this many consecutive updates restarts the global search."),
}

_FRACTIONS = ("seed_uniform_share", "resample_ess_fraction", "search_ess_fraction",
              "cluster_min_share", "inject_share", "ambiguity_match_fraction",
              "localize_match_fraction", "keep_match_fraction", "reinit_match_fraction")
# Numbers >= 0 but for these. The bounds keep a value from costing absurd memory or time (or
# being meaningless); checks of several parameters: check_parameters.
PARAMETERS: dict[str, Param] = ruled(
    _TABLE, at_least(0.0), lidar_offset_x_m=None, lidar_model=one_of(*MODEL_NAMES),
    map_walls=one_of(*MAP_WALLS),
    initial_pose=vector(0, 3), initial_pose_sigma=vector(3, low=0.0),
    seed=between(0, MAX_SEED), beams=between(1, 4096), table_angles=between(8, 4096),
    localize_updates=at_least(1), lost_updates=at_least(1), reinit_updates=at_least(1),
    z_random=between(0.0, 1.0, low_open=True, high_open=True),
    sigma_hit_m=above(0.0), kld_epsilon=above(0.0), match_tolerance_m=above(0.0),
    table_resolution_m=between(0.005, 0.2), max_memory_mb=between(1.0, 1e6),
    max_table_build_s=between(0.0, 1e6, low_open=True),
    kld_bin_xy_m=between(0.005, 10.0), kld_bin_theta_rad=between(0.005, 2 * math.pi),
    cluster_radius_m=between(0.001, 10.0), cluster_angle_rad=between(0.001, 2 * math.pi),
    **{name: between(1, MAX_PARTICLES) for name in ("max_particles", "min_particles",
                                                    "tracking_particles")},
    **{name: between(0.0, 10.0) for name in ("noise_v_per_v", "noise_v_per_w",
                                             "noise_w_per_w", "noise_w_per_v")},
    **{name: between(0.0, 1.0) for name in _FRACTIONS})


def check_parameters(overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """Every parameter's value, checked and normalised.

    Every parameter's value (defaults updated with `overrides`), checked and normalised
    (floats, ints, tuples; initial_pose None when empty); ValueError naming every bad one.
    """
    values, problems = check_values(PARAMETERS,
                                    table_values(PARAMETERS, overrides, "ParticleFilter"))
    counts = (values["min_particles"], values["max_particles"])
    if not any(p.startswith(("min_particles ", "max_particles ")) for p in problems) \
            and counts[0] > counts[1]:
        problems.append(f"min_particles ({counts[0]}) must not exceed max_particles "
                        f"({counts[1]})")
    if problems:
        raise ValueError("; ".join(problems))
    values["initial_pose"] = values["initial_pose"] or None
    return values


class TableTooSlowError(ValueError):
    """The map's expected-range table would take longer to build than max_table_build_s."""


def check_world(world: World, values: dict[str, Any]) -> MemoryPlan:
    """The expected-range table the filter will use on `world`, after checking the values there.

    `values`: check_parameters' result. ValueError if the initial pose is where the robot cannot
    be; table_memory.MapTooBigError (a ValueError) if the map needs more than max_memory_mb,
    saying how much it would need; TableTooSlowError (a ValueError) if its table would take
    longer than max_table_build_s to build, saying how long. Nothing is built but a sample of
    the table (~0.3 s of CPU), which the filter goes on from.
    """
    pose = values["initial_pose"]
    problem = pose_problem(world, pose[0], pose[1]) if pose is not None else None
    if problem:
        raise ValueError(f"initial_pose {list(pose)}: {problem}")
    plan = choose_table(world, values)
    seconds = estimated_build_s(world, plan.resolution, plan.angles, filter_walls(world, values))
    if seconds > values["max_table_build_s"]:
        forget_started_builds()
        xmin, ymin, xmax, ymax = world.bounds
        raise TableTooSlowError(
            f"{world.source}: the particle filter's expected-range table of this "
            f"{xmax - xmin:.1f} x {ymax - ymin:.1f} m map would take about {seconds:,.1f} s to "
            f"build here ({plan.describe()}, {plan.free_cells:,} cells); max_table_build_s is "
            f"{values['max_table_build_s']:g}")
    return plan


def filter_walls(world: World, values: dict[str, Any]) -> np.ndarray:
    """The walls the filter's LiDAR sees on `world` (its expected ranges are cast on them).

    A map's walls inside its occupied cells (map_walls 'likely'), else the world's own (a
    polygon world, or map_walls 'edges').
    """
    if world.raster is None or values["map_walls"] == "edges":
        return world.segments
    return likely_wall_segments(world.raster)


def pose_problem(world: World, x: float, y: float) -> str | None:
    """Why the robot's centre cannot be at (x, y) in `world` (None if it can).

    It must be in the free space and at least ROBOT_RADIUS - WALL_SLACK_M from every wall
    (where the filter keeps its particles).
    """
    if not (math.isfinite(x) and math.isfinite(y)):
        return f"({x}, {y}) is not finite"
    if not world.contains(x, y):
        return f"({x:.3f}, {y:.3f}) is outside the map's free space"
    if world.clearance(x, y) < ROBOT_RADIUS - WALL_SLACK_M:
        return (f"({x:.3f}, {y:.3f}) is on or too close to a wall: the robot's centre must be "
                f"at least {ROBOT_RADIUS - WALL_SLACK_M:.3f} m from every wall")
    return None



def checked_initial_pose(world: World, pose, sigma) -> tuple[tuple[float, float, float],
                                                            tuple[float, ...]]:
    """((x, y, theta), sigma) as floats; ValueError for an initial pose the filter refuses.

    Refused: values that are not finite, a sigma that is not 3 numbers >= 0, or a pose where
    the robot cannot be (pose_problem).
    """
    x, y, theta = (float(v) for v in pose)
    wanted = tuple(float(v) for v in sigma)
    if not all(math.isfinite(v) for v in (x, y, theta)):
        raise ValueError(f"initial pose ({x}, {y}, {theta}) is not finite")
    if len(wanted) != 3 or not all(math.isfinite(v) and v >= 0.0 for v in wanted):
        raise ValueError(f"initial pose sigma {list(wanted)} must be 3 finite numbers >= 0")
    problem = pose_problem(world, x, y)
    if problem:
        raise ValueError(f"initial pose {problem}")
    return (x, y, theta), wanted

def parameter_descriptions() -> dict[str, tuple[Any, str]]:
    """Name -> (default, description) of every parameter."""
    return dict(PARAMETERS)
