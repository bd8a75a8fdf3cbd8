"""Pose sources of the headless navigation episodes: the truth, or a localizer fed as its node.

GroundTruthPose (the simulator's pose, optionally localized late or lost for a while) and
ParticleFilterPose (a localizer, default the particle filter, fed by the rules of
amr_common.navigation_behaviour shared with the particle filter node); make_pose_source
builds one by name.
"""
from __future__ import annotations

import math
from typing import Any

from amr_common.navigation_behaviour import OdometryClock, ScanNovelty, stamp_ns
from amr_common.plugins.link_failure import checked_localization, link_call
from amr_common.plugins.loader import DEFAULT_LOCALIZER, link_class
from amr_common.world.world import World
from amr_evaluation.episode import filter_parameters, tell_scan_geometry
from amr_sim.simulator import Simulator


class GroundTruthPose:
    """The simulator's true pose as the estimate.

    Localized from `localized_after_s` on (the wall follower explores before that), lost again
    during [lost_from_s, lost_until_s).
    """

    def __init__(self, localized_after_s: float = 0.0, lost_from_s: float | None = None,
                 lost_until_s: float | None = None) -> None:
        """Times in simulated seconds."""
        self.localized_after_s = localized_after_s
        self.lost = (lost_from_s, lost_until_s)

    def update(self, sim: Simulator, z_scan, z_v: float, z_w: float):
        """((x, y, theta), localized) for the newest measurement."""
        t = sim.time
        lost = self.lost[0] is not None and self.lost[0] <= t < (self.lost[1] or math.inf)
        return sim.pose, t >= self.localized_after_s - 1e-9 and not lost


class ParticleFilterPose:
    """A localizer (default the particle filter) as the pose source, fed as its node feeds it.

    Every measurement: predict with the odometry twist over the time since the previous one
    (OdometryClock, on the stamps the node would see), then correct with the scan, which counts
    as new when its readings differ from the previous scan's (ScanNovelty): the rules of
    amr_common.navigation_behaviour, shared with the particle filter node.
    """

    def __init__(self, world: World, sim: Simulator, seed: int = 0,
                 localizer: str | type = DEFAULT_LOCALIZER, **filter_params) -> None:
        """A localizer on `world` for the profile of `sim` (its LiDAR position and scan).

        localizer: an amr_common.plugins.interfaces.Localizer class, or its MODULE:CLASS.
        """
        cls = link_class(localizer, "localizer")
        # The simulated LiDAR (position, model, skew, where the map's walls are), as far as
        # the class takes them.
        sensor = filter_parameters(sim.profile, world is sim.world, cls)
        self.filter = cls(world, **{"seed": seed, **sensor, **filter_params})
        self._geometry = sim.scan_geometry
        tell_scan_geometry(self.filter, self._geometry, with_rays=True, link="localizer")
        self._clock = OdometryClock()
        self._novelty = ScanNovelty()

    def update(self, sim: Simulator, z_scan, z_v: float, z_w: float):
        """((x, y, theta), localized) after taking in the newest measurement.

        Each call checked as the node checks it (amr_common.plugins.link_failure): what the
        localizer raises or an estimate its interface forbids is its failure (LinkFailure).
        """
        dt, _ = self._clock.advance(stamp_ns(sim.time))
        if dt is not None:
            link_call("localizer", "predict", self.filter.predict, float(z_v), float(z_w), dt)
        if sim.scan_geometry is not self._geometry:  # the LDS-02: every scan
            self._geometry = sim.scan_geometry
            tell_scan_geometry(self.filter, self._geometry, with_rays=True, link="localizer")
        link_call("localizer", "correct", lambda: self.filter.correct(
            z_scan, new_scan=self._novelty.is_new(z_scan), age_s=sim.time - sim.scan_time))
        return link_call("localizer", "estimate", lambda: checked_localization(
            self.filter.estimate, self.filter.localized))


def make_pose_source(kind: Any, world: World, sim: Simulator, seed: int,
                     filter_params: dict | None = None,
                     localizer: str | type = DEFAULT_LOCALIZER):
    """The pose source named by `kind` ("truth", "filter": `localizer`) or `kind` itself."""
    if kind == "truth":
        return GroundTruthPose()
    if kind == "filter":
        return ParticleFilterPose(world, sim, seed, localizer, **(filter_params or {}))
    if isinstance(kind, str) or not callable(getattr(kind, "update", None)):
        raise ValueError(f"pose_source must be 'truth', 'filter' or an object with update(), "
                         f"got {kind!r}")
    return kind


__all__ = ["GroundTruthPose", "ParticleFilterPose", "make_pose_source"]
