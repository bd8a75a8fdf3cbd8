"""The one rule for which LaserScan readings are returns (amr_common.sensors.scan_returns)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.sensors import scan_returns
from amr_common.sensors.scan_returns import is_return, return_mask

READINGS = [0.5, 0.12, 3.5, 0.119, 3.501, 0.0, -0.2, math.nan, math.inf, -math.inf, 1e300]
EXPECTED = [True, True, True, False, False, False, False, False, False, False, False]


@pytest.mark.parametrize("reading, expected", list(zip(READINGS, EXPECTED)))
def test_a_return_is_finite_positive_and_within_the_scans_limits(reading, expected):
    assert is_return(reading, 0.12, 3.5) is expected
    assert scan_returns._is_return(reading, 0.12, 3.5) is expected  # the plain-Python twin


def test_the_mask_and_the_compiled_rule_agree_element_for_element():
    rng = np.random.default_rng(3)
    ranges = np.concatenate([READINGS, rng.uniform(-1.0, 5.0, 500)])
    ranges[rng.integers(0, ranges.size, 40)] = np.nan
    for limits in [(0.12, 3.5), (0.0, 8.0), (0.016, math.inf)]:
        mask = return_mask(ranges, *limits)
        assert mask.tolist() == [is_return(float(r), *limits) for r in ranges]
    assert not return_mask([0.0], 0.0, 3.5)[0], "0.0 is no return even when range_min is 0"
