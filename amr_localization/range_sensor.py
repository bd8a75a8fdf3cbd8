"""The filter's idea of its range sensor: how far a reading may be off, and when it was taken.

Three kinds of scan (the `lidar_model` parameter):
- `exact`: the simulator's clean profiles (ideal, turtlebot3_clean): every ray from the scan's
  stamp pose, a fixed noise. A reading matches within `match_tolerance_m` and is weighed with
  `sigma_hit_m`; a missing return where the map expects a wall counts against a pose (the clean
  simulator returns every ray it can).
- `LDS-01`, `LDS-02` (amr_common.sensors.lidar_models: the datasheets' distance bands): the error
  grows with the range, so the tolerance of a reading r is match_tolerance_m + accuracy(r) +
  2 precision(r) (a unit off by its whole accuracy still matches ~98 % of its rays) and its
  sigma sqrt(sigma_hit_m^2 + accuracy(r)^2 + precision(r)^2); a missing return (0.0, NaN, inf)
  is unknown, neither a match nor a mismatch: real scanners drop rays on dark, far and grazing
  surfaces. The rays were measured over a clockwise revolution before the stamp
  (LidarModel.ray_ages): the filter de-skews them (scan_deskew) unless told the scans are
  instantaneous (`deskew` false: a simulated scanner without skew).
- `auto` (default): LDS-02 when the scan's range_max is beyond 10 m (the LD08 driver publishes
  100 m), else LDS-01 - the Burger's two scanners. The run scripts name the model of a
  simulated profile.
On a map world (a Nav2 map, a SLAM map) the walls are known to half a cell at best: half the
map's resolution is added to every tolerance and sigma. No rclpy import.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from amr_common.sensors.lidar_models import LIDAR_MODELS, LidarModel

EXACT = "exact"
AUTO = "auto"
MODEL_NAMES = (AUTO, EXACT, *LIDAR_MODELS)
_LDS02_FROM_RANGE_MAX_M = 10.0  # a scan reaching farther than this comes from the LDS-02
_PRECISIONS = 2.0  # the tolerance covers this many precision bounds beyond the accuracy
SCALE_ONE = 1 << 16  # the beam model's fixed-point 1.0 (sigma_hit_m / sigma of a beam)


def lidar_model_for(name: str, range_max: float) -> LidarModel | None:
    """The LidarModel `name` stands for (None for exact); `auto` decides by range_max."""
    if name == EXACT:
        return None
    if name == AUTO:
        name = "LDS-02" if range_max > _LDS02_FROM_RANGE_MAX_M else "LDS-01"
    return LIDAR_MODELS[name]


@dataclass(frozen=True)
class RangeSensor:
    """Tolerances, sigmas, missing returns and ray times of one scanner (module docstring)."""

    lidar: LidarModel | None  # None: exact
    match_tolerance_m: float
    sigma_hit_m: float
    map_uncertainty_m: float = 0.0  # half a map cell on a map world, else 0
    deskew: bool = True

    @classmethod
    def from_parameters(cls, params: dict, range_max: float, map_cell_m: float | None
                        ) -> "RangeSensor":
        """The sensor the filter's parameters describe for a scan reaching range_max (m)."""
        return cls(lidar_model_for(params["lidar_model"], range_max),
                   params["match_tolerance_m"], params["sigma_hit_m"],
                   0.5 * map_cell_m if map_cell_m else 0.0, bool(params["deskew"]))

    @property
    def name(self) -> str:
        """exact, LDS-01 or LDS-02."""
        return EXACT if self.lidar is None else self.lidar.name

    @property
    def missing_is_unknown(self) -> bool:
        """True if a missing return says nothing (a real scanner drops rays)."""
        return self.lidar is not None

    @property
    def revolution_s(self) -> float:
        """Time over which a scan's rays are measured (0: all at the stamp, no de-skew)."""
        return self.lidar.revolution_s if self.lidar is not None and self.deskew else 0.0

    @property
    def spread_free(self) -> bool:
        """True if every reading has the same tolerance and sigma (the exact model)."""
        return self.lidar is None

    def sensing_max(self, range_max: float) -> float:
        """The farthest range a return can have: the scan's limit or the datasheet's."""
        return range_max if self.lidar is None else min(range_max, self.lidar.sensing_max)

    def _bounds(self, ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.lidar is None:
            zeros = np.zeros(np.shape(ranges))
            return zeros, zeros
        return self.lidar.bounds(ranges)

    def tolerances(self, ranges: np.ndarray) -> np.ndarray:
        """Per ray: how far (m) a reading may be from the expected range and still match."""
        accuracy, precision = self._bounds(ranges)
        return self.match_tolerance_m + self.map_uncertainty_m + accuracy + \
            _PRECISIONS * precision

    def sigmas(self, ranges: np.ndarray) -> np.ndarray:
        """Per ray: the beam model's standard deviation (m) around the expected range."""
        accuracy, precision = self._bounds(ranges)
        return np.sqrt(self.sigma_hit_m ** 2 + self.map_uncertainty_m ** 2 + accuracy ** 2
                       + precision ** 2)

    def sigma_scales(self, ranges: np.ndarray) -> np.ndarray:
        """Per ray: sigma_hit_m / its sigma in fixed point (SCALE_ONE = 1), int64.

        The beam model reads its log-likelihood table (made for sigma_hit_m) at the difference
        times this scale: the same table serves every sigma.
        """
        ratio = self.sigma_hit_m / self.sigmas(ranges)
        return np.round(ratio * SCALE_ONE).astype(np.int64)

    def ray_ages(self, angles: np.ndarray, age_s: float = 0.0) -> np.ndarray | None:
        """How long before now each ray was measured (s), or None for no de-skew.

        age_s: how old the scan's stamp is (the time since it the filter has predicted).
        """
        if self.revolution_s <= 0.0:
            return None
        return age_s + self.lidar.ray_ages(angles)

    def describe(self) -> str:
        """E.g. 'LDS-01 (tolerance 3.0 cm + 1.5 cm + 2 x 1.0 cm at 0.3 m, de-skewed)'."""
        if self.lidar is None:
            extra = f" + {100 * self.map_uncertainty_m:g} cm map" if self.map_uncertainty_m \
                else ""
            return f"exact (tolerance {100 * self.match_tolerance_m:g} cm{extra})"
        at = [0.3, 1.0, 2.0]
        tolerances = ", ".join(f"{100 * t:.1f} cm at {r:g} m"
                               for r, t in zip(at, self.tolerances(np.array(at))))
        skew = "de-skewed" if self.revolution_s > 0 else "not de-skewed"
        return f"{self.name} (tolerance {tolerances}; {skew})"


__all__ = ["RangeSensor", "lidar_model_for", "MODEL_NAMES", "EXACT", "AUTO", "SCALE_ONE"]
