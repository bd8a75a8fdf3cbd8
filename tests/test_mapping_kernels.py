"""amr_mapping's compiled kernels against their plain-Python twins, and the search's optimum.

Each compiled kernel (numba through amr_common.jit) must give the same numbers as the Python
function it was compiled from, on inputs with the awkward cases in them: rays leaving the
array, axis-parallel rays, rays ending in their start cell, cells at the array's border.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.jit import HAVE_NUMBA
from amr_mapping import grid_kernels as gk
from amr_mapping import line_kernels as lk
from amr_mapping import match_kernels as mk


def test_the_kernels_are_compiled():
    assert HAVE_NUMBA
    for kernel in (gk.trace_rays, gk.smear_window, gk.max_pool, lk.fit_lines, lk.refine_lines,
                   mk.bnb_search, mk.thin_points):
        assert hasattr(kernel, "py_func"), kernel


def _random_rays(rng, count=300):
    sx, sy = 20.3, 17.7
    ends = np.column_stack([rng.uniform(-10, 50, count), rng.uniform(-10, 45, count)])
    ends[:10, 0] = sx + rng.uniform(-5, 5, 10)  # vertical rays
    ends[10:20, 1] = sy + rng.uniform(-5, 5, 10)  # horizontal rays
    ends[20] = (sx + 0.1, sy + 0.1)  # ends in its own cell
    return sx, sy, ends


def _trace(kernel, ends, sx, sy, sign=1, state=None, moments=True):
    counts, hits, sums = state or (np.zeros((40, 35), np.int32), np.zeros((40, 35), np.int32),
                                   np.zeros((5, 40, 35) if moments else (5, 0, 0)))
    changed = kernel(counts, 0, 0, sx, sy, ends, 90 * sign, -40 * sign, 0.7, sign, hits, sums)
    return changed, (counts, hits, sums)


def test_trace_rays_twin_equal_and_exactly_removable():
    rng = np.random.default_rng(3)
    sx, sy, ends = _random_rays(rng)
    compiled = _trace(gk.trace_rays, ends, sx, sy)
    plain = _trace(gk.trace_rays_python, ends, sx, sy)
    assert compiled[0] == plain[0] > 0
    for a, b in zip(compiled[1], plain[1]):
        assert np.array_equal(a, b)
    counts, hits, sums = compiled[1]
    assert counts.min() < 0 < counts.max() and hits.sum() > 0
    # Taking the same rays out again leaves nothing behind: counts and hits exactly.
    _trace(gk.trace_rays, ends, sx, sy, -1, compiled[1])
    assert not counts.any() and not hits.any()
    assert np.abs(sums).max() < 1e-12


def test_trace_rays_in_global_cells_any_array_offset_twin_equal():
    """The same rays into an array that starts elsewhere: the same cells, shifted."""
    rng = np.random.default_rng(6)
    sx, sy, ends = _random_rays(rng)
    results = []
    for kernel in (gk.trace_rays, gk.trace_rays_python):
        counts, hits = np.zeros((40, 35), np.int32), np.zeros((40, 35), np.int32)
        sums = np.zeros((5, 40, 35))
        # global cell (r, c) is counts[r + 7, c - 12]: the array starts 7 rows lower and 12
        # columns further right than _trace's
        kernel(counts, -7, 12, sx, sy, ends, 90, -40, 0.7, 1, hits, sums)
        results.append((counts, hits, sums))
    for a, b in zip(*results):
        assert np.array_equal(a, b)
    _, (counts, hits, _) = _trace(gk.trace_rays, ends, sx, sy)
    assert np.array_equal(results[0][0][7:, :23], counts[:33, 12:])
    assert np.array_equal(results[0][1][7:, :23], hits[:33, 12:]) and hits.sum() > 0


def test_trace_rays_without_moments_counts_hits_only():
    rng = np.random.default_rng(4)
    sx, sy, ends = _random_rays(rng, 50)
    _, (counts, hits, sums) = _trace(gk.trace_rays, ends, sx, sy, moments=False)
    assert hits.sum() > 0 and sums.size == 0


def _grid_with_walls(rng):
    counts = np.zeros((60, 70), np.int32)
    hits = np.zeros((60, 70), np.int32)
    sums = np.zeros((5, 60, 70))
    sx, sy = 35.0, 30.0
    angles = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    radius = 20.0
    ends = np.column_stack([sx + radius * np.cos(angles) * 1.3, sy + radius * np.sin(angles)])
    for _ in range(3):
        gk.trace_rays(counts, 0, 0, sx, sy, ends + rng.normal(0, 0.15, ends.shape), 90, -40,
                      0.0, 1, hits, sums)
    return counts, hits, sums


def test_smear_window_and_max_pool_twins_equal():
    rng = np.random.default_rng(5)
    counts, hits, sums = _grid_with_walls(rng)
    kernels = gk.shifted_gaussian_kernels(1.5)
    fields = []
    for kernel in (gk.smear_window, gk.smear_window_python):
        out = np.zeros((50, 55), np.float32)
        kernel(counts, hits, sums, 7, -3, 60.0, 90, 40.0, kernels, out)
        fields.append(out)
    assert np.array_equal(*fields) and fields[0].max() > 0.5
    pooled = []
    for kernel in (gk.max_pool, gk.max_pool_python):
        out = np.zeros_like(fields[0])
        kernel(fields[0], 2, out)
        pooled.append(out)
    assert np.array_equal(*pooled)
    # level 2 holds the maximum over each 4 x 4 block starting at the cell
    level1 = np.zeros_like(fields[0])
    gk.max_pool(fields[0], 1, level1)
    level2 = np.zeros_like(fields[0])
    gk.max_pool(level1, 2, level2)
    assert level2[10, 20] == fields[0][10:14, 20:24].max()


def test_shifted_kernels_peak_at_the_sub_cell_point():
    kernels = gk.shifted_gaussian_kernels(1.0, bins=16)
    radius = kernels.shape[2] // 2
    # point near the upper right corner of its cell: the cell up and right is as close as it
    near_corner = kernels[15, 15]
    assert near_corner[radius, radius] == pytest.approx(near_corner[radius + 1, radius + 1],
                                                        rel=0.15)
    centred = kernels[8, 8]
    assert centred[radius, radius] == centred.max()


def test_line_kernels_twins_equal_and_refinement_recovers_an_offset():
    rng = np.random.default_rng(6)
    counts, hits, sums = _grid_with_walls(rng)
    lines = []
    for kernel in (lk.fit_lines, lk.fit_lines_python):
        out = np.zeros((4, 60, 70))
        kernel(hits, sums, 0, 0, 4, 0.35, out)
        lines.append(out)
    assert np.array_equal(*lines) and lines[0][3].sum() > 100
    # Points on the walls, seen from a pose 1.5 cells and 0.02 rad away from the true one.
    resolution = 0.02
    angles = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    world = np.column_stack([35.0 + 20.0 * np.cos(angles) * 1.3, 30.0 + 20.0 * np.sin(angles)])
    true = (35.0 * resolution, 30.0 * resolution, 0.0)
    points = world * resolution - np.array(true[:2])
    results = []
    for kernel in (lk.refine_lines, lk.refine_lines_python):
        out = np.zeros(4)
        kernel(lines[0], 0, 0, resolution, points, np.array([0.73, 0.59, 0.02]),
               np.zeros(3), np.zeros(3), 100.0, 0.04, 20, 0.02, out)
        results.append(out)
    assert np.array_equal(*results)
    x, y, th, used = results[0]
    assert used > 300
    assert math.hypot(x - true[0], y - true[1]) < 0.003 and abs(th) < 0.003


def _search_case(rng):
    field = np.zeros((90, 100), np.float32)
    field[rng.random(field.shape) < 0.03] = 1.0
    smooth = np.zeros_like(field)
    for dr in range(-2, 3):
        for dc in range(-2, 3):
            smooth = np.maximum(smooth, np.roll(np.roll(field, dr, 0), dc, 1) *
                                math.exp(-(dr * dr + dc * dc) / 4.5))
    levels = np.zeros((4,) + smooth.shape, np.float32)
    levels[0] = smooth
    for h in range(1, 4):
        gk.max_pool(levels[h - 1], 1 << (h - 1), levels[h])
    cells = np.stack([rng.integers(-4, 95, (11, 150)), rng.integers(-4, 105, (11, 150))],
                     axis=2).astype(np.int32)
    return levels, cells


@pytest.mark.parametrize("penalty,exclude", [
    (0.0, [0, 0, 0, -1, 0]), (0.02, [0, 0, 0, -1, 0]), (0.0, [5, 1, -2, 1, 3])])
def test_branch_and_bound_finds_the_exhaustive_optimum(penalty, exclude):
    rng = np.random.default_rng(7)
    levels, cells = _search_case(rng)
    angle_penalty = np.exp(-np.linspace(-1, 1, 11) ** 2)
    exclude = np.array(exclude, dtype=np.int64)
    results = []
    for search in (mk.bnb_search, mk.bnb_search_python, mk.exhaustive_search_numpy):
        result = np.zeros(5)
        search(levels, cells, 13, 11, angle_penalty, penalty, exclude, 0.0, result)
        results.append(result)
    assert np.array_equal(results[0], results[1])
    assert np.array_equal(results[0][:3], results[2][:3])
    assert results[0][3] == pytest.approx(results[2][3], rel=1e-6)
    assert results[0][4] < results[2][4]  # branch and bound scored fewer candidates
    if exclude[3] >= 0:
        a, ix, iy = results[0][:3]
        assert abs(a - 5) > 1 or abs(ix - 1) > 3 or abs(iy + 2) > 3


def test_thin_points_twin_equal():
    rng = np.random.default_rng(8)
    points = np.cumsum(rng.normal(0, 0.01, (360, 2)), axis=0)
    counts = []
    for kernel in (mk.thin_points, mk.thin_points_python):
        keep = np.zeros(360, np.int64)
        counts.append((kernel(points, 0.3, 0.04, keep), keep.copy()))
    assert counts[0][0] == counts[1][0] < 360
    assert np.array_equal(counts[0][1][:counts[0][0]], counts[1][1][:counts[1][0]])
