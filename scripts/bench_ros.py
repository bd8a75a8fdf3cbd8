#!/usr/bin/env python3
"""The lockstep loop over ROS vs a bare rclpy ping-pong of the same messages, in one process.

Graphs, each alive for the whole run in its own context and ROS domain (so they never see
each other's topics), each driven by its own EventsExecutor:
- pingpong: two bare nodes; TwistStamped one way, Odometry + LaserScan (240 rays, best effort)
  back: the messages and QoS of one lockstep step, with nothing else done;
- lockstep: amr_simulator (lockstep, ideal profile, lab02) + wall_follower with the project's
  WallFollower, configured as run_sim.py configures them;
- lockstep_zero_cost_controller: the same with a controller that computes nothing (the ROS
  plumbing's share);
- lockstep_use_sim_time: the first with use_sim_time:=true on the follower (it then also takes
  /clock every step).
The graphs take turns in short segments (round robin), so that the machine's speed, which
drifts by tens of percent within a minute on a shared host, affects all of them alike; each
figure is the total of its segments after a warm-up, and the spread of the per-cycle ratios
is reported too. Usage: .venv/bin/python scripts/bench_ros.py [--cycles N] [--segment STEPS]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import launch_common  # noqa: E402,F401  (puts the repo on sys.path)
from amr_common.ros.ros_env import claim_free_domain_id, isolate_local_graph  # noqa: E402

DT = 0.05


class ZeroCostController:
    """Drives in a slow circle at no compute cost: isolates the ROS loop's own overhead."""

    def __init__(self, dt: float) -> None:
        self.dt = dt

    def compute_commands(self, z_scan, z_v: float, z_w: float) -> tuple[float, float]:
        return 0.05, 0.3


