"""The slam node's map files: Nav2 map YAML + PGM/PNG of the Mapper's map, and save requests.

write_slam_map names the map's start pose in the YAML (`starts: slam_start`), so a saved map
is a run's --map (or --world) as it is; read_save_request checks a ~/save_map request.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from amr_common.interfaces import Mapper
from amr_common.map_file import write_map


def write_slam_map(mapper: Mapper, prefix: str | Path, image_format: str,
                   start: tuple[float, float, float], mapped_scans: int) -> Path:
    """PREFIX.yaml + PREFIX.pgm (or .png) of the mapper's map; the YAML's path.

    ValueError (MapFileError included) or OSError when the files cannot be written.
    """
    stats = mapper.statistics()  # a user's mapper may count neither keyframes nor closures
    counts = "".join(f", {stats[key]} {key.replace('_', ' ')}"
                     for key in ("keyframes", "loop_closures") if key in stats)
    yaml_path, _ = write_map(mapper.occupancy_raster(), Path(prefix).expanduser(), image_format,
                             extras={"name": Path(prefix).name or "slam_map",
                                     "description": f"built by amr_slam from {mapped_scans} "
                                                    f"scans{counts}",
                                     "starts": {"slam_start": list(start)}})
    return yaml_path


def read_save_request(request: Any, default_prefix: str) -> tuple[str, str | None, str | None]:
    """(prefix, image format or None for the node's, problem or None) of a SaveMap request."""
    prefix = request.name.strip() or default_prefix
    image_format = request.image_format.strip().lower() or None
    if not prefix:
        return prefix, image_format, "no name given and the output_prefix parameter is empty"
    if image_format not in (None, "pgm", "png"):
        return prefix, image_format, f"image_format must be pgm or png (got {image_format!r})"
    return prefix, image_format, None
