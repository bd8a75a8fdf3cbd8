#!/usr/bin/env python3
"""Benchmark: the simulator's step on a map world (Nav2 map YAML) against the polygon world.

For each world (default lab02 and room_obstacles), in one run and with the same commands:
- the polygon world (its typed walls: the reference),
- the world converted to a map (scripts/world_to_map.py, 2 cm cells): its walls are the edges
  between free and non-free cells, merged into straight segments,
- a SLAM-like version of that map (`slam_like`: ragged walls and speckles, as a real mapping run
  leaves them), thousands of short segments,
each map scanned against its segments and by grid ray marching through its cells
(amr_common.world.raster_raycast), which is what World.march_grid decides between. A step =
physics, wall contacts and a full 360-ray scan (the ideal profile scans every step). Microseconds
of CPU time per step (time.process_time), the best of --repeats runs, and the ratio to the polygon
world.

--big-maps: the particle filter's expected-range table and the simulator's start-up on speckled
maps generated in the run (tools/make_speckled_map.py: a border wall, each other cell a speck
with the given probability), each measured in a fresh process (its peak RSS by
resource.getrusage, imports included), against a reference measured in the same run:
- table (a 20 x 20 m map at 2 cm with 1 % and with 50 % specks): the build as the filter does it
  (amr_localization.table_build: its estimate from a sample, then the rest on its threads), CPU
  and wall seconds; the reference is every ray against every wall (raycast.scan_kernel, what a
  build cost before the rings and buckets), timed on a sample of cells and extrapolated;
- simulator (1,000 x 1,000 cells with 1 % specks; 2,000 x 2,000, the largest map allowed, with
  50 %): Simulator(world) and its /map messages, as the simulator node's configure builds them,
  and 200 steps; the reference is a pymunk space of every wall (contact.wall_space, as every
  map had before), timed on up to 100,000 walls and extrapolated per wall (seconds, and MB of
  resident memory it adds).

Usage: .venv/bin/python scripts/bench_map_world.py [--steps N] [--repeats R] [--worlds a,b]
       .venv/bin/python scripts/bench_map_world.py --big-maps
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from amr_common.world.map_file import world_as_map  # noqa: E402
from amr_common.world.map_raster import FREE, OCCUPIED, Raster  # noqa: E402
from amr_common.world.raster_raycast import MarchGrid  # noqa: E402
from amr_common.world.world import World  # noqa: E402
from amr_sim.lidar import Lidar  # noqa: E402
from amr_sim.simulator import Simulator  # noqa: E402


def slam_like(raster: Raster, seed: int = 0, ragged: float = 0.35, speckles: float = 0.003,
              keep_clear: list[tuple[float, ...]] = (), clear_radius: float = 0.2) -> Raster:
    """A map as a SLAM run leaves it: ragged walls and speckles, the walls still closed.

    Each free cell beside a wall becomes occupied with probability `ragged` (walls one or two
    cells thick, uneven); each other free cell with probability `speckles` (spurious hits in
    the open), except within `clear_radius` of the points in `keep_clear` (start poses).
    """
    rng = np.random.default_rng(seed)
    values = raster.values.copy()
    free = values == FREE
    beside = np.zeros_like(free)
    wall = ~free
    beside[1:] |= wall[:-1]
    beside[:-1] |= wall[1:]
    beside[:, 1:] |= wall[:, :-1]
    beside[:, :-1] |= wall[:, 1:]
    values[free & beside & (rng.random(values.shape) < ragged)] = OCCUPIED
    xs, ys = raster.centres()
    spared = np.zeros_like(free)
    for x, y, *_ in keep_clear:
        spared |= np.hypot(xs - x, ys - y) < clear_radius
    values[free & ~beside & ~spared & (rng.random(values.shape) < speckles)] = OCCUPIED
    return Raster(values, raster.resolution, raster.origin)


def step_time(world: World, start, steps: int, repeats: int, grid: MarchGrid | None) -> float:
    """Best CPU microseconds per step over `repeats` runs of `steps` steps."""
    best = float("inf")
    for _ in range(repeats):
        sim = Simulator(world, start=start, profile="ideal")
        p = sim.profile
        sim.lidar = Lidar(world.segments, p.scan_rays, p.angle_min, p.angle_increment,
                          p.range_min, p.range_max, p.no_return, grid=grid)
        sim.step(0.1, 0.5)  # compiles (or loads) the kernels
        began = time.process_time()
        for i in range(steps):
            sim.step(0.15, 0.8 if (i // 40) % 2 else -0.8)
        best = min(best, (time.process_time() - began) / steps * 1e6)
    return best


def bench_world(name: str, steps: int, repeats: int, resolution: float) -> list[dict]:
    polygon = World.load(name)
    start = next(iter(polygon.starts))
    raster, _ = world_as_map(polygon, resolution)
    maps = {"map": raster, "slam-like map": slam_like(raster, keep_clear=polygon.starts.values())}
    reference = step_time(polygon, start, steps, repeats, None)
    rows = [dict(world=name, kind="polygon", segments=len(polygon.segments), scan="segments",
                 us=reference)]
    for kind, cells in maps.items():
        world = World.from_raster(cells, starts=polygon.starts)
        for scan, grid in (("segments", None), ("march", MarchGrid.from_raster(cells))):
            rows.append(dict(world=name, kind=kind, segments=len(world.segments), scan=scan,
                             us=step_time(world, start, steps, repeats, grid),
                             chosen=(world.march_grid is not None) == (scan == "march")))
    for row in rows:
        row["ratio"] = row["us"] / reference
    return rows


REPO = Path(__file__).resolve().parents[1]
BIG_TABLES = [(1000, 0.01), (1000, 0.5)]  # (cells per side, speck share) at 2 cm
BIG_SIMULATORS = [(1000, 0.01), (2000, 0.5)]
# Each measured in a fresh process; the last line it prints is a JSON object of figures.
_TABLE = """
import json, math, resource, sys, time
sys.path.insert(0, {repo!r})
import numpy as np
from amr_common.world.world import World
from amr_localization.expected_ranges import start_build
from amr_localization.particle_filter_params import check_parameters, filter_walls
from amr_localization.table_memory import choose_table
world = World.load({path!r})
values = check_parameters({{}})
plan = choose_table(world, values)
walls = filter_walls(world, values)
wall0, cpu0 = time.perf_counter(), time.process_time()
build = start_build(world, plan.resolution, plan.angles, segments=walls)
estimate = build.sample()
build.finish()
print(json.dumps(dict(wall_s=time.perf_counter() - wall0, cpu_s=time.process_time() - cpu0,
      estimate_s=estimate, march=build.march, threads=build.threads, cells=build.cells,
      angles=plan.angles, walls=build.walls_count, table_mb=build.ranges.nbytes / 1e6,
      peak_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)))
