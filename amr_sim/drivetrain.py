"""The real Burger's drive: latency, firmware clamps, motors, wheel errors, slip, IMU heading.

What a /cmd_vel goes through on the robot (OpenCR turtlebot3_ros2 firmware, turtlebot3_node):
v and w are clipped separately to the speeds of 61 rpm wheels (0.211 m/s, 2.64 rad/s), turned
into wheel speeds with the nominal geometry (radius 0.033 m, separation 0.160 m) and applied at
the next motor tick, some latency later; each wheel then accelerates at a limited rate up to its
top speed. The ground sees the TRUE radii and separation, with random slip; the encoders count
the wheels' rotation, and turtlebot3_node's odometry turns it into distance with the nominal
radius and takes the heading from the IMU, which drifts slowly. Plain Python, no rclpy; the
per-step maths is one compiled function (amr_common.jit; the plain function is its twin).
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit
from amr_common.robot import TRACK, WHEEL_RADIUS
from amr_sim.effects import NO_LIMIT, Effects

RPM = 2.0 * math.pi / 60.0  # rad/s per rpm
FIRMWARE_MOTOR_RPM = 61.0  # TurtleBot3Core::begin: model_motor_rpm for the Burger
FIRMWARE_MAX_LINEAR = WHEEL_RADIUS * FIRMWARE_MOTOR_RPM * RPM  # 0.2108 m/s
FIRMWARE_MAX_ANGULAR = FIRMWARE_MAX_LINEAR / (TRACK / 2.0)  # 2.635 rad/s (turning radius 0.08)
FIRMWARE_WHEEL_LIMIT = 337 * 0.229 * RPM  # LIMIT_X_MAX_VELOCITY: 337 x 0.229 rpm, rad/s
_SLIP_BLOCK = 1024  # Gaussian draws taken at once (one numpy call per 512 steps)
# state: wheel goals and speeds (rad/s), this step's slip, the pending-command ring's head and
# count, the next slip draw. params: see Drivetrain.__init__.
GOAL, SPEED, SLIP, HEAD, COUNT, DRAW, N_STATE = 0, 2, 4, 6, 7, 8, 9
(LATENCY, ACCELERATION, LIMIT, RADIUS, TRACK_TRUE, SLIP_SIGMA, MAX_LINEAR, MAX_ANGULAR,
 YAW_DRIFT, N_PARAMS) = (0, 1, 2, 3, 5, 6, 7, 8, 9, 10)


def accelerate_python(state, params, h, turned):
    """Each wheel towards its goal at the acceleration limit for h seconds (exact ramp)."""
    acceleration = params[ACCELERATION]
    for i in range(2):
        speed = state[SPEED + i]
        goal = state[GOAL + i]
        gap = goal - speed
        reach = acceleration * h  # h > 0
        if abs(gap) <= reach:
            ramp = abs(gap) / acceleration  # 0 without a limit (acceleration inf)
            turned[i] += 0.5 * (speed + goal) * ramp + goal * (h - ramp)
            state[SPEED + i] = goal
        else:
            new = speed + (reach if gap > 0.0 else -reach)
            turned[i] += 0.5 * (speed + new) * h
            state[SPEED + i] = new


_accelerate = jit(accelerate_python)


def drive_step_python(state, params, pending, draws, v, w, now, dt):
    """One step of the drive: (ds, dtheta) of the robot on the floor over [now, now + dt].

    The command (v, w) given at `now` is clipped by the firmware, turned into wheel goals with
    the nominal geometry and queued in `pending` (ring of [time, left, right]) until now +
    latency; the wheels follow the goals at the acceleration limit; the floor sees the true
    radii, this step's slip (from `draws`) and the true separation.
    """
    v = min(max(v, -params[MAX_LINEAR]), params[MAX_LINEAR])  # inf: no firmware clamp
    w = min(max(w, -params[MAX_ANGULAR]), params[MAX_ANGULAR])
    limit = params[LIMIT]
    capacity = pending.shape[0]
    tail = (int(state[HEAD]) + int(state[COUNT])) % capacity
    pending[tail, 0] = now + params[LATENCY]
    pending[tail, 1] = min(max((v - w * TRACK / 2.0) / WHEEL_RADIUS, -limit), limit)
    pending[tail, 2] = min(max((v + w * TRACK / 2.0) / WHEEL_RADIUS, -limit), limit)
    state[COUNT] += 1.0
    end = now + dt
    t = now
    turned = np.zeros(2)
    while state[COUNT] > 0.0 and pending[int(state[HEAD]), 0] <= end - 1e-9:
        head = int(state[HEAD])
        if pending[head, 0] > t:
            _accelerate(state, params, pending[head, 0] - t, turned)
            t = pending[head, 0]
        state[GOAL] = pending[head, 1]
        state[GOAL + 1] = pending[head, 2]
        state[HEAD] = float((head + 1) % capacity)
        state[COUNT] -= 1.0
    _accelerate(state, params, end - t, turned)
    k = int(state[DRAW])
    state[DRAW] += 2.0
    # Slip never reverses a wheel's travel (the factor stays >= 0.1).
    state[SLIP] = max(params[SLIP_SIGMA] * draws[k], -0.9)
    state[SLIP + 1] = max(params[SLIP_SIGMA] * draws[k + 1], -0.9)
    left = turned[0] * params[RADIUS] * (1.0 + state[SLIP])
    right = turned[1] * params[RADIUS + 1] * (1.0 + state[SLIP + 1])
    return 0.5 * (left + right), (right - left) / params[TRACK_TRUE]


_drive_step = jit(drive_step_python)


def sense_python(state, params, odom, ds, dtheta, dt):
    """What the robot reports of an actual motion (ds, dtheta) over dt.

    Returns (dphi_left, dphi_right, z_v, z_w) and advances `odom` [x, y, theta] in place:
    the encoders count the wheels' rotation (the inverse of the floor motion with this step's
    slip: the wheels' own turns unless a wall stopped the robot); turtlebot3_node's odometry
    takes the distance from the counts with the nominal radius and the heading from the IMU,
    which drifts.
    """
    half = dtheta * params[TRACK_TRUE] / 2.0
    left = (ds - half) / (params[RADIUS] * (1.0 + state[SLIP]))
    right = (ds + half) / (params[RADIUS + 1] * (1.0 + state[SLIP + 1]))
    ds_odom = WHEEL_RADIUS * (left + right) / 2.0
    turn = dtheta + params[YAW_DRIFT] * dt
    half_turn = 0.5 * turn
    chord = ds_odom * (1.0 - half_turn * half_turn / 6.0 if abs(half_turn) < 1e-6
                       else math.sin(half_turn) / half_turn)  # robot.sinc_half
    mid = odom[2] + half_turn
    odom[0] += chord * math.cos(mid)
    odom[1] += chord * math.sin(mid)
    odom[2] += turn
    return left, right, ds_odom / dt, turn / dt


_sense = jit(sense_python)


class Drivetrain:
    """Wheels driven by delayed, clamped, acceleration-limited commands, on imperfect geometry.

    step(v, w, now, dt) -> (ds, dtheta) on the floor; sense(ds, dtheta, dt) what the robot's
    encoders and odometry report of the actual motion (`odom`: the /odom pose).
    """

    def __init__(self, effects: Effects, rng: np.random.Generator, dt: float,
                 use_numba: bool = True) -> None:
        self.latency = effects.command_latency_s
        mean = WHEEL_RADIUS * (1.0 + effects.wheel_radius_error)
        half_difference = 0.5 * effects.wheel_radius_difference * WHEEL_RADIUS
        self.radii = (mean - half_difference, mean + half_difference)  # left, right (m)
        self.track = TRACK * (1.0 + effects.track_error)
        self.yaw_drift = math.radians(effects.imu_yaw_drift_deg_per_min) / 60.0  # rad/s
        params = np.zeros(N_PARAMS)
        params[LATENCY] = self.latency
        params[ACCELERATION] = math.inf if effects.wheel_acceleration >= NO_LIMIT else \
            effects.wheel_acceleration / WHEEL_RADIUS  # rad/s^2 of a wheel
        params[LIMIT] = min(effects.wheel_speed_limit_rpm * RPM,
                            FIRMWARE_WHEEL_LIMIT if effects.firmware_clamp else math.inf)
        params[RADIUS], params[RADIUS + 1] = self.radii
        params[TRACK_TRUE] = self.track
        params[SLIP_SIGMA] = effects.wheel_slip_sigma
        params[MAX_LINEAR], params[MAX_ANGULAR] = (FIRMWARE_MAX_LINEAR, FIRMWARE_MAX_ANGULAR) \
            if effects.firmware_clamp else (math.inf, math.inf)
        params[YAW_DRIFT] = self.yaw_drift
        self.params = params
        self.odom = np.zeros(3)  # the /odom pose [x, y, theta]: the start is (0, 0, 0)
        self.state = np.zeros(N_STATE)
        self._pending = np.zeros((int(math.ceil(self.latency / dt)) + 3, 3))
        self._rng = rng
        self._draws = np.zeros(_SLIP_BLOCK)
        self._steps_left = 0  # on the current block of slip draws
        self._step = _drive_step if use_numba else drive_step_python
        self._sense = _sense if use_numba else sense_python

    def step(self, v: float, w: float, now: float, dt: float) -> tuple[float, float]:
        """(ds, dtheta) on the floor over [now, now + dt] after the command (v, w) at `now`."""
        if not self._steps_left:
            self._draws = self._rng.standard_normal(_SLIP_BLOCK)
            self.state[DRAW] = 0.0
            self._steps_left = _SLIP_BLOCK // 2
        self._steps_left -= 1
        return self._step(self.state, self.params, self._pending, self._draws, v, w, now, dt)

    @property
    def wheel_speeds(self) -> tuple[float, float]:
        """The wheels' speeds (left, right), rad/s."""
        return float(self.state[SPEED]), float(self.state[SPEED + 1])

    def sense(self, ds: float, dtheta: float, dt: float) -> tuple[float, float, float, float]:
        """(dphi_left, dphi_right, z_v, z_w) for the actual motion; advances `odom`."""
        return self._sense(self.state, self.params, self.odom, ds, dtheta, dt)
