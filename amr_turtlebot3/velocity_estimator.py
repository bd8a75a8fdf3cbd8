"""Body velocities (v, w) of a planar robot from consecutive stamped poses.

The real TurtleBot3 publishes /odom with a pose; the controller wants the forward speed v and the
turn rate w. From two consecutive poses (x, y, yaw, stamp):

- w = wrap(yaw1 - yaw0) / dt, the heading change taken the short way round, so it is right when
  the heading crosses +-pi.
- v = the displacement projected on the mid heading (yaw0 + wrap(yaw1 - yaw0) / 2, the mean of the
  two headings on the circle), divided by dt and corrected by (d/2) / sin(d/2) with d the heading
  change: the chord of a constant-curvature arc is shorter than the arc by that factor, so the
  estimate is exact for constant (v, w) motion. The projection keeps the sign: v < 0 when
  reversing, and sideways position noise barely contributes.

Timing rules (stamps are integer nanoseconds from the message headers):
- First sample (or first after a reset): nothing to differentiate, so NO estimate is produced
  (the node publishes nothing rather than a zero twist that would be false for a moving robot).
- dt == 0 (duplicate stamp) or 0 < dt < MIN_INTERVAL_NS (1 ms: no odometry comes faster, and
  pose noise over 1 ns would read as 1e7 m/s): skipped; the previous sample is kept, so the next
  sample is differentiated over the whole interval.
- dt < 0 (bag loop, simulation reset) or dt > max_gap: reset, the sample starts a new sequence,
  instead of producing a spike or a stale average.
- Invalid input (NaN/inf position, zero-norm or NaN quaternion): rejected with a reason; the
  previous valid sample is kept, so the next valid one is differentiated against it.
- A physically impossible speed (beyond the Burger's limits with a margin, amr_common.robot:
  a pose jump such as an odometry reset): no estimate; the estimator restarts from the new
  sample, so an odometry reset costs one message and a lone outlier two.

Optional smoothing: a first-order low-pass with time constant tau (alpha = 1 - exp(-dt / tau),
correct for irregular dt), off when tau == 0. It restarts from the first estimate after a reset.
No rclpy import: this module is plain Python.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from amr_common.geometry import quaternion_to_yaw, wrap_angle
from amr_common.robot import (
    MAX_PLAUSIBLE_ANGULAR_SPEED,
    MAX_PLAUSIBLE_LINEAR_SPEED,
    is_plausible_twist,
    step_chord,
)

MIN_INTERVAL_NS = 1_000_000  # samples closer than 1 ms to the previous one are skipped


class Status(enum.Enum):
    """What one update did; the value is the human-readable reason."""

    OK = "ok"
    FIRST = "first sample, nothing to differentiate yet"
    DUPLICATE = "duplicate stamp (dt == 0), skipped"
    TOO_SHORT = "interval shorter than 1 ms, skipped"
    RESET_BACKWARDS = "time jumped backwards, estimator reset"
    RESET_GAP = "gap longer than max_gap, estimator reset"
    RESET_IMPLAUSIBLE = "physically impossible speed (pose jump), estimator reset"
    REJECTED = "invalid pose rejected"


@dataclass(frozen=True)
class VelocityEstimate:
    """Result of one update: v [m/s] and w [rad/s], both None unless status is OK."""

    v: float | None
    w: float | None
    status: Status
    reason: str = ""

    @property
    def ok(self) -> bool:
        """True when v and w were estimated."""
        return self.status is Status.OK


@dataclass(frozen=True)
class _Sample:
    x: float
    y: float
    yaw: float
    stamp_ns: int


class VelocityEstimator:
    """Differentiates a stream of stamped planar poses into (v, w); see the module docstring."""

    def __init__(self, max_gap: float = 0.5, smoothing_time_constant: float = 0.0) -> None:
        if not (math.isfinite(max_gap) and max_gap > 0.0):
            raise ValueError(f"max_gap must be a finite number > 0 s, got {max_gap}")
        if not (math.isfinite(smoothing_time_constant) and smoothing_time_constant >= 0.0):
            raise ValueError("smoothing_time_constant must be a finite number >= 0 s "
                             f"(0 = off), got {smoothing_time_constant}")
        self.max_gap = max_gap
        self.smoothing_time_constant = smoothing_time_constant
        self._previous: _Sample | None = None
        self._filtered: tuple[float, float] | None = None

    def reset(self) -> None:
        """Forget the history: the next sample is a first sample."""
        self._previous = None
        self._filtered = None

    def update(self, x: float, y: float, qx: float, qy: float, qz: float, qw: float,
               stamp_ns: int) -> VelocityEstimate:
        """Add a pose with a ROS-order (x, y, z, w) orientation quaternion."""
        try:
            yaw = quaternion_to_yaw(qx, qy, qz, qw)
        except ValueError as exc:
            return VelocityEstimate(None, None, Status.REJECTED, str(exc))
        return self.update_pose(x, y, yaw, stamp_ns)

    def update_pose(self, x: float, y: float, yaw: float, stamp_ns: int) -> VelocityEstimate:
        """Add a pose given by its yaw [rad]; stamp in integer nanoseconds."""
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            return VelocityEstimate(None, None, Status.REJECTED,
                                    f"non-finite pose x={x} y={y} yaw={yaw}")
        sample = _Sample(float(x), float(y), float(yaw), int(stamp_ns))
        previous = self._previous
        if previous is None:
            self._previous = sample
            return VelocityEstimate(None, None, Status.FIRST, Status.FIRST.value)
        dt_ns = sample.stamp_ns - previous.stamp_ns
        if dt_ns == 0:
            return VelocityEstimate(None, None, Status.DUPLICATE, Status.DUPLICATE.value)
        if 0 < dt_ns < MIN_INTERVAL_NS:
            return VelocityEstimate(None, None, Status.TOO_SHORT,
                                    f"{Status.TOO_SHORT.value} (dt = {dt_ns} ns)")
        if dt_ns < 0 or dt_ns * 1e-9 > self.max_gap:
            status = Status.RESET_BACKWARDS if dt_ns < 0 else Status.RESET_GAP
            self.reset()
            self._previous = sample
            return VelocityEstimate(None, None, status,
                                    f"{status.value} (dt = {dt_ns * 1e-9:.3f} s)")
        dt = dt_ns * 1e-9
        dyaw = wrap_angle(sample.yaw - previous.yaw)
        along = step_chord(sample.x - previous.x, sample.y - previous.y, previous.yaw, dyaw)
        half = 0.5 * dyaw
        arc_over_chord = half / math.sin(half) if abs(half) > 1e-9 else 1.0
        v = along * arc_over_chord / dt
        w = dyaw / dt
        if not (math.isfinite(v) and math.isfinite(w)):  # e.g. positions near float max
            return VelocityEstimate(None, None, Status.REJECTED,
                                    f"non-finite velocity from x={x} y={y}")
        # The displacement's length too: a sideways jump projects to v = 0 on the heading.
        jump_speed = math.hypot(sample.x - previous.x, sample.y - previous.y) / dt
        if not (is_plausible_twist(v, w) and is_plausible_twist(jump_speed, 0.0)):
            self.reset()
            self._previous = sample
            return VelocityEstimate(
                None, None, Status.RESET_IMPLAUSIBLE,
                f"physically impossible motion v={v:.3g} m/s ({jump_speed:.3g} m/s in any "
                f"direction), w={w:.3g} rad/s over dt = {dt:.3f} s (limits "
                f"{MAX_PLAUSIBLE_LINEAR_SPEED:.2f} m/s, {MAX_PLAUSIBLE_ANGULAR_SPEED:.2f} rad/s): "
                f"pose jump, estimator reset")
        self._previous = sample
        v, w = self._smooth(v, w, dt)
        return VelocityEstimate(v, w, Status.OK)

    def _smooth(self, v: float, w: float, dt: float) -> tuple[float, float]:
        tau = self.smoothing_time_constant
        if tau == 0.0:
            return v, w
        if self._filtered is None:
            self._filtered = (v, w)
            return v, w
        alpha = 1.0 - math.exp(-dt / tau)
        v_f, w_f = self._filtered
        self._filtered = (v_f + alpha * (v - v_f), w_f + alpha * (w - w_f))
        return self._filtered


__all__ = ["Status", "VelocityEstimate", "VelocityEstimator"]
