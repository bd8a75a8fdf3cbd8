"""Exhaustive pose search over the whole map: which OTHER poses explain this scan?

The last guard of the localized test (localization_check): before the filter declares a pose,
every pose the robot could have on a coarse grid (robot-centre cells every `stride` table cells,
`headings` directions) is scored by how many of the weighed beams its expected ranges (table
lookups) match within a wide tolerance; the best poses away from the estimate are refined by an
exact local search (ray casting all rays, ScanMatcher). If one of them explains nearly as much of
the scan as the estimate, the scan is ambiguous (a symmetric part of the maze): the filter does not
declare, and gets particles at those poses so that the ambiguity must be resolved by driving on.
Cost on a 2.4 m maze: about 10-30 ms (lookups) + a few ms per refined candidate; on a 40 x 40 m
floor (885,000 positions) about 3 s, so a search is a SearchJob scored a slice of SLICE_CELLS
positions at a time: the filter advances it once per scan and uses its result when done, and no
call blocks its node for long (every course maze fits in one slice). No rclpy import.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amr_common.geometry import wrap_angles
from amr_common.jit import HAVE_NUMBA, jit
from amr_localization.expected_ranges import ExpectedRangeTable
from amr_localization.localization_check import ScanMatcher
from amr_localization.scan_beams import ScanBeams

SEARCH_BEAMS = 30
_CHUNK_CELLS = 4096  # cells scored at a time (x 120 headings x 4 bytes: 2 MB)
# Cells (robot positions, x 120 headings) one SearchJob.advance() scores: at most ~0.1 s of CPU
# on the 2-core reference machine (3.5-6 us per position), against ~3 s for the 885,000 of a
# 40 x 40 m floor in one go; the course's mazes have 1,800-5,400 positions: one slice, as before.
SLICE_CELLS = 8 * _CHUNK_CELLS
_ALTERNATIVE_POSES = 4000  # best grid poses among which alternatives() picks its candidates


def score_poses_python(centres, headings, table, rows, angles, x0, y0, resolution, nx,
                       lidar_offset, beam_bins, z_mm, tolerance_mm, range_min_mm, range_max_mm,
                       max_misses, out):
    """out[c, h] = beams matched by the robot centred at centres[c] with heading h * 2 pi / H.

    A pose is dropped (scored by what it matched so far) after more than max_misses misses:
    most poses are wrong, and their misses come early because beam_bins is in an interleaved
    order (see PoseSearch). A coarse ranking: no sub-cell correction (beam_model's would cost
    half as much again here, and the tolerance is wide).
    """
    inv_res = 1.0 / resolution
    n_beams = beam_bins.shape[0]
    bins_per_heading = angles / headings
    offset_x = np.empty(headings)
    offset_y = np.empty(headings)
    for h in range(headings):
        offset_x[h] = lidar_offset * math.cos(h * (2.0 * math.pi / headings)) - x0
        offset_y[h] = lidar_offset * math.sin(h * (2.0 * math.pi / headings)) - y0
    for c in range(centres.shape[0]):
        cx = centres[c, 0]
        cy = centres[c, 1]
        for h in range(headings):
            li = int((cx + offset_x[h]) * inv_res)
            lj = int((cy + offset_y[h]) * inv_res)
            row = rows[lj * nx + li]
            t = h * bins_per_heading + 0.5
            matched = 0
            misses = 0
            for b in range(n_beams):
                k = int(t + beam_bins[b])
                if k >= angles:
                    k -= angles
                    if k >= angles:
                        k -= angles
                r = np.int32(table[row, k])
                z = z_mm[b]
                if z < 0:
                    hit = r < range_min_mm or r > range_max_mm
                else:
                    hit = abs(z - r) <= tolerance_mm
                if hit:
                    matched += 1
                else:
                    misses += 1
                    if misses > max_misses:
                        break
            out[c, h] = matched


score_poses_kernel = jit(score_poses_python)


def score_poses_numpy(centres, headings, table, rows, angles, x0, y0, resolution, nx,
                      lidar_offset, beam_bins, z_mm, tolerance_mm, range_min_mm, range_max_mm,
                      max_misses, out):
    """The same scores as numpy operations, one heading at a time.

    The same scores as numpy operations, one heading at a time (a pose's misses after the
    (max_misses + 1)-th no longer hide its later matches: the same ranking above the cut).
    """
    cx, cy = centres[:, 0], centres[:, 1]
    inv_res = 1.0 / resolution
    for h in range(headings):  # the kernel's arithmetic, operation for operation
        theta = h * (2.0 * math.pi / headings)
        li = ((cx + (lidar_offset * math.cos(theta) - x0)) * inv_res).astype(np.int64)
        lj = ((cy + (lidar_offset * math.sin(theta) - y0)) * inv_res).astype(np.int64)
        k = ((h * (angles / headings) + 0.5) + beam_bins).astype(np.int64) % angles
        r = table[rows[lj * nx + li][:, None], k[None, :]].astype(np.int32)
        hit = np.where(z_mm[None, :] < 0, (r < range_min_mm) | (r > range_max_mm),
                       np.abs(z_mm[None, :] - r) <= tolerance_mm)
        misses = np.cumsum(~hit, axis=1)
        out[:, h] = np.where(misses[:, -1] > max_misses,
                             np.sum(hit & (misses <= max_misses), axis=1), hit.sum(axis=1))


score_poses = score_poses_kernel if HAVE_NUMBA else score_poses_numpy


@dataclass
class Alternative:
    """A pose and the share of all rays it explains (exact ray casting)."""

    pose: tuple[float, float, float]
    match_fraction: float


def interleaved_order(count: int) -> np.ndarray:
    """0 .. count - 1 in an order that spreads every prefix around the circle (bit reversal)."""
    bits = max(int(count - 1).bit_length(), 1)
    keys = [int(f"{i:0{bits}b}"[::-1], 2) for i in range(count)]
    return np.argsort(keys, kind="stable")


class PoseSearch:
    """Coarse exhaustive scoring + exact refinement of the best distinct candidates.

    The grid's poses are scored in chunks of _CHUNK_CELLS cells, keeping only the best poses
    found so far: the memory stays the same on any map.
    """

    def __init__(self, table: ExpectedRangeTable, robot_ok: np.ndarray, lidar_offset: float,
                 stride: int = 2, headings: int = 120, tolerance_m: float = 0.06,
                 candidates: int = 8, miss_share: float = 0.25) -> None:
        keep = robot_ok.astype(bool).reshape(table.ny, table.nx)
        mask = np.zeros_like(keep)
        # A sub-grid of robot-centre cells: every `stride`-th cell counted from the cell centred
        # on (0, 0), so it holds the centre lines of corridors on a grid of stride cells.
        first_col, first_row = (round(v / table.resolution + 0.5) for v in (table.x0, table.y0))
        mask[-first_row % stride::stride, -first_col % stride::stride] = True
        self.cells = np.flatnonzero((keep & mask).ravel()).astype(np.int64)
        self.centres = np.ascontiguousarray(table.cell_centres(self.cells))  # of self.cells
        self.table = table
        self.lidar_offset = float(lidar_offset)
        self.headings = int(headings)
        self.tolerance_mm = int(round(tolerance_m * 1000.0))
        self.candidates = int(candidates)
        self.miss_share = float(miss_share)
        self.step = (stride * table.resolution, 2.0 * math.pi / headings)
        # Scratch scores of one chunk, shared by the jobs of this search (one at a time).
        self._scores = np.empty((min(len(self.cells), _CHUNK_CELLS), self.headings),
                                dtype=np.int32)

    def _score_into(self, centres: np.ndarray, beam_bins: np.ndarray, z_mm: np.ndarray,
                    max_misses: int, out: np.ndarray, limits_mm: tuple[int, int]) -> None:
        """Scores of the poses at `centres` x every heading into out (beams in that order)."""
        table = self.table
        score_poses(np.ascontiguousarray(centres), self.headings, table.ranges, table.rows,
                    table.angles, table.x0, table.y0, table.resolution, table.nx,
                    self.lidar_offset, np.ascontiguousarray(beam_bins), np.ascontiguousarray(z_mm),
                    self.tolerance_mm, limits_mm[0], limits_mm[1], max_misses, out)

    def start(self, count: int, beams: ScanBeams, z_mm: np.ndarray) -> "SearchJob":
        """A search of every grid pose for this scan, keeping the `count` best: nothing scored yet.

        Advance it (SearchJob.advance) until done; then best_poses() or alternatives() use it.
        """
        return SearchJob(self, count, beams, z_mm)

    def best_poses(self, job: "SearchJob", rng: np.random.Generator) -> np.ndarray:
        """The best-fitting grid poses of a finished search, jittered: a global search's particles.

        (count, 3) poses: the `count` best-scoring grid poses for the job's scan, each jittered
        uniformly within its grid step (the particles of a global search, so that every pose
        that fits the first scan, the true one and its symmetric copies alike, is represented).
        """
        flat = job.flat
        count = len(flat)
        cells, headings = np.divmod(flat, self.headings)
        half_xy, half_theta = self.step[0] / 2.0, self.step[1] / 2.0
        poses = np.empty((count, 3))
        poses[:, :2] = self.centres[cells] + rng.uniform(-half_xy, half_xy, (count, 2))
        theta = headings * self.step[1] + rng.uniform(-half_theta, half_theta, count)
        poses[:, 2] = wrap_angles(theta)
        return poses

    def best_near(self, pose, radius: float, angle: float, beams: ScanBeams, z_mm: np.ndarray,
                  matcher: ScanMatcher, ranges: np.ndarray, match_tolerance: float
                  ) -> Alternative:
        """The pose near `pose` that explains the scan best.

        The pose within `radius` (m) and `angle` (rad) of `pose` that explains the scan best:
        coarse scores of that neighbourhood, then the best three distinct candidates (and
        `pose` itself) refined exactly. Used before calling a hypothesis refuted: refuted must
        mean that NO pose near it explains the scan, not that its current pose drifted.
        """
        beam_bins = beams.bins
        near = np.flatnonzero(np.hypot(self.centres[:, 0] - pose[0],
                                       self.centres[:, 1] - pose[1]) <= radius)
        candidates = [tuple(pose)]
        if near.size:
            centres = self.centres[near]
            scores = np.empty((len(centres), self.headings), dtype=np.int32)
            order = interleaved_order(len(beam_bins))
            self._score_into(centres, beam_bins[order], z_mm[order], len(beam_bins), scores,
                             beams.limits_mm)
            headings = np.arange(self.headings) * self.step[1]
            off = np.abs(wrap_angles(headings - pose[2]))
            scores[:, off > angle] = -1
            for flat in np.argsort(-scores.ravel(), kind="stable")[:64]:
                c, h = divmod(int(flat), self.headings)
                x, y = centres[c]
                candidate = (float(x), float(y), math.remainder(h * self.step[1], 2.0 * math.pi))
                if not any(close_poses(candidate, other, 0.05, math.radians(5.0))
                           for other in candidates):
                    candidates.append(candidate)
                if len(candidates) >= 4:
                    break
        refined = [refine(c, matcher, ranges, match_tolerance, self.step) for c in candidates]
        return max(refined, key=lambda a: a.match_fraction)

    def start_alternatives(self, beams: ScanBeams, z_mm: np.ndarray) -> "SearchJob":
        """The search alternatives() takes, not scored yet."""
        return self.start(_ALTERNATIVE_POSES, beams, z_mm)

    def alternatives(self, job: "SearchJob", estimate, matcher: ScanMatcher,
                     ranges: np.ndarray, match_tolerance: float, exclusion_m: float = 0.15,
                     exclusion_rad: float = math.radians(15.0)) -> list[Alternative]:
        """The best distinct poses away from `estimate`, refined, best first.

        From a finished search of the scan `ranges` (start_alternatives): the best distinct
        poses farther than exclusion_m / exclusion_rad from `estimate`, each refined locally
        on that scan, best first.
        """
        scores, flat = job.scores, job.flat
        # Candidates: the poses within a few beams of the best (a rival explaining >= 90 % of
        # the rays matches nearly every beam at this tolerance), best first.
        flat = flat[scores >= scores[0] - max(job.scored_beams // 6, 2)] if len(flat) else flat
        chosen: list[tuple[float, float, float]] = []
        for index in flat:
            c, h = divmod(int(index), self.headings)
            x, y = self.centres[c]
            theta = math.remainder(h * self.step[1], 2.0 * math.pi)
            pose = (float(x), float(y), theta)
            if close_poses(pose, estimate, exclusion_m, exclusion_rad):
                continue
            if any(close_poses(pose, other, 0.1, math.radians(10.0)) for other in chosen):
                continue
            chosen.append(pose)
            if len(chosen) >= self.candidates:
                break
        refined = [refine(pose, matcher, ranges, match_tolerance, self.step) for pose in chosen]
        return sorted(refined, key=lambda a: -a.match_fraction)


class SearchJob:
    """One exhaustive search of PoseSearch's grid poses for one scan, scored a slice at a time.

    advance() scores the next SLICE_CELLS positions (every heading) and says whether the search
    is done; then `scores` and `flat` (cell * headings + heading) hold the `count` best poses,
    best first (ties: lowest index), the same however it was sliced.
    """

    def __init__(self, search: PoseSearch, count: int, beams: ScanBeams,
                 z_mm: np.ndarray) -> None:
        beam_bins = beams.bins
        # At most SEARCH_BEAMS beams, spread around: a coarse ranking (the candidates are then
        # refined with every ray), and half the lookups of 60 beams; misses come early in an
        # interleaved order.
        keep = np.arange(0, len(beam_bins), max(1, -(-len(beam_bins) // SEARCH_BEAMS)))
        order = interleaved_order(len(keep))
        self.search = search
        self.scored_beams = len(keep)
        self._bins = np.ascontiguousarray(beam_bins[keep][order])
        self._z_mm = np.ascontiguousarray(np.asarray(z_mm)[keep][order])
        self._max_misses = int(search.miss_share * len(keep))
        self._limits_mm = beams.limits_mm
        self._best = _TopScores(count)
        self._next = 0  # the first cell not scored yet

    @property
    def done(self) -> bool:
        """True once every position was scored."""
        return self._next >= len(self.search.cells)

    def advance(self, cells: int = SLICE_CELLS) -> bool:
        """Score the next `cells` positions (whole chunks); True if the search is done."""
        search, end = self.search, self._next + cells
        while self._next < min(end, len(search.cells)):
            first = self._next
            centres = search.centres[first:first + _CHUNK_CELLS]
            out = search._scores[:len(centres)]
            search._score_into(centres, self._bins, self._z_mm, self._max_misses, out,
                               self._limits_mm)
            self._best.add(out.ravel(), first * search.headings)
            self._next = first + len(centres)
        return self.done

    def finish(self) -> "SearchJob":
        """Score every position left (the whole search at once); returns the job."""
        while not self.advance():
            pass
        return self

    @property
    def scores(self) -> np.ndarray:
        """Scores of the best poses so far (matched beams), best first."""
        return self._best.scores

    @property
    def flat(self) -> np.ndarray:
        """Their flat indices: cell * headings + heading."""
        return self._best.flat


class _TopScores:
    """The `count` highest scores seen so far and their flat indices (ties: lowest index)."""

    def __init__(self, count: int) -> None:
        self.count = int(count)
        self.scores = np.zeros(0, dtype=np.int32)
        self.flat = np.zeros(0, dtype=np.int64)

    def add(self, scores: np.ndarray, offset: int) -> None:
        """Offer scores[i] at flat index offset + i (offsets increasing from call to call)."""
        if len(self.scores) == self.count:  # full: only a strictly higher score gets in
            index = np.flatnonzero(scores > self.scores[-1])
        elif scores.size > self.count:  # the chunk's own best `count` (ties: lowest index)
            kth = _kth_highest(scores, self.count)
            above = np.flatnonzero(scores > kth)
            index = np.sort(np.r_[above, np.flatnonzero(scores == kth)[:self.count - len(above)]])
        else:
            index = np.arange(scores.size)
        if index.size == 0:
            return
        merged_scores = np.r_[self.scores, scores[index]]
        merged_flat = np.r_[self.flat, offset + index]
        keep = np.lexsort((merged_flat, -merged_scores))[:self.count]
        self.scores, self.flat = merged_scores[keep], merged_flat[keep]


def _kth_highest(scores: np.ndarray, k: int) -> int:
    """The k-th highest of non-negative integer scores (matched beams), by counting them.

    np.partition took ~60 ms on a chunk's 491,520 scores (few distinct values); this ~2 ms.
    """
    at_least = np.cumsum(np.bincount(scores)[::-1])  # at_least[i]: scores >= top - i
    return int(len(at_least) - 1 - np.searchsorted(at_least, k))


def refine(pose, matcher: ScanMatcher, ranges: np.ndarray, tolerance: float,
           step: tuple[float, float] = (0.04, math.radians(2.0)), halvings: int = 3
           ) -> Alternative:
    """Coordinate ascent of the exact match fraction from `pose`.

    First steps half of `step` (m, rad), halved whenever no neighbour is better (`halvings` times).
    """
    best = (tuple(pose), matcher.match_fraction(pose, ranges, tolerance))
    dxy, dth = step[0] / 2.0, step[1] / 2.0
    while halvings > 0:
        x, y, theta = best[0]
        improved = False
        for candidate in ((x + dxy, y, theta), (x - dxy, y, theta), (x, y + dxy, theta),
                          (x, y - dxy, theta), (x, y, theta + dth), (x, y, theta - dth)):
            fraction = matcher.match_fraction(candidate, ranges, tolerance)
            if fraction > best[1]:
                best, improved = (candidate, fraction), True
        if not improved:
            dxy, dth = dxy / 2.0, dth / 2.0
            halvings -= 1
    x, y, theta = best[0]
    return Alternative((x, y, math.remainder(theta, 2.0 * math.pi)), best[1])


def close_poses(a, b, distance: float, angle: float) -> bool:
    """True if poses a and b (x, y, theta) are within `distance` (m) and `angle` (rad)."""
    d_theta = abs(math.remainder(a[2] - b[2], 2.0 * math.pi))
    return math.hypot(a[0] - b[0], a[1] - b[1]) <= distance and d_theta <= angle
