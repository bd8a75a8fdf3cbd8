"""The real scanner's effects on a simulated scan: skew, range error and noise, dropouts, LD08.

`RealLidar.scan(t_end)` casts every ray from the pose at its own time in the revolution (the
robot's pose history, interpolated), adds the datasheet's systematic error and Gaussian noise of
the ray's distance band, drops rays at random (more at grazing incidence and long range) and,
for the LDS-02, bins irregular samples into a scan whose ray count and angle_min change from scan
to scan, as ld08_driver does. The ray loop is one compiled kernel (amr_common.jit) with a numpy
twin (`scan_rays_numpy`) that gives the same results. The kernels take the walls as a tuple
(`walls`): the segments and, on a big map (World.wall_grid), their grid buckets, through which
each ray walks (raster_raycast.SegmentGrid: ~0.2 ms a step on a map of 2 million walls, where
a scan against every wall took 0.4 s); without buckets (empty lists) every ray meets every wall.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import HAVE_NUMBA, jit
from amr_common.sensors.lidar_models import LidarModel
from amr_common.world.raster_raycast import (
    SegmentGrid,
    cast_rays_through_buckets,
    cast_rays_through_buckets_python,
)
from amr_common.world.raycast import (
    cast_circles_kernel,
    cast_circles_numpy,
    cast_rays_kernel,
    cast_rays_numpy,
)
from amr_sim.effects import Effects
from amr_sim.profiles import SensorProfile

TWO_PI = 2.0 * math.pi
# params layout of the kernels (one float array: fewer arguments, cheaper numba dispatch)
(T_END, SKEW_S, SENSE_MIN, SENSE_MAX, NO_RETURN, DROP, DROP_FAR, DROP_GRAZE,
 N_PARAMS) = range(9)


def ray_poses_python(history, head, angles, base_cos, base_sin, params, ox, oy, dx, dy):
    """Origin and unit direction of each ray from the LiDAR pose at the ray's time.

    history: ring of [t, lidar x, lidar y, cos theta, sin theta] rows, the newest at
    `head`. Ray i (at angle angles[i], increasing) is measured at t_end - SKEW_S angles[i] /
    2 pi (clockwise rotation); its pose is interpolated between the two history rows around
    that time: the position linearly, the heading's unit vector linearly and normalised (no
    trigonometry per ray). Times beyond the history take its nearest end. The rays of one
    history interval are a contiguous run, done in one branch-free (vectorisable) loop.
    """
    size = history.shape[0]
    n = angles.shape[0]
    t_end = params[T_END]
    per_radian = params[SKEW_S] / (2.0 * math.pi)
    newer = head
    older = (head - 1) % size
    walked = 0
    i = 0
    while i < n:
        t0 = history[older, 0]
        t1 = history[newer, 0]
        last = walked >= size - 2 or not t0 < t1  # no older interval to walk back to
        end = n
        if not last:
            end = i
            while end < n and t_end - per_radian * angles[end] >= t0:
                end += 1
        inv_span = 1.0 / (t1 - t0) if t1 > t0 else 0.0
        x0, y0, c0, s0 = history[older, 1], history[older, 2], history[older, 3], history[older, 4]
        x1, y1, c1, s1 = history[newer, 1], history[newer, 2], history[newer, 3], history[newer, 4]
        for j in range(i, end):
            s = min(max((t_end - per_radian * angles[j] - t0) * inv_span, 0.0), 1.0) \
                if t1 > t0 else 1.0
            ox[j] = x0 + s * (x1 - x0)
            oy[j] = y0 + s * (y1 - y0)
            c = c0 + s * (c1 - c0)
            si = s0 + s * (s1 - s0)
            norm = 1.0 / math.sqrt(c * c + si * si)
            dx[j] = (c * base_cos[j] - si * base_sin[j]) * norm
            dy[j] = (si * base_cos[j] + c * base_sin[j]) * norm
        i = end
        newer = older
        older = (older - 1) % size
        walked += 1


def range_effects_python(true_range, cos_incidence, bands, params, gauss, uniform, out):
    """Measured ranges from true ones: band error and noise, dropouts, the no-return value.

    bands rows: [upper edge (m), bias abs (m), bias rel, sigma abs (m), sigma rel].
    Dropout probability: DROP + DROP_FAR (r / SENSE_MAX)^2 + DROP_GRAZE (1 - 2 cos i)^2 past
    60 deg incidence. A ray is drawn out when uniform < probability. Band by band, branch-free.
    """
    n = true_range.shape[0]
    for b in range(bands.shape[0]):
        lower = bands[b - 1, 0] if b > 0 else -np.inf
        bias_abs, bias_rel, sigma_abs, sigma_rel = bands[b, 1], bands[b, 2], bands[b, 3], \
            bands[b, 4]
        for i in range(n):
            r = true_range[i]
            measured = r + bias_abs + bias_rel * r + (sigma_abs + sigma_rel * r) * gauss[i]
            out[i] = measured if r >= lower else out[i]
    sense_min, sense_max = params[SENSE_MIN], params[SENSE_MAX]
    drop, drop_far, drop_graze = params[DROP], params[DROP_FAR], params[DROP_GRAZE]
    no_return = params[NO_RETURN]
    for i in range(n):
        r = true_range[i]
        measured = out[i]
        grazing = max(0.0, 1.0 - 2.0 * cos_incidence[i])
        far = r / sense_max
        probability = drop + drop_far * far * far + drop_graze * grazing * grazing
        valid = (r <= sense_max) & (measured >= sense_min) & (measured <= sense_max) \
            & (uniform[i] >= probability)
        out[i] = measured if valid else no_return


_ray_poses = jit(ray_poses_python)
_range_effects = jit(range_effects_python)


def walls_of(segments: np.ndarray, grid: SegmentGrid | None = None) -> tuple:
    """The kernels' `walls`: (segments, starts, items, x0, y0, size, nx, ny).

    The grid's (raster_raycast.SegmentGrid), or no buckets (empty lists) without one.
    """
    if grid is not None:
        return grid.arrays
    return (np.ascontiguousarray(segments, dtype=np.float64), np.zeros(0, dtype=np.int64),
            np.zeros(0, dtype=np.int32), 0.0, 0.0, 1.0, 0, 0)


def _cast_walls_python(walls, ox, oy, dx, dy, true_range, cos_incidence):
    """Each ray's range and incidence: against every wall, or through the buckets if any."""
    segments, starts, items, x0, y0, size, nx, ny = walls
    if starts.shape[0] == 0:
        cast_rays_kernel(segments, ox, oy, dx, dy, true_range, cos_incidence)
    else:
        cast_rays_through_buckets(segments, starts, items, x0, y0, size, nx, ny, ox, oy, dx, dy,
                                  true_range, cos_incidence)


