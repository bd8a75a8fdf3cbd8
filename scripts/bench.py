#!/usr/bin/env python3
"""Speed figures, each with a ratio against a reference measured in the same run.

  simulator core     steps/s of physics + 360-ray scan + encoders (bench_sim.py), vs pymunk
                     per-ray queries and a numpy scan
  ROS lockstep loop  simulator node + wall follower node in one process, steps/s, vs a bare
                     rclpy ping-pong of the same messages (TwistStamped -> Odometry + LaserScan),
                     3 interleaved rounds, medians
  synchronizer       per-add cost (bench_sync.py), vs the reference's exhaustive search
  controller         WallFollower.compute_commands cost, vs the control period dt
  evaluate.py        episode throughput on 1 process vs all cores
Usage: .venv/bin/python scripts/bench.py [--quick] [--only NAME ...] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import launch_common  # noqa: E402,F401  (puts the repo on sys.path)

from amr_control.ros_env import isolate_local_graph  # noqa: E402


class ZeroCostController:
    """Drives in a slow circle at no compute cost: isolates the ROS loop's own overhead."""

    def __init__(self, dt: float) -> None:
        self.dt = dt

    def compute_commands(self, z_scan, z_v: float, z_w: float) -> tuple[float, float]:
        return 0.05, 0.3


def _rate(count: int, seconds: float) -> float:
    return count / seconds if seconds > 0 else float("nan")


def _timed_loop(executor, count, steps: int, warm_up: int = 200) -> float:
    """Spin until count() reaches warm_up + steps; the rate over the last `steps` (first-use
    costs such as loading compiled kernels stay out of the figure)."""
    limit = time.perf_counter() + 60
    while count() < warm_up and time.perf_counter() < limit:
        executor.spin_once(timeout_sec=1.0)
    start, first = time.perf_counter(), count()
    while count() < first + steps and time.perf_counter() < limit:
        executor.spin_once(timeout_sec=1.0)
    return _rate(count() - first, time.perf_counter() - start)


def bench_ros_loop(steps: int, rounds: int = 3) -> dict:
    """Lockstep simulator + wall follower vs a bare ping-pong, one process, same executor.

    Both are measured `rounds` times, interleaved (the DDS round trip alone varies by +-20 %
    between runs on this machine); the figures are the medians, each ratio the median of the
    per-round ratios.
    """
    # The real loop as run_sim.py runs it: simulator (lockstep, ideal) + wall follower
    # (simulation mode) with the project's WallFollower; then with a zero-cost controller (ROS
    # overhead only) and with use_sim_time:=true on the follower (it then also takes /clock).
    variants = (("", "amr_control.wall_follower:WallFollower", False),
                ("_zero_cost_controller", "bench:ZeroCostController", False),
                ("_use_sim_time", "amr_control.wall_follower:WallFollower", True))
    samples: dict[str, list[float]] = {}
    for _ in range(rounds):
        pingpong = _pingpong_rate(steps)
        samples.setdefault("pingpong_round_trips_per_s", []).append(pingpong)
        for label, controller, use_sim_time in variants:
            rate = _lockstep_rate(steps, controller, use_sim_time)
            samples.setdefault(f"lockstep{label}_steps_per_s", []).append(rate)
            samples.setdefault(f"lockstep{label}_vs_pingpong", []).append(rate / pingpong)
    results: dict = {name: statistics.median(values) for name, values in samples.items()}
    results["rounds"] = {name: [round(v, 2) for v in values] for name, values in samples.items()}
    results["lockstep_real_time_factor"] = results["lockstep_steps_per_s"] * 0.05
    return results


def _pingpong_rate(steps: int) -> float:
    """Round trips/s of a bare rclpy ping-pong of the lockstep loop's messages and QoS:
    TwistStamped one way, Odometry + LaserScan (240 rays, best effort) back."""
    import rclpy
    from geometry_msgs.msg import TwistStamped
    from nav_msgs.msg import Odometry
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import LaserScan
    from amr_control.node_runner import make_executor

    best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = make_executor(context)
    ping, pong = (rclpy.create_node(n, context=context) for n in ("ping", "pong"))
    scan = LaserScan()
    scan.ranges = [1.0] * 240
    odom = Odometry()
    cmd_pub = ping.create_publisher(TwistStamped, "/bench_cmd", 10)
    odom_pub = pong.create_publisher(Odometry, "/bench_odom", 10)
    scan_pub = pong.create_publisher(LaserScan, "/bench_scan", best_effort)
    counter = {"odom": 0, "scan": 0, "trips": 0}

    def on_cmd(msg):
        odom_pub.publish(odom)
        scan_pub.publish(scan)

    def on_reply(kind):
        def callback(msg):
            counter[kind] += 1
            if counter["odom"] == counter["scan"]:  # both replies in: next round trip
                counter["trips"] += 1
                cmd_pub.publish(TwistStamped())
        return callback

    pong.create_subscription(TwistStamped, "/bench_cmd", on_cmd, 10)
    ping.create_subscription(Odometry, "/bench_odom", on_reply("odom"), 10)
    ping.create_subscription(LaserScan, "/bench_scan", on_reply("scan"), best_effort)
    for node in (ping, pong):
        executor.add_node(node)
    deadline = time.monotonic() + 10
    while pong.count_publishers("/bench_cmd") < 1 or ping.count_publishers("/bench_scan") < 1:
        executor.spin_once(timeout_sec=0.05)
        if time.monotonic() > deadline:
            raise RuntimeError("ping-pong discovery failed")
    executor.spin_once(timeout_sec=0.2)
    cmd_pub.publish(TwistStamped())
    rate = _timed_loop(executor, lambda: counter["trips"], steps)
    executor.shutdown()
    rclpy.shutdown(context=context)
    return rate


