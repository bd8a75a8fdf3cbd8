"""Correlative scan-to-map matching, multi-resolution, with sub-cell refinement.

    matcher = CorrelativeMatcher(resolution=0.02, smear_sigma=0.03)
    result = matcher.match(grid, occupied_units, points, prior=(x, y, theta),
                           linear_window=0.12, angular_window=0.12)
    result.pose, result.score

The map's occupied cells are smoothed into a field in [0, 1] (a Gaussian of the distance to
the nearest occupied cell, Karto's "smear"); a pose scores the mean field value under the scan's
points. The search covers every pose on a (resolution, angular step) lattice within the
windows around the prior - the angular step moves the farthest point by about one cell, as in
Cartographer - and finds the best by branch and bound over a pyramid of max-pooled fields
(match_kernels.bnb_search: the same optimum as scoring every pose, a fraction of the work).
Optional penalties weight the score by the distance from the prior (Karto's
distance/angle penalty), so a featureless corridor does not slide the pose. The lattice optimum
is then refined by point-to-line Gauss-Newton against the wall lines fitted in each cell
(line_kernels), with the prior as a soft constraint (as Cartographer's Ceres scan matcher
refines its correlative search): sub-cell accuracy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amr_mapping.grid_kernels import max_pool, shifted_gaussian_kernels, smear_window
from amr_mapping.line_kernels import fit_lines, refine_lines
from amr_mapping.log_odds_grid import LogOddsGrid
from amr_mapping.match_kernels import bnb_search, exhaustive_search_numpy, thin_points

_FIELD_MARGIN_M = 0.5  # a cached field covers this much more than one match needs
_REFINE_ITERATIONS = 10
_LINE_MIN_HITS = 4  # hits in a 3 x 3 neighbourhood to fit a wall line ...
_LINE_MAX_RATIO = 0.35  # ... whose spread across is at most this share of the spread along
_LINE_MAX_DISTANCE = 0.04  # m: points farther from their cell's line are outliers
_MIN_REFINE_POINTS = 10  # fewer points on lines: keep the lattice optimum
_DEGENERATE_RATIO = 0.02  # a direction the walls fix 50x less than the other: the prior's
_SEARCH_SPACING_CELLS = 2  # the search scores points at least this many cells apart
NO_EXCLUSION = np.array([0, 0, 0, -1, 0], dtype=np.int64)


@dataclass(frozen=True)
class MatchResult:
    """A match: the pose (x, y, theta), its lattice score (0..1) and search statistics."""

    pose: tuple[float, float, float]
    score: float  # mean field value under the points at the lattice optimum, no penalty
    weighted: float  # ... times the prior's penalties: what the search maximised
    lattice_pose: tuple[float, float, float]
    candidates: int  # poses scored (at any pyramid level)
    angular_step: float
    resolution: float

    def on_edge(self, prior: tuple[float, float, float], linear_window: float,
                angular_window: float) -> bool:
        """Whether the lattice optimum lies on the border of the window searched around prior.

        The best pose may then lie beyond: a wider search is needed to know.
        """
        x, y, th = self.lattice_pose
        return (abs(x - prior[0]) > linear_window - self.resolution
                or abs(y - prior[1]) > linear_window - self.resolution
                or abs(math.remainder(th - prior[2], math.tau))
                > angular_window - self.angular_step)


@dataclass
class _Field:
    levels: np.ndarray  # (depth, rows, cols) float32; level 0 = the smoothed field
    lines: np.ndarray  # (4, rows, cols) float64: line_kernels.fit_lines of each cell
    row0: int  # global cell of levels[:, 0, 0]
    col0: int
    version: int  # the grid's version it was computed from
    grid_id: int


class CorrelativeMatcher:
    """Scan-to-map matching against a LogOddsGrid (see the module docstring)."""

    def __init__(self, resolution: float, smear_sigma: float, use_reference: bool = False,
                 stale_versions: int = 0) -> None:
        """A matcher for maps of `resolution` m, smoothed by a Gaussian of smear_sigma m.

        use_reference: search with the numpy reference (the benchmark's); stale_versions: a
        cached field is reused while the grid changed at most this many times since.
        """
        self.resolution = float(resolution)
        self.kernels = shifted_gaussian_kernels(smear_sigma / self.resolution)
        self._search = exhaustive_search_numpy if use_reference else bnb_search
        self._stale_versions = int(stale_versions)
        self._cache: _Field | None = None

    def field(self, grid: LogOddsGrid, occupied_units: float, row_lo: int, col_lo: int,
              row_hi: int, col_hi: int, depth: int) -> _Field:
        """The smoothed field and its pyramid over global cells [row_lo, row_hi) x [col_lo, ...).

        Reused while the grid changed at most stale_versions times and the cached field covers
        the box at that depth.
        """
        cached = self._cache
        if cached is not None and cached.grid_id == grid.serial \
                and 0 <= grid.version - cached.version <= self._stale_versions \
                and cached.levels.shape[0] >= depth and cached.row0 <= row_lo \
                and cached.col0 <= col_lo and cached.row0 + cached.levels.shape[1] >= row_hi \
                and cached.col0 + cached.levels.shape[2] >= col_hi:
            return cached
        margin = int(round(_FIELD_MARGIN_M / self.resolution))
        row_lo, col_lo, row_hi, col_hi = (row_lo - margin, col_lo - margin, row_hi + margin,
                                          col_hi + margin)
        rows, cols = row_hi - row_lo, col_hi - col_lo
        row_off, col_off = row_lo - grid.row0, col_lo - grid.col0
        levels = np.zeros((depth, rows, cols), dtype=np.float32)
        lines = np.zeros((4, rows, cols))
        if grid.hits.size:
            smear_window(grid.counts, grid.hits, grid.sums, row_off, col_off, occupied_units,
                         grid.hit_units, float(-grid.miss_units), self.kernels, levels[0])
            fit_lines(grid.hits, grid.sums, row_off, col_off, _LINE_MIN_HITS, _LINE_MAX_RATIO,
                      lines)
        for h in range(1, depth):
            max_pool(levels[h - 1], 1 << (h - 1), levels[h])
        self._cache = _Field(levels, lines, row_lo, col_lo, grid.version, grid.serial)
        return self._cache

    def match(self, grid: LogOddsGrid, occupied_units: float, points: np.ndarray,
              prior: tuple[float, float, float], linear_window: float, angular_window: float,
              prior_sigma: tuple[float, float] | None = None,
              refine_sigmas: tuple[float, float, float] | None = None,
              exclude: tuple[tuple[float, float, float], float, float] | None = None
              ) -> MatchResult | None:
        """The best pose of `points` ((N, 2), robot frame) near `prior`, or None if none scores.

        prior_sigma (m, rad): penalties for moving away from the prior in the search (None:
        none); refine_sigmas (m, rad, point m): the prior's and a point's standard deviations
        in the refinement (None: no prior, 1 cm points); exclude (pose, distance, angle): skip
        lattice poses this close to `pose` (the ambiguity check).
        """
        res = self.resolution
        reach = float(np.sqrt((points ** 2).sum(axis=1)).max()) if len(points) else 0.0
        step = min(max(res / max(reach, res), 0.002), 0.05)
        n_half = int(math.ceil(angular_window / step - 1e-9))
        offsets = step * np.arange(-n_half, n_half + 1)
        window = max(int(math.ceil(linear_window / res - 1e-9)), 0)
        depth = 1 + max(int(math.floor(math.log2(window))), 0) if window > 1 else 1
        px, py, pth = prior
        keep = np.empty(len(points), dtype=np.int64)
        search = points[keep[:thin_points(points, pth, _SEARCH_SPACING_CELLS * res, keep)]]
        cos_a, sin_a = np.cos(pth + offsets), np.sin(pth + offsets)
        wx = search[None, :, 0] * cos_a[:, None] - search[None, :, 1] * sin_a[:, None] + px
        wy = search[None, :, 0] * sin_a[:, None] + search[None, :, 1] * cos_a[:, None] + py
        pad = (window + (1 << (depth - 1)) + 1) * res  # the search's reach beyond the points
        row_lo, col_lo, row_hi, col_hi = grid.cell_bounds(
            float(wx.min()) - pad, float(wy.min()) - pad, float(wx.max()) + pad,
            float(wy.max()) + pad)
        field = self.field(grid, occupied_units, row_lo, col_lo, row_hi, col_hi, depth)
        cells = np.empty((len(offsets), len(search), 2), dtype=np.int32)
        cells[:, :, 0] = np.floor(wy / res) - field.row0
        cells[:, :, 1] = np.floor(wx / res) - field.col0
        if prior_sigma is None:
            angle_penalty, inv_two_sigma2 = np.ones(len(offsets)), 0.0
        else:
            angle_penalty = np.exp(-offsets ** 2 / (2.0 * prior_sigma[1] ** 2))
            inv_two_sigma2 = res * res / (2.0 * prior_sigma[0] ** 2)
        excluded = NO_EXCLUSION
        if exclude is not None:
            (ex, ey, eth), distance, angle = exclude
            excluded = np.array([int(round(math.remainder(eth - pth, math.tau) / step)) + n_half,
                                 int(round((ex - px) / res)), int(round((ey - py) / res)),
                                 int(math.ceil(angle / step)), int(math.ceil(distance / res))],
                                dtype=np.int64)
        result = np.zeros(5)
        self._search(field.levels[:depth], cells, window, window, angle_penalty, inv_two_sigma2,
                     excluded, 0.0, result)
        a = int(result[0])
        if a < 0:
            return None
        lattice = (px + result[1] * res, py + result[2] * res, pth + offsets[a])
        score = result[3] / (angle_penalty[a] * math.exp(-(result[1] ** 2 + result[2] ** 2)
                                                          * inv_two_sigma2))
        pose = self._refine(field, points, lattice, prior, refine_sigmas, step)
        return MatchResult(pose, float(score), float(result[3]), lattice, int(result[4]), step,
                           res)

    def _refine(self, field: _Field, points: np.ndarray, lattice: tuple[float, float, float],
                prior: tuple[float, float, float],
                sigmas: tuple[float, float, float] | None,
                step: float) -> tuple[float, float, float]:
        out = np.zeros(4)
        if sigmas is None:
            prior_weights, point_weight = np.zeros(3), 100.0
        else:
            prior_weights = np.array([1.0 / sigmas[0], 1.0 / sigmas[0], 1.0 / sigmas[1]])
            point_weight = 1.0 / sigmas[2]
        refine_lines(field.lines, field.col0, field.row0, self.resolution, points,
                     np.asarray(lattice, dtype=np.float64), np.asarray(prior, dtype=np.float64),
                     prior_weights, point_weight, _LINE_MAX_DISTANCE, _REFINE_ITERATIONS,
                     _DEGENERATE_RATIO, out)
        x, y, th = float(out[0]), float(out[1]), float(out[2])
        res = self.resolution
        # The lattice optimum is within a cell and a step of the best pose: a refinement that
        # wanders farther has slid along a featureless direction, which the search rejected.
        if out[3] < _MIN_REFINE_POINTS or \
                not (math.isfinite(x) and math.isfinite(y) and math.isfinite(th)) or \
                abs(x - lattice[0]) > 2.0 * res or abs(y - lattice[1]) > 2.0 * res or \
                abs(th - lattice[2]) > 2.0 * step:
            return lattice
        return x, y, math.remainder(th, math.tau)


__all__ = ["CorrelativeMatcher", "MatchResult"]