_cast_walls = jit(_cast_walls_python)


def scan_rays_python(walls, circles, history, head, angles, base_cos, base_sin, bands, params,
                     gauss, uniform, out):
    """One skewed scan with the sensor's effects: poses, ray cast, range effects (fused).

    circles: rows [x, y, radius] seen on top of the walls (may be empty).
    """
    n = angles.shape[0]
    ox = np.empty(n)
    oy = np.empty(n)
    dx = np.empty(n)
    dy = np.empty(n)
    true_range = np.empty(n)
    cos_incidence = np.empty(n)
    _ray_poses(history, head, angles, base_cos, base_sin, params, ox, oy, dx, dy)
    _cast_walls(walls, ox, oy, dx, dy, true_range, cos_incidence)
    cast_circles_kernel(circles, ox, oy, dx, dy, true_range, cos_incidence)
    _range_effects(true_range, cos_incidence, bands, params, gauss, uniform, out)


scan_rays_kernel = jit(scan_rays_python)


def scan_rays_numpy(walls, circles, history, head, angles, base_cos, base_sin, bands, params,
                    gauss, uniform, out):
    """scan_rays_python with numpy arrays (the fallback without numba, and its tested twin)."""
    order = (head + 1 + np.arange(history.shape[0])) % history.shape[0]  # oldest first
    rows = history[order]
    keep = np.concatenate([[True], np.diff(rows[:, 0]) > 0.0])  # unfilled slots repeat t
    rows = rows[keep] if keep.sum() > 1 else rows[[0, 0]]  # one pose: an empty interval
    times = params[T_END] - params[SKEW_S] * angles / (2.0 * math.pi)
    times = np.clip(times, rows[0, 0], rows[-1, 0])
    newer = np.clip(np.searchsorted(rows[:, 0], times, side="left"), 1, len(rows) - 1)
    older = newer - 1
    t0, t1 = rows[older, 0], rows[newer, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(t1 <= t0, 1.0, np.clip((times - t0) / (t1 - t0), 0.0, 1.0))
    ox, oy, c, si = (rows[older, j] + s * (rows[newer, j] - rows[older, j]) for j in (1, 2, 3, 4))
    norm = 1.0 / np.sqrt(c * c + si * si)
    true_range, cos_incidence = np.empty(len(angles)), np.empty(len(angles))
    dx, dy = (c * base_cos - si * base_sin) * norm, (si * base_cos + c * base_sin) * norm
    if walls[1].shape[0] == 0:
        cast_rays_numpy(walls[0], ox, oy, dx, dy, true_range, cos_incidence)
    else:
        cast_rays_through_buckets_python(*walls, ox, oy, dx, dy, true_range, cos_incidence)
    cast_circles_numpy(circles, ox, oy, dx, dy, true_range, cos_incidence)
    band = np.searchsorted(bands[:-1, 0], true_range, side="right")
    row = bands[np.minimum(band, len(bands) - 1)]
    with np.errstate(invalid="ignore"):  # inf ranges (no hit) stay invalid
        measured = (true_range + row[:, 1] + row[:, 2] * true_range
                    + (row[:, 3] + row[:, 4] * true_range) * gauss)
        grazing = np.maximum(0.0, 1.0 - 2.0 * cos_incidence)
        far = true_range / params[SENSE_MAX]
        drop = params[DROP] + params[DROP_FAR] * far * far + params[DROP_GRAZE] * grazing ** 2
        valid = (true_range <= params[SENSE_MAX]) & (measured >= params[SENSE_MIN]) \
            & (measured <= params[SENSE_MAX]) & (uniform >= drop)
    out[:] = np.where(valid, measured, params[NO_RETURN])


def ld08_scan_python(walls, circles, history, head, phase, spacing, count, increment, bands,
                     params, gauss, uniform):
    """An LD08 revolution binned as ld08_driver bins it: (ranges, angle_min, rays).

    Samples at (phase + k) spacing (k < count, below 2 pi), each measured with the scanner's
    effects (scan_rays_python); the valid ones go to bin floor((angle - angle_min) /
    increment), angle_min = the first valid sample's angle, rays = ceil((last - first) /
    increment); a bin keeps its shortest sample, NaN (no_return) where none fell. Without any
    valid sample: one no-return ray at angle 0.
    """
    angles = np.empty(count)
    cos = np.empty(count)
    sin = np.empty(count)
    n = 0
    for k in range(count):
        angles[k] = (phase + k) * spacing
        n += angles[k] < 2.0 * math.pi
    # cos and sin without a call per sample: 8 exact, then each rotated from the one 8 before
    # (8 independent chains, so the loop vectorises; error ~1e-15 after 60 rotations).
    for k in range(min(8, n)):
        cos[k] = math.cos(angles[k])
        sin[k] = math.sin(angles[k])
    c8, s8 = math.cos(8.0 * spacing), math.sin(8.0 * spacing)
    for k in range(8, n):
        cos[k] = cos[k - 8] * c8 - sin[k - 8] * s8
        sin[k] = sin[k - 8] * c8 + cos[k - 8] * s8
    samples = np.empty(n)
    _scan_rays(walls, circles, history, head, angles[:n], cos[:n], sin[:n], bands, params,
               gauss[:n], uniform[:n], samples)
    first, last = -1, -1
    for k in range(n):
        if samples[k] > 0.0:  # NaN (no return) compares False
            last = k
            if first < 0:
                first = k
    if first < 0:
        out = np.empty(1)
        out[0] = params[NO_RETURN]
        return out, 0.0, 1
    angle_min = angles[first]
    per_increment = 1.0 / increment
    rays = max(1, int(math.ceil((angles[last] - angle_min) * per_increment)))
    out = np.full(rays, np.inf)
    for k in range(first, last + 1):
        index = int((angles[k] - angle_min) * per_increment)
        if samples[k] > 0.0 and index < rays and samples[k] < out[index]:
            out[index] = samples[k]
    for i in range(rays):
        if out[i] == np.inf:
            out[i] = params[NO_RETURN]
    return out, angle_min, rays


_scan_rays = scan_rays_kernel
ld08_scan_kernel = jit(ld08_scan_python)


def ld08_scan_numpy(walls, circles, history, head, phase, spacing, count, increment, bands,
                    params, gauss, uniform):
    """ld08_scan_python with numpy arrays (the fallback without numba, and its tested twin)."""
    angles = (phase + np.arange(count)) * spacing
    n = int(np.count_nonzero(angles < 2.0 * math.pi))
    angles = angles[:n]
    samples = np.empty(n)
    scan_rays_numpy(walls, circles, history, head, angles, np.cos(angles), np.sin(angles),
                    bands, params, gauss[:n], uniform[:n], samples)
    valid = samples > 0.0
    if not valid.any():
        return np.full(1, params[NO_RETURN]), 0.0, 1
    angle_min = float(angles[valid][0])
    per_increment = 1.0 / increment
    rays = max(1, math.ceil((float(angles[valid][-1]) - angle_min) * per_increment))
    index = ((angles[valid] - angle_min) * per_increment).astype(np.int64)
    keep = index < rays
    out = np.full(rays, np.inf)
    np.minimum.at(out, index[keep], samples[valid][keep])
    out[np.isinf(out)] = params[NO_RETURN]
    return out, angle_min, rays


def band_table(model: LidarModel, effects: Effects) -> np.ndarray:
    """The kernel's bands: [upper edge, bias abs, bias rel, sigma abs, sigma rel] per band."""
    edges = [*model.band_edges, math.inf]
    return np.array([[edge, effects.range_bias_share * acc[0], effects.range_bias_share * acc[1],
                      effects.range_noise_share * pre[0], effects.range_noise_share * pre[1]]
                     for edge, acc, pre in zip(edges, model.accuracy, model.precision)])


class RealLidar:
    """The profile's scanner with the effects; `scan(t_end)` -> ranges of the newest scan.

    `record(t, x, y, theta)` after every step keeps the pose history the skew needs. After a
    scan, `geometry` is its (angle_min, angle_increment, rays) - fixed for the LDS-01, new for
    every LDS-02 scan.
    """

    def __init__(self, segments: np.ndarray, profile: SensorProfile, effects: Effects,
                 rng: np.random.Generator, dt: float = 0.05, use_numba: bool = True,
                 grid: SegmentGrid | None = None) -> None:
        """`grid`: the walls in buckets (a big map): each ray walks through them."""
        model = profile.lidar_model
        self.model = model
        self.segments = np.ascontiguousarray(segments, dtype=np.float64)
        self.walls = walls_of(self.segments, grid)
        # Rows [x, y, radius] of round obstacles (the simulator's movers), updated in place.
        self.circles = np.zeros((0, 3))
        self.bands = band_table(model, effects)
        params = np.zeros(N_PARAMS)
        params[SKEW_S] = model.revolution_s if effects.scan_skew else 0.0
        self.offset_x = profile.lidar_offset_x
        params[SENSE_MIN], params[SENSE_MAX] = model.sensing_min, model.sensing_max
        params[NO_RETURN] = profile.no_return
        params[DROP] = effects.dropout_share
        params[DROP_FAR] = effects.dropout_far_share
        params[DROP_GRAZE] = effects.dropout_grazing_share
        self.params = params
        self.no_return = profile.no_return
        self._rng = rng
        numba = use_numba and HAVE_NUMBA
        self._kernel = scan_rays_kernel if numba else scan_rays_numpy
        self._ld08_kernel = ld08_scan_kernel if numba else ld08_scan_numpy
        # Poses of the steps a revolution spans (dt: the simulator's step), and a spare.
        self.history = np.zeros((int(math.ceil(model.revolution_s / dt)) + 3, 5))
        self._head = 0
        angles = (profile.angle_min + profile.angle_increment
                  * np.arange(profile.scan_rays)) % TWO_PI
        # The kernel walks the rays in increasing angle (decreasing time): rays cast in that
        # order, returned in the message's.
        self._order = None if np.all(np.diff(angles) > 0) else np.argsort(angles)
        self.angles = angles if self._order is None else angles[self._order]
        self._cos, self._sin = np.cos(self.angles), np.sin(self.angles)
        self.geometry = (profile.angle_min, profile.angle_increment, profile.scan_rays)
        if model.samples_per_s:  # an LD08 revolution 5 sigma slower than nominal
            self._most_samples = int(model.samples_per_s * model.revolution_s
                                     * (1.0 + 5.0 * model.speed_sigma)) + 1

    def reset(self, t: float, x: float, y: float, theta: float) -> None:
        """Forget the history: the robot has been at (x, y, theta) ever since (start, teleport)."""
        self.record(t, x, y, theta)
        self.history[:] = self.history[self._head]

    def record(self, t: float, x: float, y: float, theta: float) -> None:
        """The robot's pose at time t (the end of a step)."""
        self._head = (self._head + 1) % self.history.shape[0]
        c, s = math.cos(theta), math.sin(theta)
        self.history[self._head] = (t, x + self.offset_x * c, y + self.offset_x * s, c, s)

    def cast(self, t_end: float, angles: np.ndarray, cos: np.ndarray | None = None,
             sin: np.ndarray | None = None) -> np.ndarray:
        """Measured ranges of rays at increasing `angles` (rad, in [0, 2 pi)).

        The revolution ends at t_end; cos and sin of the angles may be given.
        """
        params = self.params
        params[T_END] = t_end
        n = len(angles)
        out = np.empty(n)
        self._kernel(self.walls, self.circles, self.history, self._head, angles,
                     np.cos(angles) if cos is None else cos,
                     np.sin(angles) if sin is None else sin, self.bands, params,
                     self._rng.standard_normal(n), self._rng.random(n, dtype=np.float32), out)
        return out

    def scan(self, t_end: float) -> np.ndarray:
        """The scan whose revolution ends at t_end (the driver's stamp)."""
        if self.model.samples_per_s is not None:
            return self._ld08_scan(t_end)
        ranges = self.cast(t_end, self.angles, self._cos, self._sin)
        if self._order is None:
            return ranges
        out = np.empty_like(ranges)
        out[self._order] = ranges
        return out

    def _ld08_scan(self, t_end: float) -> np.ndarray:
        """Samples at the LD08's fixed rate over one revolution, binned as ld08_driver bins.

        The rotation speed changes a little from scan to scan and the first sample's angle is
        random. The reported angle_increment (speed / 2300) is the last packet's speed, a
        little off the revolution's mean; angle_min/max = the first and last valid sample,
        rays = ceil((max - min) / increment), each sample in bin floor((angle - min) /
        increment) keeping the shortest, NaN where none fell (ld08_scan_python).
        """
        model, rng, params, most = self.model, self._rng, self.params, self._most_samples
        # Two draws for the whole scan (scalar draws cost as much as hundreds of numbers): the
        # last two normals give the speed and increment errors (within 5 sigma), the last
        # uniform the first sample's angle.
        gauss = rng.standard_normal(most + 2)
        uniform = rng.random(most + 1, dtype=np.float32)
        speed_error = min(max(float(gauss[-2]), -5.0), 5.0)
        increment_error = min(max(float(gauss[-1]), -5.0), 5.0)
        revolution = model.revolution_s * (1.0 + model.speed_sigma * speed_error)
        spacing = TWO_PI / (model.samples_per_s * revolution)
        increment = spacing * (1.0 + model.increment_sigma * increment_error)
        count = min(int(TWO_PI / spacing) + 1, most)
        params[T_END] = t_end
        out, angle_min, rays = self._ld08_kernel(
            self.walls, self.circles, self.history, self._head, float(uniform[-1]), spacing,
            count, increment, self.bands, params, gauss, uniform)
        self.geometry = (float(angle_min), increment, int(rays))
        return out
