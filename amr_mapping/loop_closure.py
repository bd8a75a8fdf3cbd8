"""Loop closure: find an earlier keyframe near the current one, match against its map, verify.

How far to look is the uncertainty the estimate gathered since it was last tied to the map:
`window(travel)` grows from loop_window_m / loop_window_rad by loop_drift_per_m and
loop_drift_rad_per_m per metre travelled, where `travel` is the least of the travel since the
last verified closure and the travel since the earlier keyframe (a building's loop drifts by
metres, a room's by centimetres), up to loop_max_window_m / loop_max_window_rad (a global
search in heading). Candidates are keyframes the robot left at least `loop_min_travel_m` of
travel ago (closer ones are in the local map already) within loop_search_radius_m of the
current keyframe's estimate, plus how far its window grew; the nearest is taken. Its map is
drawn from the keyframes around it in the chain (Karto's "chain" of scans) and, when the
window is wider than loop_search_radius_m (the nearest keyframe may then not be the place),
the earlier keyframes within the window (at most loop_map_keyframes, evenly spaced), at their
current estimates. The current keyframe's scan is matched against it over the window by the
multi-resolution branch and bound, weighted by a prior: the window holds `search_sigmas`
standard deviations of the drift, so of places scoring alike the nearer is the likelier (a
look-alike corridor 0.5 m over, after 11 m of travel, keeps 8 % of its score); the place it
chose is searched again +-4 cells and angle steps without the prior (the prior picks the
place, the scan alone says where in it). Verification (wrong closures bend a whole map):
- the match scores at least `loop_min_score` and does not lie on the window's edge (the best
  pose may lie beyond);
- no pose farther than `loop_ambiguity_distance_m` (or turned) in the whole window scores
  `loop_ambiguity_ratio` of it: in a featureless corridor, or among look-alike rooms when the
  window is wide, the match is a guess (a later attempt, closer or after another closure
  narrowed the window, may succeed);
- at most `loop_max_free_share` of the scan's points land deep in space the map saw free: a
  scan placed one corridor over, in a maze whose own corridor the map has not seen, scores
  well on the neighbouring walls and has no rival there, but its walls stand in that
  neighbour's free corridor (maze_deadends: 11 % of the points against at most 4 % for true
  closures there and on the Intel log).

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
_LOCAL_CELLS = 4  # the place the prior chose is searched again +-4 cells and steps without it


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


def points_in_free_space(grid: LogOddsGrid, free_units: float, pose,
                         points: np.ndarray) -> float:
    """Share of the points that, at `pose`, land deep in space the grid saw free.

    Deep: the point's cell and its 8 neighbours all below free_units (a point just beside a
    wall is range noise; one in the middle of an observed corridor contradicts the map).
    """
    if len(points) == 0:
        return 0.0
    res = grid.resolution
    world = world_points(pose, points)
    col = np.floor(world[:, 0] / res).astype(np.int64) - grid.col0
    row = np.floor(world[:, 1] / res).astype(np.int64) - grid.row0
    rows, cols = grid.counts.shape
    free = np.ones(len(points), dtype=bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            r, c = row + dr, col + dc
            inside = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
            cell_free = np.zeros(len(points), dtype=bool)
            cell_free[inside] = grid.counts[r[inside], c[inside]] < free_units
            free &= cell_free
    return float(free.mean())


class LoopCloser:
    """Searches and verifies loop closures for the Mapper (see the module docstring)."""

    def __init__(self, params: dict) -> None:
        self.p = params
        self.matcher = CorrelativeMatcher(
            params["resolution_m"], params["smear_sigma_m"],
            use_reference=params["correlative_search"] == "exhaustive")

    def window(self, travel):
        """Half-widths (m, rad) of the search after `travel` m without a closure (or arrays)."""
        p = self.p
        return (np.minimum(p["loop_window_m"] + p["loop_drift_per_m"] * travel,
                           p["loop_max_window_m"]),
                np.minimum(p["loop_window_rad"] + p["loop_drift_rad_per_m"] * travel,
                           p["loop_max_window_rad"]))

    def candidate(self, poses: np.ndarray, travelled: np.ndarray, current: int,
                  since_closure: float = math.inf) -> tuple[int, float] | None:
        """(index, travel) of the nearest keyframe that may close a loop with `current`.

        travel: the least of since_closure (m travelled since the last closure) and the travel
        since that keyframe: what sizes its window. None if no keyframe qualifies.
        """
        p = self.p
        earlier = np.flatnonzero(travelled[:current] <= travelled[current] -
                                 p["loop_min_travel_m"])
        if earlier.size == 0:
            return None
        travel = np.minimum(travelled[current] - travelled[earlier], since_closure)
        reach = p["loop_search_radius_m"] + self.window(travel)[0] - p["loop_window_m"]
        d = np.hypot(poses[earlier, 0] - poses[current, 0], poses[earlier, 1] - poses[current, 1])
        inside = np.flatnonzero(d <= reach)
        if inside.size == 0:
            return None
        best = int(inside[np.argmin(d[inside])])
        return int(earlier[best]), float(travel[best])

    def close(self, poses: np.ndarray, travelled: np.ndarray, points: list[np.ndarray],
              current: int, since_closure: float = math.inf) -> LoopClosure | None:
        """A verified closure of keyframe `current` against an earlier one, or None."""
        p = self.p
        found = self.candidate(poses, travelled, current, since_closure)
        if found is None:
            return None
        candidate, travel = found
        linear, angular = self.window(travel)
        n = p["loop_chain_keyframes"]
        limit = travelled[current] - 0.5 * p["loop_min_travel_m"]
        chain = [k for k in range(max(candidate - n, 0), min(candidate + n + 1, current))
                 if travelled[k] <= limit]
        # A window wider than the candidate search radius: the nearest keyframe may not be the
        # place; the map also gets the earlier keyframes within the window.
        if linear > p["loop_search_radius_m"]:
            near = np.flatnonzero((travelled[:current] <= limit) & (np.hypot(
                poses[:current, 0] - poses[current, 0],
                poses[:current, 1] - poses[current, 1]) <= linear))
            extra = np.setdiff1d(near, chain)
            room = p["loop_map_keyframes"] - len(chain)
            if extra.size > room > 0:
                extra = extra[np.linspace(0, extra.size - 1, room).round().astype(int)]
            chain = sorted(chain + [int(k) for k in extra[:max(room, 0)]])
        return self.verify(poses, points, chain, candidate, current, float(linear),
                           float(angular))

    def anchor(self, poses: np.ndarray, points: list[np.ndarray],
               current: int) -> LoopClosure | None:
        """A verified closure of keyframe `current` against the map of the first keyframes."""
        p = self.p
        first = min(p["anchor_keyframes"], current)
        if first < 1 or math.hypot(*(poses[current, :2] - poses[0, :2])) > \
                p["loop_search_radius_m"]:
            return None
        closure = self.verify(poses, points, list(range(first)), 0, current, prior=False)
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
               candidate: int, current: int, linear: float | None = None,
               angular: float | None = None, prior: bool = True) -> LoopClosure | None:
        """Match keyframe `current` against the map of `chain`; a closure to `candidate`.

        Over linear / angular (m, rad; None: loop_window_m / loop_window_rad); prior: weigh
        the poses by the drift the window stands for (the anchor bounds its shift instead).
        """
        p = self.p
        linear = p["loop_window_m"] if linear is None else linear
        angular = p["loop_window_rad"] if angular is None else angular
        grid = LogOddsGrid(p["resolution_m"], p["max_map_cells"], p["log_odds_hit"],
                           p["log_odds_miss"], p["miss_stop_m"], hit_moments=True)
        for k in chain:
            draw(grid, poses[k], points[k], p["lidar_offset_x_m"])
        occupied = p["occupied_log_odds"] * UNITS
        estimate = tuple(poses[current])
        # The window holds search_sigmas standard deviations of the drift: of places that
        # score alike, the nearer is the likelier (module docstring). The ambiguity check is
        # on the bare scores: any other pose in the window that explains the scan nearly as
        # well makes the closure a guess.
        sigmas = (linear / p["search_sigmas"], angular / p["search_sigmas"]) if prior else None
        found = self.matcher.match(grid, occupied, points[current], estimate, linear, angular,
                                   prior_sigma=sigmas)
        # On the window's edge the best pose may lie beyond it: not a verified optimum.
        if found is None or found.on_edge(estimate, linear, angular):
            return None
        match = found
        if sigmas is not None:  # the prior chose the place; the scan alone says where in it
            res = p["resolution_m"]
            match = self.matcher.match(grid, occupied, points[current], found.lattice_pose,
                                       _LOCAL_CELLS * res, _LOCAL_CELLS * found.angular_step)
            if match is None:
                return None
        if match.score < p["loop_min_score"]:
            return None
        rival = self.matcher.match(grid, occupied, points[current], estimate, linear, angular,
                                   exclude=(match.lattice_pose, p["loop_ambiguity_distance_m"],
                                            _AMBIGUITY_ANGLE))
        rival_score = 0.0 if rival is None else rival.score
        if rival_score >= p["loop_ambiguity_ratio"] * match.score:
            return None
        # A scan placed one corridor over (a look-alike place whose own corridor the map has
        # not seen) lands its walls in space the map saw free.
        if points_in_free_space(grid, p["free_log_odds"] * UNITS, match.pose,
                                points[current]) > p["loop_max_free_share"]:
            return None
        relative = compose(inverse(tuple(poses[candidate])), match.pose)
        return LoopClosure(candidate, current, relative, match.score, rival_score)


__all__ = ["LoopCloser", "LoopClosure", "draw", "world_points"]
