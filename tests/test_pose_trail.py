"""amr_control.pose_trail: the wall follower's loop closure.

A loop is closed only by coming back to a recorded pose with the same heading, at least
MIN_LOOP_M of travel later.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_control import pose_trail
from amr_control.pose_trail import (
    CAPACITY,
    MATCH_HEADING_RAD,
    MATCH_RADIUS_M,
    MIN_LOOP_M,
    SPACING_M,
    PoseTrail,
)

STEP_M = 1.0 / 64  # odometer step: a binary fraction, so the spacing test is exact


def drive_circle(trail, radius, laps, centre=(0.0, 0.0), odometer=0.0, grow_per_lap=0.0):
    """Drive counter-clockwise around `centre` (winding = angle turned).

    Returns every (odometer, winding, result) of record_and_close.
    """
    results = []
    angle = 0.0
    while angle < laps * 2.0 * math.pi:
        r = radius + grow_per_lap * angle / (2.0 * math.pi)
        x, y = centre[0] + r * math.cos(angle), centre[1] + r * math.sin(angle)
        turned = trail.record_and_close(odometer, x, y, angle + 0.5 * math.pi, angle)
        results.append((odometer, angle, turned))
        odometer += STEP_M
        angle += STEP_M / r
    return results


def first_closure(results):
    return next(((odometer, winding, turned) for odometer, winding, turned in results
                 if turned is not None), None)


def test_a_pose_is_recorded_every_spacing_of_travel():
    assert SPACING_M == pytest.approx(0.05)  # 4 steps of 1/64 m are the first >= the spacing
    trail = PoseTrail()
    for k in range(65):  # 1 m straight east
        assert trail.record_and_close(k * STEP_M, k * STEP_M, 0.0, 0.0, 0.0) is None
    assert len(trail) == 17  # at 0, 4, 8, ..., 64 steps
    trail.clear()
    assert len(trail) == 0


def test_coming_back_to_the_start_with_the_same_heading_closes_the_loop():
    trail = PoseTrail()
    results = drive_circle(trail, radius=0.3, laps=1.2)
    odometer, winding, turned = first_closure(results)
    # It closes once within MATCH_RADIUS_M of the start (an arc of about 0.27 rad before it)
    # and reports the winding turned since the matching pose: one full turn, nearly.
    assert 2.0 * math.pi - MATCH_RADIUS_M / 0.3 - 0.01 < turned < 2.0 * math.pi
    assert turned == pytest.approx(winding)  # matched the start pose (winding 0)
    assert odometer >= MIN_LOOP_M


def test_the_same_place_with_another_heading_is_no_loop():
    # Out 1.5 m along a corridor and back along the same line, facing the other way.
    trail = PoseTrail()
    odometer = 0.0
    for x in np.arange(0.0, 1.5, STEP_M):
        assert trail.record_and_close(odometer, x, 0.0, 0.0, 0.0) is None
        odometer += STEP_M
    for x in np.arange(1.5, -0.5, -STEP_M):
        assert trail.record_and_close(odometer, x, 0.0, math.pi, math.pi) is None
        odometer += STEP_M
    # A heading just inside the tolerance does close it.
    assert trail.record_and_close(odometer + 1.0, 0.5, 0.0, 0.9 * MATCH_HEADING_RAD,
                                  0.3) == pytest.approx(0.3)


def test_passing_beside_a_recorded_pose_is_no_loop():
    # A spiral: after one lap the robot is 0.1 m (> MATCH_RADIUS_M) outside its first lap.
    assert MATCH_RADIUS_M < 0.1
    trail = PoseTrail()
    assert first_closure(drive_circle(trail, radius=0.3, laps=2.5, grow_per_lap=0.1)) is None


def test_a_loop_shorter_than_the_minimum_travel_is_ignored():
    # A 0.63 m circle: back at the start after one lap, but too little travel to count.
    assert 2.0 * math.pi * 0.1 < MIN_LOOP_M
    trail = PoseTrail()
    results = drive_circle(trail, radius=0.1, laps=2.2)
    odometer, _, turned = first_closure(results)
    assert odometer >= MIN_LOOP_M
    assert turned == pytest.approx(4.0 * math.pi, abs=MATCH_RADIUS_M / 0.1 + 0.05)


def test_clear_forgets_the_loop():
    trail = PoseTrail()
    results = drive_circle(trail, radius=0.3, laps=0.9)
    assert first_closure(results) is None
    trail.clear()
    assert first_closure(drive_circle(trail, radius=0.3, laps=0.3,
                                      odometer=results[-1][0] + STEP_M)) is None


def test_a_full_trail_drops_its_oldest_poses():
    trail = PoseTrail()
    spacing = 4 * STEP_M
    for k in range(CAPACITY + 1000):  # a long straight line east, one pose per call
        assert trail.record_and_close(k * spacing, k * spacing, 0.0, 0.0, 0.0) is None
        assert len(trail) <= CAPACITY
    assert len(trail) == CAPACITY
    odometer = (CAPACITY + 1000) * spacing
    # The oldest poses are gone (1000 at a time): the start no longer closes a loop ...
    assert trail.record_and_close(odometer, 0.0, 0.0, 0.0, 2.0) is None
    # ... a pose recorded later still does.
    assert trail.record_and_close(odometer + spacing, 3000 * spacing, 0.0, 0.0,
                                  2.0) == pytest.approx(2.0)


def test_compiled_and_plain_search_agree():
    plain = getattr(pose_trail._closing_pose, "py_func", pose_trail._closing_pose)
    rng = np.random.default_rng(5)
    for _ in range(300):
        count = int(rng.integers(0, 60))
        trail = np.zeros((count + 1, 5))
        trail[:count, 0] = np.sort(rng.uniform(0.0, 5.0, count))
        trail[:count, 1:3] = rng.uniform(-0.2, 0.2, (count, 2))
        trail[:count, 3] = rng.uniform(-4.0, 4.0, count)
        query = (5.0 + rng.uniform(0.0, 1.0), *rng.uniform(-0.2, 0.2, 2), rng.uniform(-4.0, 4.0))
        assert pose_trail._closing_pose(trail, count, *query) == plain(trail, count, *query)
