"""A course-style Monte Carlo localization with the likelihood-field model (Thrun et al., ch. 6.4).

A small, readable amr_common.plugins.interfaces.Localizer: the project's ParticleFilter does much
more (a beam model on an expected-range table, adaptive particle counts, exhaustive pose searches,
a guarded "localized" flag). Run it in place of the project's:

    .venv/bin/python scripts/run_sim.py --world lab02 --localize \
        --localizer examples.likelihood_mcl:LikelihoodFieldMcl
    .venv/bin/python scripts/evaluate.py --localize --worlds lab02 --seeds 0-4 --duration 60 \
        --localizer examples.likelihood_mcl:LikelihoodFieldMcl --out out/mcl

The cycle:
- predict: every particle follows the odometry twist (v, w) over dt with Gaussian noise whose
  spread grows with the speeds (alpha parameters, the course's velocity motion model);
- correct (a new scan, once the robot moved a little): each particle projects `beams` evenly
  picked readings into the map; a reading's likelihood is z_hit * N(d; 0, sigma_hit) + z_random,
  d the distance from its end point to the nearest wall (a precomputed field: the "likelihood
  field"); the weights are multiplied and renormalized, and the particles are resampled (low
  variance) when the effective sample size falls below half;
- localized: the particles' spread is small (position std <= localized_spread_m, heading std <=
  localized_spread_rad) for `localized_updates` updates in a row. Nothing checks that the tight
  cloud is in the RIGHT place: in a symmetric maze it may settle on the twin of the true pose
  and declare it - scripts/compare.py shows where (false localizations).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from amr_common.plugins.parameter_table import at_least, checked_values, ruled, vector
from amr_common.robot import ROBOT_RADIUS
from amr_common.sensors.scan_returns import return_mask
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.world import World

# name: (default, description); ruled() adds what values are allowed (checked_values checks).
_PARAMETERS = ruled({
    "seed": (0, "Seed of the random numbers"),
    "lidar_offset_x_m": (0.0, "Where the LiDAR sits ahead of the robot centre [m]"),
    "particles": (3000, "Number of particles"),
    "beams": (36, "Readings used per scan (evenly picked)"),
    "sigma_hit_m": (0.08, "Spread of a reading's end point around the nearest wall [m]"),
    "z_random": (0.05, "Weight of a random reading (keeps one bad reading from killing a "
                       "particle)"),
    "field_resolution_m": (0.02, "Cell size of the likelihood field [m]"),
    "alpha_v": (0.1, "Motion noise: std of v per unit of |v| and |w|"),
    "alpha_w": (0.2, "Motion noise: std of w per unit of |w| and |v|"),
    "update_min_distance_m": (0.02, "Weigh a new scan once the robot moved this far [m]"),
    "update_min_angle_rad": (0.05, "... or turned this much [rad]"),
    "localized_spread_m": (0.05, "Localized: position std of the particles at most this [m]"),
    "localized_spread_rad": (0.1, "... and heading std at most this [rad]"),
    "localized_updates": (3, "... for this many measurement updates in a row"),
    "initial_pose": ([], "Start tracking from [x, y, theta] (m, m, rad); [] = global "
                         "localization"),
    "initial_pose_sigma": ([0.1, 0.1, 0.2], "Spread around initial_pose [m, m, rad]"),
}, at_least(0.0), lidar_offset_x_m=None, particles=at_least(1), beams=at_least(1),
    sigma_hit_m=at_least(1e-3), initial_pose=vector(0, 3), initial_pose_sigma=vector(3, low=0.0))


class LikelihoodFieldMcl:
    """Monte Carlo localization with a likelihood field (see the module docstring)."""

    particles: np.ndarray  # (N, 3) [x, y, theta]: the interface's members set in __init__
    global_searches: int

    @staticmethod
    def parameter_descriptions() -> dict[str, tuple[Any, str]]:
        """Each parameter: name -> (default, description); the node declares them."""
        return dict(_PARAMETERS)

    def __init__(self, map: World, **params: Any) -> None:
        self.p = checked_values(_PARAMETERS, params, "LikelihoodFieldMcl")  # ValueError
        self._map = map
        self.rng = np.random.default_rng(int(self.p["seed"]))
        grid = OccupancyGrid.from_world(map, float(self.p["field_resolution_m"]))
        self.grid = grid
        # The likelihood field: every cell centre's distance to the nearest wall.
        centres = np.column_stack([a.ravel() for a in np.meshgrid(grid.x_centres,
                                                                  grid.y_centres)])
        self.field = map.clearances(centres).reshape(grid.shape)
        # Where a global localization may put the robot: free, a robot radius from the walls.
        rows, cols = np.nonzero(grid.clearance >= ROBOT_RADIUS)
        self.free_centres = grid.cell_centres(rows, cols)
        self.beam_index: np.ndarray | None = None
        self.global_searches = 0
        self._moved = [math.inf, math.inf]  # distance, angle since the last update
        pose = list(self.p["initial_pose"] or [])
        if pose:
            self.initialize_pose(pose)
        else:
            self.initialize_global()

    # --- the interface's settings -----------------------------------------------------------
    @property
    def map(self) -> World:
        """The World it localizes on."""
        return self._map

    @property
    def lidar_offset_x_m(self) -> float:
        """Where the LiDAR sits ahead of the robot centre (m)."""
        return float(self.p["lidar_offset_x_m"])

    def set_lidar_offset(self, offset_m: float) -> None:
        """Place the LiDAR offset_m ahead of the robot centre."""
        if not (math.isfinite(offset_m) and abs(offset_m) <= 1.0):
            raise ValueError(f"LiDAR offset must be within +-1 m, got {offset_m!r}")
        self.p["lidar_offset_x_m"] = float(offset_m)

    def set_scan_geometry(self, angle_min, angle_increment, rays, range_min, range_max) -> None:
        """Which readings are used (evenly picked) and where they point."""
        count = min(int(self.p["beams"]), int(rays))
        self.beam_index = np.linspace(0, rays - 1, count).round().astype(int)
        self.beam_angles = angle_min + angle_increment * self.beam_index
        self.rays, self.range_limits = int(rays), (float(range_min), float(range_max))

    def describe(self) -> str:
        """One line for logs."""
        return (f"likelihood-field MCL, {len(self.particles)} particles, {self.p['beams']} "
                f"beams, field {self.grid.width} x {self.grid.height} cells")

    # --- (re-)initialization ----------------------------------------------------------------
    def initialize_global(self) -> None:
        """Particles uniform over the free space, all headings."""
        n = int(self.p["particles"])
        picks = self.rng.integers(len(self.free_centres), size=n)
        jitter = self.rng.uniform(-0.5, 0.5, size=(n, 2)) * self.grid.resolution
        headings = self.rng.uniform(-math.pi, math.pi, size=n)
        self._reset(np.column_stack([self.free_centres[picks] + jitter, headings]))
        self.global_searches += 1

    def initialize_pose(self, pose, sigma=None):
        """Particles around pose (x, y, theta) with spread sigma (m, m, rad)."""
        x, y, theta = (float(v) for v in pose)
        sigma = [float(s) for s in (sigma if sigma is not None
                                    else self.p["initial_pose_sigma"])]
        if not all(math.isfinite(v) for v in (x, y, theta, *sigma)):
            raise ValueError(f"initial pose {pose} or sigma {sigma} not finite")
        if not self._map.contains(x, y):
            raise ValueError(f"initial pose ({x:.2f}, {y:.2f}) is not in the free space")
        n = int(self.p["particles"])
        self._reset(np.array([x, y, theta]) + self.rng.normal(size=(n, 3)) * sigma)
        return sigma

    def _reset(self, particles: np.ndarray) -> None:
        self.particles = particles
        self.weights = np.full(len(particles), 1.0 / len(particles))
        self._tight_updates = 0
        self._moved = [math.inf, math.inf]

    # --- the filter cycle -------------------------------------------------------------------
    def predict(self, v: float, w: float, dt: float) -> None:
        """The velocity motion model with noise, every particle."""
        if not (math.isfinite(v) and math.isfinite(w) and math.isfinite(dt)) or dt <= 0.0:
            return
        n = len(self.particles)
        speed = abs(v) + abs(w)
        v_noisy = v + self.rng.normal(size=n) * self.p["alpha_v"] * speed
        w_noisy = w + self.rng.normal(size=n) * self.p["alpha_w"] * speed
        theta = self.particles[:, 2]
        self.particles[:, 0] += v_noisy * dt * np.cos(theta + 0.5 * w_noisy * dt)
        self.particles[:, 1] += v_noisy * dt * np.sin(theta + 0.5 * w_noisy * dt)
        self.particles[:, 2] = np.arctan2(np.sin(theta + w_noisy * dt),
                                          np.cos(theta + w_noisy * dt))
        self._moved[0] += abs(v) * dt
        self._moved[1] += abs(w) * dt

    def correct(self, ranges, force: bool = False, new_scan: bool = True,
                age_s: float = 0.0) -> bool:
        """Weigh the particles with the scan (likelihood field), resample if needed.

        age_s (how old the scan is) is not used: this filter does not de-skew.
        """
        if self.beam_index is None:
            raise RuntimeError("set_scan_geometry() before correct()")
        ranges = np.asarray(ranges, dtype=float)
        if ranges.shape != (self.rays,):
            raise ValueError(f"scan has {ranges.size} rays, the scan geometry {self.rays}")
        moved = self._moved[0] >= self.p["update_min_distance_m"] or \
            self._moved[1] >= self.p["update_min_angle_rad"]
        if not (force or (new_scan and moved)):
            return False
        readings = ranges[self.beam_index]
        valid = return_mask(readings, *self.range_limits)
        if not valid.any():
            return False
        self.weights *= self._likelihoods(readings[valid], self.beam_angles[valid])
        total = self.weights.sum()
        if not (total > 0.0 and math.isfinite(total)):
            self.weights = np.full(len(self.particles), 1.0 / len(self.particles))
        else:
            self.weights /= total
        if 1.0 / np.sum(self.weights ** 2) < 0.5 * len(self.weights):
            self._resample()
        self._moved = [0.0, 0.0]
        spread_xy, spread_theta = self._spread()
        tight = spread_xy <= self.p["localized_spread_m"] and \
            spread_theta <= self.p["localized_spread_rad"]
        self._tight_updates = self._tight_updates + 1 if tight else 0
        return True

    def _likelihoods(self, readings: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Each particle's likelihood of the readings: the product over the beams."""
        x, y, theta = (self.particles[:, i:i + 1] for i in range(3))
        lidar_x = x + self.lidar_offset_x_m * np.cos(theta)
        lidar_y = y + self.lidar_offset_x_m * np.sin(theta)
        end_x = lidar_x + readings * np.cos(theta + angles)  # (N, B) end points, map frame
        end_y = lidar_y + readings * np.sin(theta + angles)
        rows, cols = self.grid.cells_of(end_x, end_y)  # float: NaN for a non-finite point
        inside = (rows >= 0) & (rows < self.grid.height) & (cols >= 0) & (cols < self.grid.width)
        rows = np.where(inside, rows, 0).astype(int)
        cols = np.where(inside, cols, 0).astype(int)
        distance = np.where(inside, self.field[rows, cols], np.inf)  # off the map: no wall
        sigma = self.p["sigma_hit_m"]
        z_random = self.p["z_random"]
        beam = (1.0 - z_random) * np.exp(-0.5 * (distance / sigma) ** 2) + z_random
        log_likelihood = np.log(beam).sum(axis=1)
        return np.exp(log_likelihood - log_likelihood.max())  # scaled: no underflow

    def _resample(self) -> None:
        """Low-variance resampling (one random offset, evenly spaced pointers)."""
        n = len(self.particles)
        pointers = (self.rng.uniform() + np.arange(n)) / n
        picks = np.minimum(np.searchsorted(np.cumsum(self.weights), pointers), n - 1)
        self.particles = self.particles[picks].copy()
        self.weights = np.full(n, 1.0 / n)

    def _spread(self) -> tuple[float, float]:
        """Weighted position std (m) and circular heading std (rad) of the particles."""
        w = self.weights
        mean_xy = w @ self.particles[:, :2]
        spread_xy = math.sqrt(float(w @ np.sum((self.particles[:, :2] - mean_xy) ** 2, axis=1)))
        headings = self.particles[:, 2]
        resultant = abs(complex(w @ np.cos(headings), w @ np.sin(headings)))
        spread_theta = math.sqrt(max(-2.0 * math.log(max(resultant, 1e-12)), 0.0))
        return spread_xy, spread_theta

    # --- results ----------------------------------------------------------------------------
    @property
    def estimate(self) -> tuple[float, float, float]:
        """The weighted mean pose (circular mean of the headings)."""
        w = self.weights
        x, y = w @ self.particles[:, :2]
        theta = math.atan2(w @ np.sin(self.particles[:, 2]), w @ np.cos(self.particles[:, 2]))
        return float(x), float(y), theta

    @property
    def covariance(self) -> np.ndarray:
        """Weighted covariance of (x, y, theta) (headings about the mean)."""
        x, y, theta = self.estimate
        offsets = self.particles - np.array([x, y, theta])
        offsets[:, 2] = np.arctan2(np.sin(offsets[:, 2]), np.cos(offsets[:, 2]))
        return (offsets * self.weights[:, None]).T @ offsets

    @property
    def localized(self) -> bool:
        """The particles have been tightly together for localized_updates updates."""
        return self._tight_updates >= int(self.p["localized_updates"])
