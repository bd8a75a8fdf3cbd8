"""amr_common.sensors.range_calibration: a LiDAR's range correction from walls at taped ranges."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.sensors.range_calibration import (
    MIN_WALL_RETURNS,
    RangeCorrection,
    fit_correction,
    wall_distance,
    wall_points,
)

INCREMENT = 2 * math.pi / 360  # an LDS-01 scan: 360 rays from 0 (straight ahead)
ANGLES = np.arctan2(np.sin(INCREMENT * np.arange(360)), np.cos(INCREMENT * np.arange(360)))


def wall_scan(distance: float, rng: np.random.Generator | None = None, sigma: float = 0.0,
              tilt: float = 0.0) -> np.ndarray:
    """Ranges of a wall `distance` m ahead (its normal turned by `tilt`), no return elsewhere."""
    with np.errstate(divide="ignore"):
        ranges = distance / np.cos(ANGLES - tilt)
    if rng is not None:
        ranges = ranges + rng.normal(0.0, sigma, ranges.size)
    return np.where(np.abs(ANGLES) < 0.6, ranges, 0.0)


@pytest.mark.parametrize("values, message", [
    ([0.3, 0.01, 1.0], "needs pairs"),
    ([0.3, math.nan, 1.0, 0.0], "not finite"),
    ([0.3, 0.0, math.inf, 0.0], "not finite"),
    ([1.0, 0.0, 0.3, 0.0], "positive and ascending"),
    ([1.0, 0.0, 1.0, 0.01], "positive and ascending"),
    ([0.0, 0.0, 1.0, 0.0], "positive and ascending"),
    ([1.0, -0.3, 2.0, 0.0], "more than any LiDAR's error"),
])
def test_a_malformed_correction_is_refused_saying_why(values, message):
    with pytest.raises(ValueError, match=message):
        RangeCorrection.from_list(values)


def test_no_values_is_no_correction_and_the_list_round_trips():
    assert RangeCorrection.from_list([]) is None
    values = [0.31, -0.01, 1.03, -0.03, 2.06, -0.06]
    assert RangeCorrection.from_list(values).as_list() == values


def test_apply_interpolates_holds_below_extends_beyond_and_keeps_no_returns():
    correction = RangeCorrection.from_list([0.5, 0.01, 1.0, -0.02, 2.0, -0.06])
    ranges = np.array([0.2, 0.75, 1.5, 3.0, 0.0, math.nan, math.inf])
    corrected = correction.apply(ranges)
    assert corrected[:4] == pytest.approx([0.21,            # below the first: its correction
                                           0.75 - 0.005,    # halfway between 0.01 and -0.02
                                           1.5 - 0.04,
                                           3.0 - 0.10])     # along the last two: -0.04 per m
    assert corrected[4] == 0.0 and math.isnan(corrected[5]) and corrected[6] == math.inf


def test_wall_points_are_the_returns_ahead():
    points = wall_points(wall_scan(1.0), 0.0, INCREMENT)
    assert len(points) == 19  # +-0.17 rad of 1 deg rays; the zeros beyond are no returns
    assert points[:, 0] == pytest.approx(np.ones(19))


def test_wall_distance_of_a_wall_seen_straight_or_at_a_slant():
    assert wall_distance(wall_points(wall_scan(1.2), 0.0, INCREMENT)) == pytest.approx(1.2)
    slanted = wall_points(wall_scan(1.2, tilt=0.3), 0.0, INCREMENT)
    assert wall_distance(slanted) == pytest.approx(1.2)  # the perpendicular distance


def test_no_wall_distance_from_too_few_points_or_points_off_a_line():
    line = wall_points(wall_scan(1.0), 0.0, INCREMENT)
    assert wall_distance(line[:MIN_WALL_RETURNS - 1]) is None
    assert wall_distance(line[:MIN_WALL_RETURNS]) == pytest.approx(1.0)
    zigzag = line * np.where(np.arange(len(line)) % 2, 0.6, 1.4)[:, None]  # 0.6 m and 1.4 m
    assert wall_distance(zigzag) is None
    assert wall_distance(np.empty((0, 2))) is None


def test_pooled_scans_read_the_wall_where_single_noisy_scans_read_it_short():
    """One scan at the LDS-01's 3.5 % noise reads the wall ~5 mm short, 25 pooled do not.

    The line through one scan tilts and passes closer; the same 200 scans both ways.
    """
    rng = np.random.default_rng(7)
    scans = [wall_points(wall_scan(1.0, rng, sigma=0.035), 0.0, INCREMENT) for _ in range(200)]
    single = np.mean([wall_distance(points) for points in scans]) - 1.0
    pooled = np.mean([wall_distance(np.vstack(scans[i:i + 25]))
                      for i in range(0, 200, 25)]) - 1.0
    assert single < -0.003
    assert abs(pooled) < 0.0015


def test_fit_correction_from_readings_and_a_wall_not_seen():
    correction = fit_correction({2.0: 2.06, 0.3: 0.309, 1.0: 1.03})  # any order
    assert correction.as_list() == pytest.approx([0.309, -0.009, 1.03, -0.03, 2.06, -0.06])
    assert correction.apply(np.array([1.03, 2.06])) == pytest.approx([1.0, 2.0])
    with pytest.raises(ValueError, match="no reading of the wall at 1 m"):
        fit_correction({0.3: 0.31, 1.0: None})
