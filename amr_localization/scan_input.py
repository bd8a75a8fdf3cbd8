"""One scan as the filter's measurement update uses it: de-skewed, with its tolerances and beams.

From the raw ranges of a scan: the rays moved to the LiDAR's pose now (scan_deskew, when the
sensor's rays were measured over a revolution: range_sensor), each ray's match tolerance and the
beam model's sigma scale (range_sensor: by the datasheet's band of its reading), and the weighed
beams at the de-skewed directions with the pose search's extra tolerance (scan_beams). Every
part of the update (weighing, the exhaustive pose search, the exact scan match, the rival
tracks) then judges the same scan the same way. No rclpy import.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from amr_common.sensors.scan_deskew import MotionHistory, deskew
from amr_common.sensors.scan_returns import return_mask
from amr_localization.range_sensor import RangeSensor
from amr_localization.scan_beams import BeamReadings, ScanBeams


@dataclass(frozen=True)
class TakenScan:
    """A scan ready for the update (see the module docstring)."""

    ranges: np.ndarray  # (rays,) m from the LiDAR's pose now (no return: as read)
    angles: np.ndarray | None  # (rays,) rad, de-skewed; None: the scan geometry's own
    tolerances: np.ndarray  # (rays,) m: a reading matches within this
    beams: ScanBeams  # the weighed beams at this scan's directions
    scales: np.ndarray | None  # (rays,) the beam model's sigma scales; None: all sigma_hit

    def readings(self) -> BeamReadings:
        """The weighed beams split by reading, for the beam model's kernels."""
        return self.beams.split(self.beams.readings_mm(self.ranges), self.scales)


def take_scan(ranges: np.ndarray, age_s: float, sensor: RangeSensor, beams: ScanBeams,
              nominal_angles: np.ndarray, limits: tuple[float, float], history: MotionHistory,
              lidar_offset: float, table_angles: int) -> TakenScan:
    """The scan `ranges` (at nominal_angles, rad), stamped age_s before the newest prediction.

    limits: the valid range limits (m); history: the odometry the filter predicted with;
    table_angles: the expected-range table's directions.
    """
    angles = None
    ages = sensor.ray_ages(nominal_angles, age_s)
    if ages is not None:
        angles, ranges = deskew(nominal_angles, ranges, return_mask(ranges, *limits), ages,
                                history, lidar_offset)
    tolerances = sensor.tolerances(ranges)
    uniform = sensor.spread_free and sensor.map_uncertainty_m == 0.0
    extra_mm = None if uniform else np.round(
        (tolerances - sensor.match_tolerance_m) * 1000.0).astype(np.int32)
    return TakenScan(ranges, angles, tolerances, beams.turned(angles, table_angles, extra_mm),
                     None if uniform else sensor.sigma_scales(ranges))


__all__ = ["TakenScan", "take_scan"]
