"""amr_common.geometry: the one angle wrap and yaw <-> quaternion every package uses."""
from __future__ import annotations

import math

import numpy as np
import pytest
from transforms3d.euler import euler2quat, quat2euler

from amr_common.geometry import (
    angle_difference,
    polyline_length,
    quaternion_to_yaw,
    without_repeats,
    wrap_angle,
    wrap_angles,
    yaw_to_quaternion,
)


def test_wrap_angle_range_and_edges():
    assert wrap_angle(math.pi) == math.pi and wrap_angle(-math.pi) == math.pi
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_angle(-3 * math.pi / 2) == pytest.approx(math.pi / 2)
    angles = np.random.default_rng(0).uniform(-50, 50, 2000)
    wrapped = np.array([wrap_angle(a) for a in angles])
    assert np.all(wrapped > -math.pi) and np.all(wrapped <= math.pi)
    np.testing.assert_allclose(np.cos(wrapped), np.cos(angles), atol=1e-12)
    np.testing.assert_allclose(np.sin(wrapped), np.sin(angles), atol=1e-12)


def test_angle_difference_takes_the_short_way_across_pi():
    assert angle_difference(math.pi - 0.1, -math.pi + 0.1) == pytest.approx(-0.2)
    assert angle_difference(-math.pi + 0.1, math.pi - 0.1) == pytest.approx(0.2)


@pytest.mark.parametrize("yaw", [0.0, 1.0, -2.5, math.pi - 1e-6, -math.pi + 1e-6, math.pi])
def test_yaw_quaternion_round_trip_and_transforms3d(yaw):
    x, y, z, w = yaw_to_quaternion(yaw)
    assert quaternion_to_yaw(x, y, z, w) == pytest.approx(wrap_angle(yaw), abs=1e-9)
    qw, qx, qy, qz = euler2quat(0.0, 0.0, yaw)
    assert (x, y, z, w) == pytest.approx((qx, qy, qz, qw), abs=1e-15)


def test_quaternion_to_yaw_of_general_rotations_matches_transforms3d():
    rng = np.random.default_rng(1)
    for q in rng.normal(size=(200, 4)):
        x, y, z, w = q
        expected = quat2euler(np.array([w, x, y, z]) / np.linalg.norm(q), "sxyz")[2]
        assert quaternion_to_yaw(x, y, z, w) == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("scale", [3.0, 1e-5, 1e300, 1e-300 * 1e299])
def test_non_unit_quaternions_keep_their_yaw(scale):
    """A 1e300-norm quaternion used to overflow the norm and give a wrong yaw ."""
    x, y, z, w = yaw_to_quaternion(0.7)
    assert quaternion_to_yaw(x * scale, y * scale, z * scale, w * scale) == pytest.approx(0.7)


@pytest.mark.parametrize("q", [(0.0, 0.0, 0.0, 0.0), (math.nan, 0.0, 0.0, 1.0),
                               (0.0, 0.0, math.inf, 1.0), (0.0, 0.0, 1e-9, 1e-9)])
def test_unusable_quaternions_raise(q):
    with pytest.raises(ValueError, match="quaternion"):
        quaternion_to_yaw(*q)


def test_wrap_angles_of_arrays():
    angles = np.random.default_rng(2).uniform(-50, 50, 2000)
    wrapped = wrap_angles(angles)
    assert np.all(wrapped >= -math.pi) and np.all(wrapped < math.pi)
    np.testing.assert_allclose(np.cos(wrapped), np.cos(angles), atol=1e-12)
    np.testing.assert_allclose(np.sin(wrapped), np.sin(angles), atol=1e-12)
    assert wrap_angles(np.array([math.pi]))[0] == -math.pi


def test_polyline_length_and_repeated_points():
    path = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 4.0], [3.0, 5.0]])
    assert polyline_length(path) == pytest.approx(6.0)
    assert polyline_length(path[:1]) == 0.0 and polyline_length(path[:0]) == 0.0
    np.testing.assert_array_equal(without_repeats(path), path[[0, 1, 3]])
    np.testing.assert_array_equal(without_repeats(path[:1]), path[:1])
