"""Sensor and actuation profiles: the course's idealised CoppeliaSim robot and the real Burger.

`ideal` reproduces the course simulator (turtlebot3.md / course-template.md): a 240-ray scan over
360 deg every step from the robot centre with NaN for no return, and an /odometry twist every
step. `turtlebot3_clean` imitates the interfaces of the real TurtleBot3 Burger with its LDS-01:
360 rays at 1 deg from base_scan, 32 mm behind the robot centre, 0.12-3.5 m, 0.0 for no return,
Gaussian range noise (sigma 0.01 m), a new scan every 0.2 s (5 Hz), /odom with a pose only at
20 Hz, and commands quantised like turtlebot3_node (int(v * 100) / 100) and limited to 0.22 m/s
and 2.84 rad/s. It was called `turtlebot3` before the reality-gap profiles: the figures
measured before were measured with it.

`turtlebot3` is the Burger as a user gets it: `turtlebot3_clean` with every reality-gap effect
at its typical value (amr_sim.effects, docs/reality-gap.md: LDS-01 range error and noise by
distance band, scan skew, dropouts, command latency, motor acceleration, the firmware's 61 rpm
clamp, wheel radius and track errors, slip, IMU heading drift, and in real time /scan jitter and
loss); `turtlebot3_lds02` is the same robot with the newer LDS-02 (LD08 driver: the ray count
and angles change from scan to scan, NaN for no return, range_min 0 and range_max 100 as
published). A profile name takes options after colons: `turtlebot3:randomized` draws every
effect within its documented range from the seed; `turtlebot3:command_latency_s=0.1` sets one;
`turtlebot3:off:scan_skew=1` starts from every effect off (to see what one effect does).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

from amr_common.robot import LIDAR_OFFSET_X, MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED
from amr_common.sensors.lidar_models import LDS01, LDS02, LidarModel
from amr_sim.effects import Effects, parse_effect_value

RANDOMIZED = "randomized"  # the profile option that draws the effects from the seed
OFF = "off"  # the profile option that turns every effect off (then EFFECT=VALUE turns some on)


@dataclass(frozen=True)
class SensorProfile:
    """What the simulated robot's sensors and command path look like (ideal, turtlebot3...)."""

    name: str
    scan_rays: int  # nominal (turtlebot3_lds02: it changes from scan to scan)
    angle_min: float  # rad, relative to the robot heading; rays go counter-clockwise
    angle_increment: float  # rad
    range_min: float  # m
    range_max: float  # m
    no_return: float  # value reported for rays without a valid return (nan or 0.0)
    range_noise_sigma: float  # m, Gaussian
    scan_period: float | None  # s between new scans; None = every step
    odom_period: float | None  # s between odometry messages; None = every step
    odom_topic: str  # "/odometry" (twist from encoders) | "/odom" (pose only)
    command_resolution: float | None  # commands truncated toward zero to multiples of this
    max_linear: float  # m/s, command limit
    max_angular: float  # rad/s, command limit
    # True: v and w are clipped separately to max_linear / max_angular before the wheel-speed
    # saturation (turtlebot3_node); False: only the wheel-speed saturation, which keeps the
    # curvature (the course robot; it bounds |v| <= 0.22 and |w| <= 2.75 by itself).
    clamp_commands: bool = False
    # m, forward position of the LiDAR (the scan's origin) from the robot centre, along its axis.
    lidar_offset_x: float = 0.0
    # The reality gap: None = the clean models (ideal, turtlebot3_clean), bit for bit as before.
    effects: Effects | None = None
    lidar_model: LidarModel | None = None
    randomize: bool = False  # draw `effects` from the seed (then apply effect_overrides)
    effect_overrides: tuple[tuple[str, float], ...] = ()

    @property
    def angle_max(self) -> float:
        """Angle of the last ray, rad."""
        return self.angle_min + (self.scan_rays - 1) * self.angle_increment


IDEAL = SensorProfile(
    name="ideal", scan_rays=240, angle_min=0.0, angle_increment=2.0 * math.pi / 240,
    range_min=0.016, range_max=8.0, no_return=math.nan, range_noise_sigma=0.0,
    scan_period=None, odom_period=None, odom_topic="/odometry", command_resolution=None,
    max_linear=MAX_LINEAR_SPEED, max_angular=MAX_ANGULAR_SPEED)

