"""The slam node's map files: Nav2 map YAML + PGM/PNG of the Mapper's map, and save requests.

write_slam_map writes only a map the project reads back (a map without a free cell is refused)
and names the map's start pose in the YAML (`starts: slam_start`) when the map's cells can take
it, so a saved map is a run's --map (or --world) as it is; read_save_request checks a
~/save_map request.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

from amr_common.world.map_file import as_read_back, write_map
from amr_common.world.map_raster import Raster
from amr_common.world.world import World, WorldError


def write_slam_map(raster: Raster, statistics: Mapping[str, Any], prefix: str | Path,
                   image_format: str, start: tuple[float, float, float],
                   mapped_scans: int) -> tuple[Path, str | None]:
    """PREFIX.yaml + PREFIX.pgm (or .png) of a mapper's map; (the YAML's path, why no start).

    `raster` and `statistics`: the mapper's (checked, amr_common.plugins.link_failure). The start
    is named unless the map read back cannot take it (a coarse map's cells: a wall within the
    robot's radius); the second item then says why, else None. ValueError (MapFileError
    included) or OSError when the files cannot be written or the map has no free cell (it
    would read back as nothing to drive or localize in); the files of an earlier save stay.
    """
    counts = "".join(f", {statistics[key]} {key.replace('_', ' ')}"  # a user's mapper may
                     for key in ("keyframes", "loop_closures") if key in statistics)  # lack
    try:
        world = World.from_raster(as_read_back(raster), source="the map")
    except WorldError:
        raise ValueError(f"the map has no free cell at {raster.resolution:g} m cells (every "
                         "cell explored holds a wall): it would read back as nothing to drive "
                         "or localize in; map with a smaller resolution_m") from None
    no_start = world.pose_problem(start[0], start[1], "the start")
    extras: dict[str, Any] = {"name": Path(prefix).name or "slam_map",
                              "description": f"built by amr_slam from {mapped_scans} "
                                             f"scans{counts}"}
    if no_start is None:
        extras["starts"] = {"slam_start": list(start)}
    yaml_path, _ = write_map(raster, Path(prefix).expanduser(), image_format, extras=extras)
    return yaml_path, no_start


def read_save_request(request: Any, default_prefix: str) -> tuple[str, str | None, str | None]:
    """(prefix, image format or None for the node's, problem or None) of a SaveMap request."""
    prefix = request.name.strip() or default_prefix
    image_format = request.image_format.strip().lower() or None
    if not prefix:
        return prefix, image_format, "no name given and the output_prefix parameter is empty"
    if image_format not in (None, "pgm", "png"):
        return prefix, image_format, f"image_format must be pgm or png (got {image_format!r})"
    return prefix, image_format, None
