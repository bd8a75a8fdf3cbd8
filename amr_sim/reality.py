"""The reality gap inside the Simulator: its drivetrain, scanner and random streams.

A profile with effects (turtlebot3, turtlebot3_lds02) gives the Simulator a `RealRobot`:
the effects in use (typical, set, or drawn from the seed with `:randomized`), the Drivetrain
that turns commands into motion and reports encoders and IMU, and the RealLidar. Each has its
own random stream derived from the seed, so a seed fully determines a run, and changing one
effect does not reshuffle the others' random numbers.
"""
from __future__ import annotations

import numpy as np

from amr_common.world.raster_raycast import SegmentGrid
from amr_sim.drivetrain import Drivetrain
from amr_sim.effects import Effects, draw_effects
from amr_sim.lidar_effects import RealLidar
from amr_sim.profiles import SensorProfile

_DRAW, _DRIVE, _LIDAR, _DELIVERY = 0, 1, 2, 3  # random streams: [seed, 21, stream]


def stream(seed: int, which: int) -> np.random.Generator:
    """The random generator of one stream of a run with `seed` (independent of the others)."""
    return np.random.default_rng([int(seed), 21, which])


def effects_of(profile: SensorProfile, seed: int) -> Effects | None:
    """The effects a run with this profile and seed uses: drawn if randomized, then the set."""
    if profile.effects is None:
        return None
    if not profile.randomize:
        return profile.effects
    return draw_effects(stream(seed, _DRAW)).with_values(dict(profile.effect_overrides))


def delivery_stream(seed: int) -> np.random.Generator:
    """The random stream of the real-time /scan jitter and loss (the simulator node's)."""
    return stream(seed, _DELIVERY)


class RealRobot:
    """The effects of one run: its drivetrain (`drive`) and scanner (`lidar`)."""

    def __init__(self, profile: SensorProfile, segments: np.ndarray, seed: int,
                 pose: tuple[float, float, float], dt: float,
                 grid: SegmentGrid | None = None) -> None:
        """`grid`: the walls in buckets (a big map's, World.wall_grid), for the scanner."""
        self.effects = effects_of(profile, seed)
        self.drive = Drivetrain(self.effects, stream(seed, _DRIVE), dt)
        self.lidar = RealLidar(segments, profile, self.effects, stream(seed, _LIDAR), dt,
                               grid=grid)
        self.lidar.reset(0.0, *pose)
