"""Links that fail at run time (importable as tests.failing_links:NAME by --controller & co).

Each is the project's class with one member broken from its FROM_CALL-th call on: raising, or
returning what the link's interface forbids (None, NaN, a wrong shape). Test plug-ins for the
rule of amr_common.plugins.link_failure.
"""
import dataclasses
import math
from types import SimpleNamespace

import numpy as np

from amr_control.pure_pursuit import PurePursuit
from amr_control.wall_follower import WallFollower
from amr_localization.particle_filter import ParticleFilter
from amr_mapping.mapper import Mapper
from amr_planning.planner import Planner


class _Breaks:
    """HOW a member breaks ("raise", or a bad value: "none", "nan", "shape"), from FROM_CALL."""

    HOW, FROM_CALL = "raise", 20

    def _after(self, member: str, good, nan, shape):
        calls = self.__dict__.setdefault("_calls", {})
        calls[member] = calls.get(member, 0) + 1
        if calls[member] < self.FROM_CALL:
            return good
        if self.HOW == "raise":
            raise RuntimeError(f"{member} broke")
        return {"none": None, "nan": nan, "shape": shape}[self.HOW]


class RaisingController(_Breaks, WallFollower):
    def compute_commands(self, z_scan, z_v, z_w):
        return self._after("compute_commands", super().compute_commands(z_scan, z_v, z_w),
                           (math.nan, 0.0), (0.1, 0.0, 0.0))


class NanController(RaisingController):
    HOW = "nan"


class NoneController(RaisingController):
    HOW = "none"


class RaisingFollower(_Breaks, PurePursuit):
    FROM_CALL = 5

    def compute_commands(self, *args, **kwargs):
        return self._after("compute_commands", super().compute_commands(*args, **kwargs),
                           (0.1, math.inf), [0.1])


class InfFollower(RaisingFollower):
    HOW = "nan"


class RaisingLocalizer(_Breaks, ParticleFilter):
    def correct(self, *args, **kwargs):
        return self._after("correct", super().correct(*args, **kwargs), None, None)


class NonePlanner(_Breaks, Planner):
    HOW, FROM_CALL = "none", 1

    def plan(self, start, goal):
        return self._after("plan", super().plan(start, goal),
                           SimpleNamespace(points=np.full((4, 2), math.nan)),
                           SimpleNamespace(points=np.zeros((3, 7))))


class ShapePlanner(NonePlanner):
    HOW = "shape"


class NoneUpdateMapper(_Breaks, Mapper):
    HOW = "none"

    def update(self, scan, odom_pose, stamp):
        good = super().update(scan, odom_pose, stamp)
        return self._after("update", good, dataclasses.replace(good, pose=(math.nan,) * 3),
                           good)


class NanPoseMapper(NoneUpdateMapper):
    """Every pose NaN from the first scan on."""

    HOW, FROM_CALL = "nan", 1


class NoneRasterMapper(_Breaks, Mapper):
    HOW, FROM_CALL = "none", 1

    def occupancy_raster(self):
        return self._after("occupancy_raster", super().occupancy_raster(), None, None)


class RaisingRasterMapper(NoneRasterMapper):
    HOW = "raise"


class NoneStatisticsMapper(_Breaks, Mapper):
    HOW, FROM_CALL = "none", 1

    def statistics(self):
        return self._after("statistics", super().statistics(), None, None)


class RaisingStatisticsMapper(NoneStatisticsMapper):
    HOW = "raise"