TURTLEBOT3_CLEAN = SensorProfile(
    name="turtlebot3_clean", scan_rays=360, angle_min=0.0, angle_increment=2.0 * math.pi / 360,
    range_min=0.12, range_max=3.5, no_return=0.0, range_noise_sigma=0.01,
    scan_period=0.2, odom_period=0.05, odom_topic="/odom", command_resolution=0.01,
    max_linear=MAX_LINEAR_SPEED, max_angular=MAX_ANGULAR_SPEED, clamp_commands=True,
    lidar_offset_x=LIDAR_OFFSET_X)  # base_scan at (-0.032, 0, 0.172) from base_link

# The Burger as a user gets it: the clean model with every effect at its typical value (the
# LDS-01 model's range noise replaces the clean model's 1 cm).
TURTLEBOT3 = replace(TURTLEBOT3_CLEAN, name="turtlebot3", range_noise_sigma=0.0,
                     effects=Effects(), lidar_model=LDS01)

# ld08_driver: angle_increment = speed / 2300 samples/s (0.78 deg at 5 Hz, ~460 rays),
# angle_min/angle_max = the first/last valid sample, range_min 0, range_max 100, NaN = no return.
TURTLEBOT3_LDS02 = replace(TURTLEBOT3, name="turtlebot3_lds02", scan_rays=460,
                           angle_increment=2.0 * math.pi / 460, range_min=0.0, range_max=100.0,
                           no_return=math.nan, lidar_model=LDS02)

PROFILES: dict[str, SensorProfile] = {
    p.name: p for p in (IDEAL, TURTLEBOT3_CLEAN, TURTLEBOT3, TURTLEBOT3_LDS02)}

# Names a profile no longer has: what to say instead of "unknown profile".
RETIRED_PROFILES: dict[str, str] = {
    "turtlebot3_real": "profile 'turtlebot3_real' is now 'turtlebot3' (every reality-gap effect "
                       "at its typical value); the clean model is 'turtlebot3_clean'"}


def get_profile(name: str | SensorProfile) -> SensorProfile:
    """The profile `name` ("ideal", "turtlebot3", ...) with its options; a SensorProfile passes.

    Options follow the name after colons: `randomized` (draw every effect from the seed), `off`
    (every effect off) and EFFECT=VALUE (amr_sim.effects), applied last; e.g.
    "turtlebot3:randomized:command_latency_s=0.1". ValueError names what is wrong (a retired
    name, e.g. turtlebot3_real, says what it is called now).
    """
    if isinstance(name, SensorProfile):
        return name
    if not isinstance(name, str):
        raise ValueError(f"unknown profile {name!r}; choose one of {sorted(PROFILES)}")
    base, *options = [part.strip() for part in name.split(":")]
    if base in RETIRED_PROFILES:
        raise ValueError(RETIRED_PROFILES[base])
    if base not in PROFILES:
        raise ValueError(f"unknown profile {base!r}; choose one of {sorted(PROFILES)}")
    profile = PROFILES[base]
    if not options:
        return profile
    randomize, off, overrides = False, False, {}
    for option in options:
        if option in (RANDOMIZED, OFF):
            randomize, off = randomize or option == RANDOMIZED, off or option == OFF
        elif "=" in option:
            key, value = (part.strip() for part in option.split("=", 1))
            overrides[key] = parse_effect_value(key, value)
        else:
            raise ValueError(f"profile option {option!r} is none of '{RANDOMIZED}', '{OFF}' "
                             f"and EFFECT=VALUE (in profile {name!r})")
    if profile.effects is None:
        raise ValueError(f"profile {base!r} has no reality-gap effects to "
                         f"{'randomize' if randomize else 'set'}; use turtlebot3 or "
                         f"turtlebot3_lds02")
    if randomize and off:
        raise ValueError(f"profile {name!r}: '{RANDOMIZED}' and '{OFF}' exclude each other")
    canonical = ":".join([base] + [RANDOMIZED] * randomize + [OFF] * off
                         + [f"{k}={v:g}" for k, v in overrides.items()])
    effects = Effects.none() if off else profile.effects
    return replace(profile, name=canonical, effects=effects.with_values(overrides),
                   randomize=randomize, effect_overrides=tuple(overrides.items()))


def randomized_profile_name(name: str) -> str:
    """`name` with the `randomized` option (--randomize); ValueError without effects."""
    profile = get_profile(name)
    if profile.effects is None:
        raise ValueError(f"--randomize: profile {profile.name!r} has no reality-gap effects "
                         f"to draw; use turtlebot3 or turtlebot3_lds02")
    if profile.randomize:
        return profile.name
    base, _, rest = profile.name.partition(":")
    return ":".join([base, RANDOMIZED] + ([rest] if rest else []))
