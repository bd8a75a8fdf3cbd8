"""The filter's view of a World: a fine grid of free space and clearance.

The filter's view of a World: a fine grid over the map with, per cell centre, whether it lies
in the free space (inside the boundary, outside every hole) and its distance to the nearest wall.

Particles are drawn and kept where the robot can be: centre inside the free space and at least
the robot radius from every wall (`sample_free_poses` checks each drawn point exactly with the
world's clearance kernel). Free space, clearances and the grid size limit are the World's and
amr_common.coverage_grid's. No rclpy import.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amr_common.coverage_grid import check_grid_size
from amr_common.robot import ROBOT_RADIUS
from amr_common.world import World


@dataclass(frozen=True)
class MapGrid:
    """A grid of square cells over the world's bounds.

    Cell (i, j) spans x in [x0 + i * resolution, x0 + (i + 1) * resolution) and likewise y with j
    (row-major, j * nx + i).
    """

    x0: float
    y0: float
    resolution: float
    nx: int
    ny: int
    inside: np.ndarray  # (ny * nx,) bool: cell centre in the free space
    clearance: np.ndarray  # (ny * nx,) float64: cell centre's distance to the nearest wall (m)

    @property
    def size(self) -> int:
        """Number of cells."""
        return self.nx * self.ny

    def centres(self) -> np.ndarray:
        """(ny * nx, 2) cell centres in row-major order."""
        xs = self.x0 + (np.arange(self.nx) + 0.5) * self.resolution
        ys = self.y0 + (np.arange(self.ny) + 0.5) * self.resolution
        gx, gy = np.meshgrid(xs, ys)
        return np.column_stack([gx.ravel(), gy.ravel()])

    def cell_of(self, x: float, y: float) -> int:
        """Row-major index of the cell holding (x, y), or -1 off the grid (or not finite)."""
        fi = (x - self.x0) / self.resolution
        fj = (y - self.y0) / self.resolution
        if not (0.0 <= fi < self.nx and 0.0 <= fj < self.ny):
            return -1
        return int(fj) * self.nx + int(fi)

    def robot_cells(self, radius: float = ROBOT_RADIUS, slack: float = 0.0) -> np.ndarray:
        """(ny * nx,) uint8: 1 where a robot centre may be: inside, clearance >= radius - slack."""
        return (self.inside & (self.clearance >= radius - slack)).astype(np.uint8)


def build_map_grid(world: World, resolution: float, margin: float = 0.1) -> MapGrid:
    """The grid over the world's bounds grown by `margin` on each side (m)."""
    if not (math.isfinite(resolution) and resolution > 0.0):
        raise ValueError(f"grid resolution must be > 0 m, got {resolution}")
    xmin, ymin, xmax, ymax = world.bounds
    x0, y0 = xmin - margin, ymin - margin
    nx = math.ceil((xmax + margin - x0) / resolution)
    ny = math.ceil((ymax + margin - y0) / resolution)
    check_grid_size(float(nx), float(ny), resolution, f"{world.source}: the localization grid",
                    "use a coarser resolution")
    grid = MapGrid(x0, y0, float(resolution), nx, ny, np.zeros(0, bool), np.zeros(0))
    centres = grid.centres()
    inside = world.contains_points(centres)
    clearance = np.full(len(centres), -1.0)
    clearance[inside] = world.clearances(centres[inside])
    return MapGrid(x0, y0, float(resolution), nx, ny, inside, clearance)


def sample_free_poses(world: World, grid: MapGrid, count: int, rng: np.random.Generator,
                      radius: float = ROBOT_RADIUS) -> np.ndarray:
    """Poses uniform over the free space, at least `radius` from every wall.

    (count, 3) poses uniform over the free space at least `radius` from every wall, headings
    uniform in [-pi, pi).

    Cells whose centre is inside and could hold such a point are drawn by area, a point uniform
    in the cell, and each point is kept only if its exact clearance is >= radius (a point that far
    from every wall lies on the same side of all walls as its cell centre, so it is inside too).
    """
    half_diagonal = grid.resolution * math.sqrt(0.5)
    candidates = np.flatnonzero(grid.inside & (grid.clearance >= radius - half_diagonal))
    if candidates.size == 0:
        raise ValueError(f"{world.source}: no free space at least {radius} m from the walls")
    out = np.empty((count, 3))
    filled = 0
    while filled < count:
        batch = max(2 * (count - filled), 64)
        cells = candidates[rng.integers(0, candidates.size, batch)]
        x = grid.x0 + (cells % grid.nx + rng.random(batch)) * grid.resolution
        y = grid.y0 + (cells // grid.nx + rng.random(batch)) * grid.resolution
        points = np.column_stack([x, y])
        keep = points[world.clearances(points) >= radius]
        take = min(len(keep), count - filled)
        out[filled:filled + take, :2] = keep[:take]
        filled += take
    out[:, 2] = rng.uniform(-math.pi, math.pi, count)
    return out
