#!/usr/bin/env python3
"""Benchmarks of the SLAM Mapper, each against the plain numpy reference of the same matcher.

The reference is the Mapper with `correlative_search: exhaustive`: every candidate pose of the
correlative search scored with numpy (the same optimum as the compiled branch and bound, which
tests/test_mapping_kernels.py checks); everything else is the same code, fed the same scans.
1. One SLAM update (scan-to-map match + grid update when the scan is a keyframe), 360 rays,
   2 cm cells: median CPU ms over a 60 s lab02 session (target <= 5 ms).
2. A loop closure (candidate search, correlative match over the loop window, ambiguity check,
   iSAM2 optimization, local map redraw) in a session on twin_maze, the 2.4 m x 2.4 m maze
   (600 s, --quick 240 s: long enough to close loops; a session without any is an error):
   median and worst CPU ms of the closures made (target <= 100 ms).
3. A headless mapping episode (simulator + wall follower + Mapper), lab02, 300 s: simulated
   seconds per CPU second (target >= 50x real time); the reference over 60 s.
4. The ROS lockstep graph with SLAM, as run_sim.py --slam runs it (amr_simulator + wall_follower
   + slam, one process, lab02, 300 s): real-time factor (target >= 15x), against the same graph
   whose slam node searches exhaustively (the reference) and the graph without SLAM; the
   graphs take turns in segments (bench_ros.round_robin), so a drifting machine speed hits
   all alike. Also the slam node's worst callback (update + loop closure; /map).
All with the `turtlebot3_clean` profile (LDS-01 at 5 Hz, no reality gap) and the episode's
typical odometry drift (the ROS graph: the simulator's exact odometry).
5. The reality gap's cost (--deskew alone runs only this): one SLAM update on `turtlebot3`
   (its scans skewed and in range error; the Mapper de-skewing, calibrated and smoothing them,
   as the episodes set it) against the same session with `deskew` false and with
   `smooth_half_window` 0, lab02, seed 0, alternating; the de-skew itself (the motion
   history's step + 360 points moved) and the smoothing of 360 rays in microseconds.
CPU times are this thread's / process's (time.thread_time / process_time): on a shared machine
the wall clock also counts waiting for a CPU; wall-clock figures are printed alongside.

Usage: .venv/bin/python scripts/bench_mapping.py [--quick]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from amr_evaluation.mapping_episode import run_mapping_episode  # noqa: E402

TARGET_UPDATE_MS = 5.0
TARGET_LOOP_MS = 100.0
TARGET_REAL_TIME = 50.0
TARGET_ROS_REAL_TIME = 15.0
# The twin_maze sessions of the loop-closure figure (full, --quick): 19 closures in 240 s
# (none before about 100 s: the robot must travel loop_min_travel_m and come back).
LOOP_SESSION_S = (600.0, 240.0)
SEARCHES = ("branch_and_bound", "exhaustive")


def _session(world: str, duration: float, search: str, profile: str = "turtlebot3_clean",
             **params):
    """A mapping episode with one search; (result, Mapper statistics, wall seconds)."""
    started = time.perf_counter()
    result = run_mapping_episode(world, profile=profile, seed=0, duration=duration,
                                 mapper_params={"correlative_search": search, **params})
    return result, result.statistics, time.perf_counter() - started


def bench_deskew(duration: float, rounds: int = 2) -> dict:
    """SLAM update medians (CPU ms) on turtlebot3 with de-skew on and off; its own cost."""
    import numpy as np

    from amr_common.sensors.lidar_models import revolution_ages
    from amr_common.sensors.scan_deskew import MotionHistory, points_now
    from amr_mapping.scan_smoothing import smooth_ranges
    variants = {"on": {}, "off": {"deskew": False}, "no_smoothing": {"smooth_half_window": 0}}
    medians: dict = {name: [] for name in variants}
    for _ in range(rounds):  # alternating: a drifting machine speed hits all alike
        for name, params in variants.items():
            _, stats, _ = _session("lab02", duration, "branch_and_bound", "turtlebot3",
                                   **params)
            medians[name].append(stats["update_cpu_ms"]["median"])
    angles = np.radians(np.arange(360.0))
    points = np.column_stack([np.cos(angles), np.sin(angles)])
    history, repeats = MotionHistory(), 2000
    started = time.thread_time()
    for _ in range(repeats):
        history.add_motion((0.04, 0.001, 0.2), 0.2)
        points_now(points, revolution_ages(angles, 0.2), history)
    deskew_us = 1e6 * (time.thread_time() - started) / repeats
    rng = np.random.default_rng(0)
    ranges = 1.0 / np.maximum(np.abs(np.cos(angles)), np.abs(np.sin(angles)))  # a square room
    ranges = ranges * (1.0 + 0.0175 * rng.standard_normal(angles.size))
    sigma = 0.035 * ranges
    started = time.thread_time()
    for _ in range(repeats // 4):
        smooth_ranges(ranges, angles, np.radians(1.0), 7, sigma)
    on, off = float(np.median(medians["on"])), float(np.median(medians["off"]))
    return {"on_median": on, "off_median": off, "ratio": on / off, "deskew_us": deskew_us,
            "no_smoothing_median": float(np.median(medians["no_smoothing"])),
            "smoothing_us": 1e6 * (time.thread_time() - started) / (repeats // 4)}


def bench_update(duration: float) -> dict:
    figures = {}
    for search in SEARCHES:
        _, stats, _ = _session("lab02", duration, search)
        figures[search] = {"cpu_median": stats["update_cpu_ms"]["median"],
                           "cpu_p90": stats["update_cpu_ms"]["p90"],
                           "wall_median": stats["update_ms"]["median"],
                           "updates": stats["updates"], "keyframes": stats["keyframes"]}
    figures["ratio"] = figures["exhaustive"]["cpu_median"] / \
        figures["branch_and_bound"]["cpu_median"]
    return figures


def bench_loop_closure(duration: float) -> dict:
    """CPU ms of the loop closures made in a twin_maze session, with each search.

    RuntimeError if a session made none: there would be nothing to time (the wall follower
    comes back to a place after loop_min_travel_m only after about 100 s there).
    """
    figures = {}
    for search in SEARCHES:
        _, stats, _ = _session("twin_maze", duration, search)
        closed, cpu = stats["loop_closed_ms"], stats["loop_closed_cpu_ms"]
        if not closed["count"]:
            raise RuntimeError(f"loop closure: none in {duration:g} s on twin_maze with the "
                               f"{search} search ({stats['loop_attempts']} attempts): nothing "
                               "to time")
        figures[search] = {"closures": closed["count"], "attempts": stats["loop_attempts"],
                           "cpu_median": cpu["median"], "cpu_max": cpu["max"],
                           "wall_median": closed["median"], "wall_max": closed["max"],
                           "attempt_cpu_median": stats["loop_cpu_ms"]["median"]}
    figures["ratio"] = figures["exhaustive"]["cpu_median"] / \
        max(figures["branch_and_bound"]["cpu_median"], 1e-9)
    return figures


def bench_episode(duration: float, reference_duration: float) -> dict:
    figures = {}
    for search, seconds in (("branch_and_bound", duration), ("exhaustive", reference_duration)):
        result, _, _ = _session("lab02", seconds, search)
        figures[search] = {"duration_s": seconds, "cpu_real_time": result.cpu_real_time_factor,
                           "wall_real_time": result.real_time_factor,
                           "slam_share_of_wall": result.slam_wall_time_s / result.wall_time_s}
    figures["ratio"] = figures["branch_and_bound"]["cpu_real_time"] / \
        figures["exhaustive"]["cpu_real_time"]
    return figures


def bench_ros_graph(duration: float) -> dict:
    """Real-time factors of the lockstep graph without SLAM, with it, with the reference."""
    import bench_ros

    from amr_common.ros.ros_env import isolate_local_graph
    isolate_local_graph()
    wall_follower = "amr_control.wall_follower:WallFollower"
    graphs: dict = {}

    def make(name: str, slam):
        def build():
            graphs[name] = bench_ros.Lockstep(wall_follower, False, f"_{name}", "turtlebot3_clean",
                                              slam)
            return graphs[name]
        return build

    segment = 500
    cycles = max(1, round(duration / (segment * bench_ros.DT)))
    rates, per_cycle = bench_ros.round_robin({
        "no_slam": make("no_slam", None), "slam": make("slam", {}),
        "slam_exhaustive": make("slam_exhaustive", {"correlative_search": "exhaustive"})},
        cycles, segment, warm_up=100)
    figures = {name: {"real_time": rate * bench_ros.DT} for name, rate in rates.items()}
    for name in ("slam", "slam_exhaustive"):
        timings = graphs[name].slam.timings()
        figures[name].update(scans=timings["scan_ms"]["count"],
                             scan_ms_median=timings["scan_ms"]["median"],
                             scan_ms_max=timings["scan_ms"]["max"],
                             map_ms_max=timings["map_ms"]["max"])
    figures["ratio"] = rates["slam"] / rates["slam_exhaustive"]
    figures["share_of_no_slam"] = rates["slam"] / rates["no_slam"]
    figures["ratio_range"] = (min(a / b for a, b in zip(per_cycle["slam"],
                                                         per_cycle["slam_exhaustive"])),
                              max(a / b for a, b in zip(per_cycle["slam"],
                                                         per_cycle["slam_exhaustive"])))
    figures["duration_s"] = cycles * segment * bench_ros.DT
    return figures


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="shorter sessions")
    parser.add_argument("--deskew", action="store_true", help="only the de-skew's cost (5.)")
    args = parser.parse_args(argv)
    run_mapping_episode("lab02", duration=2.0)  # compile / load the kernels from the cache
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    d = bench_deskew(20.0 if args.quick else 60.0)
    print(f"SLAM update on turtlebot3 (skewed scans in range error), lab02: median "
          f"{d['on_median']:.2f} ms CPU de-skewing and smoothing vs {d['off_median']:.2f} ms "
          f"without de-skew ({d['ratio']:.2f}x), {d['no_smoothing_median']:.2f} ms without "
          f"smoothing (target <= {TARGET_UPDATE_MS:g} ms); the de-skew itself "
          f"{d['deskew_us']:.0f} us a scan, the smoothing {d['smoothing_us']:.0f} us")
    if args.deskew:
        return {"deskew": d, "load": load}
    u = bench_update(20.0 if args.quick else 60.0)
    b, r = u["branch_and_bound"], u["exhaustive"]
    print(f"SLAM update (match + grid), 360 rays, 2 cm, lab02: median {b['cpu_median']:.2f} ms "
          f"CPU (p90 {b['cpu_p90']:.2f}, wall median {b['wall_median']:.2f}; {b['updates']} "
          f"updates, {b['keyframes']} keyframes) vs numpy exhaustive search "
          f"{r['cpu_median']:.1f} ms: {u['ratio']:.0f}x (target <= {TARGET_UPDATE_MS:g} ms)")
    c = bench_loop_closure(LOOP_SESSION_S[1] if args.quick else LOOP_SESSION_S[0])
    b, r = c["branch_and_bound"], c["exhaustive"]
    print(f"loop closure (search + optimization), twin_maze 2.4 m: median {b['cpu_median']:.1f} "
          f"ms CPU, worst {b['cpu_max']:.1f} (wall {b['wall_median']:.1f} / {b['wall_max']:.1f}"
          f"; {b['closures']} closures in {b['attempts']} attempts, an attempt "
          f"{b['attempt_cpu_median']:.1f} ms) vs numpy exhaustive search {r['cpu_median']:.0f} "
          f"ms: {c['ratio']:.0f}x (target <= {TARGET_LOOP_MS:g} ms)")
    e = bench_episode(*((60.0, 20.0) if args.quick else (300.0, 60.0)))
    b, r = e["branch_and_bound"], e["exhaustive"]
    print(f"mapping episode lab02 {b['duration_s']:.0f} s: {b['cpu_real_time']:.0f}x real time "
          f"per CPU second (wall {b['wall_real_time']:.0f}x; SLAM "
          f"{100 * b['slam_share_of_wall']:.0f} % of the loop) vs numpy exhaustive search "
          f"{r['cpu_real_time']:.1f}x over {r['duration_s']:.0f} s: {e['ratio']:.0f}x "
          f"(target >= {TARGET_REAL_TIME:g}x)")
    g = bench_ros_graph(75.0 if args.quick else 300.0)
    b, r, n = g["slam"], g["slam_exhaustive"], g["no_slam"]
    print(f"ROS lockstep graph with SLAM (amr_simulator + wall_follower + slam, lab02 "
          f"{g['duration_s']:.0f} s): {b['real_time']:.1f}x real time ({b['scans']} scans; "
          f"slam callback median {b['scan_ms_median']:.1f} ms, worst {b['scan_ms_max']:.0f} "
          f"ms, /map worst {b['map_ms_max']:.0f} ms) vs the slam node with the numpy "
          f"exhaustive search {r['real_time']:.1f}x: {g['ratio']:.1f}x (per segment "
          f"{g['ratio_range'][0]:.1f}-{g['ratio_range'][1]:.1f}); without SLAM "
          f"{n['real_time']:.1f}x ({100 * g['share_of_no_slam']:.0f} % of it) "
          f"(target >= {TARGET_ROS_REAL_TIME:g}x)")
    print(f"load average {load:.1f} on {os.cpu_count()} cores")
    return {"update": u, "loop_closure": c, "episode": e, "ros_graph": g, "deskew": d,
            "load": load}


if __name__ == "__main__":
    from script_endings import guard_output  # a closed output loses nothing
    guard_output()
    main()
