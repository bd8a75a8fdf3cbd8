"""Loop closure scaled to the drift since the last closure, and its verification.

A building's loop drifts by metres: a 16 m x 10 m ring corridor (pillars here and there, so
places differ), driven once round with the front end made to believe odometry 3 % long and 2 %
over-turning (as test_mapping_mapper does for the small loop), ends ~1 m off. A search sized for
a room (+-0.3 m) cannot close it; one that grows with the travel since the last closure does.
Then each check that keeps wrong closures out, on a case built to trip it.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.geometry import compose, inverse
from amr_mapping.log_odds_grid import UNITS, LogOddsGrid
from amr_mapping.loop_closure import LoopCloser, draw, points_in_free_space
from amr_mapping.mapper import Mapper
from amr_mapping.mapper_params import check_parameters
from amr_mapping.scan_points import Scan
from tests.scan_helpers import LDS01_360, cast
from tests.test_mapping_mapper import TRUST_ODOMETRY


def box(x, y, width, height):
    return [[x, y, x + width, y], [x + width, y, x + width, y + height],
            [x + width, y + height, x, y + height], [x, y + height, x, y]]


BUILDING = np.array(box(0, 0, 16, 10) + box(2, 2, 12, 6) + [
    segment for x, y in [(5, 0.3), (11.5, 1.5), (15.4, 4), (14.4, 6.5), (9, 9.4), (3.5, 8.3),
                         (0.3, 6), (1.3, 3)] for segment in box(x, y, 0.3, 0.3)], dtype=float)


def ring_poses(step=0.1, turn=0.1, beyond=5.0):
    """Round the ring's centre line counter-clockwise from (1, 1), then `beyond` m further."""
    corners = [(1.0, 1.0), (15.0, 1.0), (15.0, 9.0), (1.0, 9.0)]
    poses, heading = [], 0.0
    for k in range(5):
        (x1, y1), (x2, y2) = corners[k % 4], corners[(k + 1) % 4]
        length = math.hypot(x2 - x1, y2 - y1)
        n = int((length if k < 4 else beyond) / step)
        poses += [(x1 + (x2 - x1) * step * j / length, y1 + (y2 - y1) * step * j / length,
                   heading) for j in range(n)]
        target = heading + math.pi / 2
        while k < 4 and heading < target - 1e-9:
            heading = min(heading + turn, target)
            poses.append((x2, y2, heading))
    return poses


def drive_the_ring(params):
    """Position errors per scan and the statistics, the odometry 3 % long, turning 2 % more."""
    rng = np.random.default_rng(0)
    poses = ring_poses()
    mapper = Mapper({**TRUST_ODOMETRY, **params})
    odom, previous, start = (0.0, 0.0, 0.0), poses[0], poses[0]
    errors = []
    for k, pose in enumerate(poses):
        dx, dy, dth = compose(inverse(previous), pose)
        odom = compose(odom, (1.03 * dx, 1.03 * dy, 1.02 * dth))
        previous = pose
        ranges = cast(BUILDING, LDS01_360, pose)
        ranges = np.where(ranges > 0, ranges + rng.normal(0, 0.01, ranges.size), 0.0)
        estimate = mapper.update(Scan(ranges, 0.0, 2 * math.pi / 360, 0.12, 3.5), odom,
                                 0.2 * k)
        truth = compose(inverse(start), pose)
        errors.append(math.hypot(estimate.pose[0] - truth[0], estimate.pose[1] - truth[1]))
    return np.array(errors), mapper.statistics()


def test_a_buildings_loop_closes_with_a_search_grown_by_the_drift():
    lap = len(ring_poses(beyond=0.0))  # the scans of one lap
    fixed, fixed_stats = drive_the_ring({"loop_drift_per_m": 0.0, "loop_drift_rad_per_m": 0.0})
    grown, grown_stats = drive_the_ring({})
    # 44 m round: the believed odometry ends ~1 m off. A +-0.3 m search never closes the loop
    # (only the heading anchor at the very start links anything) ...
    assert fixed[lap - 1] > 0.8 and fixed[lap:].min() > 0.5
    assert fixed_stats["loop_closures"] == fixed_stats["anchor_closures"] == 1
    # ... one grown by 2 cm per metre since the last closure (+-1.2 m by then) does, on the
    # way back along the first corridor, and the estimate is back on the truth.
    assert grown_stats["loop_closures"] > 3
    assert grown[lap - 1] < 0.02 and grown[lap:].max() < 0.15  # then 3 % drift again


