"""The slam node's calls of its mapper, each checked (amr_common.plugins.link_failure).

MapperCalls is a base of SlamNode (amr_mapping.slam_node): the mapper's map, statistics and
map -> odom as the node and the run scripts read them. A mapper that raises or returns what the
Mapper interface forbids has failed: the node logs it once, maps no more and keeps the map it
saved (GuardedLifecycleNode.use_link); the run scripts end the run, failed.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

from amr_common.geometry import compose
from amr_common.plugins.link_failure import (
    LinkFailure,
    checked_pose,
    checked_raster,
    checked_statistics,
    shown,
)
from amr_common.ros.ros_conversions import time_to_nanoseconds
from amr_common.world.map_raster import Raster


class MapperCalls:
    """The checked mapper calls of SlamNode (its mapper, node_params, _start, _tf, ...)."""

    @property
    def map_to_odom(self) -> tuple[float, float, float]:
        """The map -> odom transform (x, y, yaw) of the newest estimate."""
        return compose(self.mapper.map_to_odom, self._start)

    def _use_mapper(self, member: str, function, *args, **options) -> Any:
        """function(*args), a call of the mapper's `member`; None once it failed.

        Its failure (amr_common.plugins.link_failure) is kept and logged once: the node maps no
        more, and the map saved so far stays (GuardedLifecycleNode.use_link).
        """
        stamp = self._last_scan_stamp
        options.setdefault("time_s", None if stamp is None else time_to_nanoseconds(stamp) * 1e-9)
        return self.use_link("mapper", member, function, *args,
                             spec=self.node_params.get("mapper"), then="mapping stopped",
                             **options)

    def map_raster(self) -> Raster | None:
        """The mapper's map now (checked); None before configure and once the mapper failed."""
        if self.mapper is None:
            return None
        return self._use_mapper("occupancy_raster", self.mapper.occupancy_raster,
                                check=checked_raster)

    def mapper_statistics(self) -> Mapping[str, Any]:
        """The mapper's statistics() (checked); {} before configure and once it failed."""
        if self.mapper is None:
            return {}
        stats = self._use_mapper("statistics", self.mapper.statistics, check=checked_statistics)
        return {} if stats is None else stats

    def mapper_max_range(self) -> float | None:
        """The mapper's max_range_m (checked); None before configure and once it failed."""
        if self.mapper is None:
            return None
        return self._use_mapper("max_range_m", lambda: _positive(self.mapper.max_range_m))

    def _publish_tf(self, stamp, stamp_ns: int) -> None:
        """Send map -> odom on /tf from the mapper's newest estimate (finite, checked)."""
        transform = self._use_mapper("map_to_odom", lambda: checked_pose(
            "mapper", "map_to_odom", self.map_to_odom), time_s=stamp_ns * 1e-9)
        if transform is not None:
            self._tf.publish(transform, stamp)
            self._last_tf_ns = stamp_ns


def _positive(value: Any) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise LinkFailure("mapper", f"max_range_m is {shown(value)}, not a distance > 0")
    return float(value)


__all__ = ["MapperCalls"]
