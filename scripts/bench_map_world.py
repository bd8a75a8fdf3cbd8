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

Usage: .venv/bin/python scripts/bench_map_world.py [--steps N] [--repeats R] [--worlds a,b]
"""
from __future__ import annotations

import argparse
import os
import sys
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


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--worlds", default="lab02,room_obstacles")
    parser.add_argument("--resolution", type=float, default=0.02)
    args = parser.parse_args(argv)
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
