#!/usr/bin/env python3
"""Benchmarks of the particle filter, each against a reference measured in the same run.

1. Measurement update (the beam model on the expected-range table, 60 beams per particle):
   particle updates per second on one core, numba kernel vs the plain numpy version of the same
   model (target >= 5 M/s), for particles spread over the whole map (a global search: every
   particle reads its own 720-byte table row, so memory bound) and gathered around one pose
   (tracking: the rows stay in cache); the median of several rounds, with best and worst.
2. One full filter update (move, weigh, resample, cluster, scan check) at 2,000 particles x 60
   beams (target <= 1 ms), vs the measurement model alone.
3. Headless localization episode (simulator + wall follower + filter) in simulated seconds per
   CPU second (target >= 200x real time), vs the same episode without the filter.
4. (--memory) Big maps: peak memory (RSS) of a headless global-localization episode on generated
   office floors (tools/make_building_world.py), each in a fresh process: 40 x 40 m
   (tests/worlds/building_40m.yaml) and 20 x 20 m with the default max_memory_mb, vs 20 x 20 m
   with the 2 cm x 360 table every map had before (target: 40 x 40 m within 1 GB).
5. (--callbacks) Big maps: the longest ParticleFilter.correct() call (CPU time of the calling
   thread: what blocks a node's callback) of global-localization episodes on the 40 x 40 m
   floor, vs one exhaustive pose search in one go, what such a call took before the searches
   were sliced (target: every call within 0.2 s).
Rates are per CPU second of this process (time.process_time: on a shared machine the
wall-clock figure also counts waiting for a CPU); wall-clock figures are printed alongside.

Usage: .venv/bin/python scripts/bench_localization.py [--quick] [--measurement-only] [--memory]
       [--callbacks]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from amr_common.robot import LIDAR_OFFSET_X  # noqa: E402
from amr_common.world.world import World  # noqa: E402
from amr_localization import beam_model  # noqa: E402
from amr_localization.particle_filter import ParticleFilter  # noqa: E402
from amr_sim.lidar import Lidar  # noqa: E402

TARGET_UPDATES_PER_S = 5e6
TARGET_UPDATE_MS = 1.0
TARGET_REAL_TIME = 200.0
TARGET_PEAK_MB = 1000.0
TARGET_CALL_S = 0.2
BUILDING_40M = Path(__file__).resolve().parents[1] / "tests" / "worlds" / "building_40m.yaml"
REPO = Path(__file__).resolve().parents[1]
# One episode in a fresh process: its peak RSS is the episode's (imports included).
_EPISODE = """
import json, resource, sys, time
sys.path.insert(0, {repo!r})
from amr_common.world.world import World
from amr_evaluation.localization_episode import run_localization_episode
from amr_localization.particle_filter import ParticleFilter
world = World.load({world!r})
cpu = time.process_time()
table = ParticleFilter(world, **{params!r}).table
build = time.process_time() - cpu
result = run_localization_episode(world, {start!r}, profile="turtlebot3_clean", seed=0,
                                  duration={duration!r}, record=False, filter_params={params!r})
print(json.dumps({{"peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "table": f"{{100 * table.resolution:g}} cm x {{table.angles}}",
                  "table_mb": table.nbytes / 1e6, "build_cpu_s": build,
                  "episode_cpu_s": time.process_time() - cpu - build,
                  "time_to_localized_s": result.time_to_localized_s,
                  "false_localizations": result.false_localizations,
                  "tracking_error_mean_m": result.tracking_error_mean_m}}))
"""



def scan_from_robot(lidar: Lidar, x: float, y: float, theta: float) -> np.ndarray:
    """The Burger's LiDAR scan (LIDAR_OFFSET_X along the heading) at robot pose x, y, theta."""
    return lidar.scan(x + LIDAR_OFFSET_X * math.cos(theta),
                      y + LIDAR_OFFSET_X * math.sin(theta), theta)

def _timed(function, repeats: int) -> tuple[float, float]:
    """Best (CPU seconds, wall seconds) per call over `repeats` calls."""
    best_cpu = best_wall = math.inf
    for _ in range(repeats):
        cpu, wall = time.process_time(), time.perf_counter()
        function()
        best_cpu = min(best_cpu, time.process_time() - cpu)
        best_wall = min(best_wall, time.perf_counter() - wall)
    return best_cpu, best_wall


