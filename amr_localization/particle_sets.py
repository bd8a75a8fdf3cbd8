"""Where particles are drawn: uniform over the free space, or Gaussian around poses.

Particles are drawn and kept where the robot can be: centre inside the free space and at least
the robot radius from every wall (`sample_free_poses` checks each drawn point exactly with the
world's clearance kernel). The grid is the expected-range table's
(amr_common.world.occupancy_grid). Headings are kept in [-pi, pi). No rclpy import.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.geometry import wrap_angles
from amr_common.robot import ROBOT_RADIUS
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.world import World


def wrap_headings(particles: np.ndarray) -> np.ndarray:
    """Wrap column 2 (theta) of (N, 3) particles into [-pi, pi), in place; returns them."""
    particles[:, 2] = wrap_angles(particles[:, 2])
    return particles


def gaussian_poses(poses, sigma, count_per_pose: int, rng: np.random.Generator) -> np.ndarray:
    """(len(poses) * count_per_pose, 3) particles, Gaussian around each pose (x, y, theta).

    sigma: standard deviations (sx m, sy m, stheta rad).
    """
    centres = np.repeat(np.asarray(poses, dtype=np.float64).reshape(-1, 3), count_per_pose,
                        axis=0)
    return wrap_headings(centres + rng.standard_normal(centres.shape) * np.asarray(sigma))


def sample_free_poses(world: World, grid: OccupancyGrid, count: int, rng: np.random.Generator,
                      radius: float = ROBOT_RADIUS) -> np.ndarray:
    """Poses uniform over the free space, at least `radius` from every wall.

    (count, 3) poses uniform over the free space at least `radius` from every wall, headings
    uniform in [-pi, pi).

    Cells whose centre is in the free space and could hold such a point are drawn by area, a point
    uniform in the cell, and each point is kept only if its exact clearance is >= radius (a point
    that far from every wall lies on the same side of all walls as its cell centre, so it is in
    the free space too).
    """
    half_diagonal = grid.resolution * math.sqrt(0.5)
    clearance = grid.clearance.ravel()
    candidates = np.flatnonzero((clearance > 0.0) & (clearance >= radius - half_diagonal))
    if candidates.size == 0:
        raise ValueError(f"{world.source}: no free space at least {radius} m from the walls")
    out = np.empty((count, 3))
    filled = 0
    while filled < count:
        batch = max(2 * (count - filled), 64)
        rows, cols = np.divmod(candidates[rng.integers(0, candidates.size, batch)], grid.width)
        points = grid.cell_centres(rows, cols) + (rng.random((batch, 2)) - 0.5) * grid.resolution
        keep = points[world.clearances(points) >= radius]
        take = min(len(keep), count - filled)
        out[filled:filled + take, :2] = keep[:take]
        filled += take
    out[:, 2] = rng.uniform(-math.pi, math.pi, count)
    return out
