"""The correlative scan matcher: a known offset recovered, the same optimum as the reference."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.world.world import World
from amr_mapping.log_odds_grid import UNITS, LogOddsGrid
from amr_mapping.loop_closure import draw
from amr_mapping.scan_matcher import CorrelativeMatcher
from tests.scan_helpers import LDS01_360, cast

RES = 0.02
OCCUPIED_UNITS = 0.6 * UNITS


def _points(segments, pose, rng, noise=0.01):
    """Robot-frame points of an LDS-01 scan from pose (LiDAR at the robot centre)."""
    ranges = cast(segments, LDS01_360, pose)
    ranges = np.where(ranges > 0, ranges + rng.normal(0.0, noise, ranges.size), 0.0)
    angles = np.arange(ranges.size) * 2 * math.pi / ranges.size
    ok = ranges > 0
    return np.column_stack([ranges[ok] * np.cos(angles[ok]), ranges[ok] * np.sin(angles[ok])])


def _mapped(segments, poses, rng) -> LogOddsGrid:
    grid = LogOddsGrid(RES, 10_000_000, 0.9, 0.4, 0.02, hit_moments=True)
    for pose in poses:
        for _ in range(3):
            draw(grid, pose, _points(segments, pose, rng), 0.0)
    return grid


@pytest.fixture(scope="module")
def lab02_map():
    rng = np.random.default_rng(11)
    segments = World.load("lab02").segments
    poses = [(1.0, -1.0 + 0.1 * k, math.pi / 2 + 0.02 * k) for k in range(8)]
    return segments, _mapped(segments, poses, rng)


@pytest.mark.parametrize("offset", [(0.06, -0.05, 0.04), (-0.08, 0.03, -0.06),
                                    (0.0, 0.0, 0.0)])
def test_matcher_recovers_a_known_offset(lab02_map, offset):
    segments, grid = lab02_map
    rng = np.random.default_rng(12)
    true = (1.01, -0.73, math.pi / 2 + 0.05)
    points = _points(segments, true, rng)
    prior = (true[0] + offset[0], true[1] + offset[1], true[2] + offset[2])
    result = CorrelativeMatcher(RES, 0.03).match(grid, OCCUPIED_UNITS, points, prior, 0.12,
                                                 0.1)
    assert result is not None and result.score > 0.8
    x, y, th = result.pose
    assert math.hypot(x - true[0], y - true[1]) < 0.004
    assert abs(th - true[2]) < 0.003
    # The lattice optimum is within a cell and an angular step; the refinement does the rest.
    lx, ly, lth = result.lattice_pose
    assert abs(lx - true[0]) <= 1.5 * RES and abs(ly - true[1]) <= 1.5 * RES
    assert abs(lth - true[2]) <= 1.5 * result.angular_step


def test_branch_and_bound_finds_the_reference_optimum(lab02_map):
    segments, grid = lab02_map
    rng = np.random.default_rng(13)
    true = (1.0, -0.5, math.pi / 2)
    points = _points(segments, true, rng)
    prior = (1.04, -0.55, math.pi / 2 + 0.03)
    fast = CorrelativeMatcher(RES, 0.03).match(grid, OCCUPIED_UNITS, points, prior, 0.1, 0.06,
                                               prior_sigma=(0.1, 0.1))
    reference = CorrelativeMatcher(RES, 0.03, use_reference=True).match(
        grid, OCCUPIED_UNITS, points, prior, 0.1, 0.06, prior_sigma=(0.1, 0.1))
    assert fast.lattice_pose == pytest.approx(reference.lattice_pose, abs=1e-12)
    assert fast.score == pytest.approx(reference.score, rel=1e-6)
    assert fast.candidates < reference.candidates / 3


def test_odometry_prior_holds_the_pose_along_a_featureless_corridor():
    """Along a corridor longer than the LiDAR's range every position scores the same.

    The refinement keeps the prior's position along it and fixes the rest from the walls.
    """
    rng = np.random.default_rng(14)
    segments = np.array([[-10.0, -0.2, 10.0, -0.2], [-10.0, 0.2, 10.0, 0.2]])
    grid = _mapped(segments, [(x, 0.0, 0.0) for x in np.arange(-1.0, 1.01, 0.1)], rng)
    true = (0.0, 0.013, 0.01)
    points = _points(segments, true, rng)
    prior = (0.03, 0.05, 0.03)
    matcher = CorrelativeMatcher(RES, 0.03)
    result = matcher.match(grid, OCCUPIED_UNITS, points, prior, 0.1, 0.06,
                           prior_sigma=(0.1, 0.1), refine_sigmas=(0.01, 0.01, 0.015))
    x, y, th = result.pose
    assert abs(y - true[1]) < 0.003 and abs(th - true[2]) < 0.003  # across: from the walls
    assert abs(x - prior[0]) < 0.021  # along: the lattice and prior's, no slide
    # And the best match 10 cm away scores as well: a loop closure here would be a guess.
    rival = matcher.match(grid, OCCUPIED_UNITS, points, prior, 0.3, 0.06,
                          exclude=(result.lattice_pose, 0.1, 0.1))
    assert rival.score > 0.95 * result.score


def test_no_map_no_match():
    grid = LogOddsGrid(RES, 10_000_000, 0.9, 0.4, hit_moments=True)
    points = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    assert CorrelativeMatcher(RES, 0.03).match(grid, OCCUPIED_UNITS, points, (0, 0, 0), 0.1,
                                               0.1) is None
