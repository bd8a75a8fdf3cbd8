"""The SLAM round trip, headless: map a world, save the map, then localize and navigate on it.

    result = run_round_trip("lab02", seed=0, folder="out/round_trip")
    print(result["summary"])

1. Mapping: the wall follower explores the TRUE world for `map_duration` s from its first start
   while the Mapper maps it with a drifting odometry (amr_evaluation.mapping_episode, the map
   built in the world's frame as run_sim.py --slam builds it); the map is written as Nav2 map
   files (amr_common.world.map_file) and read back as a world, as a user does with map_saver's
   files.
2. Navigation on the map: the simulator drives the TRUE world; the particle filter (global
   localization: no initial pose) and the planner get the SLAM map
   (amr_evaluation.navigation_episode with the filter and the planner built on the map world);
   the wall follower explores until the filter is localized, then the planner and the pure
   pursuit drive to the goal. Start and goal: the world's named ones at least MIN_TRIP_M apart,
   a start other than the mapping start first, the first pair the planner finds a path for on
   the map.
Figures: the map's precision / recall, false localizations (localized while more than 10 cm or
10 degrees off the truth, amr_evaluation.localization_episode), time to localized, goal reached
and the final distance to it where the robot rests, collisions.

The filter runs with its own defaults, as on the world: it expects a map's walls inside the
occupied cells (amr_common.world.map_raster.likely_wall_segments: SLAM marks both cells around a
wall), known to half a cell (range_sensor), so its localized test (97 % of the rays within 3 cm,
plus that half cell) holds on the SLAM map as on the world. (On the cells' free edges, up to a cell
into the free space, the true pose explained ~75 % of the rays and the round trip needed the
check widened to 8 cm and 90 %.)
"""
from __future__ import annotations

import math
import traceback
from pathlib import Path
from typing import Any, Callable

import numpy as np

from amr_common.world.map_file import write_map
from amr_common.world.world import World
from amr_evaluation.executors import TaskLost, local_executor, run_tasks

MAP_DURATION_S = 300.0
NAVIGATION_DURATION_S = 300.0
GOAL_WITHIN_M = 0.05
MIN_TRIP_M = 1.0  # a goal nearer the start is no trip (some worlds name a start's place a goal)
# The Burger as it is (the reality gap at its typical values); turtlebot3_clean: without it
# (the mapping episode then adds a typical odometry drift of its own).
PROFILE = "turtlebot3"


class RecordedFilterPose:
    """The particle filter on the map world as the pose source, every estimate recorded."""

    def __init__(self, map_world: World, seed: int, **filter_params) -> None:
        self._map_world, self._seed, self._params = map_world, seed, filter_params
        self._source = None
        self.rows: list[list[float]] = []  # [t, x, y, theta, localized]

    def update(self, sim, z_scan, z_v: float, z_w: float):
        """((x, y, theta), localized) of the filter after the newest measurement."""
        if self._source is None:  # built on the first step: it needs the simulator's profile
            from amr_evaluation.pose_sources import ParticleFilterPose
            self._source = ParticleFilterPose(self._map_world, sim, self._seed, **self._params)
        pose, localized = self._source.update(sim, z_scan, z_v, z_w)
        self.rows.append([sim.time, *pose, float(localized)])
        return pose, localized


def build_map(world: World, seed: int, prefix: Path, duration: float = MAP_DURATION_S,
              profile: str = PROFILE) -> tuple[World, dict[str, Any]]:
    """Map `world` from its first start; write PREFIX.yaml + .pgm; (the map world, figures).

    The Mapper as the run scripts set it for the profile (and the unit's calibration).
    """
    from amr_evaluation.episode import mapper_parameters
    from amr_evaluation.mapping_episode import run_mapping_episode
    from amr_mapping.mapper import Mapper
    from amr_sim.profiles import get_profile
    mapper = Mapper(mapper_parameters(get_profile(profile), Mapper, seed))
    result = run_mapping_episode(world, profile=profile, seed=seed, duration=duration,
                                 mapper=mapper, world_frame=True)
    yaml_path, _ = write_map(mapper.occupancy_raster(), prefix,
                             extras={"name": f"{world.name}_slam",
                                     "description": f"SLAM map of {world.name}, seed {seed}"})
    figures = {key: getattr(result, key) for key in (
        "trajectory_rmse_m", "trajectory_max_m", "precision", "recall", "loop_closures",
        "collisions")}
    return World.load(str(yaml_path)), {"map_file": str(yaml_path), **figures}


def start_and_goal(world: World, map_world: World):
    """The first (start name, goal name, planner) with a path on the map, or None.

    Starts other than the mapping start (the first) come first: the filter must find itself;
    goals at least MIN_TRIP_M from the start, the world's default goal first.
    """
    from amr_planning.planner import Planner, PlanningError
    planner = Planner(map_world)
    starts = list(world.starts)
    goals = list(dict.fromkeys([*(n for n, xy in world.goals.items() if xy == world.goal),
                                *world.goals]))
    for start in [*starts[1:], *starts[:1]]:
        for goal in goals:
            (x, y, _), (gx, gy) = world.starts[start], world.goals[goal]
            if math.hypot(gx - x, gy - y) < MIN_TRIP_M:
                continue
            try:
                planner.plan(world.starts[start][:2], world.goals[goal])
            except (PlanningError, ValueError):
                continue
            return start, goal, planner
    return None


