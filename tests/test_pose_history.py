"""PoseHistory: the odometry pose at a scan's stamp, interpolated; bad stamps and poses refused."""
from __future__ import annotations

import math

import pytest

from amr_common.pose_history import GAP, LATER, NON_FINITE, OLDER, OUT_OF_ORDER, PoseHistory

MS = 1_000_000


def test_interpolates_between_the_poses_around_the_stamp_the_short_way_round():
    history = PoseHistory(max_gap_s=0.5)
    assert history.pose_at(0) == LATER
    assert history.add(1000 * MS, (0.0, 0.0, math.pi - 0.1)) is None
    assert history.add(1050 * MS, (0.1, -0.2, -math.pi + 0.1)) is None  # across +-pi
    x, y, theta = history.pose_at(1025 * MS)
    assert (x, y) == pytest.approx((0.05, -0.1))
    assert math.cos(theta) == pytest.approx(-1.0) and abs(math.sin(theta)) < 1e-9
    assert history.pose_at(1050 * MS) == (0.1, -0.2, -math.pi + 0.1), "an exact stamp: its pose"
    assert history.pose_at(1051 * MS) == LATER, "newer than the newest: wait"
    assert history.pose_at(999 * MS) == OLDER


def test_gaps_stamps_going_back_and_non_finite_poses():
    history = PoseHistory(max_gap_s=0.5)
    history.add(0, (0.0, 0.0, 0.0))
    history.add(1000 * MS, (1.0, 0.0, 0.0))
    assert history.pose_at(500 * MS) == GAP, "no pose within 0.5 s: not interpolated"
    assert history.add(900 * MS, (0.9, 0.0, 0.0)) == OUT_OF_ORDER
    assert history.add(1000 * MS, (0.9, 0.0, 0.0)) == OUT_OF_ORDER
    for bad in ((math.nan, 0.0, 0.0), (0.0, math.inf, 0.0), ("x", 0, 0), (1.0, 2.0)):
        assert history.add(1100 * MS, bad) == NON_FINITE
    # Time went back by more than max_gap_s (a restarted clock): start again from there.
    assert history.add(100 * MS, (5.0, 5.0, 0.0)) is None
    assert len(history) == 1 and history.newest_stamp == 100 * MS


def test_keeps_only_the_last_span_seconds():
    history = PoseHistory(span_s=1.0)
    for i in range(100):  # 5 s at 20 Hz
        history.add(i * 50 * MS, (i * 0.01, 0.0, 0.0))
    assert 20 <= len(history) <= 22
    assert history.pose_at(4000 * MS) == pytest.approx((0.8, 0.0, 0.0))
    assert history.pose_at(3000 * MS) == OLDER