def _lockstep_rate(steps: int, controller: str, use_sim_time: bool) -> float:
    import rclpy
    from rclpy.parameter import Parameter
    from amr_control.node_runner import make_executor
    from amr_control.wall_follower_node import WallFollowerNode
    from amr_sim.simulator_node import SimulatorNode
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = make_executor(context)
    simulator = SimulatorNode(context=context, parameter_overrides=[
        Parameter("world", value="lab02"), Parameter("start", value="outer")])
    follower = WallFollowerNode(context=context, parameter_overrides=[
        Parameter("use_sim_time", value=use_sim_time), Parameter("controller", value=controller)])
    for node in (follower, simulator):
        executor.add_node(node)
    follower.trigger_configure()
    simulator.trigger_configure()
    follower.trigger_activate()
    deadline = time.monotonic() + 10
    while simulator.count_subscribers("/scan") < 1 or follower.count_publishers("/scan") < 1 \
            or simulator.count_publishers("/cmd_vel") < 1:
        executor.spin_once(timeout_sec=0.05)
        if time.monotonic() > deadline:
            raise RuntimeError("lockstep discovery failed")
    executor.spin_once(timeout_sec=0.2)
    simulator.trigger_activate()
    sim = simulator.simulator
    rate = _timed_loop(executor, lambda: sim.steps, steps)
    for node in (follower, simulator):
        executor.remove_node(node)
        node.destroy_node()
    executor.shutdown()
    rclpy.shutdown(context=context)
    return rate


def bench_controller(calls: int) -> dict:
    import numpy as np
    from amr_control.wall_follower import WallFollower
    from amr_sim.simulator import Simulator
    sim = Simulator("lab02", start="outer", profile="turtlebot3", seed=0)
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
    from amr_sim.evaluation import EpisodeSpec, run_episodes
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
                        choices=["sim", "ros", "sync", "controller", "evaluate"])
    parser.add_argument("--json", default=None, help="also write the figures to this file")
    args = parser.parse_args(argv)
    isolate_local_graph()
    chosen = args.only or ["sim", "ros", "sync", "controller", "evaluate"]
    figures: dict[str, dict] = {}
    if "sim" in chosen:
        import bench_sim
        figures["sim"] = bench_sim.main()
    if "ros" in chosen:
        figures["ros"] = bench_ros_loop(1000 if args.quick else 3000, 1 if args.quick else 3)
        r = figures["ros"]
        print(f"ROS lockstep loop (simulator + wall follower nodes in one process, configured "
              f"as run_sim.py does): {r['lockstep_steps_per_s']:.0f} steps/s "
              f"({r['lockstep_real_time_factor']:.0f}x real time) vs a bare rclpy ping-pong of "
              f"the same messages "
              f"{r['pingpong_round_trips_per_s']:.0f} round trips/s: ratio "
              f"{r['lockstep_vs_pingpong']:.2f} (target >= 0.5). Also: zero-cost controller "
              f"{r['lockstep_zero_cost_controller_steps_per_s']:.0f} steps/s (ratio "
              f"{r['lockstep_zero_cost_controller_vs_pingpong']:.2f}); follower with "
              f"use_sim_time:=true {r['lockstep_use_sim_time_steps_per_s']:.0f} steps/s (ratio "
              f"{r['lockstep_use_sim_time_vs_pingpong']:.2f}, one more message per step)")
    if "sync" in chosen:
        import bench_sync
        figures["sync"] = bench_sync.main()
    if "controller" in chosen:
        figures["controller"] = bench_controller(2000 if args.quick else 20000)
        c = figures["controller"]
        print(f"controller: compute_commands {c['compute_commands_us']:.1f} us per call = "
              f"{c['compute_commands_share_of_dt'] * 100:.3f}% of dt")
    if "evaluate" in chosen:
        figures["evaluate"] = bench_evaluate(6 if args.quick else 12, 60.0)  # pool start-up included
        e = figures["evaluate"]
        print("evaluate.py: " + ", ".join(f"{k} {v:.2f}" for k, v in e.items()))
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
