"""VelocityEstimator against analytic constant-(v, w) trajectories sampled like the robot's /odom.

The estimator is exact for constant-curvature motion (chord correction), so noise-free cases use
a tolerance of 1e-9 (float rounding over a few hundred samples); noisy cases state theirs.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_turtlebot3.velocity_estimator import Status, VelocityEstimator

EXACT = 1e-9
ODOM_PERIOD_NS = 50_000_000  # 20 Hz like the TurtleBot3


def pose_at(v: float, w: float, t: float, x0: float = 0.3, y0: float = -0.2,
            yaw0: float = 0.0) -> tuple[float, float, float]:
    """Pose after t seconds of constant (v, w) from (x0, y0, yaw0); yaw NOT wrapped."""
    yaw = yaw0 + w * t
    if abs(w) < 1e-12:
        return x0 + v * t * math.cos(yaw0), y0 + v * t * math.sin(yaw0), yaw
    radius = v / w
    return (x0 + radius * (math.sin(yaw) - math.sin(yaw0)),
            y0 - radius * (math.cos(yaw) - math.cos(yaw0)), yaw)


def quaternion(yaw: float, scale: float = 1.0) -> tuple[float, float, float, float]:
    """ROS-order (x, y, z, w) quaternion of a yaw, optionally scaled (non-unit)."""
    return (0.0, 0.0, scale * math.sin(yaw / 2.0), scale * math.cos(yaw / 2.0))


def run(estimator: VelocityEstimator, v: float, w: float, steps: int = 100,
        yaw0: float = 0.0, stamps_ns: list[int] | None = None, scale: float = 1.0):
    """Feed a trajectory through update() (quaternion path); return the OK estimates."""
    stamps_ns = stamps_ns or [1_000_000_000 + k * ODOM_PERIOD_NS for k in range(steps)]
    estimates = []
    for stamp in stamps_ns:
        x, y, yaw = pose_at(v, w, (stamp - stamps_ns[0]) * 1e-9, yaw0=yaw0)
        estimates.append(estimator.update(x, y, *quaternion(yaw, scale), stamp))
    assert estimates[0].status is Status.FIRST and estimates[0].v is None
    ok = [e for e in estimates[1:] if e.ok]
    assert len(ok) == len(stamps_ns) - 1
    return ok


def assert_all(estimates, v: float, w: float, tolerance: float = EXACT) -> None:
    vs = np.array([e.v for e in estimates])
    ws = np.array([e.w for e in estimates])
    assert np.max(np.abs(vs - v)) < tolerance, f"v error {np.max(np.abs(vs - v)):.3g}"
    assert np.max(np.abs(ws - w)) < tolerance, f"w error {np.max(np.abs(ws - w)):.3g}"


def test_straight_line():
    assert_all(run(VelocityEstimator(), v=0.2, w=0.0, yaw0=0.7), 0.2, 0.0)


def test_arc_with_irregular_stamps():
    # Real /odom arrives at ~19.6-20 Hz: jittered periods of 40-60 ms.
    rng = np.random.default_rng(3)
    periods = rng.integers(40_000_000, 60_000_000, size=150)
    stamps = [5_000_000_000 + int(s) for s in np.concatenate(([0], np.cumsum(periods)))]
    assert_all(run(VelocityEstimator(), v=0.15, w=0.8, stamps_ns=stamps), 0.15, 0.8)


def test_reversing_gives_negative_speed():
    estimates = run(VelocityEstimator(), v=-0.1, w=0.3, yaw0=2.0)
    assert all(e.v < 0 for e in estimates)
    assert_all(estimates, -0.1, 0.3)


@pytest.mark.parametrize("w", [2.0, -2.0])
def test_spinning_in_place_through_pi(w):
    # Several full turns from near +pi: the heading crosses +-pi many times.
    estimates = run(VelocityEstimator(), v=0.0, w=w, steps=200, yaw0=3.0)
    assert_all(estimates, 0.0, w)


@pytest.mark.parametrize("v,w", [(0.2, 1.0), (-0.2, -1.0), (0.22, 2.84)])
def test_arc_crossing_pi(v, w):
    assert_all(run(VelocityEstimator(), v=v, w=w, steps=120, yaw0=2.9), v, w)


def test_non_unit_quaternion_gives_the_same_result():
    unit = run(VelocityEstimator(), v=0.12, w=-0.6, yaw0=-3.0)
    scaled = run(VelocityEstimator(), v=0.12, w=-0.6, yaw0=-3.0, scale=3.0)
    assert max(abs(a.v - b.v) + abs(a.w - b.w) for a, b in zip(unit, scaled)) < 1e-12


@pytest.mark.parametrize("q", [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, math.nan, 1.0),
                               (0.0, 0.0, 0.0, math.inf)])
def test_zero_or_nan_quaternion_rejected_and_history_kept(q):
    estimator = VelocityEstimator()
    assert estimator.update(0.0, 0.0, *quaternion(0.0), 0).status is Status.FIRST
    rejected = estimator.update(0.01, 0.0, *q, ODOM_PERIOD_NS)
    assert rejected.status is Status.REJECTED and rejected.v is None and rejected.reason
    # The next valid pose is differentiated against the last valid one (dt = 0.1 s).
    after = estimator.update(0.02, 0.0, *quaternion(0.0), 2 * ODOM_PERIOD_NS)
    assert after.ok and after.v == pytest.approx(0.2, abs=EXACT)


@pytest.mark.parametrize("x,y", [(math.nan, 0.0), (0.0, math.inf), (1e308, -1e308)])
def test_non_finite_position_rejected(x, y):
    estimator = VelocityEstimator()
    estimator.update(0.0, 0.0, *quaternion(0.0), 0)
    result = estimator.update(x, y, *quaternion(0.0), ODOM_PERIOD_NS)
    assert result.status is Status.REJECTED and result.v is None and result.w is None


def test_duplicate_stamp_skipped():
    estimator = VelocityEstimator()
    estimator.update(0.0, 0.0, *quaternion(0.0), 0)
    assert estimator.update(0.01, 0.0, *quaternion(0.0), ODOM_PERIOD_NS).v == pytest.approx(0.2)
    duplicate = estimator.update(0.5, 0.0, *quaternion(1.0), ODOM_PERIOD_NS)
    assert duplicate.status is Status.DUPLICATE and duplicate.v is None
    # The duplicate's pose is ignored: the next sample is compared with the first one at that
    # stamp.
    nxt = estimator.update(0.02, 0.0, *quaternion(0.0), 2 * ODOM_PERIOD_NS)
    assert nxt.v == pytest.approx(0.2, abs=EXACT) and nxt.w == pytest.approx(0.0, abs=EXACT)


def test_backwards_stamp_resets_instead_of_spiking():
    estimator = VelocityEstimator()
    run(estimator, v=0.2, w=0.5, steps=20)
    # Bag loop / simulation reset: time and pose jump back to the start.
    jumped = estimator.update(0.3, -0.2, *quaternion(0.0), 1_000_000_000)
    assert jumped.status is Status.RESET_BACKWARDS and jumped.v is None
    nxt = estimator.update(*pose_at(0.2, 0.5, 0.05)[:2], *quaternion(0.5 * 0.05),
                           1_000_000_000 + ODOM_PERIOD_NS)
    assert nxt.ok and nxt.v == pytest.approx(0.2, abs=EXACT) and nxt.w == pytest.approx(0.5)


def test_gap_longer_than_max_gap_resets():
    estimator = VelocityEstimator(max_gap=0.5)
    estimator.update(0.0, 0.0, *quaternion(0.0), 0)
    within = estimator.update(0.09, 0.0, *quaternion(0.0), 450_000_000)  # 0.45 s < max_gap
    assert within.ok and within.v == pytest.approx(0.2, abs=EXACT)
    gap = estimator.update(5.0, 0.0, *quaternion(2.0), 1_000_000_000)  # 0.55 s > max_gap
    assert gap.status is Status.RESET_GAP and gap.v is None
    nxt = estimator.update(5.01, 0.0, *quaternion(1.9), 1_050_000_000)
    assert nxt.ok  # differentiated against the post-gap sample, not the stale one
    assert nxt.w == pytest.approx(-0.1 / 0.05, abs=EXACT)


def test_smoothing_reduces_noise_variance_without_bias():
    # Straight run at 0.2 m/s with 2 mm position and 5 mrad heading noise, like wheel odometry
    # plus IMU heading. A 0.3 s time constant should cut the variance several times.
    rng = np.random.default_rng(11)
    steps, v_true, w_true = 400, 0.2, 0.3
    stamps = [k * ODOM_PERIOD_NS for k in range(steps)]
    raw, smoothed = VelocityEstimator(), VelocityEstimator(smoothing_time_constant=0.3)
    raw_v, raw_w, smooth_v, smooth_w = [], [], [], []
    for stamp in stamps:
        x, y, yaw = pose_at(v_true, w_true, stamp * 1e-9)
        x, y = x + rng.normal(0, 0.002), y + rng.normal(0, 0.002)
        q = quaternion(yaw + rng.normal(0, 0.005))
        for estimator, vs, ws in ((raw, raw_v, raw_w), (smoothed, smooth_v, smooth_w)):
            result = estimator.update(x, y, *q, stamp)
            if result.ok:
                vs.append(result.v)
                ws.append(result.w)
    settled = slice(40, None)  # skip the filter's first 2 s
    assert np.var(smooth_v[settled]) < 0.2 * np.var(raw_v[settled])
    assert np.var(smooth_w[settled]) < 0.2 * np.var(raw_w[settled])
    assert abs(np.mean(smooth_v[settled]) - v_true) < 0.01  # m/s
    assert abs(np.mean(smooth_w[settled]) - w_true) < 0.02  # rad/s


def test_smoothing_is_off_by_default_and_restarts_after_reset():
    estimator = VelocityEstimator(smoothing_time_constant=1.0)
    run(estimator, v=0.2, w=0.0, steps=10)
    estimator.reset()
    # After a reset the filter starts from the first new estimate (no ramp from stale values).
    estimates = run(estimator, v=-0.1, w=0.4, steps=5)
    assert_all(estimates, -0.1, 0.4, tolerance=1e-9)
    assert VelocityEstimator().smoothing_time_constant == 0.0


@pytest.mark.parametrize("kwargs", [{"max_gap": 0.0}, {"max_gap": math.nan},
                                    {"max_gap": -1.0}, {"smoothing_time_constant": -0.1},
                                    {"smoothing_time_constant": math.inf}])
def test_bad_parameters_raise(kwargs):
    with pytest.raises(ValueError):
        VelocityEstimator(**kwargs)


# ---- implausible intervals and speeds -------------------------------------------------------
def test_stamps_a_nanosecond_apart_are_skipped_not_turned_into_megametres_per_second():
    estimator = VelocityEstimator()
    estimator.update(0.0, 0.0, *quaternion(0.0), 1_000_000_000)
    close = estimator.update(0.01, 0.0, *quaternion(0.001), 1_000_000_001)   # 1 ns later
    assert close.status is Status.TOO_SHORT and close.v is None and close.reason
    # The next sample is differentiated over the whole interval from the kept one.
    nxt = estimator.update(0.01, 0.0, *quaternion(0.0), 1_000_000_000 + ODOM_PERIOD_NS)
    assert nxt.ok and nxt.v == pytest.approx(0.2, abs=EXACT) and nxt.w == pytest.approx(0.0)


@pytest.mark.parametrize("jump", [(1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1e6, 0.0)])
def test_physically_impossible_speed_restarts_from_the_new_pose(jump):
    estimator = VelocityEstimator()
    run(estimator, v=0.2, w=0.0, steps=10)
    stamp = 1_000_000_000 + 10 * ODOM_PERIOD_NS
    x, y, yaw = pose_at(0.2, 0.0, 10 * ODOM_PERIOD_NS * 1e-9)
    dx, dy, dyaw = jump   # 1 m or 1 rad in 50 ms: 20 m/s, 20 rad/s
    jumped = estimator.update(x + dx, y + dy, *quaternion(yaw + dyaw), stamp)
    assert jumped.status is Status.RESET_IMPLAUSIBLE and jumped.v is None
    assert "impossible" in jumped.reason
    # An odometry reset (the new pose is the truth) goes on from there at once.
    nxt = estimator.update(x + dx + 0.01, y + dy, *quaternion(yaw + dyaw),
                           stamp + ODOM_PERIOD_NS)
    assert nxt.ok and nxt.w == pytest.approx(0.0, abs=EXACT)
    assert nxt.v == pytest.approx(0.2 * math.cos(yaw + dyaw), abs=1e-6)


def test_quaternion_of_norm_1e300_gives_the_right_turn_rate():
    unit = run(VelocityEstimator(), v=0.1, w=0.5, steps=20, yaw0=1.0)
    huge = run(VelocityEstimator(), v=0.1, w=0.5, steps=20, yaw0=1.0, scale=1e300)
    assert_all(huge, 0.1, 0.5)
    assert max(abs(a.w - b.w) for a, b in zip(unit, huge)) < 1e-12