def bench_measurement(particles: int, repeats: int, rounds: int) -> dict:
    """Measurement updates per CPU second, numba vs numpy; best and median over `rounds`.

    Each round times every case in turn (best of `repeats` calls), so a burst of load on the
    shared machine hits all of them alike; the spread over rounds shows how noisy it was.
    """
    world = World.load("lab02")
    pf = ParticleFilter(world, max_particles=particles, lidar_offset_x_m=LIDAR_OFFSET_X)
    pf.set_scan_geometry(0.0, 2 * math.pi / 360, 360, 0.12, 3.5)
    lidar = Lidar(world.segments, 360, 0.0, 2 * math.pi / 360, 0.12, 3.5, 0.0)
    ranges = scan_from_robot(lidar, 1.0, -1.0, math.pi / 2)
    readings = pf.beams.split(pf.beams.readings_mm(ranges))
    spread = pf.particles
    rng = np.random.default_rng(0)
    gathered = np.column_stack([rng.normal(1.0, 0.02, particles),
                                rng.normal(-1.0, 0.02, particles),
                                rng.normal(math.pi / 2, 0.05, particles)])
    small = min(particles, 20000)

    def run(kernel, poses):
        return lambda: pf.model.scores(poses, readings, pf.beams.limits_mm, kernel)

    cases = {"numba": (run(beam_model.log_likelihoods_kernel, spread), particles),
             "numba_tracking": (run(beam_model.log_likelihoods_kernel, gathered), particles),
             "numpy": (run(beam_model.log_likelihoods_numpy, spread[:small]), small)}
    run(beam_model.log_likelihoods_kernel, spread[:16])()  # compile / load from cache
    rates: dict[str, list[float]] = {name: [] for name in cases}
    walls: list[float] = []
    for _ in range(rounds):
        for name, (function, count) in cases.items():
            cpu, wall = _timed(function, repeats if name != "numpy" else max(repeats // 4, 2))
            rates[name].append(count / cpu)
            if name == "numba":
                walls.append(count / wall)
    best = {name: max(values) for name, values in rates.items()}
    median = {name: float(np.median(values)) for name, values in rates.items()}
    figures = {"particles": particles, "beams": pf.beams.count, "rounds": rounds,
               "numba_updates_per_s": median["numba"],
               "numba_updates_per_s_best": best["numba"],
               "numba_updates_per_s_worst": min(rates["numba"]),
               "numba_updates_per_s_wall": float(np.median(walls)),
               "numba_tracking_updates_per_s": median["numba_tracking"],
               "numpy_updates_per_s": median["numpy"],
               "numba_over_numpy": median["numba"] / median["numpy"]}
    figures["beam_evaluations_per_s"] = figures["numba_updates_per_s"] * figures["beams"]
    return figures


def bench_full_update(particles: int, updates: int, lidar_model: str = "exact") -> dict:
    """Tracking a robot driving an arc in lab02's inner maze, a scan at every pose.

    lidar_model: 'exact' (the clean profiles') or 'auto' (the default: LDS-01 on this scan,
    per-ray tolerances and sigmas, de-skewed).
    """
    world = World.load("lab02")
    pose = (0.6, -0.6, math.pi)
    pf = ParticleFilter(world, initial_pose=list(pose), tracking_particles=particles,
                        min_particles=particles, max_particles=particles,
                        initial_pose_sigma=[0.02, 0.02, 0.05], lidar_offset_x_m=LIDAR_OFFSET_X,
                        lidar_model=lidar_model)
    pf.set_scan_geometry(0.0, 2 * math.pi / 360, 360, 0.12, 3.5)
    lidar = Lidar(world.segments, 360, 0.0, 2 * math.pi / 360, 0.12, 3.5, 0.0)
    v, w, dt = 0.1, 0.1, 0.05
    x, y, theta = pose
    times_cpu, times_wall = [], []
    for k in range(updates + 20):
        mid = theta + 0.5 * w * dt
        x, y, theta = x + v * dt * math.cos(mid), y + v * dt * math.sin(mid), theta + w * dt
        if k % 40 == 39:
            w = -w  # wiggle: stay within the inner maze's corridor
        ranges = scan_from_robot(lidar, x, y, theta)
        cpu, wall = time.process_time(), time.perf_counter()
        pf.predict(v, w, dt)
        pf.correct(ranges, force=True)
        pf._resample()  # a full update resamples every time here (the worst case)
        if k >= 20:  # after the first localization and its one exhaustive search
            times_cpu.append(time.process_time() - cpu)
            times_wall.append(time.perf_counter() - wall)
    assert pf.particle_count == particles
    return {"particles": particles, "beams": pf.beams.count, "localized": pf.localized,
            "sensor": pf.sensor.name,
            "update_ms_median": 1e3 * float(np.median(times_cpu)),
            "update_ms_p90": 1e3 * float(np.percentile(times_cpu, 90)),
            "update_ms_median_wall": 1e3 * float(np.median(times_wall))}


def bench_episode(duration: float) -> dict:
    from amr_evaluation.episode import run_episode
    from amr_evaluation.localization_episode import run_localization_episode
    world = World.load("twin_maze")
    run_localization_episode(world, "south_west", duration=2.0, record=False)  # warm caches
    figures = {}
    for profile in ("ideal", "turtlebot3_clean"):
        cpu = time.process_time()
        result = run_localization_episode(world, "south_west", profile=profile, seed=0,
                                          duration=duration, record=False)
        cpu = time.process_time() - cpu
        cpu_plain = time.process_time()
        run_episode(world, "south_west", profile=profile, duration=duration,
                    record_trajectory=False)
        cpu_plain = time.process_time() - cpu_plain
        figures[profile] = {"real_time": duration / cpu, "real_time_wall":
                            result.real_time_factor, "without_filter_real_time":
                            duration / cpu_plain, "filter_share_of_wall":
                            result.filter_wall_time_s / result.wall_time_s,
                            "time_to_localized_s": result.time_to_localized_s}
    return figures


def bench_memory(duration: float) -> dict:
    """Peak RSS of a global-localization episode on office floors, one fresh process each."""
    sys.path.insert(0, str(REPO / "tools"))
    from make_building_world import building, to_yaml
    figures = {}
    with tempfile.TemporaryDirectory() as folder:
        floor_20 = Path(folder) / "building_20m.yaml"
        floor_20.write_text(to_yaml(building(20, 18)))
        cases = {"40 x 40 m": (REPO / "tests" / "worlds" / "building_40m.yaml", {}),
                 "20 x 20 m": (floor_20, {}),
                 "20 x 20 m, the old 2 cm x 360 table": (floor_20, {"max_memory_mb": 5000.0})}
        for name, (world, params) in cases.items():
            code = _EPISODE.format(repo=str(REPO), world=str(world), params=params,
                                   start="corridor_west", duration=duration)
            run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                 check=True)
            figures[name] = json.loads(run.stdout.strip().splitlines()[-1])
    return figures


def bench_callbacks(duration: float, seeds: int) -> dict:
    """The longest correct() call per episode on the 40 x 40 m floor, vs a search in one go."""
    from amr_evaluation.localization_episode import run_localization_episode
    from amr_sim.profiles import get_profile
    world = World.load(BUILDING_40M)
    profile = get_profile("turtlebot3_clean")
    pf = ParticleFilter(world, lidar_offset_x_m=profile.lidar_offset_x)  # the table, cached
    pf.set_scan_geometry(profile.angle_min, profile.angle_increment, profile.scan_rays,
                         profile.range_min, profile.range_max)
    lidar = Lidar(world.segments, profile.scan_rays, profile.angle_min, profile.angle_increment,
                  profile.range_min, profile.range_max, math.nan)
    z_mm = pf.beams.readings_mm(scan_from_robot(lidar, *world.starts["corridor_west"]))
    pf.search.start(100, pf.beams, z_mm).advance()  # compiled
    cpu = time.thread_time()
    pf.search.start(7200, pf.beams, z_mm).finish()  # a global search's, in one go
    whole = time.thread_time() - cpu
    calls: list[float] = []
    correct = ParticleFilter.correct

    def timed(self, *args, **kwargs):
        started = time.thread_time()
        try:
            return correct(self, *args, **kwargs)
        finally:
            calls.append(time.thread_time() - started)

    episodes = []
    ParticleFilter.correct = timed
    try:
        for start in ("corridor_west", "corridor_north"):
            for seed in range(seeds):
                calls.clear()
                result = run_localization_episode(world, start, profile="turtlebot3_clean",
                                                  seed=seed, duration=duration, record=False)
                episodes.append({"start": start, "seed": seed, "longest_call_s": max(calls),
                                 "calls_over_target": sum(c > TARGET_CALL_S for c in calls),
                                 "time_to_localized_s": result.time_to_localized_s,
                                 "false_localizations": result.false_localizations})
    finally:
        ParticleFilter.correct = correct
    return {"search_in_one_go_s": whole, "positions": len(pf.search.cells),
            "episodes": episodes}


def _print_callbacks(c: dict, load: float) -> None:
    """The big map's longest filter calls, per episode and against the target."""
    longest = max(e["longest_call_s"] for e in c["episodes"])
    for e in c["episodes"]:
        localized = "never" if e["time_to_localized_s"] is None else \
            f"after {e['time_to_localized_s']:.1f} s"
        print(f"40 x 40 m, {e['start']} seed {e['seed']}: longest call "
              f"{e['longest_call_s']:.3f} s CPU ({e['calls_over_target']} over "
              f"{TARGET_CALL_S} s); localized {localized}, {e['false_localizations']} false")
    whole = c["search_in_one_go_s"]
    print(f"longest call {longest:.3f} s vs one search in one go ({c['positions']:,} "
          f"positions) {whole:.2f} s: {whole / longest:.0f}x shorter; target every call "
          f"within {TARGET_CALL_S} s: "
          f"{'met' if longest <= TARGET_CALL_S else 'MISSED'}; load average {load:.1f} on "
          f"{os.cpu_count()} cores")


def _print_memory(figures: dict, load: float) -> None:
    """The big maps' peak memory, against the old table's and the target."""
    reference = figures["20 x 20 m, the old 2 cm x 360 table"]["peak_mb"]
    for name, f in figures.items():
        localized = "never" if f["time_to_localized_s"] is None else \
            f"after {f['time_to_localized_s']:.1f} s"
        error = "" if f["tracking_error_mean_m"] is None else \
            f", tracking error mean {100 * f['tracking_error_mean_m']:.2f} cm"
        print(f"{name}: peak {f['peak_mb']:.0f} MB ({f['peak_mb'] / reference:.2f}x the old "
              f"table's on 20 x 20 m), table {f['table']} directions {f['table_mb']:.0f} MB "
              f"built in {f['build_cpu_s']:.1f} s CPU; localized {localized}, "
              f"{f['false_localizations']} false{error}; episode {f['episode_cpu_s']:.1f} s "
              f"CPU")
    print(f"target: 40 x 40 m within {TARGET_PEAK_MB:.0f} MB: "
          f"{'met' if figures['40 x 40 m']['peak_mb'] <= TARGET_PEAK_MB else 'MISSED'}; "
          f"load average {load:.1f} on {os.cpu_count()} cores")


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--measurement-only", action="store_true",
                        help="only the measurement update (1.)")
    parser.add_argument("--memory", action="store_true",
                        help="only the big maps' peak memory (4.)")
    parser.add_argument("--callbacks", action="store_true",
                        help="only the big map's longest filter call (5.)")
    args = parser.parse_args(argv)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    if args.callbacks:
        c = bench_callbacks(30.0 if args.quick else 60.0, 1 if args.quick else 4)
        _print_callbacks(c, load)
        return {"callbacks": c, "load": load}
    if args.memory:
        figures = bench_memory(30.0 if args.quick else 60.0)
        _print_memory(figures, load)
        return {"memory": figures, "load": load}
    m = bench_measurement(50000, 5 if args.quick else 10, 3 if args.quick else 7)
    print(f"measurement update: {m['numba_updates_per_s'] / 1e6:.1f} M particle updates/s at "
          f"{m['beams']} beams spread over the map (median of {m['rounds']} rounds, best "
          f"{m['numba_updates_per_s_best'] / 1e6:.1f}, worst "
          f"{m['numba_updates_per_s_worst'] / 1e6:.1f}; "
          f"{m['beam_evaluations_per_s'] / 1e6:.0f} M beams/s; wall "
          f"{m['numba_updates_per_s_wall'] / 1e6:.1f} M/s), "
          f"{m['numba_tracking_updates_per_s'] / 1e6:.1f} M/s gathered (tracking) vs numpy "
          f"{m['numpy_updates_per_s'] / 1e6:.2f} M/s: {m['numba_over_numpy']:.0f}x "
          f"(target >= {TARGET_UPDATES_PER_S / 1e6:.0f} M/s)")
    if args.measurement_only:
        print(f"load average {load:.1f} on {os.cpu_count()} cores")
        return {"measurement": m, "load": load}
    u = bench_full_update(2000, 50 if args.quick else 300)
    lds = bench_full_update(2000, 50 if args.quick else 300, "auto")
    print(f"full update (move, weigh, resample, cluster, scan check), {u['particles']} particles "
          f"x {u['beams']} beams: median {u['update_ms_median']:.2f} ms, p90 "
          f"{u['update_ms_p90']:.2f} ms (wall {u['update_ms_median_wall']:.2f} ms; target <= "
          f"{TARGET_UPDATE_MS} ms) with the exact sensor model (the clean profiles'); "
          f"{lds['sensor']} (the default: per-ray tolerances, de-skewed): median "
          f"{lds['update_ms_median']:.2f} ms, p90 {lds['update_ms_p90']:.2f} ms, "
          f"{lds['update_ms_median'] / u['update_ms_median']:.2f}x")
    e = bench_episode(30.0 if args.quick else 60.0)
    for profile, f in e.items():
        print(f"localization episode twin_maze/{profile}: {f['real_time']:.0f}x real time per "
              f"CPU second (wall {f['real_time_wall']:.0f}x), without the filter "
              f"{f['without_filter_real_time']:.0f}x; filter {100 * f['filter_share_of_wall']:.0f}"
              f"% of the loop (target >= {TARGET_REAL_TIME:.0f}x)")
    print(f"load average {load:.1f} on {os.cpu_count()} cores")
    return {"measurement": m, "full_update": u, "full_update_lds": lds, "episode": e,
            "load": load}


if __name__ == "__main__":
    from script_endings import guard_output  # a closed output loses nothing
    guard_output()
    main()