def room_grid(poses, resolution=0.02):
    """A grid of the building drawn from scans at poses (exact ranges)."""
    grid = LogOddsGrid(resolution, 10_000_000, 0.9, 0.4, 0.02, hit_moments=True)
    for pose in poses:
        ranges = cast(BUILDING, LDS01_360, pose)
        keep = ranges > 0
        angles = np.arange(360) * 2 * math.pi / 360
        points = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)])[keep]
        draw(grid, pose, points, 0.0)
    return grid


def scan_points_at(pose):
    ranges = cast(BUILDING, LDS01_360, pose)
    angles = np.arange(360) * 2 * math.pi / 360
    return np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)])[ranges > 0]


def test_a_scan_placed_where_the_map_saw_free_space_is_told_apart():
    grid = room_grid([(x, 1.0, 0.0) for x in np.arange(1.0, 8.0, 0.5)])
    points = scan_points_at((4.0, 1.0, 0.0))
    free = -0.4 * UNITS
    assert points_in_free_space(grid, free, (4.0, 1.0, 0.0), points) < 0.01
    # 0.6 m to the side: the corridor's wall stands in its free middle.
    assert points_in_free_space(grid, free, (4.0, 1.6, 0.0), points) > 0.2
    # Into space never seen (beyond the outer wall): unknown is no contradiction.
    assert points_in_free_space(grid, free, (4.0, -3.0, 0.0), points) == 0.0


@pytest.mark.parametrize("window,closes", [(0.15, False), (0.5, True)])
def test_a_closure_found_on_the_windows_edge_is_refused(window, closes):
    """A keyframe 0.17 m off, at a corner of the ring, searched over +-0.15 m: refused.

    The best pose lies on the window's edge: it scores well (the true pose is just beyond),
    but an edge is no verified optimum (in a maze the true one may be a corridor further).
    Without the drift prior (the heading anchor's search), so the edge alone decides.
    """
    closer = LoopCloser(check_parameters({"resolution_m": 0.02}))
    chain = [(x, 1.0, 0.0) for x in np.arange(1.0, 4.0, 0.25)]
    chain += [(1.0, y, math.pi / 2) for y in np.arange(1.25, 4.0, 0.25)]
    truth, estimate = (1.5, 1.0, 0.0), (1.5, 1.17, 0.0)
    poses = np.array(chain + [estimate])
    points = [scan_points_at(pose) for pose in chain] + [scan_points_at(truth)]
    current = len(chain)
    closure = closer.verify(poses, points, list(range(current)), 2, current, window, window,
                            prior=False)
    assert (closure is not None) == closes
    if closes:  # the closure puts the keyframe back where it was
        x, y, _ = compose(tuple(poses[2]), closure.relative)
        assert math.hypot(x - truth[0], y - truth[1]) < 0.01
    else:  # what the search found, and why it is refused
        grid = LogOddsGrid(0.02, 10_000_000, 0.9, 0.4, 0.02, hit_moments=True)
        for k in range(current):
            draw(grid, poses[k], points[k], 0.0)
        match = closer.matcher.match(grid, 0.6 * UNITS, points[current], estimate, window,
                                     window)
        assert match.score > 0.8 and match.on_edge(estimate, window, window)


def test_of_look_alike_places_in_the_window_the_nearer_one_closes_the_loop():
    """lab02 from its inner start, 100 s: a look-alike place 0.56 m off does not close the loop.

    After 11 m without a closure the search spans +-0.75 m, and a corridor 0.56 m from where
    the robot is scores better on the candidate's map (0.71) than anything near it. Weighted by
    the drift the window stands for (3 sigmas), the look-alike keeps 8 % of its score and
    loses; taken as one sigma it won, and the map broke (RMSE 7.6 cm, max 55 cm, precision
    16 %).
    """
    from amr_evaluation.mapping_episode import run_mapping_episode
    result = run_mapping_episode("lab02", "inner", profile="turtlebot3_clean", seed=0,
                                 duration=100.0)
    assert result.trajectory_max_m < 0.02 and result.precision > 0.95
