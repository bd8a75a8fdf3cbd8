"""How much memory the particle filter needs on a map, and the expected-range table it can afford.

The expected-range table dominates: 2 bytes per direction per cell of free space (the cells a
LiDAR can be in get a row, see expected_ranges), 4 bytes per cell of the map's bounding box (each
cell's row number). Around it: the occupancy grid (12 bytes per cell, and ~50 more for a moment
while it is built), the pose search's cells, the resampler's bins and the particles.

The filter uses `table_resolution_m` x `table_angles` (2 cm x 360 by default) if that fits in
`max_memory_mb`, else the first that fits of: half the directions, twice the cell size, both
(never coarser than COARSEST_RESOLUTION_M: with 6-8 cm cells the filter declared wrong poses in
the course's mazes). A map that fits none of them is refused (MapTooBigError, saying what it
would need). 4 cm x 180 with beam_model's sub-cell correction, in the course's mazes (200
episodes of scripts/evaluate.py --localize): no wrong pose, tracking error mean 0.24-0.34 cm
(2 cm x 360: 0.29-0.34 cm). The free space is estimated on a lattice of at most
_LATTICE_POINTS points, so a plan costs milliseconds and nothing is built: run scripts call it
(particle_filter_params.check_world, which also estimates the table's build time from a sample
of it) to refuse a map before anything runs. No rclpy import.

A map world (a Nav2 map YAML, a SLAM map: World.raster) has its table on the map's own cells
(OccupancyGrid of a raster), whatever table_resolution_m says: its plan takes the map's shape,
cell size and free cells (counted, not estimated), and only the directions can shrink.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from amr_common.world.coverage_grid import MAX_GRID_CELLS
from amr_common.world.distance_transform import free_cell_clearances
from amr_common.world.map_raster import Raster
from amr_common.world.occupancy_grid import grid_shape
from amr_common.world.world import World
from amr_localization.expected_ranges import MIN_CLEARANCE_M

COARSEST_RESOLUTION_M = 0.04
_LATTICE_POINTS = 100_000  # the free space is estimated on at most this many points ...
_LATTICE_STEP_M = 0.04  # ... at least this far apart (a maze: a few thousand, ~2 ms)
_GRID_BYTES_PER_CELL = 64  # occupancy grid kept (12) or while it is built (~60), robot cells
_SEARCH_BYTES_PER_CELL = 16  # the pose search's cell centres (float64 x, y)
_PARTICLE_BYTES = 128  # per particle: poses, weights, scratch of the kernels and resampling
_MB = 1e6


class MapTooBigError(ValueError):
    """The map needs more memory than max_memory_mb even with the coarsest table."""


@dataclass(frozen=True)
class MemoryPlan:
    """A table (cell size, directions) for a map and the memory it needs (bytes)."""

    resolution: float
    angles: int
    cells: int  # cells of the grid over the map's bounding box
    free_cells: int  # of them, in the free space (an estimate): those get a row
    table_bytes: int
    other_bytes: int
    reduced: bool = False  # fewer directions or coarser cells than the parameters ask for

    @property
    def total_bytes(self) -> int:
        """Memory of the filter's map data: the table and everything around it."""
        return self.table_bytes + self.other_bytes

    def describe(self) -> str:
        """E.g. '4 cm x 180 directions: 450 MB (table 355 MB)'."""
        return (f"{100 * self.resolution:g} cm x {self.angles} directions: "
                f"{self.total_bytes / _MB:.0f} MB (table {self.table_bytes / _MB:.0f} MB)")


def free_share(world: World) -> float:
    """Share of the map's bounding box inside its free space (a lattice estimate)."""
    xmin, ymin, xmax, ymax = world.bounds
    step = max(math.sqrt((xmax - xmin) * (ymax - ymin) / _LATTICE_POINTS), _LATTICE_STEP_M)
    xs = np.arange(xmin + step / 2, xmax, step)
    ys = np.arange(ymin + step / 2, ymax, step)
    if xs.size == 0 or ys.size == 0:
        return 1.0
    gx, gy = np.meshgrid(xs, ys)
    return float(np.mean(world.contains_points(np.column_stack([gx.ravel(), gy.ravel()]))))


