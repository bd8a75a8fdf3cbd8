"""When is the filter localized? The estimate, its cluster, the scan match and the decision.

Why not "the particles' spread is small": in the course's mazes (0.4 m corridors on a 0.4 m grid)
a pose rotated by 90 or 180 degrees, or shifted by one cell, explains almost every beam, so the
particles can gather tightly around a WRONG pose; a spread test then declares it (7 of 30 global
runs in the prototypes of localization-planning.md). The test here needs three things, held for
`localize_updates` consecutive measurement updates (the robot moving between them):
1. one dominant cluster: the particles within `cluster_radius_m` / `cluster_angle_rad` of the
   heaviest region carry at least `cluster_min_share` of the weight (two symmetric hypotheses
   alive at once fail this);
2. the estimate (the cluster's weighted mean) explains the WHOLE scan: at least
   `localize_match_fraction` of all rays, ray-cast exactly from the estimate (not the table, not
   only the beams the filter weighs), match the reading within `match_tolerance_m`, a reading
   without a return matching only a ray that expects none;
3. both hold at every update of the streak: a wrong pose that happens to fit one corridor stops
   fitting once the robot moves on.
Once localized, the scan match is checked at every update: below `keep_match_fraction` for
`lost_updates` updates in a row, the filter reports localized false and starts a global search
(kidnapping, a wrong convergence). A dominant cluster that explains less than
`reinit_match_fraction` of the rays for `reinit_updates` updates also restarts the search.
No rclpy import.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from amr_common.raycast import scan_into


@dataclass
class Cluster:
    """The heaviest group of particles and its weighted mean."""

    pose: tuple[float, float, float]  # weighted mean (x, y, theta)
    share: float  # weight carried by the cluster, in [0, 1]
    members: np.ndarray  # (N,) bool


def weighted_pose_mean(particles: np.ndarray, weights: np.ndarray) -> tuple[float, float, float]:
    """Weighted mean position and circular mean heading of particles (N, 3)."""
    total = float(weights.sum())
    if not total > 0.0:
        weights = np.ones(len(particles))
        total = float(len(particles))
    x = float(np.dot(weights, particles[:, 0]) / total)
    y = float(np.dot(weights, particles[:, 1]) / total)
    theta = math.atan2(float(np.dot(weights, np.sin(particles[:, 2]))),
                       float(np.dot(weights, np.cos(particles[:, 2]))))
    return x, y, theta


def dominant_cluster(particles: np.ndarray, weights: np.ndarray, radius: float,
                     angle: float) -> Cluster:
    """The particles within `radius` (m) and `angle` (rad) of the heaviest region.

    The region is found on a coarse histogram (bins of radius x radius x angle, weighted), then
    the cluster is gathered around that bin's weighted mean and re-centred once on its own mean.
    """
    x, y, theta = particles[:, 0], particles[:, 1], particles[:, 2]
    bx = np.floor((x - x.min()) / radius).astype(np.int64)
    by = np.floor((y - y.min()) / radius).astype(np.int64)
    nbt = max(int(math.ceil(2.0 * math.pi / angle)), 1)
    bt = np.minimum(np.floor((theta + math.pi) / angle).astype(np.int64), nbt - 1)
    nby = int(by.max()) + 1
    key = (bx * nby + by) * nbt + bt
    heaviest = int(np.argmax(np.bincount(key, weights=weights)))
    in_bin = key == heaviest
    centre = weighted_pose_mean(particles[in_bin], weights[in_bin])
    members = in_bin
    for _ in range(2):
        near = ((x - centre[0]) ** 2 + (y - centre[1]) ** 2 <= radius * radius) & \
            (np.abs(np.remainder(theta - centre[2] + math.pi, 2.0 * math.pi) - math.pi) <= angle)
        if not near.any():
            break
        members = near
        centre = weighted_pose_mean(particles[members], weights[members])
    total = float(weights.sum())
    share = float(weights[members].sum() / total) if total > 0 else 0.0
    return Cluster(pose=centre, share=share, members=members)


def pose_covariance(particles: np.ndarray, weights: np.ndarray,
                    mean: tuple[float, float, float]) -> np.ndarray:
    """3 x 3 weighted covariance of (x, y, theta) about `mean` (headings wrapped around it)."""
    total = float(weights.sum())
    w = weights / total if total > 0 else np.full(len(weights), 1.0 / max(len(weights), 1))
    d = np.column_stack([particles[:, 0] - mean[0], particles[:, 1] - mean[1],
                         np.remainder(particles[:, 2] - mean[2] + math.pi, 2.0 * math.pi)
                         - math.pi])
    return (d * w[:, None]).T @ d


class ScanMatcher:
    """Fraction of a scan's rays that a pose explains, ray-cast exactly against the walls."""

    def __init__(self, segments: np.ndarray, angle_min: float, angle_increment: float,
                 rays: int, range_min: float, range_max: float, lidar_offset: float,
                 allowed: Callable[[float, float], bool] | None = None) -> None:
        """`allowed(x, y)`: False where the robot centre cannot be (a pose there explains
        nothing: match fraction 0)."""
        angles = angle_min + angle_increment * np.arange(rays)
        self.segments = np.ascontiguousarray(segments, dtype=np.float64)
        self.base_cos, self.base_sin = np.cos(angles), np.sin(angles)
        self.range_min, self.range_max = float(range_min), float(range_max)
        self.lidar_offset = float(lidar_offset)
        self.rays = int(rays)
        self.allowed = allowed
        self._expected = np.empty(rays)
        self._zeros = np.zeros(rays)

    def expected(self, pose: tuple[float, float, float]) -> np.ndarray:
        """The scan a LiDAR on the robot at `pose` reads (NaN = no return), as a new array."""
        x, y, theta = pose
        ox = x + self.lidar_offset * math.cos(theta)
        oy = y + self.lidar_offset * math.sin(theta)
        scan_into(self.segments, ox, oy, theta, self.base_cos, self.base_sin, self.range_min,
                  self.range_max, math.nan, self._zeros, self._expected)
        return self._expected.copy()

    def match_fraction(self, pose: tuple[float, float, float], ranges: np.ndarray,
                       tolerance: float) -> float:
        """Share of rays where reading and expectation agree within `tolerance` (m), or where
        both have no return. Readings: NaN, inf, 0.0 or outside the limits = no return."""
        if self.allowed is not None and not self.allowed(pose[0], pose[1]):
            return 0.0
        expected = self.expected(pose)
        r = np.asarray(ranges, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(r) & (r >= self.range_min) & (r <= self.range_max) & (r > 0)
            expected_valid = np.isfinite(expected)
            close = np.abs(r - expected) <= tolerance
        matches = (valid & expected_valid & close) | (~valid & ~expected_valid)
        return float(np.count_nonzero(matches)) / max(self.rays, 1)


@dataclass
class CheckSettings:
    """Thresholds of the localized test (see the module docstring)."""

    match_tolerance_m: float = 0.03
    localize_match_fraction: float = 0.97
    localize_updates: int = 10
    cluster_min_share: float = 0.9
    keep_match_fraction: float = 0.8
    lost_updates: int = 3
    reinit_match_fraction: float = 0.5
    reinit_updates: int = 3


class LocalizedDecision:
    """The localized flag with its streaks; `update()` once per measurement update."""

    def __init__(self, settings: CheckSettings) -> None:
        self.settings = settings
        self.reset()

    def reset(self) -> None:
        """Not localized, all streaks at zero (after any re-initialization)."""
        self.localized = False
        self.good_streak = 0
        self.bad_streak = 0
        self.poor_streak = 0

    def confirm(self) -> None:
        """The candidate pose is unambiguous: localized from now on."""
        self.localized = True
        self.bad_streak = 0

    def reject(self) -> None:
        """The candidate pose is ambiguous: start the streak again."""
        self.good_streak = 0

    def update(self, share: float, match: float) -> str:
        """Record one update: returns "candidate" (the streak is complete: check for ambiguity,
        then confirm() or reject()), "lost" (just lost: re-initialize globally), "reinit"
        (converged on a pose that does not explain the scan) or ""."""
        s = self.settings
        if self.localized:
            self.bad_streak = self.bad_streak + 1 if match < s.keep_match_fraction else 0
            if self.bad_streak >= s.lost_updates:
                self.reset()
                return "lost"
            return ""
        good = share >= s.cluster_min_share and match >= s.localize_match_fraction
        self.good_streak = self.good_streak + 1 if good else 0
        if self.good_streak >= s.localize_updates:
            return "candidate"  # the caller checks for ambiguity, then confirm() or reject()
        poor = share >= s.cluster_min_share and match < s.reinit_match_fraction
        self.poor_streak = self.poor_streak + 1 if poor else 0
        if self.poor_streak >= s.reinit_updates:
            self.reset()
            return "reinit"
        return ""


__all__ = ["Cluster", "weighted_pose_mean", "dominant_cluster", "pose_covariance", "ScanMatcher",
           "CheckSettings", "LocalizedDecision"]
