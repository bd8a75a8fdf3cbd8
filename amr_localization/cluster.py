"""The dominant cluster of the particles and the weighted statistics of the estimate.

One compiled pass family (numba, plain Python without it) instead of ~30 small numpy operations:
this runs at every measurement update, where numpy's per-call overhead cost ~0.2 ms with a few
hundred particles. No rclpy import.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amr_common.jit import jit

_DENSE_BINS_PER_PARTICLE = 8  # histogram array up to this many bins per particle (+ the minimum)
_DENSE_BINS_MIN = 65536
_SPARSE_BIN_LIMIT = 1 << 20  # bins per axis of the sorted keys (beyond: the last bin, 100 km)


@dataclass
class Cluster:
    """The heaviest group of particles, its weighted mean and covariance."""

    pose: tuple[float, float, float]  # weighted mean (x, y, theta)
    share: float  # weight carried by the cluster, in [0, 1]
    members: np.ndarray  # (N,) bool
    covariance: np.ndarray  # 3 x 3 of ALL particles about `pose` (headings wrapped around it)


def _wrap(angle):
    return angle - 2.0 * math.pi * math.floor((angle + math.pi) / (2.0 * math.pi))


def _mean_of(particles, weights, mask, use_mask):
    """Weighted mean (x, y, circular theta) and weight of the (masked) particles."""
    sw = 0.0
    sx = 0.0
    sy = 0.0
    sc = 0.0
    ss = 0.0
    for p in range(particles.shape[0]):
        if use_mask and not mask[p]:
            continue
        w = weights[p]
        sw += w
        sx += w * particles[p, 0]
        sy += w * particles[p, 1]
        sc += w * math.cos(particles[p, 2])
        ss += w * math.sin(particles[p, 2])
    if sw > 0.0:
        return sx / sw, sy / sw, math.atan2(ss, sc), sw
    return np.nan, np.nan, np.nan, 0.0


_mean_kernel = jit(_mean_of)
_wrap_kernel = jit(_wrap)


def _heaviest_sparse(keys, weights):
    """The key carrying the most weight, by sorting the keys (any spread, O(n log n))."""
    order = np.argsort(keys)
    best_key = keys[order[0]]
    best = -1.0
    run = 0.0
    for i in range(order.shape[0]):
        p = order[i]
        if i > 0 and keys[p] != keys[order[i - 1]]:
            run = 0.0
        run += weights[p]
        if run > best:
            best = run
            best_key = keys[p]
    return best_key


_heaviest_sparse_kernel = jit(_heaviest_sparse)


def cluster_python(particles, weights, radius, angle, members, stats):
    """Dominant cluster membership, its weighted mean and the covariance.

    members[p]: particle p belongs to the dominant cluster; stats = [x, y, theta, share,
    then the 3 x 3 covariance of all particles about (x, y, theta) row by row].
    The histogram is an array over the particles' extent while that has at most
    _DENSE_BINS_PER_PARTICLE bins per particle, else a sort of the particles' bin keys: its
    size never grows with how far apart the particles are.
    Long: one compiled kernel (~80 lines): extent, histogram, heaviest bin, two gathers around
    its mean and the weighted moments share the local arrays; split, they would be passed
    between kernels at every call.
    """
    n = particles.shape[0]
    xmin = np.inf
    ymin = np.inf
    xmax = -np.inf
    ymax = -np.inf
    for p in range(n):
        xmin = min(xmin, particles[p, 0])
        xmax = max(xmax, particles[p, 0])
        ymin = min(ymin, particles[p, 1])
        ymax = max(ymax, particles[p, 1])
    nbt = max(int(math.ceil(2.0 * math.pi / angle)), 1)
    span_x = (xmax - xmin) / radius + 1.0  # floats: a huge spread must not overflow an int
    span_y = (ymax - ymin) / radius + 1.0
    dense = span_x * span_y * nbt <= _DENSE_BINS_PER_PARTICLE * n + _DENSE_BINS_MIN
    nby = int(span_y) if dense else _SPARSE_BIN_LIMIT
    keys = np.empty(n, dtype=np.int64)
    for p in range(n):
        bt = min(int((particles[p, 2] + math.pi) / angle), nbt - 1)
        bt = max(bt, 0)
        bx = min((particles[p, 0] - xmin) / radius, _SPARSE_BIN_LIMIT - 1.0)
        by = min((particles[p, 1] - ymin) / radius, _SPARSE_BIN_LIMIT - 1.0)
        keys[p] = (int(bx) * nby + int(by)) * nbt + bt
    if dense:
        weight_of_bin = np.zeros(int(span_x) * nby * nbt)
        for p in range(n):
            weight_of_bin[keys[p]] += weights[p]
        heaviest = int(np.argmax(weight_of_bin))
    else:
        heaviest = _heaviest_sparse_kernel(keys, weights)
    for p in range(n):
        members[p] = keys[p] == heaviest
    x, y, theta, _ = _mean_kernel(particles, weights, members, True)
    for _ in range(2):  # gather around the bin's mean, re-centre, gather again
        found = 0
        for p in range(n):
            dx = particles[p, 0] - x
            dy = particles[p, 1] - y
            near = dx * dx + dy * dy <= radius * radius and \
                abs(_wrap_kernel(particles[p, 2] - theta)) <= angle
            members[p] = near
            found += near
        if found == 0:
            for p in range(n):
                members[p] = keys[p] == heaviest
            break
        x, y, theta, _ = _mean_kernel(particles, weights, members, True)
    total = 0.0
    inside = 0.0
    cov = np.zeros((3, 3))
    for p in range(n):
        w = weights[p]
        total += w
        if members[p]:
            inside += w
        d0 = particles[p, 0] - x
        d1 = particles[p, 1] - y
        d2 = _wrap_kernel(particles[p, 2] - theta)
        cov[0, 0] += w * d0 * d0
        cov[0, 1] += w * d0 * d1
        cov[0, 2] += w * d0 * d2
        cov[1, 1] += w * d1 * d1
        cov[1, 2] += w * d1 * d2
        cov[2, 2] += w * d2 * d2
    stats[0] = x
    stats[1] = y
    stats[2] = theta
    stats[3] = inside / total if total > 0.0 else 0.0
    norm = 1.0 / total if total > 0.0 else 0.0
    for i in range(3):
        for j in range(i, 3):
            stats[4 + 3 * i + j] = cov[i, j] * norm
            stats[4 + 3 * j + i] = cov[i, j] * norm


cluster_kernel = jit(cluster_python)


def weighted_pose_mean(particles: np.ndarray, weights: np.ndarray) -> tuple[float, float, float]:
    """Weighted mean position and circular mean heading of particles (N, 3).

    The plain mean if the weights sum to zero.
    """
    particles = np.ascontiguousarray(particles, dtype=np.float64)
    weights = np.ascontiguousarray(weights, dtype=np.float64)
    if not weights.sum() > 0.0:
        weights = np.ones(len(particles))
    x, y, theta, _ = _mean_kernel(particles, weights, np.zeros(0, dtype=np.bool_), False)
    return float(x), float(y), float(theta)


def dominant_cluster(particles: np.ndarray, weights: np.ndarray, radius: float,
                     angle: float) -> Cluster:
    """The particles within `radius` (m) and `angle` (rad) of the heaviest region.

    The region is found on a coarse histogram (bins of radius x radius x angle, weighted), then
    the cluster is gathered around that bin's weighted mean and re-centred once on its own mean.
    """
    particles = np.ascontiguousarray(particles, dtype=np.float64)
    weights = np.ascontiguousarray(weights, dtype=np.float64)
    members = np.zeros(len(particles), dtype=np.bool_)
    stats = np.zeros(13)
    cluster_kernel(particles, weights, float(radius), float(angle), members, stats)
    return Cluster(pose=(float(stats[0]), float(stats[1]), float(stats[2])),
                   share=float(stats[3]), members=members, covariance=stats[4:].reshape(3, 3))
