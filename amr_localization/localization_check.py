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

from amr_common.jit import jit
from amr_common.sensors.scan_returns import is_return
from amr_common.world.raycast import scan_into
from amr_localization.cluster import Cluster, dominant_cluster, weighted_pose_mean
from amr_localization.particle_filter_params import PARAMETERS


def _match_share(expected, ranges, range_min, range_max, tolerances, missing_unknown):
    """Share of the judged rays where reading and expectation agree.

    A ray agrees when reading and expectation are within its tolerance, or both have no return
    (expected: NaN = no return; readings: NaN, inf, 0.0 or outside the limits). A missing
    reading where a return is expected is a mismatch, or with missing_unknown (a real scanner
    drops rays) not judged at all. 0 if no ray is judged.
    """
    matches = 0
    judged = 0
    for i in range(ranges.shape[0]):
        r = ranges[i]
        valid = is_return(r, range_min, range_max)
        e = expected[i]
        if valid:
            judged += 1
            if e == e and abs(r - e) <= tolerances[i]:
                matches += 1
        elif e != e:
            judged += 1
            matches += 1
        elif not missing_unknown:
            judged += 1
    return matches / judged if judged > 0 else 0.0


match_share = jit(_match_share)


class ScanMatcher:
    """Fraction of a scan's rays that a pose explains, ray-cast exactly against the walls."""

    def __init__(self, segments: np.ndarray, angle_min: float, angle_increment: float,
                 rays: int, range_min: float, range_max: float, lidar_offset: float,
                 allowed: Callable[[float, float], bool] | None = None,
                 missing_unknown: bool = False) -> None:
        """Rays and limits of the scan, LiDAR position, where the robot can be.

        `allowed(x, y)`: False where the robot centre cannot be (a pose there explains
        nothing: match fraction 0). missing_unknown: a missing return where the map has a wall
        is not judged (range_sensor: real scanners drop rays), else a mismatch.
        """
        self.angles = angle_min + angle_increment * np.arange(rays)
        self.segments = np.ascontiguousarray(segments, dtype=np.float64)
        self.base_cos, self.base_sin = np.cos(self.angles), np.sin(self.angles)
        self._nominal = (self.base_cos, self.base_sin)
        self.range_min, self.range_max = float(range_min), float(range_max)
        self.lidar_offset = float(lidar_offset)
        self.rays = int(rays)
        self.allowed = allowed
        self.missing_unknown = bool(missing_unknown)
        self._expected = np.empty(rays)
        self._zeros = np.zeros(rays)

    def set_ray_angles(self, angles: np.ndarray | None) -> None:
        """Where this scan's rays point (rad, de-skewed: scan_deskew), or None for the nominal.

        Every match_fraction call until the next one casts the rays at these angles.
        """
        if angles is None:
            self.base_cos, self.base_sin = self._nominal
        else:
            self.base_cos, self.base_sin = np.cos(angles), np.sin(angles)

    def match_fraction(self, pose: tuple[float, float, float], ranges: np.ndarray,
                       tolerance) -> float:
        """Share of rays where reading and expectation agree.

        Within `tolerance` (m: one number, or one per ray), or where both have no return.
        Readings: NaN, inf, 0.0 or outside the limits = no return (see _match_share).
        """
        if self.allowed is not None and not self.allowed(pose[0], pose[1]):
            return 0.0
        x, y, theta = pose
        ox = x + self.lidar_offset * math.cos(theta)
        oy = y + self.lidar_offset * math.sin(theta)
        scan_into(self.segments, ox, oy, theta, self.base_cos, self.base_sin, self.range_min,
                  self.range_max, math.nan, self._zeros, self._expected)
        tolerances = np.broadcast_to(np.asarray(tolerance, dtype=np.float64), (self.rays,))
        return float(match_share(self._expected, np.asarray(ranges, dtype=np.float64),
                                 self.range_min, self.range_max,
                                 np.ascontiguousarray(tolerances), self.missing_unknown))


def _default(name: str):
    return PARAMETERS[name][0]


@dataclass
class CheckSettings:
    """Thresholds of the localized test (see the module docstring).

    The defaults are the filter's parameter table's (particle_filter_params: their one home).
    """

    match_tolerance_m: float = _default("match_tolerance_m")
    localize_match_fraction: float = _default("localize_match_fraction")
    localize_updates: int = _default("localize_updates")
    cluster_min_share: float = _default("cluster_min_share")
    keep_match_fraction: float = _default("keep_match_fraction")
    lost_updates: int = _default("lost_updates")
    reinit_match_fraction: float = _default("reinit_match_fraction")
    reinit_updates: int = _default("reinit_updates")


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
        """Record one measurement update and return what it decided.

        Record one update: returns "candidate" (the streak is complete: check for ambiguity,
        then confirm() or reject()), "lost" (just lost: re-initialize globally), "reinit"
        (converged on a pose that does not explain the scan) or "".
        """
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


__all__ = ["Cluster", "weighted_pose_mean", "dominant_cluster", "ScanMatcher", "CheckSettings",
           "LocalizedDecision"]
