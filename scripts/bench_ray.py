#!/usr/bin/env python3
"""evaluate.py on a local Ray instance against the local process pool, measured in the same run.

The same episodes (default 24 of 300 s: the baseline of docs/tune.md, lab02, maze_deadends and
room_obstacles from every start with the turtlebot3_clean profile, seeds 0-2) are run by whole
`evaluate.py` processes, as a user runs them, in four ways:
- `evaluate.py` (the local pool of --jobs processes),
- `evaluate.py --ray` (starts a local Ray instance of --jobs CPUs, stops it at the end),
- `evaluate.py --ray ADDRESS` joining a local Ray instance that is already running (as after
  `ray start --head`), twice in a row: the first run starts the episode workers (cold: the
  warm ones of earlier runs are ended first), the second finds them warm (left by the first
  for --ray-keep-workers, 60 s), as a user's next run within a minute does.
Each round runs the pool, --ray and the two joins in a rotating order, so the host's drifting
speed (a shared machine) hits all alike; ratios are taken per round, then the median. Also
measured: per-episode dispatch overhead (1-step episodes, in this process) and the size of one
episode's result with its trajectory and as a summary. Needs the cluster extra
(requirements-cluster.lock). Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from amr_evaluation.evaluation import EpisodeSpec, run_episodes, run_one  # noqa: E402
from amr_evaluation.executors import LocalPoolExecutor  # noqa: E402
from amr_evaluation.ray_executor import RayExecutor  # noqa: E402
from amr_evaluation.ray_workers import release_idle_warm_workers  # noqa: E402

WAYS = ("pool", "ray_started", "ray_joined_cold", "ray_joined_warm")
SLOTS = (("pool",), ("ray_started",), ("ray_joined_cold", "ray_joined_warm"))  # rotated


def evaluate_args(episodes: int, duration: float) -> list[str]:
    """evaluate.py options for `episodes` episodes (a multiple of 8).

    docs/tune.md's baseline (lab02, maze_deadends, room_obstacles: 8 starts; turtlebot3_clean)
    with seeds 0, 1, ...
    """
    if episodes < 8 or episodes % 8:
        raise SystemExit("--episodes must be a multiple of 8 (8 starts per seed)")
    return ["--worlds", "lab02,maze_deadends,room_obstacles", "--profiles", "turtlebot3_clean",
            "--seeds", f"0-{episodes // 8 - 1}", "--duration", f"{duration:g}", "--no-sheet"]


def run_evaluate(args: list[str], out: Path) -> float:
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, str(REPO / "scripts" / "evaluate.py"), *args,
                           "--out", str(out)], capture_output=True, text=True, timeout=900)
    elapsed = time.perf_counter() - start
    if proc.returncode not in (0, 1):
        raise SystemExit(f"evaluate.py failed ({proc.returncode}): {proc.stderr[-2000:]}")
    return elapsed


def measure_sweeps(episodes: int, duration: float, rounds: int, jobs: int) -> dict:
    args = evaluate_args(episodes, duration)
    running = RayExecutor(num_cpus=jobs)  # the instance `--ray ADDRESS` joins (`jobs` CPUs)
    running.connect()
    address = running._ray.get_runtime_context().gcs_address
    times: dict[str, list[float]] = {way: [] for way in WAYS}
    jobs_option = ["--jobs", str(jobs)]
    extra = {"pool": jobs_option, "ray_started": ["--ray", *jobs_option],
             "ray_joined_cold": ["--ray", address], "ray_joined_warm": ["--ray", address]}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            run_evaluate([*args, "--duration", "1"], Path(tmp) / "warm")  # kernels cached
            for r in range(rounds):
                for k in range(len(SLOTS)):
                    for way in SLOTS[(r + k) % len(SLOTS)]:
                        if way == "ray_joined_cold":  # no workers left by an earlier run
                            release_idle_warm_workers(running._ray)
                            time.sleep(1.0)  # their CPUs back
                        times[way].append(run_evaluate(args + extra[way],
                                                       Path(tmp) / f"{way}-{r}"))
                        print(f"  round {r + 1}: {way} {times[way][-1]:.2f} s", flush=True)
    finally:
        release_idle_warm_workers(running._ray)
        running.close()
    median = statistics.median
    figures: dict = {"episodes": episodes, "duration_s": duration, "jobs": jobs,
                     "rounds": rounds, "sweep_s": times}
    for way in WAYS:
        figures[f"{way}_episodes_per_s"] = episodes / median(times[way])
    for way in WAYS[1:]:
        figures[f"{way}_over_pool"] = median(
            t / p for t, p in zip(times[way], times["pool"]))
    return figures


def measure_overhead(jobs: int) -> dict:
    tiny = [EpisodeSpec("lab02", "outer", seed=k, duration=0.05) for k in range(200)]
    run_episodes(tiny[:jobs], executor=LocalPoolExecutor(jobs))
    begin = time.perf_counter()
    run_episodes(tiny, executor=LocalPoolExecutor(jobs), trajectory=False)
    pool = time.perf_counter() - begin
    with RayExecutor(num_cpus=jobs) as executor:
        run_episodes(tiny[:jobs * 2], executor=executor)  # workers up and imported
        begin = time.perf_counter()
        run_episodes(tiny, executor=executor, trajectory=False)
        ray = time.perf_counter() - begin
    return {"overhead_ms_per_episode_pool": 1000 * pool / len(tiny),
            "overhead_ms_per_episode_ray": 1000 * ray / len(tiny)}


def measure_result_size(duration: float) -> dict:
    spec = EpisodeSpec("lab02", "outer", duration=duration)
    full = run_one(spec)
    return {"result_bytes_with_trajectory": len(pickle.dumps(full)),
            "result_bytes_summary": len(pickle.dumps(run_one(spec, trajectory=False))),
            "episode_wall_s": full.wall_time_s}


def report(f: dict) -> str:
    med = statistics.median
    lines = [f"evaluate.py --no-sheet, {f['episodes']} episodes of {f['duration_s']:g} s on "
             f"{f['jobs']} CPUs, whole processes ({f['rounds']} rounds, medians):"]
    names = {"pool": "local pool", "ray_started": "--ray (starts Ray)",
             "ray_joined_cold": "--ray ADDRESS, 1st run", "ray_joined_warm": "--ray ADDRESS, next"}
    for way in WAYS:
        ratio = "" if way == "pool" else f"  ratio to the pool {f[way + '_over_pool']:.2f}"
        lines.append(f"  {names[way]:24s} {med(f['sweep_s'][way]):6.2f} s  "
                     f"{f[way + '_episodes_per_s']:.2f} episodes/s{ratio}")
    lines.append(f"  per-episode overhead (1-step episodes, warm workers): pool "
                 f"{f['overhead_ms_per_episode_pool']:.1f} ms, Ray "
                 f"{f['overhead_ms_per_episode_ray']:.1f} ms")
    lines.append(f"  one {f['duration_s']:g} s episode: {f['episode_wall_s']:.2f} s; its result "
                 f"{f['result_bytes_with_trajectory'] / 1024:.0f} KiB with the trajectory, "
                 f"{f['result_bytes_summary']} bytes as a summary")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=24, help="a multiple of 8 (default 24)")
    parser.add_argument("--duration", type=float, default=300.0)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--quick", action="store_true", help="8 episodes of 120 s, 1 round")
    parser.add_argument("--json", default=None, help="also write the figures to this file")
    args = parser.parse_args(argv)
    if args.quick:
        args.episodes, args.duration, args.rounds = 8, 120.0, 1
    from amr_evaluation.ray_executor import RaySetupError
    try:
        figures = measure_sweeps(args.episodes, args.duration, args.rounds, args.jobs)
    except RaySetupError as exc:
        print(f"bench_ray: {exc}", file=sys.stderr)
        return 2
    figures.update(measure_overhead(args.jobs))
    figures.update(measure_result_size(args.duration))
    print(report(figures))
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1))
    return 0


if __name__ == "__main__":
    from script_endings import run_script  # a closed output loses nothing
    sys.exit(run_script(main))
