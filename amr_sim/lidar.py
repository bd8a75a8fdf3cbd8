"""The simulated 2D LiDAR: a scan of rays from a pose against the world's wall segments.

The ray-casting kernels live in amr_common.world.raycast (shared with the particle filter and the
planner); this module adds the sensor: ray angles, range limits and the no-return value. A map
world with many wall segments is scanned through its cells instead
(amr_common.world.raster_raycast: the same ranges, at a cost that does not grow with the segments).
Circles (`circles`, rows [x, y, radius]: the world's movers where they are now, kept up to date by
the simulator) are seen on top of the walls.
"""
from __future__ import annotations

import numpy as np

from amr_common.jit import HAVE_NUMBA
from amr_common.world.raster_raycast import MarchGrid, scan_grid_kernel
from amr_common.world.raycast import (
    scan_circles_kernel,
    scan_circles_numpy,
    scan_kernel,
    scan_numpy,
)


class Lidar:
    """A 2D LiDAR at the robot centre: `scan(x, y, theta, noise)` -> ranges (float64 array).

    Rays go counter-clockwise from angle_min (relative to the robot heading) in steps of
    angle_increment; a ray without a valid return reads `no_return` (NaN or 0.0).
    """

    def __init__(self, segments: np.ndarray, rays: int, angle_min: float, angle_increment: float,
                 range_min: float, range_max: float, no_return: float,
                 use_numba: bool = True, grid: MarchGrid | None = None) -> None:
        """`grid`: scan through these cells instead of the segments (World.march_grid)."""
        self.grid = grid
        self.segments = np.ascontiguousarray(segments, dtype=np.float64)
        angles = angle_min + angle_increment * np.arange(rays)
        self.base_cos = np.cos(angles)
        self.base_sin = np.sin(angles)
        self.range_min = float(range_min)
        self.range_max = float(range_max)
        self.no_return = float(no_return)
        self._zeros = np.zeros(rays)
        numba = use_numba and HAVE_NUMBA
        self._kernel = scan_kernel if numba else scan_numpy
        self._circles_kernel = scan_circles_kernel if numba else scan_circles_numpy
        # Rows [x, y, radius] of round obstacles (the simulator's movers), updated in place.
        self.circles = np.zeros((0, 3))

    @property
    def rays(self) -> int:
        """Number of rays per scan."""
        return self.base_cos.shape[0]

    def scan(self, x: float, y: float, theta: float,
             noise: np.ndarray | None = None) -> np.ndarray:
        """Ranges from the pose (x, y, theta), plus `noise` (one value per ray) if given."""
        out = np.empty(self.rays)
        x, y, theta = float(x), float(y), float(theta)
        noise = self._zeros if noise is None else noise
        circles = self.circles
        if circles.shape[0] == 0:
            self._walls(x, y, theta, self.range_min, self.range_max, self.no_return, noise, out)
            return out
        # The walls' true ranges first (no noise, no limits), then the circles, the noise and
        # the limits (scan_circles).
        self._walls(x, y, theta, 0.0, np.inf, np.inf, self._zeros, out)
        self._circles_kernel(circles, x, y, theta, self.base_cos, self.base_sin, self.range_min,
                             self.range_max, self.no_return, noise, out)
        return out

    def _walls(self, x: float, y: float, theta: float, range_min: float, range_max: float,
               no_return: float, noise: np.ndarray, out: np.ndarray) -> None:
        if self.grid is not None:
            g = self.grid
            scan_grid_kernel(g.cells, g.width, g.x0, g.y0, g.resolution, x, y, theta,
                             self.base_cos, self.base_sin, range_min, range_max, no_return,
                             noise, out)
        else:
            self._kernel(self.segments, x, y, theta, self.base_cos, self.base_sin, range_min,
                         range_max, no_return, noise, out)
