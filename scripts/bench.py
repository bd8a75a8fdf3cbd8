#!/usr/bin/env python3
"""Speed figures, each with a ratio against a reference measured in the same run.

  simulator core     steps/s of physics + 360-ray scan + encoders (bench_sim.py), vs pymunk
                     per-ray queries and a numpy scan
  ROS lockstep loop  simulator node + wall follower node in one process, steps/s, vs a bare
                     rclpy ping-pong of the same messages (bench_ros.py: the graphs take turns
                     in short segments)
  synchronizer       per-add cost (bench_sync.py), vs the reference's exhaustive search
  controller         WallFollower.compute_commands cost, vs the control period dt
  evaluate.py        episode throughput on 1 process vs all cores
  planning           A* compiled vs the same search in plain Python; navigation episodes in
                     real-time factors (bench_planning.py)
  localization       particle filter: measurement update rate vs numpy, one full update at
                     2,000 particles, headless localization episode (bench_localization.py)
  maps               simulator step on Nav2 map worlds (converted, SLAM-like) vs the polygon
                     world, segment scan vs grid ray marching (bench_map_world.py)
  mapping            SLAM: one update, a loop closure, a headless mapping episode, each vs
                     the numpy exhaustive search of the same matcher (bench_mapping.py)
Usage: .venv/bin/python scripts/bench.py [--quick] [--only NAME ...] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import launch_common  # noqa: E402,F401  (puts the repo on sys.path)
from amr_common.ros.ros_env import isolate_local_graph  # noqa: E402


def _rate(count: int, seconds: float) -> float:
    return count / seconds if seconds > 0 else float("nan")


def bench_controller(calls: int) -> dict:
    import numpy as np

    from amr_control.wall_follower import WallFollower
    from amr_sim.simulator import Simulator
    sim = Simulator("lab02", start="outer", profile="turtlebot3_clean", seed=0)
    controller = WallFollower(sim.dt)
    p = sim.profile
    if hasattr(controller, "set_scan_geometry"):
        controller.set_scan_geometry(p.angle_min, p.angle_increment, p.range_min, p.range_max)
    scans = []
    z_scan, z_v, z_w = sim.measure()
    for _ in range(200):
        v, w = controller.compute_commands(z_scan, z_v, z_w)
        z_scan, z_v, z_w = sim.step(v, w)
        scans.append((np.array(z_scan), z_v, z_w))
    start = time.perf_counter()
    for k in range(calls):
        controller.compute_commands(*scans[k % len(scans)])
    per_call = (time.perf_counter() - start) / calls
    return {"compute_commands_us": per_call * 1e6,
            "compute_commands_share_of_dt": per_call / sim.dt}


def bench_evaluate(episodes: int, duration: float) -> dict:
    from amr_evaluation.evaluation import EpisodeSpec, run_episodes
    specs = [EpisodeSpec(world="lab02", start="outer", profile="ideal", seed=seed,
                         duration=duration) for seed in range(episodes)]
    results = {}
    cores = os.cpu_count() or 1
    for jobs in sorted({1, cores}):
        start = time.perf_counter()
        run_episodes(specs, jobs=jobs)
        results[f"episodes_per_s_{jobs}_jobs"] = _rate(episodes, time.perf_counter() - start)
    results["parallel_speedup"] = (results[f"episodes_per_s_{cores}_jobs"]
                                   / results["episodes_per_s_1_jobs"])
    return results


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    parser.add_argument("--only", nargs="*", default=None,
                        choices=["sim", "ros", "sync", "controller", "evaluate",
                                 "localization", "planning", "maps", "mapping"])
    parser.add_argument("--json", default=None, help="also write the figures to this file")
    args = parser.parse_args(argv)
    isolate_local_graph()
    chosen = args.only or ["sim", "ros", "sync", "controller", "evaluate", "localization",
                           "planning", "maps", "mapping"]
    figures: dict[str, dict] = {}
    if "sim" in chosen:
        import bench_sim
        figures["sim"] = bench_sim.main()
    if "ros" in chosen:
        import bench_ros
        figures["ros"] = bench_ros.measure(3, 300) if args.quick else bench_ros.measure()
        print(bench_ros.report(figures["ros"]))
    if "sync" in chosen:
        import bench_sync
        figures["sync"] = bench_sync.main()
    if "controller" in chosen:
        figures["controller"] = bench_controller(2000 if args.quick else 20000)
        c = figures["controller"]
        print(f"controller: compute_commands {c['compute_commands_us']:.1f} us per call = "
              f"{c['compute_commands_share_of_dt'] * 100:.3f}% of dt")
    if "evaluate" in chosen:
        # Pool start-up (interpreter + compiled kernels per worker, ~1 s) included: episodes of
        # 300 s (evaluate.py defaults to 600 s) so that it weighs as in real use.
        figures["evaluate"] = bench_evaluate(*((6, 120.0) if args.quick else (12, 300.0)))
        e = figures["evaluate"]
        print("evaluate.py: " + ", ".join(f"{k} {v:.2f}" for k, v in e.items()))
    if "localization" in chosen:
        import bench_localization
        figures["localization"] = bench_localization.main(["--quick"] if args.quick else [])
    if "planning" in chosen:
        import bench_planning
        figures["planning"] = bench_planning.measure(args.quick)
        print(bench_planning.report(figures["planning"]))
    if "maps" in chosen:
        import bench_map_world
        figures["maps"] = bench_map_world.main(["--steps", "1000", "--repeats", "2"]
                                               if args.quick else [])
    if "mapping" in chosen:
        import bench_mapping
        figures["mapping"] = bench_mapping.main(["--quick"] if args.quick else [])
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1, default=float))
    return 0


if __name__ == "__main__":
    from script_endings import run_script  # a closed output loses nothing
    sys.exit(run_script(main))
