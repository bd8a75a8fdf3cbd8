"""Compiled loops of the correlative scan matcher: branch and bound and its numpy reference.

A candidate pose is (angle index a, column offset ix, row offset iy) around the search centre;
`cells[a]` holds each scan point's (row, col) in the field window for angle a at offset (0, 0).
The score of a candidate is the mean field value under its points, times the penalties for
moving away from the prior (exp(-d^2 / 2 sigma^2) in translation; `angle_penalty[a]`).

- `bnb_search`: Cartographer's branch and bound over a pyramid of max-pooled fields (level h
  holds the maximum of the field over 2^h x 2^h blocks, so a level-h score bounds the score of
  every offset in its block); depth first, best children first, a subtree pruned when its
  bound is not above the best complete score. Gives the same optimum as trying every offset.
  An exclusion box (offsets within `exclude` of a pose) lets the loop closer ask for the best
  match elsewhere: the ambiguity check.
- `exhaustive_search_numpy`: the same search by scoring every candidate with numpy (the plain
  reference the benchmark compares against).
The `*_python` functions are the plain twins the tests hold the compiled ones to.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit


def _score_python(level, cells, a, ix, iy):
    rows, cols = level.shape
    total = 0.0
    n = cells.shape[1]
    for i in range(n):
        r = cells[a, i, 0] + iy
        c = cells[a, i, 1] + ix
        if 0 <= r < rows and 0 <= c < cols:
            total += level[r, c]
    return total / n


_score = jit(_score_python)


def _block_penalty_python(ix, iy, size, wx, wy, inv_two_sigma2):
    """Translation penalty of the offset of the block [ix, ix+size) x [iy, iy+size) nearest 0."""
    if inv_two_sigma2 <= 0.0:
        return 1.0
    hi_x = min(ix + size - 1, wx)
    hi_y = min(iy + size - 1, wy)
    nx = 0 if ix <= 0 <= hi_x else (ix if ix > 0 else hi_x)
    ny = 0 if iy <= 0 <= hi_y else (iy if iy > 0 else hi_y)
    return math.exp(-(nx * nx + ny * ny) * inv_two_sigma2)


_block_penalty = jit(_block_penalty_python)


def _excluded_python(a, ix, iy, exclude):
    return (exclude[3] >= 0 and abs(a - exclude[0]) <= exclude[3]
            and abs(ix - exclude[1]) <= exclude[4] and abs(iy - exclude[2]) <= exclude[4])


_excluded = jit(_excluded_python)


def bnb_search_python(levels, cells, wx, wy, angle_penalty, inv_two_sigma2, exclude, min_score,
                      result):
    """Best (a, ix, iy) with |ix| <= wx, |iy| <= wy and score > min_score.

    levels: (H, rows, cols) float32 pyramid (level 0 = the field); cells: (A, N, 2) int32;
    angle_penalty: (A,); inv_two_sigma2: cell^2 / (2 sigma^2) (0 = no translation penalty);
    exclude: int64 [a, ix, iy, angle_radius, cell_radius] (angle_radius < 0: none).
    result (float64, 5): [a, ix, iy, score, candidates scored]; score -1 if none beat min_score.
    Long: one function on purpose (~100 lines): the compiled search keeps its explicit stack in
    local arrays; split, the pieces would pass that state back and forth.
    """
    depth = levels.shape[0]
    n_angles = cells.shape[0]
    top = depth - 1
    size = 1 << top
    nx = (2 * wx) // size + 1
    ny = (2 * wy) // size + 1
    count = n_angles * nx * ny
    scores = np.empty(count)
    cand = np.empty((count, 3), dtype=np.int64)
    k = 0
    for a in range(n_angles):
        for jx in range(nx):
            ix = -wx + jx * size
            for jy in range(ny):
                iy = -wy + jy * size
                cand[k, 0] = a
                cand[k, 1] = ix
                cand[k, 2] = iy
                scores[k] = (_score(levels[top], cells, a, ix, iy) * angle_penalty[a]
                             * _block_penalty(ix, iy, size, wx, wy, inv_two_sigma2))
                k += 1
    scored = count
    order = np.argsort(-scores, kind="mergesort")
    capacity = count + 4 * depth + 4
    stack_h = np.empty(capacity, dtype=np.int64)
    stack_c = np.empty((capacity, 3), dtype=np.int64)
    stack_s = np.empty(capacity)
    top_of_stack = 0
    for m in range(count - 1, -1, -1):  # best last: popped first
        j = order[m]
        stack_h[top_of_stack] = top
        stack_c[top_of_stack, 0] = cand[j, 0]
        stack_c[top_of_stack, 1] = cand[j, 1]
        stack_c[top_of_stack, 2] = cand[j, 2]
        stack_s[top_of_stack] = scores[j]
        top_of_stack += 1
    best = min_score
    best_a = -1
    best_ix = 0
    best_iy = 0
    child_s = np.empty(4)
    child_c = np.empty((4, 2), dtype=np.int64)
    while top_of_stack > 0:
        top_of_stack -= 1
        h = stack_h[top_of_stack]
        score = stack_s[top_of_stack]
        if score <= best:
            continue
        a = stack_c[top_of_stack, 0]
        ix = stack_c[top_of_stack, 1]
        iy = stack_c[top_of_stack, 2]
        if h == 0:
            if not _excluded(a, ix, iy, exclude):
                best = score
                best_a = a
                best_ix = ix
                best_iy = iy
            continue
        half = 1 << (h - 1)
        n_children = 0
        for dx in range(2):
            cx = ix + dx * half
            if cx > wx:
                continue
            for dy in range(2):
                cy = iy + dy * half
                if cy > wy:
                    continue
                s = (_score(levels[h - 1], cells, a, cx, cy) * angle_penalty[a]
                     * _block_penalty(cx, cy, half, wx, wy, inv_two_sigma2))
                scored += 1
                # insertion sort, ascending: the best child is pushed last
                m = n_children
                while m > 0 and child_s[m - 1] > s:
                    child_s[m] = child_s[m - 1]
                    child_c[m, 0] = child_c[m - 1, 0]
                    child_c[m, 1] = child_c[m - 1, 1]
                    m -= 1
                child_s[m] = s
                child_c[m, 0] = cx
                child_c[m, 1] = cy
                n_children += 1
        for m in range(n_children):
            if child_s[m] > best:
                stack_h[top_of_stack] = h - 1
                stack_c[top_of_stack, 0] = a
                stack_c[top_of_stack, 1] = child_c[m, 0]
                stack_c[top_of_stack, 2] = child_c[m, 1]
                stack_s[top_of_stack] = child_s[m]
                top_of_stack += 1
    result[0] = best_a
    result[1] = best_ix
    result[2] = best_iy
    result[3] = best if best_a >= 0 else -1.0
    result[4] = scored


def thin_points_python(points, theta, spacing, keep):
    """Indices of the points (robot frame, scan order) to score, written into keep; the count.

    A point is kept when its square of side `spacing` (axes of the map at heading theta)
    differs from the last kept point's: near walls give several points per map cell, and one
    or two score the same shape for less work (the refinement uses them all).
    """
    c = math.cos(theta)
    s = math.sin(theta)
    count = 0
    last_col = -(1 << 40)
    last_row = -(1 << 40)
    for i in range(points.shape[0]):
        col = math.floor((c * points[i, 0] - s * points[i, 1]) / spacing)
        row = math.floor((s * points[i, 0] + c * points[i, 1]) / spacing)
        if col != last_col or row != last_row:
            keep[count] = i
            count += 1
            last_col = col
            last_row = row
    return count


bnb_search = jit(bnb_search_python)
thin_points = jit(thin_points_python)


def exhaustive_search_numpy(levels, cells, wx, wy, angle_penalty, inv_two_sigma2, exclude,
                            min_score, result):
    """bnb_search's optimum by scoring every candidate on level 0 with numpy (the reference)."""
    field = levels[0]
    rows, cols = field.shape
    # Zero border wide enough that every index outside the field, clipped, lands on a zero.
    padded = np.zeros((rows + 2 * wy + 2, cols + 2 * wx + 2), dtype=np.float64)
    padded[wy + 1:wy + 1 + rows, wx + 1:wx + 1 + cols] = field
    offsets_x = np.arange(-wx, wx + 1)
    offsets_y = np.arange(-wy, wy + 1)
    penalty = np.exp(-(offsets_y[:, None] ** 2 + offsets_x[None, :] ** 2) * inv_two_sigma2)
    best = (-1, 0, 0, min_score)
    n = cells.shape[1]
    for a in range(cells.shape[0]):
        rr = np.clip(cells[a, :, 0].astype(np.int64)[:, None, None] + offsets_y[None, :, None]
                     + wy + 1, 0, padded.shape[0] - 1)
        cc = np.clip(cells[a, :, 1].astype(np.int64)[:, None, None] + offsets_x[None, None, :]
                     + wx + 1, 0, padded.shape[1] - 1)
        scores = padded[rr, cc].sum(axis=0) / n * angle_penalty[a] * penalty
        if exclude[3] >= 0 and abs(a - exclude[0]) <= exclude[3]:
            ex = np.abs(offsets_x[None, :] - exclude[1]) <= exclude[4]
            ey = np.abs(offsets_y[:, None] - exclude[2]) <= exclude[4]
            scores = np.where(ex & ey, -np.inf, scores)
        j = int(np.argmax(scores))
        iy, ix = divmod(j, scores.shape[1])
        if scores[iy, ix] > best[3]:
            best = (a, int(offsets_x[ix]), int(offsets_y[iy]), float(scores[iy, ix]))
    result[0], result[1], result[2] = best[0], best[1], best[2]
    result[3] = best[3] if best[0] >= 0 else -1.0
    result[4] = cells.shape[0] * len(offsets_x) * len(offsets_y)


__all__ = ["bnb_search", "bnb_search_python", "exhaustive_search_numpy", "thin_points",
           "thin_points_python"]
