#!/usr/bin/env python3
"""Write a speckled map (a noisy SLAM map at its worst) as a Nav2 map: PREFIX.yaml + .pgm.

A square open floor of `cells` x `cells` cells with a one-cell border wall, each other cell
occupied with probability `share` (the specks a noisy SLAM run leaves), except within
CLEAR_RADIUS_M of the start at the centre (so the robot fits there). The particle filter's and
the simulator's benchmarks (scripts/bench_localization.py --big-maps, scripts/bench_sim.py
--big-maps) and their tests use it: 1,000 x 1,000 cells at 2 cm with 1 % specks is a 20 x 20 m
floor with ~39,000 wall segments; 2,000 x 2,000 with 50 % specks the largest map allowed
(amr_common.world.coverage_grid.MAX_GRID_CELLS) at its worst. Deterministic for a given seed.

    tools/make_speckled_map.py 1000 0.01 /tmp/specks   # writes /tmp/specks.yaml, .pgm
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from amr_common.world.map_raster import FREE, OCCUPIED, Raster  # noqa: E402

CLEAR_RADIUS_M = 0.3  # no speck this close to the start: the Burger (0.105 m) fits there


def speckled_raster(cells: int, share: float, resolution: float = 0.02, seed: int = 0
                    ) -> Raster:
    """The map's cells: border wall, specks with probability `share`, a clear start."""
    rng = np.random.default_rng(seed)
    values = np.where(rng.random((cells, cells)) < share, OCCUPIED, FREE).astype(np.int8)
    centre = (np.arange(cells) + 0.5 - cells / 2) * resolution
    values[np.hypot(*np.meshgrid(centre, centre)) < CLEAR_RADIUS_M] = FREE
    values[0, :] = values[-1, :] = values[:, 0] = values[:, -1] = OCCUPIED
    return Raster(values, resolution, (0.0, 0.0))


def start_pose(raster: Raster) -> tuple[float, float, float]:
    """The start at the map's centre, facing +x."""
    rows, cols = raster.values.shape
    return (raster.origin[0] + cols * raster.resolution / 2,
            raster.origin[1] + rows * raster.resolution / 2, 0.0)


def write_speckled_map(prefix: str | Path, cells: int, share: float, resolution: float = 0.02,
                       seed: int = 0) -> Path:
    """Write the map (with its start, named `centre`); returns the YAML's path."""
    from amr_common.world.map_file import write_map
    raster = speckled_raster(cells, share, resolution, seed)
    extras = {"name": Path(prefix).name,
              "description": f"{cells} x {cells} cells of {resolution:g} m, {100 * share:g} % "
                             f"specks (tools/make_speckled_map.py, seed {seed})",
              "starts": {"centre": list(start_pose(raster))}}
    yaml_path, _ = write_map(raster, prefix, "pgm", extras)
    return yaml_path


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("cells", type=int, help="cells along each side")
    parser.add_argument("share", type=float, help="share of the cells that are specks (0-1)")
    parser.add_argument("prefix", help="output PREFIX (PREFIX.yaml and PREFIX.pgm)")
    parser.add_argument("--resolution", type=float, default=0.02, help="m per cell")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    print(write_speckled_map(args.prefix, args.cells, args.share, args.resolution, args.seed))


if __name__ == "__main__":
    main()
