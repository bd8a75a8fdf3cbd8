"""The reality gap: what makes a real TurtleBot3 run differ from a clean simulation.

`Effects` holds one value per effect; `EFFECTS` says, for each, its unit, its typical value (the
`turtlebot3` and `turtlebot3_lds02` profiles), the range `--randomize` draws it from, the
range a user may set it to, and where the figures come from (docs/reality-gap.md has the
sources in full). Plain Python, no rclpy.

    effects = Effects()                                   # typical values
    effects = Effects(command_latency_s=0.1)              # ValueError if out of its valid range
    drawn = draw_effects(np.random.default_rng(3))        # each uniformly within its range
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, Mapping

import numpy as np


@dataclass(frozen=True)
class EffectSpec:
    """One effect parameter: typical value, drawn range, valid range, unit, meaning, source."""

    typical: float
    drawn: tuple[float, float]  # --randomize draws uniformly in [low, high]
    valid: tuple[float, float]  # what a user may set (inclusive)
    unit: str
    meaning: str
    source: str


NO_LIMIT = 1e6  # the largest wheel acceleration / top speed: no limit at all

EFFECTS: dict[str, EffectSpec] = {
    # --- the LiDAR -------------------------------------------------------------------------
    "range_bias_share": EffectSpec(
        0.5, (-1.0, 1.0), (-5.0, 5.0), "",
        "systematic range error, as a share of the datasheet's distance accuracy of each band "
        "(LDS-01: 15 mm below 0.5 m, 5 % of the range above)", "LDS-01/LDS-02 datasheets"),
    "range_noise_share": EffectSpec(
        0.5, (0.33, 1.0), (0.0, 5.0), "",
        "Gaussian range noise sigma, as a share of the datasheet's distance precision of each "
        "band (LDS-01: 10 mm below 0.5 m, 3.5 % of the range above)",
        "LDS-01/LDS-02 datasheets"),
    "scan_skew": EffectSpec(
        1.0, (1.0, 1.0), (0.0, 1.0), "0/1",
        "each ray is measured from the pose at its own time in the revolution; the scan is "
        "stamped at the revolution's end, as the drivers stamp it",
        "hls_lfcd_lds_driver, ld08_driver"),
    "dropout_share": EffectSpec(
        0.01, (0.0, 0.03), (0.0, 1.0), "",
        "share of rays without a return anywhere", "estimate (see docs/reality-gap.md)"),
    "dropout_far_share": EffectSpec(
        0.10, (0.0, 0.3), (0.0, 1.0), "",
        "extra dropout share at the sensor's longest range, growing with (range / longest)^2",
        "estimate: a triangulation return weakens with the square of the range"),
    "dropout_grazing_share": EffectSpec(
        0.5, (0.2, 0.9), (0.0, 1.0), "",
        "extra dropout share at 90 deg incidence, growing from 0 at 60 deg with the square",
        "estimate: a grazing spot spreads along the wall"),
    # --- commands and motors ---------------------------------------------------------------
    "command_latency_s": EffectSpec(
        0.03, (0.01, 0.10), (0.0, 2.0), "s",
        "from a /cmd_vel to the wheels (DDS, turtlebot3_node, the OpenCR's 20 ms motor loop)",
        "OpenCR turtlebot3_ros2 firmware (INTERVAL_MS_TO_CONTROL_MOTOR = 20)"),
    "wheel_acceleration": EffectSpec(
        1.0, (1.0, 3.0), (1e-3, NO_LIMIT), "m/s^2",
        f"largest change of each wheel's rim speed per second ({NO_LIMIT:g}: no limit)",
        "turtlebot3_gazebo burger model.sdf (max_linear_acceleration 1.0); Nav2 burger.yaml "
        "(acc_lim_x 2.5-3.0)"),
    "firmware_clamp": EffectSpec(
        1.0, (1.0, 1.0), (0.0, 1.0), "0/1",
        "the firmware clips v and w separately to the speeds of 61 rpm wheels (0.211 m/s, "
        "2.64 rad/s), not keeping the curvature",
        "OpenCR turtlebot3_ros2 firmware: model_motor_rpm 61, constrain() on each"),
    "wheel_speed_limit_rpm": EffectSpec(
        61.0, (57.0, 61.0), (1.0, NO_LIMIT), "rpm",
        "each wheel's top speed (clipped per wheel: a turn slows the outer wheel only)",
        "XL430-W250: 57 rpm at 11.1 V, 61 at 12 V; Velocity Limit 265 x 0.229 rpm"),
    "wheel_radius_error": EffectSpec(
        -0.01, (-0.02, 0.02), (-0.5, 0.5), "",
        "true mean wheel radius / 0.033 m - 1 (the firmware and odometry assume 0.033 m)",
        "UMBmark (Borenstein & Feng 1996): systematic odometry errors of ~1 %"),
    "wheel_radius_difference": EffectSpec(
        0.005, (-0.01, 0.01), (-0.5, 0.5), "",
        "(right - left radius) / 0.033 m: the robot curves when commanded straight",
        "UMBmark (Borenstein & Feng 1996)"),
    "track_error": EffectSpec(
        0.02, (-0.03, 0.03), (-0.5, 0.5), "",
        "true wheel separation / 0.160 m - 1 (the tyres' contact patches are 18 mm wide)",
        "UMBmark (Borenstein & Feng 1996); Burger tyre width"),
    "wheel_slip_sigma": EffectSpec(
        0.02, (0.0, 0.05), (0.0, 1.0), "",
        "random slip: each wheel's ground travel differs from its rotation by this share "
        "(Gaussian, per step)", "estimate"),
    "imu_yaw_drift_deg_per_min": EffectSpec(
        0.5, (-2.0, 2.0), (-360.0, 360.0), "deg/min",
        "drift of the IMU heading that the real /odom uses (odometry.use_imu: true)",
        "github.com/ROBOTIS-GIT/turtlebot3/issues/655 and /819 (yaw drifts at rest); MEMS gyro "
        "after calibration: "
        "1-2 deg/min"),
    # --- real time only (the simulator node's timer mode) ----------------------------------
    "scan_loss_share": EffectSpec(
        0.02, (0.0, 0.10), (0.0, 1.0), "",
        "share of best-effort /scan messages that never arrive",
        "real-robot bags: /scan at about 4.9 Hz of 5 (shared/notes/turtlebot3.md)"),
    "scan_jitter_s": EffectSpec(
        0.01, (0.0, 0.05), (0.0, 1.0), "s",
        "each /scan arrives up to this much later than its stamp (uniform)",
        "ld08_driver polls at 100 Hz; Wi-Fi DDS delivery (estimate)"),
}


@dataclass(frozen=True)
class Effects:
    """Every effect's value (typical by default); out-of-range values raise ValueError."""

    range_bias_share: float = EFFECTS["range_bias_share"].typical
    range_noise_share: float = EFFECTS["range_noise_share"].typical
    scan_skew: float = EFFECTS["scan_skew"].typical
    dropout_share: float = EFFECTS["dropout_share"].typical
    dropout_far_share: float = EFFECTS["dropout_far_share"].typical
    dropout_grazing_share: float = EFFECTS["dropout_grazing_share"].typical
    command_latency_s: float = EFFECTS["command_latency_s"].typical
    wheel_acceleration: float = EFFECTS["wheel_acceleration"].typical
    firmware_clamp: float = EFFECTS["firmware_clamp"].typical
    wheel_speed_limit_rpm: float = EFFECTS["wheel_speed_limit_rpm"].typical
    wheel_radius_error: float = EFFECTS["wheel_radius_error"].typical
    wheel_radius_difference: float = EFFECTS["wheel_radius_difference"].typical
    track_error: float = EFFECTS["track_error"].typical
    wheel_slip_sigma: float = EFFECTS["wheel_slip_sigma"].typical
    imu_yaw_drift_deg_per_min: float = EFFECTS["imu_yaw_drift_deg_per_min"].typical
    scan_loss_share: float = EFFECTS["scan_loss_share"].typical
    scan_jitter_s: float = EFFECTS["scan_jitter_s"].typical

    def __post_init__(self) -> None:
        problems = []
        for name in EFFECT_NAMES:
            value = getattr(self, name)
            problem = _value_problem(name, value)
            if problem:
                problems.append(problem)
            else:
                object.__setattr__(self, name, float(value))
        if problems:
            raise ValueError("; ".join(problems))

    def as_dict(self) -> dict[str, float]:
        """{name: value}, JSON-serialisable."""
        return asdict(self)

    def with_values(self, values: Mapping[str, Any]) -> "Effects":
        """A copy with some values changed; ValueError for unknown names or bad values."""
        unknown = sorted(set(values) - set(EFFECT_NAMES))
        if unknown:
            raise ValueError(f"unknown effect(s) {', '.join(unknown)}; the effects are "
                             f"{', '.join(EFFECT_NAMES)}")
        return Effects(**{**self.as_dict(), **values})

    @classmethod
    def none(cls) -> "Effects":
        """Every effect off (accelerations and top speeds at the largest valid values)."""
        return cls(**{name: 0.0 for name in EFFECT_NAMES if name not in _OFF}, **_OFF)

    def summary(self) -> str:
        """One short line of every value, for tables and logs."""
        return " ".join(f"{_SHORT[name]}={_fmt(value)}" for name, value in self.as_dict().items())