def memory_plan(world: World, resolution: float, angles: int, params: dict[str, Any],
                share: float | None = None) -> MemoryPlan:
    """The memory the filter needs on `world` with this table and the (checked) parameters.

    A map world: on the map's cells, whatever `resolution` says (see the module docstring).
    """
    height, width = grid_shape(world, resolution)
    cells = height * width
    if world.raster is not None:
        resolution = world.raster.resolution
        free = map_table_cells(world.raster)
    else:
        free = int(math.ceil(cells * (free_share(world) if share is None else share)))
    table = (free + 1) * angles * 2 + cells * 4
    xmin, ymin, xmax, ymax = world.bounds
    bins = ((math.ceil((xmax - xmin) / params["kld_bin_xy_m"]) + 2)
            * (math.ceil((ymax - ymin) / params["kld_bin_xy_m"]) + 2)
            * (math.ceil(2.0 * math.pi / params["kld_bin_theta_rad"]) + 2))
    search = free * _SEARCH_BYTES_PER_CELL // search_stride(resolution) ** 2
    particles = max(params["max_particles"], params["tracking_particles"]) * _PARTICLE_BYTES
    other = cells * _GRID_BYTES_PER_CELL + search + bins + particles
    return MemoryPlan(float(resolution), int(angles), cells, free, int(table), int(other))


def map_table_cells(raster: Raster) -> int:
    """The cells of a map that get a row of the table, counted.

    Those with clearance >= MIN_CLEARANCE_M (expected_ranges). A free cell's centre is at
    least half a cell from every non-free one (the map's walls), so with cells of 2 cm or more
    every free cell; finer maps need their clearances.
    """
    if 0.5 * raster.resolution >= MIN_CLEARANCE_M:
        return int(np.count_nonzero(raster.free))
    clearance = free_cell_clearances(raster.free, raster.resolution)
    return int(np.count_nonzero(clearance >= MIN_CLEARANCE_M))


def search_stride(resolution: float) -> int:
    """Table cells between two poses of the exhaustive pose search: a 4 cm grid.

    Its lines must hold the centre lines of 0.4 m corridors (multiples of 0.2 m): with 8 cm
    (4 cm cells, every second one) the symmetric twin of a pose in corridor_loop scored 19 of 30
    beams instead of ~30, was not checked, and the filter declared the wrong one.
    """
    return max(1, int(round(0.04 / resolution)))


def candidate_plans(world: World, params: dict[str, Any]) -> list[MemoryPlan]:
    """The tables the filter may use on `world`, finest first (see the module docstring)."""
    resolution, angles = params["table_resolution_m"], params["table_angles"]
    choices = [(resolution, angles), (resolution, angles // 2)]
    if world.raster is not None:  # the map's cells: only the directions can shrink
        share = None
    else:
        if 2 * resolution <= COARSEST_RESOLUTION_M + 1e-9:
            choices += [(2 * resolution, angles), (2 * resolution, angles // 2)]
        share = free_share(world)
    return [memory_plan(world, r, a, params, share) for r, a in choices if a >= 8]


def choose_table(world: World, params: dict[str, Any]) -> MemoryPlan:
    """The finest candidate plan within max_memory_mb; MapTooBigError if none fits.

    A plan whose grid exceeds amr_common.world.coverage_grid.MAX_GRID_CELLS does not fit either.
    """
    plans = candidate_plans(world, params)
    budget = params["max_memory_mb"] * _MB
    for index, plan in enumerate(plans):
        if plan.total_bytes <= budget and plan.cells <= MAX_GRID_CELLS:
            return replace(plan, reduced=index > 0)
    xmin, ymin, xmax, ymax = world.bounds
    last = plans[-1]
    too_many = f"; its grid has {last.cells:,} cells (most {MAX_GRID_CELLS:,})" \
        if last.cells > MAX_GRID_CELLS else ""
    raise MapTooBigError(
        f"{world.source}: a {xmax - xmin:.1f} x {ymax - ymin:.1f} m map is too big for the "
        f"particle filter: it would need {last.total_bytes / _MB:,.0f} MB even with the "
        f"coarsest expected-range table ({100 * last.resolution:g} cm x {last.angles} "
        f"directions, table {last.table_bytes / _MB:,.0f} MB); max_memory_mb is "
        f"{params['max_memory_mb']:g}{too_many}")
