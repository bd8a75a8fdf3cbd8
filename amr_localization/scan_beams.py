"""The beams of a scan the filter weighs: which rays, their table directions, their readings.

From the scan's geometry (angle_min, angle_increment, ray count, range limits) and the number of
beams wanted: the rays used (evenly spread), each one's direction relative to the robot's heading
in bins of the expected-range table (whole part and fraction: the common scans' beams fall on
whole bins, which the kernels exploit), and the conversion of a scan's readings to the integer
millimetres the kernels compare with the table. A de-skewed scan (scan_deskew) moves each ray's
direction: `turned` gives the same beams at those directions. Each valid beam carries its
sigma scale (range_sensor: the beam model's sigma grows with the range) and the pose search's
extra tolerance (`search_extra_mm`). No rclpy import.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from amr_common.jit import jit
from amr_common.sensors.scan_returns import is_return
from amr_localization.expected_ranges import NO_RANGE_MM
from amr_localization.range_sensor import SCALE_ONE

_WHOLE_BIN = 1e-9  # a direction this close to a whole table bin is that bin


def _reading_to_mm(ranges, range_min, range_max, out):
    for i in range(ranges.shape[0]):
        r = ranges[i]
        if is_return(r, range_min, range_max) and r < 2.0e6:  # 2e6 m: int32 mm
            out[i] = np.int32(round(r * 1000.0))
        else:
            out[i] = -1


_reading_to_mm_kernel = jit(_reading_to_mm)


def reading_to_mm(ranges: np.ndarray, range_min: float, range_max: float) -> np.ndarray:
    """Ranges (m) as int32 mm, -1 for readings without a return.

    Readings without a return: NaN, inf, 0.0, outside [range_min, range_max]. The measured side
    of the beam model.
    """
    r = np.ascontiguousarray(ranges, dtype=np.float64)
    out = np.empty(r.shape, dtype=np.int32)
    _reading_to_mm_kernel(r, float(range_min), float(range_max), out)
    return out


class BeamReadings(NamedTuple):
    """One scan's beams split by reading: with a return (and its mm) and without one."""

    valid_whole: np.ndarray  # int64 table bins (whole part) of the beams with a return
    valid_fraction: np.ndarray  # float64 fractional part of their bins
    valid_mm: np.ndarray  # int32 readings (mm)
    invalid_whole: np.ndarray  # int64: the beams without a return (NaN, inf, 0.0, out of limits)
    invalid_fraction: np.ndarray
    # int64 per beam with a return: sigma_hit / the beam's sigma in fixed point (1 << 16 = 1)
    valid_scale: np.ndarray


def _table_bins(angles: np.ndarray, table_angles: int) -> tuple[np.ndarray, ...]:
    """(bins, whole, fraction) of directions `angles` (rad) in a table of table_angles bins."""
    bins = np.remainder(angles * (table_angles / (2.0 * math.pi)), table_angles)
    nearest = np.round(bins)
    bins = np.where(np.abs(bins - nearest) < _WHOLE_BIN, nearest, bins) % table_angles
    whole = np.floor(bins).astype(np.int64)
    return bins, whole, bins - whole


@dataclass(frozen=True)
class ScanBeams:
    """The weighed beams of one scan geometry (see the module docstring)."""

    rays: np.ndarray  # int64 indices of the weighed rays, increasing
    bins: np.ndarray  # float64 their directions from the heading in table bins, in [0, angles)
    whole: np.ndarray  # int64 floor(bins)
    fraction: np.ndarray  # float64 bins - whole, 0 for beams on a whole bin
    range_min: float  # m
    range_max: float  # m
    # int32 per weighed beam: the pose search's tolerance beyond its own (wider readings), or None
    search_extra_mm: np.ndarray | None = None

    @classmethod
    def from_geometry(cls, angle_min: float, angle_increment: float, rays: int,
                      range_min: float, range_max: float, beams: int,
                      table_angles: int) -> "ScanBeams":
        """`beams` rays evenly spread over the scan; ValueError for an unusable geometry."""
        if not (math.isfinite(angle_min) and math.isfinite(angle_increment)
                and angle_increment != 0.0 and rays >= 1):
            raise ValueError(f"unusable scan geometry: angle_min {angle_min}, increment "
                             f"{angle_increment}, {rays} rays")
        if not (math.isfinite(range_min) and math.isfinite(range_max) and
                0.0 <= range_min < range_max):
            raise ValueError(f"unusable scan limits: range_min {range_min}, range_max {range_max}")
        used = np.unique(np.round(np.linspace(0, rays, min(beams, rays), endpoint=False))
                         .astype(np.int64))
        bins, whole, fraction = _table_bins(angle_min + angle_increment * used, table_angles)
        return cls(used, bins, whole, fraction, float(range_min), float(range_max))

    def turned(self, angles: np.ndarray | None, table_angles: int,
               search_extra_mm: np.ndarray | None = None) -> "ScanBeams":
        """The same beams pointing at angles[rays] (every ray's angle, rad; None: as they are).

        search_extra_mm: every ray's extra pose-search tolerance (the weighed beams' kept).
        """
        extra = None if search_extra_mm is None else \
            np.ascontiguousarray(search_extra_mm[self.rays], dtype=np.int32)
        if angles is None:
            return replace(self, search_extra_mm=extra)
        bins, whole, fraction = _table_bins(np.asarray(angles)[self.rays], table_angles)
        return replace(self, bins=bins, whole=whole, fraction=fraction, search_extra_mm=extra)

    @property
    def count(self) -> int:
        """Number of weighed beams."""
        return int(self.rays.size)

    @property
    def fractional(self) -> bool:
        """True if some beam falls between two table directions."""
        return bool(np.any(self.fraction > 0.0))

    @property
    def limits_mm(self) -> tuple[int, int]:
        """The valid range limits in whole mm (a table range outside them means no return).

        Below the table's NO_RANGE_MM (a ray that hits nothing), whatever range_max says (the
        LD08 driver publishes 100 m).
        """
        return int(math.ceil(self.range_min * 1000.0)), min(int(self.range_max * 1000.0),
                                                             NO_RANGE_MM - 1)

    def readings_mm(self, ranges: np.ndarray) -> np.ndarray:
        """The weighed beams' readings as int32 mm, -1 for no return (beam_model)."""
        return reading_to_mm(ranges[self.rays], self.range_min, self.range_max)

    def split(self, z_mm: np.ndarray, scales: np.ndarray | None = None) -> BeamReadings:
        """The beams with a return and those without one, for the kernels' two loops.

        scales: every ray's sigma scale (range_sensor.RangeSensor.sigma_scales), default 1.
        """
        valid = z_mm >= 0
        keep = np.ascontiguousarray
        scale = np.full(int(np.count_nonzero(valid)), SCALE_ONE, dtype=np.int64) \
            if scales is None else keep(scales[self.rays][valid], dtype=np.int64)
        return BeamReadings(keep(self.whole[valid]), keep(self.fraction[valid]),
                            keep(z_mm[valid]), keep(self.whole[~valid]),
                            keep(self.fraction[~valid]), scale)