def run_round_trip(world_name: str, seed: int, folder: str | Path,
                   map_duration: float = MAP_DURATION_S,
                   navigation_duration: float = NAVIGATION_DURATION_S,
                   filter_params: dict[str, Any] | None = None,
                   profile: str = PROFILE) -> dict[str, Any]:
    """One world and seed: map, save, navigate on the map (see the module docstring)."""
    from amr_evaluation.localization_episode import metrics_from_rows
    from amr_evaluation.navigation_episode import run_navigation_episode
    world = World.load(world_name)
    map_world, mapping = build_map(world, seed, Path(folder) / f"{world.name}-seed{seed}",
                                   map_duration, profile)
    row: dict[str, Any] = {"world": world.name, "seed": seed, **mapping}
    chosen = start_and_goal(world, map_world)
    if chosen is None:
        return {**row, "error": "no named start and goal with a path on the map"}
    start, goal, planner = chosen
    source = RecordedFilterPose(map_world, seed, **(filter_params or {}))
    result = run_navigation_episode(world, start, goal, profile=profile, seed=seed,
                                    duration=navigation_duration, pose_source=source,
                                    planner=planner)
    localization = metrics_from_rows(result.trajectory, source.rows)
    reached = result.goal_reached and result.final_position_error_m <= GOAL_WITHIN_M
    row.update(start=start, goal=goal, time_to_localized_s=localization["time_to_localized_s"],
               false_localizations=localization["false_localizations"],
               goal_reached=bool(reached), final_position_error_m=result.final_position_error_m,
               navigation_collisions=result.collisions, finish_reason=result.finish_reason,
               planning_errors=result.planning_errors)
    return row


def _run_spec(spec: tuple) -> dict[str, Any]:
    world, seed, folder, map_duration, navigation_duration, filter_params, profile = spec
    try:
        return run_round_trip(world, seed, folder, map_duration, navigation_duration,
                              filter_params, profile)
    except Exception as exc:  # noqa: BLE001 - reported per episode, the batch goes on
        return {"world": world, "seed": seed, "error": f"{type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc()}


def run_round_trips(worlds: list[str], seeds: list[int], folder: str | Path,
                    jobs: int | None = None, map_duration: float = MAP_DURATION_S,
                    navigation_duration: float = NAVIGATION_DURATION_S,
                    filter_params: dict[str, Any] | None = None,
                    progress: Callable[[int, int, Any], None] | None = None,
                    profile: str = PROFILE) -> list[dict[str, Any]]:
    """Every world x seed on `jobs` local processes; rows in that order."""
    specs = [(w, int(s), str(folder), map_duration, navigation_duration, filter_params,
              profile) for w in worlds for s in seeds]

    def lost(spec: tuple, loss: TaskLost) -> dict[str, Any]:
        return {"world": spec[0], "seed": spec[1], "error": loss.error}

    return run_tasks(_run_spec, specs, local_executor(jobs, len(specs)), lost, progress,
                     preload=("amr_evaluation.mapping_episode",
                              "amr_evaluation.navigation_episode"))


def round_trip_summary(rows: list[dict[str, Any]],
                       symmetric: tuple[str, ...] = ("corridor_loop",)) -> dict[str, Any]:
    """Episodes, failures, false localizations, goals reached within 5 cm, collisions.

    The goal share leaves out the `symmetric` worlds, where no filter can tell the robot's
    place from its twin's (the filter never declares a pose there, by design).
    """
    ran = [r for r in rows if "error" not in r]
    errors = [r["final_position_error_m"] for r in ran if r["goal_reached"]]
    counted = [r for r in rows if r["world"] not in symmetric]
    reached = sum(r.get("goal_reached", False) for r in counted)
    return {"episodes": len(rows), "failed": len(rows) - len(ran),
            "false_localizations": sum(r["false_localizations"] for r in ran),
            "goals_reached_within_5cm": reached, "goal_episodes": len(counted),
            "goal_share": reached / len(counted) if counted else math.nan,
            "collisions": sum(r["navigation_collisions"] + r["collisions"] for r in ran),
            "final_error_max_m_reached": max(errors, default=None),
            "final_error_median_m_reached": float(np.median(errors)) if errors else None,
            "map_precision_min": min((r["precision"] for r in ran), default=None),
            "map_recall_min": min((r["recall"] for r in ran), default=None)}


def round_trip_line(row: dict[str, Any]) -> str:
    """One line per episode."""
    if "error" in row:
        return f"{row['world']} seed {row['seed']}: ERROR {row['error']}"
    when = row["time_to_localized_s"]
    return (f"{row['world']} seed {row['seed']}: map precision {100 * row['precision']:.1f} %, "
            f"recall {100 * row['recall']:.1f} %; {row['start']} -> {row['goal']}: localized "
            f"{'never' if when is None else f'{when:.1f} s'}, false localizations "
            f"{row['false_localizations']}, goal {'reached' if row['goal_reached'] else 'MISSED'}"
            f" (final error {100 * row['final_position_error_m']:.1f} cm), collisions "
            f"{row['navigation_collisions']}")


__all__ = ["RecordedFilterPose", "build_map", "round_trip_line", "round_trip_summary",
           "run_round_trip", "run_round_trips", "start_and_goal"]
