"""Loop closure: find an earlier keyframe near the current one, match against its map, verify.

Candidates are keyframes within `loop_search_radius_m` of the current keyframe's estimate that
the robot left at least `loop_min_travel_m` of travel ago (closer ones are in the local map
already). The nearest is taken; its map is drawn from the keyframes around it in the chain
(Karto's "chain" of scans) at their current estimates, and the current keyframe's scan is
matched against it over a window much larger than tracking uses, without a prior. A match is
accepted only if it scores at least `loop_min_score` and no pose farther than
`loop_ambiguity_distance_m` (or turned) scores nearly as well: in a featureless corridor the
match is ambiguous along it and the closure is refused rather than guessed.

The heading anchor (`anchor`, tried when the search found nothing): a keyframe within
`loop_search_radius_m` of the first one is matched, verified the same way, against the map of
the first `anchor_keyframes` keyframes and linked to keyframe 0, however little the robot
travelled, unless the match would move it more than `anchor_max_shift_m` or
`anchor_max_turn_rad` from its estimate (a small map verifies less: that is a false match).
The first metres are where the map's heading is set: each match there is good to about a
milliradian, the keyframes pass the error on, and without a link back to the start a map 3 m
wide ends up turned as a whole (maze_deadends seed 4: 5-8 mrad, walls at the far side 2-3 cm
off). Karto and Cartographer get such links by matching against every earlier scan chain or
submap in range; the chain search here skips the start until the robot travelled
loop_min_travel_m, and a robot that does not come back to the start area never gets one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amr_common.geometry import compose, inverse
from amr_mapping.log_odds_grid import UNITS, LogOddsGrid
from amr_mapping.scan_matcher import CorrelativeMatcher

_AMBIGUITY_ANGLE = 0.1  # rad: poses turned more than this count as "elsewhere"


@dataclass(frozen=True)
class LoopClosure:
    """A verified closure: keyframe `later` seen from `earlier` at `relative`."""

    earlier: int
    later: int
    relative: tuple[float, float, float]
    score: float
    rival_score: float  # best score elsewhere (the ambiguity check), 0 if none


def world_points(pose, points: np.ndarray) -> np.ndarray:
    """(N, 2) robot-frame points placed at pose (x, y, theta)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.column_stack([pose[0] + c * points[:, 0] - s * points[:, 1],
                            pose[1] + s * points[:, 0] + c * points[:, 1]])


def draw(grid: LogOddsGrid, pose, points: np.ndarray, lidar_offset_x: float,
         sign: int = 1) -> bool:
    """Add (sign +1) or remove (-1) a keyframe's rays at `pose`; False if the grid is full."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    sensor = (pose[0] + c * lidar_offset_x, pose[1] + s * lidar_offset_x)
    return grid.add_scan(sensor, world_points(pose, points), sign)


class LoopCloser:
    """Searches and verifies loop closures for the Mapper (see the module docstring)."""

    def __init__(self, params: dict) -> None:
        self.p = params
        self.matcher = CorrelativeMatcher(
            params["resolution_m"], params["smear_sigma_m"],
            use_reference=params["correlative_search"] == "exhaustive")

    def candidate(self, poses: np.ndarray, travelled: np.ndarray, current: int) -> int | None:
        """Index of the nearest keyframe eligible to close a loop with `current`, or None."""
        p = self.p
        earlier = np.flatnonzero(travelled[:current] <= travelled[current] -
                                 p["loop_min_travel_m"])
        if earlier.size == 0:
            return None
        d = np.hypot(poses[earlier, 0] - poses[current, 0], poses[earlier, 1] - poses[current, 1])
        best = int(np.argmin(d))
        return int(earlier[best]) if d[best] <= p["loop_search_radius_m"] else None

    def close(self, poses: np.ndarray, travelled: np.ndarray, points: list[np.ndarray],
              current: int) -> LoopClosure | None:
        """A verified closure of keyframe `current` against an earlier one, or None."""
        p = self.p
        candidate = self.candidate(poses, travelled, current)
        if candidate is None:
            return None
        n = p["loop_chain_keyframes"]
        limit = travelled[current] - 0.5 * p["loop_min_travel_m"]
        chain = [k for k in range(max(candidate - n, 0), min(candidate + n + 1, current))
                 if travelled[k] <= limit]
        return self.verify(poses, points, chain, candidate, current)

    def anchor(self, poses: np.ndarray, points: list[np.ndarray],
               current: int) -> LoopClosure | None:
        """A verified closure of keyframe `current` against the map of the first keyframes."""
        p = self.p
        first = min(p["anchor_keyframes"], current)
        if first < 1 or math.hypot(*(poses[current, :2] - poses[0, :2])) > \
                p["loop_search_radius_m"]:
            return None
        closure = self.verify(poses, points, list(range(first)), 0, current)
        if closure is None:
            return None
        # The anchor corrects the heading the front end lost near the start, a few mrad and
        # millimetres; a match that would move the keyframe farther is a false one (a map of
        # a few scans verifies less than a chain's), and one false link to keyframe 0 bends
        # the whole map.
        estimate = compose(inverse(tuple(poses[0])), tuple(poses[current]))
        shift = compose(inverse(estimate), closure.relative)
        if math.hypot(shift[0], shift[1]) > p["anchor_max_shift_m"] or \
                abs(shift[2]) > p["anchor_max_turn_rad"]:
            return None
        return closure

    def verify(self, poses: np.ndarray, points: list[np.ndarray], chain: list[int],
               candidate: int, current: int) -> LoopClosure | None:
        """Match keyframe `current` against the map of `chain`; a closure to `candidate`."""
        p = self.p
        grid = LogOddsGrid(p["resolution_m"], p["max_map_cells"], p["log_odds_hit"],
                           p["log_odds_miss"], p["miss_stop_m"], hit_moments=True)
        for k in chain:
            draw(grid, poses[k], points[k], p["lidar_offset_x_m"])
        occupied = p["occupied_log_odds"] * UNITS
        prior = tuple(poses[current])
        match = self.matcher.match(grid, occupied, points[current], prior, p["loop_window_m"],
                                   p["loop_window_rad"])
        if match is None or match.score < p["loop_min_score"]:
            return None
        rival = self.matcher.match(grid, occupied, points[current], prior, p["loop_window_m"],
                                   p["loop_window_rad"],
                                   exclude=(match.lattice_pose, p["loop_ambiguity_distance_m"],
                                            _AMBIGUITY_ANGLE))
        rival_score = 0.0 if rival is None else rival.score
        if rival_score >= p["loop_ambiguity_ratio"] * match.score:
            return None
        relative = compose(inverse(tuple(poses[candidate])), match.pose)
        return LoopClosure(candidate, current, relative, match.score, rival_score)


__all__ = ["LoopCloser", "LoopClosure", "draw", "world_points"]