class _Graph:
    """A context on its own domain with an executor; `progress()` counts completed loops."""

    def __init__(self) -> None:
        import rclpy

        from amr_common.ros.node_runner import make_executor
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=claim_free_domain_id())
        self.executor = make_executor(self.context)
        self.nodes: list = []

    def progress(self) -> int:
        raise NotImplementedError

    def wait_for(self, condition, what: str, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            self.executor.spin_once(timeout_sec=0.05)
            if time.monotonic() > deadline:
                raise RuntimeError(f"{what}: discovery failed")
        self.executor.spin_once(timeout_sec=0.2)

    def run(self, loops: int, timeout: float = 60.0) -> tuple[int, float]:
        """Spin until `loops` more loops completed; (loops done, seconds)."""
        first = self.progress()
        start = time.perf_counter()
        limit = start + timeout
        while self.progress() < first + loops and time.perf_counter() < limit:
            self.executor.spin_once(timeout_sec=1.0)
        return self.progress() - first, time.perf_counter() - start

    def close(self) -> None:
        import rclpy
        for node in self.nodes:
            self.executor.remove_node(node)
            node.destroy_node()
        self.executor.shutdown()
        rclpy.shutdown(context=self.context)


class PingPong(_Graph):
    def __init__(self) -> None:
        super().__init__()
        import rclpy
        from geometry_msgs.msg import TwistStamped
        from nav_msgs.msg import Odometry
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import LaserScan
        best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        ping, pong = (rclpy.create_node(n, context=self.context) for n in ("ping", "pong"))
        self.nodes = [ping, pong]
        scan = LaserScan()
        scan.ranges = [1.0] * 240
        odom = Odometry()
        cmd_pub = ping.create_publisher(TwistStamped, "/bench_cmd", 10)
        odom_pub = pong.create_publisher(Odometry, "/bench_odom", 10)
        scan_pub = pong.create_publisher(LaserScan, "/bench_scan", best_effort)
        self.counter = {"odom": 0, "scan": 0, "trips": 0}

        def on_cmd(msg):
            odom_pub.publish(odom)
            scan_pub.publish(scan)

        def on_reply(kind):
            def callback(msg):
                self.counter[kind] += 1
                if self.counter["odom"] == self.counter["scan"]:  # both in: next round trip
                    self.counter["trips"] += 1
                    cmd_pub.publish(TwistStamped())
            return callback

        pong.create_subscription(TwistStamped, "/bench_cmd", on_cmd, 10)
        ping.create_subscription(Odometry, "/bench_odom", on_reply("odom"), 10)
        ping.create_subscription(LaserScan, "/bench_scan", on_reply("scan"), best_effort)
        for node in self.nodes:
            self.executor.add_node(node)
        self.wait_for(lambda: pong.count_publishers("/bench_cmd") >= 1
                      and ping.count_publishers("/bench_scan") >= 1, "ping-pong")
        cmd_pub.publish(TwistStamped())

    def progress(self) -> int:
        return self.counter["trips"]


class Lockstep(_Graph):
    """amr_simulator (lockstep) + wall_follower, as run_sim.py runs them.

    `profile`: the simulator's sensor profile; `slam`: also the slam node (its parameter
    overrides), the map built in the world's frame as run_sim.py --slam builds it.
    """

    def __init__(self, controller: str, use_sim_time: bool, name_suffix: str = "",
                 profile: str = "ideal", slam: dict | None = None) -> None:
        super().__init__()
        from rclpy.parameter import Parameter

        from amr_control.wall_follower_node import WallFollowerNode
        from amr_sim.profiles import get_profile
        from amr_sim.simulator_node import SimulatorNode
        # Distinct node names: the graphs share the process's loggers.
        simulator = SimulatorNode("amr_simulator" + name_suffix, context=self.context,
                                  parameter_overrides=[
            Parameter("world", value="lab02"), Parameter("start", value="outer"),
            Parameter("dt", value=DT), Parameter("profile", value=profile),
            Parameter("publish_map", value=slam is None)])
        lidar = get_profile(profile).lidar_offset_x
        follower = WallFollowerNode("wall_follower" + name_suffix, context=self.context,
                                    parameter_overrides=[
            Parameter("use_sim_time", value=use_sim_time),
            Parameter("controller", value=controller), Parameter("dt", value=DT)] + ([
                Parameter("lidar_offset_x_m", value=lidar)] if lidar else []))
        self.nodes = [follower, simulator]
        if slam is not None:
            from amr_mapping.slam_node import SlamNode
            self.slam = SlamNode("slam" + name_suffix, context=self.context, parameter_overrides=[
                Parameter(name, value=value) for name, value in {
                    "lidar_offset_x_m": lidar, "map_start_pose": [1.0, -1.0, 1.5707963267948966],
                    **slam}.items()])
            self.nodes.append(self.slam)
        for node in self.nodes:
            self.executor.add_node(node)
        follower.trigger_configure()
        simulator.trigger_configure()
        follower.trigger_activate()
        if slam is not None:
            self.slam.trigger_configure()
            self.slam.trigger_activate()
        self.wait_for(lambda: simulator.count_subscribers("/scan") >= 1
                      and follower.count_publishers("/scan") >= 1
                      and simulator.count_publishers("/cmd_vel") >= 1, "lockstep")
        simulator.trigger_activate()      # publishes the first measurement: the loop starts
        self.simulator = simulator.simulator

    def progress(self) -> int:
        return self.simulator.steps


GRAPHS = {
    "pingpong": lambda: PingPong(),
    "lockstep": lambda: Lockstep("amr_control.wall_follower:WallFollower", False),
    "lockstep_zero_cost_controller": lambda: Lockstep("bench_ros:ZeroCostController", False,
                                                      "_zero_cost"),
    "lockstep_use_sim_time": lambda: Lockstep("amr_control.wall_follower:WallFollower", True,
                                              "_sim_time"),
}


CYCLES, SEGMENT = 12, 500   # the default run: 12 turns of 500 loops per graph


def round_robin(makers: dict, cycles: int, segment: int, warm_up: int
                ) -> tuple[dict[str, float], dict[str, list[float]]]:
    """Build the graphs, let them take turns; (loops/s in total, loops/s per cycle) per graph."""
    graphs = {}
    try:
        for name, make in makers.items():
            graphs[name] = make()
        for graph in graphs.values():
            graph.run(warm_up)            # first-use costs (kernel loading, caches) left out
        totals = {name: [0, 0.0] for name in graphs}
        per_cycle: dict[str, list[float]] = {name: [] for name in graphs}
        for _ in range(cycles):
            for name, graph in graphs.items():
                loops, seconds = graph.run(segment)
                totals[name][0] += loops
                totals[name][1] += seconds
                per_cycle[name].append(loops / seconds)
    finally:
        for graph in graphs.values():
            graph.close()
    return {name: loops / seconds for name, (loops, seconds) in totals.items()}, per_cycle


def measure(cycles: int = CYCLES, segment: int = SEGMENT, warm_up: int = 300) -> dict:
    """Loops/s of every graph, and each lockstep graph's ratio to the ping-pong.

    Over `cycles` round-robin segments of `segment` loops each; ratios in total and min/max
    over the cycles.
    """
    rates, per_cycle = round_robin(GRAPHS, cycles, segment, warm_up)
    result: dict = {"loops_per_s": rates, "segments": cycles, "segment_loops": segment}
    for name in rates:
        if name == "pingpong":
            continue
        ratios = [a / b for a, b in zip(per_cycle[name], per_cycle["pingpong"])]
        result[f"{name}_vs_pingpong"] = rates[name] / rates["pingpong"]
        result[f"{name}_vs_pingpong_range"] = (min(ratios), max(ratios))
    result["lockstep_real_time_factor"] = rates["lockstep"] * DT
    return result


def report(r: dict) -> str:
    rates = r["loops_per_s"]
    lines = [f"ROS lockstep loop, one process ({r['segments']} round-robin segments of "
             f"{r['segment_loops']} loops per graph): bare rclpy ping-pong of the same messages "
             f"{rates['pingpong']:.0f} round trips/s"]
    labels = {"lockstep": "simulator + wall follower as run_sim.py",
              "lockstep_zero_cost_controller": "with a zero-cost controller",
              "lockstep_use_sim_time": "with use_sim_time:=true on the follower"}
    for name, label in labels.items():
        low, high = r[f"{name}_vs_pingpong_range"]
        lines.append(f"  {label}: {rates[name]:.0f} steps/s, ratio {r[f'{name}_vs_pingpong']:.2f}"
                     f" (per segment {low:.2f}-{high:.2f})")
    lines.append(f"  target: ratio >= 0.5 (within 2x of the ping-pong); run_sim.py at "
                 f"{r['lockstep_real_time_factor']:.0f}x real time")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cycles", type=int, default=CYCLES)
    parser.add_argument("--segment", type=int, default=SEGMENT, help="loops per segment")
    args = parser.parse_args(argv)
    isolate_local_graph()
    result = measure(args.cycles, args.segment)
    print(report(result))
    return result


if __name__ == "__main__":
    from script_endings import guard_output  # a closed output loses nothing
    guard_output()
    main()