"""
_EVERY_WALL = """
import json, math, sys, time
sys.path.insert(0, {repo!r})
import numpy as np
from amr_common.world.raycast import scan_kernel
from amr_common.world.world import World
from amr_localization.expected_ranges import start_build
from amr_localization.particle_filter_params import check_parameters, filter_walls
from amr_localization.table_memory import choose_table
world = World.load({path!r})
values = check_parameters({{}})
plan = choose_table(world, values)
walls = filter_walls(world, values)
build = start_build(world, plan.resolution, plan.angles, segments=walls)
cells = np.flatnonzero(build.rows)
sample = np.random.default_rng(0).choice(cells, {cells}, replace=False)
directions = np.arange(plan.angles) * (2 * math.pi / plan.angles)
c, s = np.cos(directions), np.sin(directions)
zeros, out = np.zeros(plan.angles), np.empty(plan.angles)
scan_kernel(walls, 0.0, 0.0, 0.0, c, s, 0.0, np.inf, np.inf, zeros, out)  # compiled or loaded
began = time.process_time()
for cell in sample:
    x, y = build.grid.cell_centres(*np.divmod([cell], build.grid.width))[0]
    scan_kernel(walls, x, y, 0.0, c, s, 0.0, np.inf, np.inf, zeros, out)
print(json.dumps(dict(cpu_s=(time.process_time() - began) / len(sample) * len(cells))))
"""
_SIMULATOR = """
import json, resource, sys, time
sys.path.insert(0, {repo!r})
from amr_common.ros.map_messages import world_map_messages
from amr_common.world.world import World
from amr_sim.simulator import Simulator
wall0, cpu0 = time.perf_counter(), time.process_time()
world = World.load({path!r})
sim = Simulator(world, start="centre", profile="ideal")
world_map_messages(world, 0.02)
configure = dict(wall_s=time.perf_counter() - wall0, cpu_s=time.process_time() - cpu0)
began = time.process_time()
for i in range(200):
    sim.step(0.15, 0.8 if (i // 40) % 2 else -0.8)
print(json.dumps(dict(configure, walls=len(world.segments), shapes=len(sim.space.shapes),
      step_us=(time.process_time() - began) / 200 * 1e6,
      peak_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)))
"""
_EVERY_WALL_SPACE = """
import json, os, sys, time
sys.path.insert(0, {repo!r})
from amr_common.world.world import World
from amr_sim.contact import wall_space

def resident_mb():  # now, not the peak: what the space adds
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6

world = World.load({path!r})
sample = world.segments[:{walls}]
before = resident_mb()
began = time.process_time()
space = wall_space(sample, world.starts["centre"])
per_wall = (time.process_time() - began) / len(sample)
grown = resident_mb() - before
print(json.dumps(dict(cpu_s=per_wall * len(world.segments),
      mb=grown / len(sample) * len(world.segments))))
"""


def _in_process(code: str, **values) -> dict:
    """Run a snippet in a fresh Python; the JSON object its last line prints."""
    done = subprocess.run([sys.executable, "-c", code.format(repo=str(REPO), **values)],
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def bench_big_maps(folder: Path) -> dict:
    """The table's build and the simulator's start-up on speckled maps, vs every wall."""
    from tools.make_speckled_map import write_speckled_map
    paths = {(cells, share): write_speckled_map(folder / f"specks_{cells}_{share:g}", cells,
                                                share)
             for cells, share in {*BIG_TABLES, *BIG_SIMULATORS}}
    tables = {}
    for key in BIG_TABLES:
        tables[key] = _in_process(_TABLE, path=str(paths[key]))
        tables[key]["every_wall_cpu_s"] = _in_process(_EVERY_WALL, path=str(paths[key]),
                                                      cells=100)["cpu_s"]
    simulators = {}
    for key in BIG_SIMULATORS:
        simulators[key] = _in_process(_SIMULATOR, path=str(paths[key]))
        every = _in_process(_EVERY_WALL_SPACE, path=str(paths[key]), walls=100_000)
        simulators[key].update(every_wall_space_cpu_s=every["cpu_s"],
                               every_wall_space_mb=every["mb"])
    return {"tables": tables, "simulators": simulators}


def _print_big_maps(figures: dict) -> None:
    print("expected-range table, built as the filter does (fresh process each):")
    print(f"{'map':24s} {'walls':>9s} {'table':>14s} {'estimate':>9s} {'cpu':>7s} {'wall':>7s} "
          f"{'peak':>8s} {'every wall (cpu)':>17s} {'ratio':>6s}")
    for (cells, share), t in figures["tables"].items():
        print(f"{cells} x {cells}, {100 * share:g} % specks".ljust(24)
              + f" {t['walls']:9,d} {t['cells']:8,d} x {t['angles']:3d} {t['estimate_s']:8.1f}s "
              f"{t['cpu_s']:6.1f}s {t['wall_s']:6.1f}s {t['peak_mb']:6.0f}MB "
              f"{t['every_wall_cpu_s']:16.0f}s {t['every_wall_cpu_s'] / t['cpu_s']:6.0f}x"
              + ("  (marched)" if t["march"] else ""))
    print("simulator start-up: Simulator(world) + /map messages, then 200 steps:")
    print(f"{'map':24s} {'walls':>9s} {'shapes':>7s} {'cpu':>7s} {'wall':>7s} {'peak':>8s} "
          f"{'us/step':>8s} {'every wall in pymunk':>21s} {'ratio':>6s}")
    for (cells, share), r in figures["simulators"].items():
        print(f"{cells} x {cells}, {100 * share:g} % specks".ljust(24)
              + f" {r['walls']:9,d} {r['shapes']:7d} {r['cpu_s']:6.1f}s {r['wall_s']:6.1f}s "
              f"{r['peak_mb']:6.0f}MB {r['step_us']:8.0f} {r['every_wall_space_cpu_s']:7.1f}s "
              f"{r['every_wall_space_mb']:7.0f}MB "
              f"{r['every_wall_space_cpu_s'] / r['cpu_s']:7.0f}x")


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--worlds", default="lab02,room_obstacles")
    parser.add_argument("--resolution", type=float, default=0.02)
    parser.add_argument("--big-maps", action="store_true",
                        help="the filter's table and the simulator's start-up on speckled maps")
    args = parser.parse_args(argv)
    if args.big_maps:
        print(f"load average {os.getloadavg()[0]:.2f}; speckled maps at 2 cm")
        with tempfile.TemporaryDirectory() as folder:
            figures = bench_big_maps(Path(folder))
        _print_big_maps(figures)
        return figures
    print(f"load average {os.getloadavg()[0]:.2f}; {args.steps} steps x {args.repeats}, best; "
          f"maps at {args.resolution} m")
    print(f"{'world':16s} {'kind':14s} {'segments':>8s} {'scan':9s} {'us/step':>8s} "
          f"{'x polygon':>9s}")
    rows = []
    for name in args.worlds.split(","):
        for row in bench_world(name, args.steps, args.repeats, args.resolution):
            chosen = " <- World.march_grid's choice" if row.get("chosen") else ""
            print(f"{row['world']:16s} {row['kind']:14s} {row['segments']:8d} {row['scan']:9s} "
                  f"{row['us']:8.1f} {row['ratio']:9.2f}{chosen}")
            rows.append(row)
    return {"rows": rows}


if __name__ == "__main__":
    from script_endings import guard_output  # a closed output loses nothing
    guard_output()
    main()
