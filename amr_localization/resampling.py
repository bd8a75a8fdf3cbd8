"""Low-variance resampling and the KLD-style adaptive particle count. No rclpy import.

Low-variance (systematic) resampling draws M particles with ONE random offset: sample j takes
the particle whose cumulative weight interval holds (u + j) / M, u uniform in [0, 1). Each
particle is copied floor(M w) or ceil(M w) times, so the expected count M w holds with the least
variance.

KLD sampling (Fox 2003) sizes the set so that, with probability 1 - delta, the K-L divergence
between the sample-based and the true posterior stays below epsilon: with k histogram bins
occupied, n = (k - 1) / (2 epsilon) * (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z)^3. The
bins here are small (5 cm x 5 cm x 10 degrees by default), sized for 2-3 m mazes, not Nav2's fixed
0.5 m bins (a 2.4 m maze would be ~5 x 5 bins and never shrink the set usefully).
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit


def low_variance_indices_python(weights, count, u, out):
    """out[:count] = indices drawn by low-variance resampling; weights sum to 1, u in [0, 1)."""
    n = weights.shape[0]
    step = 1.0 / count
    target = u * step
    cumulative = weights[0]
    i = 0
    for j in range(count):
        while target > cumulative and i < n - 1:
            i += 1
            cumulative += weights[i]
        out[j] = i
        target += step


low_variance_indices = jit(low_variance_indices_python)


def resample(particles: np.ndarray, weights: np.ndarray, count: int,
             rng: np.random.Generator) -> np.ndarray:
    """A new (count, 3) particle array drawn from `particles` with normalised `weights`."""
    indices = np.empty(count, dtype=np.int64)
    low_variance_indices(weights, count, float(rng.random()), indices)
    return particles[indices]


def occupied_bins_python(particles, count, x0, y0, bin_xy, bin_theta, nbx, nby, nbt, seen):
    """Number of distinct (x, y, theta) bins the first `count` particles fall in.

    `seen` is a zeroed uint8 array of nbx * nby * nbt entries; it is zeroed again on return.
    """
    occupied = 0
    touched = np.empty(count, dtype=np.int64)
    for p in range(count):
        bx = int(math.floor((particles[p, 0] - x0) / bin_xy))
        by = int(math.floor((particles[p, 1] - y0) / bin_xy))
        bt = int(math.floor((particles[p, 2] + math.pi) / bin_theta))
        bx = min(max(bx, 0), nbx - 1)
        by = min(max(by, 0), nby - 1)
        bt = min(max(bt, 0), nbt - 1)
        key = (by * nbx + bx) * nbt + bt
        if seen[key] == 0:
            seen[key] = 1
            touched[occupied] = key
            occupied += 1
    for k in range(occupied):
        seen[touched[k]] = 0
    return occupied


occupied_bins = jit(occupied_bins_python)


def kld_count(bins: int, epsilon: float, z: float) -> int:
    """Particles needed for `bins` occupied bins (KLD bound; 1 for a single bin)."""
    if bins <= 1:
        return 1
    k = bins - 1
    a = 2.0 / (9.0 * k)
    return int(math.ceil(k / (2.0 * epsilon) * (1.0 - a + math.sqrt(a) * z) ** 3))


def effective_sample_size(weights: np.ndarray) -> float:
    """1 / sum(w^2) of normalised weights: N for uniform weights, 1 for a single carrier."""
    return float(1.0 / np.dot(weights, weights))


class KldResampler:
    """Low-variance resampling to the KLD-sized count, within [min_count, max_count].

    Bins of bin_xy (m) x bin_xy x bin_theta (rad) over a map whose lower-left corner is
    (x0, y0) and extent (width, height) m.
    """

    def __init__(self, x0: float, y0: float, width: float, height: float, bin_xy: float,
                 bin_theta: float, epsilon: float, z: float, min_count: int,
                 max_count: int) -> None:
        self.origin = (float(x0), float(y0))
        self.bin_xy, self.bin_theta = float(bin_xy), float(bin_theta)
        self.shape = (int(math.ceil(width / bin_xy)) + 1, int(math.ceil(height / bin_xy)) + 1,
                      int(math.ceil(2.0 * math.pi / bin_theta)) + 1)
        self.epsilon, self.z = float(epsilon), float(z)
        self.min_count, self.max_count = int(min_count), int(max_count)
        self._seen = np.zeros(int(np.prod(self.shape)), dtype=np.uint8)

    def __call__(self, particles: np.ndarray, weights: np.ndarray,
                 rng: np.random.Generator) -> np.ndarray:
        """The resampled particles (equal weights), as many as the KLD bound asks for."""
        count = len(particles)
        drawn = resample(particles, weights, count, rng)
        bins = occupied_bins(drawn, count, *self.origin, self.bin_xy, self.bin_theta,
                             *self.shape, self._seen)
        wanted = min(max(kld_count(bins, self.epsilon, self.z), self.min_count), self.max_count)
        if wanted != count:
            drawn = resample(particles, weights, wanted, rng)
        return np.ascontiguousarray(drawn)
