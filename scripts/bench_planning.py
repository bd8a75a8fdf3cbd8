#!/usr/bin/env python3
"""Planning and navigation speed, each against a reference measured in the same run.

  A* search      lab02 (2.4 x 2.4 m maze) on the 2 cm grid, from `outer` to the cell farthest
                 into the inner maze (the whole maze crossed): the compiled search kernel vs the
                 SAME function run by the interpreter (amr_planning.search.astar_python) on the
                 same grid held in Python lists; the paths must be identical. Target: compiled
                 <= 1 ms.
  plan()         the whole plan (search + simplification + rounded corners + sampling), and the
                 seeds' wavefront for comparison.
  navigation     headless navigation episodes (simulator + planner + pure pursuit, on the true
                 pose and, with amr_localization installed, on the particle filter's;
                 amr_evaluation.navigation_episode): simulated seconds per wall-clock second.
                 Target: >= 100x real time.
  ROS loop       with amr_localization: run_sim.py --goal, the five lifecycle nodes in lockstep
                 in one process (simulator, wall follower, particle filter, planner, pure
                 pursuit). Target: >= 15x real time.
Usage: .venv/bin/python scripts/bench_planning.py [--quick] [--json FILE]
`measure()` returns the figures as a dict.
"""
from __future__ import annotations

import argparse
import itertools
import json
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from amr_common.world.world import World  # noqa: E402
from amr_planning import search  # noqa: E402
from amr_planning.planner import Planner  # noqa: E402


def _timed(function, repeats: int) -> list[float]:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return times


def measure(quick: bool = False) -> dict:
    world = World.load("lab02")
    planner = Planner(world)
    planner.warm_up()
    start, goal = world.starts["outer"][:2], world.goals["inner_far"]
    cells = planner.cell_index(*start), planner.cell_index(*goal)
    compiled = planner.search(*cells)
    python = planner.search(*cells, compiled=False)  # on lists (see Planner.search)
    if not np.array_equal(compiled[0], python[0]):
        raise SystemExit("bench_planning: compiled and Python A* disagree")
    # The kernels alone, same grid, same arguments (the Python one on lists, its natural data).
    arrays = (planner.cost, planner._moves, planner._offsets, planner.grid.width, *cells, 1.0,
              planner._came_from, planner._g)
    (cost, moves, offsets), came_from, g = planner._lists
    lists = (cost, moves, offsets, planner.grid.width, *cells, 1.0, came_from, g)
    repeats = (50, 3, 20, 2) if quick else (500, 10, 100, 5)
    t_astar = _timed(lambda: search.astar(*arrays), repeats[0])
    t_python = _timed(lambda: search.astar_python(*lists), repeats[1])
    t_plan = _timed(lambda: planner.plan(start, goal), repeats[2])
    t_wave = _timed(lambda: planner.search(*cells, algorithm="wavefront"), repeats[2])
    from amr_evaluation.navigation_episode import run_navigation_episode
    sources = ["truth"] + (["filter"] if _have_filter() else [])
    episodes = {}
    for source, profile in itertools.product(sources, ("ideal", "turtlebot3_clean")):
        runs = [run_navigation_episode(world, "outer", "inner_far", profile=profile,
                                       pose_source=source, planner=planner, duration=300.0,
                                       record_trajectory=False) for _ in range(repeats[3])]
        episodes[f"{profile}, {source} pose"] = {
            "real_time_factor": statistics.median(r.real_time_factor for r in runs),
            "sim_time_s": runs[0].sim_time_s, "goal_reached": runs[0].goal_reached}
    ros_loop = _ros_loop() if "filter" in sources else None
    return {
        "grid_cells": int(planner.cost.size), "grid_shape": [planner.grid.height,
                                                             planner.grid.width],
        "path_cells": int(len(compiled[0])), "expanded": compiled[2],
        "astar_ms_median": statistics.median(t_astar) * 1e3,
        "astar_ms_min": min(t_astar) * 1e3,
        "python_astar_ms_median": statistics.median(t_python) * 1e3,
        "speedup": statistics.median(t_python) / statistics.median(t_astar),
        "plan_ms_median": statistics.median(t_plan) * 1e3,
        "wavefront_ms_median": statistics.median(t_wave) * 1e3,
        "navigation": episodes,
        "ros_loop": ros_loop,
    }


def _have_filter() -> bool:
    try:
        import amr_localization.particle_filter  # noqa: F401
    except ImportError:
        return False
    return True


def _ros_loop() -> dict:
    """run_sim.py --goal on lab02 (lockstep, ideal): the five-node graph's real-time factor."""
    import tempfile

    sys.path.insert(0, str(REPO / "scripts"))
    import run_sim
    with tempfile.TemporaryDirectory() as folder:
        report_path = Path(folder) / "run.json"
        run_sim.main(["--world", "lab02", "--start", "outer", "--goal", "inner_far",
                      "--duration", "300", "--report", str(report_path)])
        report = json.loads(report_path.read_text())
    return {"real_time_factor": report["real_time_factor"], "sim_time_s": report["sim_time_s"],
            "steps": report["steps"], "goal_reached": report["goal_reached_time_s"] is not None}


def report(f: dict) -> str:
    lines = [
        f"A* on lab02 at 2 cm ({f['grid_cells']} cells, path {f['path_cells']} cells, "
        f"{f['expanded']} expanded): compiled {f['astar_ms_median']:.3f} ms median "
        f"(min {f['astar_ms_min']:.3f}; target <= 1 ms) vs plain Python "
        f"{f['python_astar_ms_median']:.1f} ms: {f['speedup']:.0f}x, same path",
        f"plan() with smoothing {f['plan_ms_median']:.2f} ms median; wavefront search "
        f"{f['wavefront_ms_median']:.3f} ms",
    ]
    for case, e in f["navigation"].items():
        lines.append(f"navigation episode lab02 outer -> inner_far ({case}, "
                     f"{e['sim_time_s']:.1f} s simulated, reached {e['goal_reached']}): "
                     f"{e['real_time_factor']:.0f}x real time (target >= 100x)")
    if f["ros_loop"] is not None:
        r = f["ros_loop"]
        lines.append(f"ROS lockstep loop, five nodes (run_sim.py --goal, lab02, "
                     f"{r['steps']} steps, reached {r['goal_reached']}): "
                     f"{r['real_time_factor']:.1f}x real time (target >= 15x)")
    return "\n".join(lines)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    parser.add_argument("--json", default=None, help="also write the figures to this file")
    args = parser.parse_args(argv)
    figures = measure(args.quick)
    print(report(figures))
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1, default=float))
    return figures


if __name__ == "__main__":
    from script_endings import guard_output  # a closed output loses nothing
    guard_output()
    main()
    sys.exit(0)
