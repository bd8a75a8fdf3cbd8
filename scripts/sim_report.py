"""The report of one run_sim.py start and its summary line (sim_session.py builds them).

Keys: what ran (world, the map of the filter and the planner with what it and the world disagree
on, start, profile, mode, nodes), the simulator's figures, the trajectory metrics (in the
world); with the particle filter its localization figures, with a goal the navigation ones,
with SLAM the mapping figures (as the headless mapping episode's) and the SLAM pose. A run
stopped before its graph ran gets the same keys (report_before_start).
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.geometry import polyline_length
from amr_common.world.movers import collisions_text
from amr_common.world.world import map_label, start_label
from amr_evaluation.episode import trajectory_metrics


def run_report(args, world, start, sim, trajectory, wall_errors, wall_time: float,
               interrupted: bool, graph: dict, map_world=None) -> dict:
    """The JSON report of one start; `sim` is the Simulator (or its figures before any step).

    `map_world`: the map of the filter and the planner (None: the world).
    """
    positions = np.array([row[1:3] for row in trajectory])
    rms = (math.sqrt(sum(e * e for e in wall_errors) / len(wall_errors))
           if wall_errors else None)
    return {
        "world": world.name, "world_source": world.source, "map": (map_world or world).name,
        "map_source": (map_world or world).source,
        "map_warnings": list(getattr(args, "map_warnings", [])),
        "start": start_label(start), "interrupted": interrupted,
        "profile": args.profile, "mode": "realtime" if args.realtime else "lockstep",
        "seed": args.seed, "dt": args.dt, **graph,
        "steps": sim.steps, "sim_time_s": round(sim.time, 6),
        "wall_time_s": round(wall_time, 3),
        "real_time_factor": round(sim.time / wall_time, 2) if wall_time > 0 else None,
        "collisions": sim.collisions,  # every one the robot started, with movers too
        "collisions_with_movers": sim.collisions_with_movers,
        "first_collision_time_s": sim.first_collision_time,
        "min_clearance_m": sim.min_clearance, "distance_m": sim.distance,
        **trajectory_metrics(world, positions),  # None + metric_errors if not computable
        "rms_wall_error_m": rms,
        "trajectory": trajectory,
        "collision_points": [list(p) for p in sim.collision_points],
        "mover_waits": sim.mover_waits,  # per mover [[t_from, t_to], ...]: it let the robot by
        "effects": sim.effects.as_dict() if getattr(sim, "effects", None) else None,
        **link_failure_fields(None),
    }


def link_failure_fields(failure) -> dict:
    """The report's `link_failure`: why a link failed (amr_common.plugins.link_failure) or None."""
    return {"link_failure": None if failure is None else str(failure)}


def report_before_start(args, world, start, map_world=None) -> dict:
    """The report of a run stopped before its graph ran: nothing simulated, interrupted.

    The keys of a run's report, localization and navigation ones included.
    """
    from types import SimpleNamespace

    from amr_common.robot import ROBOT_RADIUS
    x, y, theta = world.resolve_start(start)
    sim = SimpleNamespace(steps=0, time=0.0, collisions=0, first_collision_time=None,
                          min_clearance=world.clearance(x, y) - ROBOT_RADIUS, distance=0.0,
                          collision_points=[], collisions_with_movers=0,
                          mover_waits=[[] for _ in world.movers])
    trajectory = [[0.0, x, y, theta]]
    report = run_report(args, world, start, sim, trajectory, [], 0.0, True, graph={
        "controller": args.controller_spec, "nodes": [], "controller_mode": None},
        map_world=map_world)
    goal = getattr(args, "goal", None)
    if getattr(args, "localize", False) or goal is not None:
        report |= localization_fields(args, trajectory, [], [])
    if goal is not None:
        report |= navigation_fields(goal, {
            "goal_reached_time_s": None, "stopped_time_s": None,
            "final_position_error_m": math.hypot(x - goal[0], y - goal[1])}, None, [], None)
    if getattr(args, "slam", False):
        report |= slam_fields(world, args.profile, trajectory, [], None, {}, None, {},
                              map_error="no scan was mapped" if getattr(args, "map_out", None)
                              else None)
    return report


