"""The chain's behaviour rules (amr_common.navigation_behaviour), without ROS."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.navigation_behaviour import (
    GoalCheck,
    Handover,
    KidnapSchedule,
    OdometryClock,
    OdometryHold,
    ScanNovelty,
    as_sent_pose,
    as_sent_ranges,
    as_sent_scan_geometry,
    limit_command,
    stamp_ns,
    timer_action,
)


def test_handover_plans_on_the_first_localization_and_after_each_loss():
    handover = Handover()
    events = [handover.update(flag) for flag in (False, True, True, False, False, True)]
    assert events == [None, "localized", None, "lost", None, "relocalized"]
    assert [handover.plans(e) for e in events] == [False, True, False, False, False, True]
    assert not handover.explorer_in_charge
    assert not Handover(replan_on_relocalization=False).plans("relocalized")


def test_goal_is_reached_only_while_localized_and_the_run_ends_after_the_rest():
    check = GoalCheck((1.0, 0.0), tolerance=0.15, rest_time=0.1)
    assert not check.update(1.0, (0.95, 0.0), localized=False, resting=True, dt=0.05)
    assert check.reached_time is None, "a lost robot at the goal has not arrived"
    assert not check.update(1.05, (0.95, 0.0), localized=True, resting=False, dt=0.05)
    assert check.reached_time == 1.05
    assert not check.update(1.10, (0.97, 0.0), localized=True, resting=True, dt=0.05)
    assert check.update(1.15, (0.97, 0.0), localized=False, resting=True, dt=0.05)
    assert check.rest_since == pytest.approx(1.05)
    assert GoalCheck((0.0, 0.0), 0.15, 0.0).update(0.05, (0.1, 0.0), True, True, 0.05)
    assert not GoalCheck(None, 0.15, 0.0).update(0.05, (0.0, 0.0), True, True, 0.05)


def test_a_scan_is_new_when_its_float32_readings_differ():
    novelty = ScanNovelty()
    scan = np.array([1.0, 2.0, 3.0])
    assert novelty.is_new(scan)
    assert not novelty.is_new(scan.copy()), "the held scan re-published"
    assert not novelty.is_new(scan + 1e-12), "below float32: the same LaserScan"
    assert novelty.is_new(scan + 1e-3)


def test_odometry_clock_skips_late_stamps_gaps_and_restarts_after_a_jump_back():
    clock = OdometryClock(max_gap_s=1.0)
    assert clock.advance(stamp_ns(0.0)) == (None, "first")
    assert clock.advance(stamp_ns(0.05)) == (pytest.approx(0.05, abs=1e-15), "ok")
    assert clock.advance(stamp_ns(0.05)) == (None, "back")
    assert clock.advance(stamp_ns(1.5)) == (None, "gap")
    assert clock.advance(stamp_ns(1.55))[1] == "ok"
    assert clock.advance(stamp_ns(0.2)) == (None, "jumped back")
    assert clock.advance(stamp_ns(0.25))[1] == "ok", "integrating again from the new stamp"
    assert clock.advance(stamp_ns(0.30))[0] == (stamp_ns(0.30) - stamp_ns(0.25)) * 1e-9


def test_odometry_hold_changes_the_twist_only_with_each_odom_message():
    hold = OdometryHold(0.1, 0.0, 0.0)
    seen = [hold.update(0.05 * k, 0.01 * k, 0.0)[0] for k in range(1, 6)]
    assert seen == pytest.approx([0.01, 0.02, 0.02, 0.04, 0.04])  # held 0.1 s
    every_step = OdometryHold(None, 0.0, 0.0)
    assert every_step.update(0.05, 0.1, 0.2) == (0.1, 0.2)
    with_pose = OdometryHold(0.1, 0.0, 0.0, (0.0, 0.0, 0.0))  # the mapping episode's pose too
    with_pose.update(0.05, 0.1, 0.0, (0.005, 0.0, 0.0))
    assert with_pose.update(0.1, 0.1, 0.0, (0.01, 0.0, 0.0))[2] == (0.01, 0.0, 0.0)
    assert with_pose.update(0.15, 0.2, 0.0, (0.02, 0.0, 0.0)) == (0.1, 0.0, (0.01, 0.0, 0.0))


def test_kidnapping_happens_once_from_its_time_on():
    schedule = KidnapSchedule((1.0, 0.5, -0.5, math.pi))
    assert schedule.due(0.95) is None
    assert schedule.due(1.0 - 1e-12) == (0.5, -0.5, math.pi)
    assert schedule.due(1.05) is None
    assert KidnapSchedule(None).due(5.0) is None


def test_what_crosses_a_topic():
    ranges = as_sent_ranges([0.1, math.inf, math.nan])
    assert ranges.dtype == np.float64 and ranges[0] == float(np.float32(0.1)) != 0.1
    assert math.isinf(ranges[1]) and math.isnan(ranges[2])
    angle_min, increment, rays, range_min, range_max = as_sent_scan_geometry(
        0.0, math.radians(1.0), 360, 0.12, 3.5)
    assert increment == float(np.float32(math.radians(1.0))) and rays == 360
    x, y, theta = as_sent_pose((1.0, 2.0, 3 * math.pi / 2))
    assert (x, y) == (1.0, 2.0) and theta == pytest.approx(-math.pi / 2, abs=1e-15)
    assert stamp_ns(0.15000000000000002) == 150_000_000
    assert limit_command(1.0, -9.0) == (0.22, -2.84)
    assert limit_command(math.nan, 0.1) == (0.0, 0.0)


def test_stale_or_missing_data_means_zero_whoever_commands():
    assert timer_action(None, 0.5, in_charge=True) == "zero"
    assert timer_action(0.6, 0.5, in_charge=False) == "zero", "a stale 'not in charge' too"
    assert timer_action(0.5, 0.5, in_charge=False) == "silent"
    assert timer_action(0.1, 0.5, in_charge=True) == "compute"


def test_a_scan_with_another_geometry_is_new():
    novelty = ScanNovelty()
    assert novelty.is_new([1.0, 2.0], (0.0, 0.5))
    assert not novelty.is_new([1.0, 2.0], (0.0, 0.5))
    assert novelty.is_new([1.0, 2.0], (0.1, 0.5)), "the LDS-02's angles change per scan"
