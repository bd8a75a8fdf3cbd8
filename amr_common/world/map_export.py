"""A world exported as a Nav2 map: its occupancy grid's cells and this project's map keys.

What scripts/world_to_map.py writes (with amr_common.world.map_file.write_map): any World, a
world file's or a map's, as map_server's files at CONVERT_RESOLUTION (2 cm) by default. The
other way, a map file read as a World, is World.load's (amr_common.world.world).
"""
from __future__ import annotations

from typing import Any

from amr_common.world.map_raster import Raster
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.world import World

# Worlds converted to maps: 2 cm, this project's SLAM and planner cell (walls within 1 cm of
# their place; slam_toolbox's 5 cm would narrow a 0.4 m corridor by 5 cm).
CONVERT_RESOLUTION = 0.02


def world_as_map(world: World, resolution: float = CONVERT_RESOLUTION
                 ) -> tuple[Raster, dict[str, Any]]:
    """(cells, extras) of any World as a map at `resolution` m per cell.

    The cells are the world's occupancy grid (OccupancyGrid.from_world: cell centres on
    multiples of the resolution, so a wall on such a line is one cell thick around its true
    place, and the free space loses half a cell along each wall); the extras keep its name,
    starts, goals and coverage grid (write_map(raster, prefix, extras=extras)).
    """
    raster = OccupancyGrid.from_world(world, resolution).raster()
    grid_origin = world.grid_origin
    if grid_origin is None and world.boundary is not None:  # the coverage grid's default
        grid_origin = tuple(float(v) for v in world.boundary.min(axis=0))
    extras: dict[str, Any] = {"name": world.name, "description": world.description or
                              f"converted from {world.source}", "cell_size": world.cell_size}
    if grid_origin is not None:
        extras["grid_origin"] = list(grid_origin)
    if world.starts:
        extras["starts"] = world.starts
    if world.goals:
        extras["goals"] = world.goals
    if world.goal is not None and world.goal != next(iter(world.goals.values()), None):
        extras["goal"] = world.goal
    return raster, extras


__all__ = ["CONVERT_RESOLUTION", "world_as_map"]