def slam_fields(world, profile: str, trajectory: list, estimate: list, raster, stats,
                max_range_m: float | None, timings: dict, map_file=None,
                range_correction=None, map_error: str | None = None) -> dict:
    """The report's SLAM figures and every SLAM pose ([t, x, y, theta], map = world frame).

    The headless mapping episode's figures (amr_evaluation.mapping_metrics): trajectory RMSE /
    max against the truth at each scan's stamp, map precision and recall (noise-free rays from
    the true poses); loop closures, Mapper and node timings (wall ms), the map file written
    (map_saved: True; False with map_error, why, when --map-out's map was not written; None
    without --map-out), the simulated LiDAR unit's calibration given to the slam node (None:
    none). `stats` and `max_range_m`: the mapper's statistics() and max_range_m (checked by the
    slam node). None for the figures when nothing was mapped.
    """
    figures: dict = dict.fromkeys(("trajectory_rmse_m", "trajectory_max_m", "heading_rmse_rad",
                                   "precision", "recall", "seen_wall_m"))
    if estimate and raster is not None and max_range_m is not None:
        from amr_evaluation.mapping_metrics import RayHits, mapping_figures
        from amr_sim.profiles import get_profile
        prof = get_profile(profile)
        rows = np.asarray(trajectory, dtype=np.float64).reshape(-1, 4)
        est = np.asarray(estimate, dtype=np.float64).reshape(-1, 4)
        index = np.clip(np.searchsorted(rows[:, 0], est[:, 0] - 1e-6), 0, len(rows) - 1)
        truth = rows[index, 1:]
        hits = RayHits(world, prof.angle_min, prof.angle_increment, prof.scan_rays,
                       prof.range_min, min(prof.range_max, max_range_m))
        for x, y, theta in truth:
            hits.add(x + prof.lidar_offset_x * math.cos(theta),
                     y + prof.lidar_offset_x * math.sin(theta), theta)
        figures = mapping_figures(world, (0.0, 0.0, 0.0), truth, est[:, 1:], raster, hits)
    # keyframes, loop closures: None when the mapper does not report them (not 0)
    return {"slam": {**figures, "scans": len(estimate), "keyframes": stats.get("keyframes"),
                     "loop_closures": stats.get("loop_closures"),
                     "rejected_scans": stats.get("rejected", {}),
                     "update_ms": stats.get("update_ms"),
                     "loop_closure_ms": stats.get("loop_closed_ms"),
                     "node_scan_ms": timings.get("scan_ms"), "node_map_ms": timings.get("map_ms"),
                     "map_file": None if map_file is None else str(map_file),
                     "map_saved": True if map_file is not None else
                     False if map_error is not None else None,
                     "map_error": map_error,
                     "range_correction": range_correction},
            "estimate": estimate}


def slam_line(report: dict) -> str:
    s = report.get("slam")
    if s is None:
        return ""
    if s["trajectory_rmse_m"] is None:
        return "; SLAM: nothing mapped"
    return (f"; SLAM: {s['scans']} scans, pose RMSE {100 * s['trajectory_rmse_m']:.2f} cm, max "
            f"{100 * s['trajectory_max_m']:.2f} cm, map precision {100 * s['precision']:.1f} %, "
            f"recall {100 * s['recall']:.1f} %"
            + ("" if s["loop_closures"] is None else f", {s['loop_closures']} loop closures")
            + (f", map written to {s['map_file']}" if s["map_file"] else "")
            + (f", map NOT written ({s['map_error']})" if s.get("map_saved") is False else ""))


def map_lost(report: dict) -> bool:
    """Scans were mapped, --map-out was given, and the map could not be written there."""
    slam = report.get("slam") or {}
    return slam.get("map_saved") is False and slam.get("scans", 0) > 0


def localization_fields(args, trajectory: list, estimate: list, particles: list) -> dict:
    """The report's localization figures, the kidnapping, every /pose and the particles."""
    from amr_evaluation.localization_episode import metrics_from_rows
    kidnap = list(args.kidnap) if getattr(args, "kidnap", None) else None
    return {"localization": metrics_from_rows(trajectory, estimate, kidnap), "kidnap": kidnap,
            "estimate": estimate, "particles_snapshot": particles}


