"""Drawing rays with the LiDAR's range error: near returns mark walls, far ones only clear.

A datasheet LiDAR's range error grows with the range (LDS-01: noise up to 3.5 % and a per-unit
bias up to 5 % of it beyond 0.5 m; amr_common.lidar_models). Drawn as returned, a wall seen
from 2 m lands several cells deep and a few centimetres off its place, and a scan of it from
another distance disagrees: walls come out thick, the matcher slides with them. With a model
the grid takes each ray by its band (RangeErrorRays.split):
- a return whose expected error (noise sigma + bias, half the datasheet's precision and
  accuracy bounds, as the simulator draws them at their typical value) is at most
  `hit_max_error_m` marks its end cell occupied and clears the cells up to `stop_errors`
  errors short of it (at least the grid's own miss stop);
- a farther return only clears, up to `stop_errors` errors short of its end: free space, never
  a wall.
Rays are grouped by their miss stop (bins of one cell) so the compiled trace_rays kernel draws
each group unchanged; removing a scan (sign -1) groups it the same way, so it stays exact.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from amr_common.lidar_models import LIDAR_MODELS, LidarModel

MODEL_NAMES = ("none",) + tuple(LIDAR_MODELS)


@dataclass(frozen=True)
class RangeErrorRays:
    """How one LiDAR's rays are drawn (see the module docstring)."""

    model: LidarModel
    hit_max_error_m: float
    stop_errors: float

    def expected_error(self, ranges: np.ndarray) -> np.ndarray:
        """Noise sigma + bias (m) at their typical value: half the precision and accuracy."""
        accuracy, precision = self.model.bounds(ranges)
        return 0.5 * (accuracy + precision)

    def split(self, ranges: np.ndarray, base_stop_cells: float, resolution: float
              ) -> list[tuple[np.ndarray, float, bool]]:
        """Groups (ray indices, miss stop in cells, marks a hit) covering every ray once."""
        error = self.expected_error(ranges)
        stop = np.maximum(self.stop_errors * error / resolution, base_stop_cells)
        stop_bin = np.ceil(stop).astype(np.int64)
        near = error <= self.hit_max_error_m
        groups = []
        for hit in (True, False):
            chosen = near if hit else ~near
            for value in np.unique(stop_bin[chosen]):
                index = np.flatnonzero(chosen & (stop_bin == value))
                groups.append((index, float(max(value, base_stop_cells)), hit))
        return groups


def range_error_rays(params: dict) -> RangeErrorRays | None:
    """How the Mapper's parameters say to draw rays (lidar_model 'none': None, as returned).

    Parameters `lidar_model`, `range_hit_max_error_m`, `range_stop_errors`.
    """
    if params["lidar_model"] == "none":
        return None
    return RangeErrorRays(LIDAR_MODELS[params["lidar_model"]],
                          float(params["range_hit_max_error_m"]),
                          float(params["range_stop_errors"]))


__all__ = ["MODEL_NAMES", "RangeErrorRays", "range_error_rays"]