EFFECT_NAMES: tuple[str, ...] = tuple(f.name for f in fields(Effects))
_SHORT = {"range_bias_share": "bias", "range_noise_share": "noise", "scan_skew": "skew",
          "dropout_share": "drop", "dropout_far_share": "drop_far",
          "dropout_grazing_share": "drop_graze", "command_latency_s": "latency_s",
          "wheel_acceleration": "acc", "firmware_clamp": "clamp", "wheel_speed_limit_rpm": "rpm",
          "wheel_radius_error": "radius", "wheel_radius_difference": "radius_lr",
          "track_error": "track", "wheel_slip_sigma": "slip",
          "imu_yaw_drift_deg_per_min": "imu_deg_min", "scan_loss_share": "loss",
          "scan_jitter_s": "jitter_s"}
_OFF = {"wheel_acceleration": EFFECTS["wheel_acceleration"].valid[1],
        "wheel_speed_limit_rpm": EFFECTS["wheel_speed_limit_rpm"].valid[1]}
assert set(EFFECT_NAMES) == set(EFFECTS) == set(_SHORT)


def _fmt(value: float) -> str:
    return f"{value:.3g}"


def _value_problem(name: str, value: Any) -> str:
    spec = EFFECTS[name]
    low, high = spec.valid
    unit = f" {spec.unit}" if spec.unit and spec.unit != "0/1" else ""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not math.isfinite(float(value)) or not low <= float(value) <= high:
        return f"effect {name} must be a number in [{low:g}, {high:g}]{unit} (got {value!r})"
    if spec.unit == "0/1" and float(value) not in (0.0, 1.0):
        return f"effect {name} must be 0 (off) or 1 (on) (got {value!r})"
    return ""


def parse_effect_value(name: str, text: str) -> float:
    """An effect's value from text ("0.1", "on", "off"); ValueError naming the effect."""
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; the effects are {', '.join(EFFECT_NAMES)}")
    words = {"on": 1.0, "true": 1.0, "off": 0.0, "false": 0.0}
    try:
        value = words[text.strip().lower()] if text.strip().lower() in words else float(text)
    except ValueError:
        value = text  # reported below as not a number
    problem = _value_problem(name, value)
    if problem:
        raise ValueError(problem)
    return float(value)


def draw_effects(rng: np.random.Generator) -> Effects:
    """Every effect drawn uniformly within its documented range (`EffectSpec.drawn`)."""
    return Effects(**{name: float(rng.uniform(*EFFECTS[name].drawn)) if
                      EFFECTS[name].drawn[0] < EFFECTS[name].drawn[1] else EFFECTS[name].drawn[0]
                      for name in EFFECT_NAMES})


__all__ = ["EFFECTS", "EFFECT_NAMES", "NO_LIMIT", "EffectSpec", "Effects", "draw_effects",
           "parse_effect_value"]