def navigation_fields(goal, summary: dict, plan, estimate: list,
                       planning_error: str | None) -> dict:
    """The report's navigation figures.

    Goal, time localized, goal reached and stopped times, planned path, final error, and why the
    planner found no path (None if it found one or has not planned).
    """
    localized = next((row[0] for row in estimate if row[4] > 0.5), None)
    return {
        "goal": [float(goal[0]), float(goal[1])], "localized_time_s": localized,
        "goal_reached_time_s": summary["goal_reached_time_s"],
        "stopped_time_s": summary["stopped_time_s"],
        "final_position_error_m": summary["final_position_error_m"],
        "path_length_m": polyline_length(plan.points) if plan is not None else None,
        "path": plan.points.tolist() if plan is not None else [],
        "planning_error": planning_error,
    }


def world_label(report: dict) -> str:
    """'lab02', or 'lab02_box on map lab02' when the filter and the planner had their own map."""
    if report["map_source"] == report["world_source"]:
        return report["world"]
    return f"{report['world']} on map {map_label(report['map'], report['map_source'])}"


def localization_line(report: dict) -> str:
    m = report.get("localization")
    if m is None:
        return ""
    if m["time_to_localized_s"] is None:
        return f"; not localized, false localizations {m['false_localizations']}"
    text = (f"; localized after {m['time_to_localized_s']:.1f} s "
            f"({m['distance_to_localized_m']:.2f} m), false localizations "
            f"{m['false_localizations']}")
    if m["tracking_error_mean_m"] is not None:
        text += (f", error mean {100 * m['tracking_error_mean_m']:.1f} cm, p95 "
                 f"{100 * m['tracking_error_p95_m']:.1f} cm, max "
                 f"{100 * m['tracking_error_max_m']:.1f} cm, heading p95 "
                 f"{m['heading_error_p95_deg']:.1f} deg")
    if m["relocalization_times_s"]:
        text += ", relocalized at " + ", ".join(f"{t:.1f}" for t in m["relocalization_times_s"])
    if m["loss_reported_after_s"] is not None:
        text += f", loss reported {m['loss_reported_after_s']:.2f} s after the kidnapping"
    return text


def navigation_line(report: dict) -> str:
    def when(key: str) -> str:
        return "never" if report[key] is None else f"{report[key]:.1f} s"
    path = "no path" if report["path_length_m"] is None else \
        f"path {report['path_length_m']:.2f} m"
    factor = report["real_time_factor"]
    return (f"run_sim: {world_label(report)} / {report['start']} -> goal "
            f"({report['goal'][0]:g}, {report['goal'][1]:g}) / {report['profile']} "
            f"({report['mode']}): localized {when('localized_time_s')}, goal reached "
            f"{when('goal_reached_time_s')}, stopped {when('stopped_time_s')}, {path}, "
            f"final error {report['final_position_error_m'] * 100:.1f} cm, collisions "
            f"{collisions_text(report['collisions'], report.get('collisions_with_movers'))}, "
            f"min clearance {report['min_clearance_m'] * 100:.1f} "
            f"cm; {report['sim_time_s']:.1f} s simulated in {report['wall_time_s']:.1f} s "
            f"({f'{factor}x' if factor else 'n/a'} real time)" + failed_line(report))


def run_line(report: dict) -> str:
    """The terminal's line of a run without a goal: where, how long, how fast, how safe."""
    laps = report["laps"]
    factor = report["real_time_factor"]
    return (f"run_sim: {world_label(report)} / {report['start']} / {report['profile']} "
            f"({report['mode']}): {report['sim_time_s']:.1f} s simulated in "
            f"{report['wall_time_s']:.1f} s ({f'{factor}x' if factor else 'n/a'} real time), "
            f"{report['steps']} steps, collisions "
            f"{collisions_text(report['collisions'], report.get('collisions_with_movers'))}, "
            f"min clearance "
            f"{report['min_clearance_m'] * 100:.1f} cm, distance {report['distance_m']:.1f} m,"
            + (" explored n/a" if report["explored_fraction"] is None else
               f" explored {report['explored_fraction'] * 100:.0f}%")
            + (f", laps {laps}" if laps else "") + localization_line(report)
            + slam_line(report) + failed_line(report))


def failed_line(report: dict) -> str:
    """'; FAILED: <why>' when a link failed (the run's exit code is 3), else ''."""
    return f"; FAILED: {report['link_failure']}" if report.get("link_failure") else ""
