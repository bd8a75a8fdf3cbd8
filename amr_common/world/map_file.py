"""Nav2 map_server map files (a YAML + a PGM or PNG image), read into and written from a Raster.

What SLAM (slam_toolbox, Cartographer) and `map_saver_cli -f ~/map` produce, and what Nav2's
map_server loads. The YAML::

    image: map.pgm            # path relative to the YAML (or absolute)
    mode: trinary             # optional: trinary (default) | scale | raw
    resolution: 0.05          # m per pixel, > 0
    origin: [-2.0, -3.5, 0]   # pose of the LOWER-LEFT pixel's corner: x, y (m), yaw (rad, 0)
    negate: 0                 # 0/1 or false/true: 1 = white is occupied
    occupied_thresh: 0.65
    free_thresh: 0.196

The keys map_server requires (all but `mode`) are required here too, so a file read here loads
in Nav2. Reading follows map_server's loadMapFromFile (navigation2 jazzy, nav2_map_server
map_io.cpp): the image in 8-bit gray (RGB through the Rec. 601 luma, 16-bit scaled down),
p = 1 - v/255 (v/255 with negate) in float32, then
- trinary: p >= occupied_thresh -> 100, p <= free_thresh -> 0, else -1;
- scale: as trinary, values between the thresholds -> round(100 (p - free) / (occ - free));
- raw: v itself if 0 <= v <= 100, else -1;
- trinary and scale: a pixel with alpha < 255 is -1;
and image row 0 is the TOP of the map (Raster row 0 is the bottom). Before navigation2 1.4
(jazzy until mid-2025, humble) the comparisons were strict (p > occ, p < free, in double):
they differ only for a pixel exactly at a threshold.

Writing follows map_saver in trinary mode: 0 for occupied (value >= 65), 254 for free
(0 <= value <= 25), 205 for unknown and everything else; the YAML says occupied_thresh 0.65
and free_thresh 0.196, as map_saver writes since navigation2 1.3.7: with the 0.25 it wrote
before, 205 (p = 0.196) reads back as FREE, so unknown space came back free. Images are PGM
(binary P5, written here: no library needed) or PNG (Pillow, which also reads both).

A map YAML may carry this project's keys (name, description, cell_size, grid_origin, starts,
goals, goal: amr_common.world.world_file); map_server ignores keys it does not know, so the file
stays a Nav2 map. Other unknown keys are ignored too, as map_server does.

Every problem raises MapFileError (a WorldError, so each script's `--world` check reports it as
one line): a missing or unreadable image, missing or non-numeric keys, a resolution <= 0,
thresholds outside [0, 1] or free_thresh >= occupied_thresh, an unknown mode, an origin yaw
other than 0 (rotated maps are not supported; map_saver always writes 0), an image of more than
MAX_GRID_CELLS pixels (the message says how many it has), or a map without a free cell.
"""
from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml
from PIL import Image, UnidentifiedImageError

from amr_common.world.coverage_grid import GridTooLargeError, check_grid_size
from amr_common.world.map_raster import FREE, OCCUPIED, UNKNOWN, Raster
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.world_file import (
    NAV2_MAP_KEYS,
    PROJECT_KEYS,
    WorldError,
    number_value,
    positive_number,
    project_values,
    read_world_file,
)

if TYPE_CHECKING:
    from amr_common.world.world import World

MODES = ("trinary", "scale", "raw")
NAV2_KEYS = NAV2_MAP_KEYS  # what map_server reads (amr_common.world.world_file dispatches on them)
# map_saver's trinary pixels and the thresholds it writes with them.
OCCUPIED_PIXEL, FREE_PIXEL, UNKNOWN_PIXEL = 0, 254, 205
SAVED_OCCUPIED_THRESH, SAVED_FREE_THRESH = 0.65, 0.196
# Worlds converted to maps: 2 cm, this project's SLAM and planner cell (walls within 1 cm of
# their place; slam_toolbox's 5 cm would narrow a 0.4 m corridor by 5 cm).
CONVERT_RESOLUTION = 0.02
_LOG = logging.getLogger(__name__)


class MapFileError(WorldError):
    """A map YAML or its image is missing or malformed; the message names the file."""


@dataclass(frozen=True)
class MapFile:
    """A read map: its cells (raster) and what its YAML said."""

    path: Path  # the YAML
    image_path: Path
    raster: Raster  # values as map_server publishes them, row 0 at the bottom
    mode: str = "trinary"
    negate: bool = False
    occupied_thresh: float = SAVED_OCCUPIED_THRESH
    free_thresh: float = SAVED_FREE_THRESH
    name: str = ""
    description: str = ""
    cell_size: float = 0.4
    grid_origin: tuple[float, float] | None = None
    starts: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    goals: dict[str, tuple[float, float]] = field(default_factory=dict)
    goal: tuple[float, float] | None = None


def read_map(path: str | Path) -> MapFile:
    """Read a map YAML and its image (MapFileError if it is not one or is malformed)."""
    spec = read_world_file(Path(path))
    if not isinstance(spec, MapFile):
        raise MapFileError(f"{spec.path}: not a Nav2 map YAML (none of the keys "
                           f"{', '.join(NAV2_KEYS)})")
    return spec


def map_from_yaml(data: dict[str, Any], path: Path) -> MapFile:
    """The MapFile of a parsed map YAML `data` read from `path` (loads the image)."""
    try:
        return _map_from_yaml(data, path)
    except MapFileError:
        raise
    except WorldError as exc:  # the shared value checks of world_file
        raise MapFileError(str(exc)) from None


def _map_from_yaml(data: dict[str, Any], path: Path) -> MapFile:
    missing = [k for k in NAV2_KEYS if k != "mode" and k not in data]
    if missing:
        raise MapFileError(f"{path}: missing key(s) {', '.join(missing)} (a Nav2 map YAML "
                           f"needs {', '.join(NAV2_KEYS)}; mode is optional)")
    ignored = set(data) - set(NAV2_KEYS) - PROJECT_KEYS
    if ignored:
        _LOG.info("%s: ignoring unknown key(s) %s, as map_server does", path, sorted(ignored))
    image = data["image"]
    if not isinstance(image, str) or not image.strip():
        raise MapFileError(f"{path}: 'image' must be a file name, got {image!r}")
    image_path = Path(image) if image.startswith("/") else path.parent / image
    mode = "trinary" if data.get("mode") is None else str(data["mode"])
    if mode not in MODES:
        raise MapFileError(f"{path}: mode must be one of {', '.join(MODES)}, got {mode!r}")
    resolution = positive_number(data["resolution"], path, "resolution")
    origin = data["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise MapFileError(f"{path}: origin must be [x, y, yaw], got {origin!r}")
    x0, y0, yaw = (number_value(v, path, f"origin {axis}")
                   for v, axis in zip(origin, ("x", "y", "yaw")))
    if yaw != 0.0:
        raise MapFileError(f"{path}: origin yaw {yaw:g} rad is not supported (only maps aligned "
                           f"with the map frame; map_saver writes 0): rotate the image instead")
    negate = data["negate"]
    if isinstance(negate, str) or not isinstance(negate, (bool, int)):
        raise MapFileError(f"{path}: negate must be 0, 1, true or false, got {negate!r}")
    occupied = number_value(data["occupied_thresh"], path, "occupied_thresh")
    free = number_value(data["free_thresh"], path, "free_thresh")
    if not (0.0 <= free < occupied <= 1.0):
        raise MapFileError(f"{path}: thresholds must satisfy 0 <= free_thresh < occupied_thresh "
                           f"<= 1, got free_thresh {free:g}, occupied_thresh {occupied:g}")
    gray, alpha = _read_image(image_path, path, resolution)
    values = cell_values(gray, alpha, mode, bool(negate), occupied, free)
    if not (values == FREE).any():
        raise MapFileError(f"{path}: the map has no free cell (value 0) in {image_path.name}: "
                           f"nothing to drive or localize in")
    if mode == "trinary" and not negate and ((gray == UNKNOWN_PIXEL) & (values == FREE)).any():
        _LOG.warning("%s: free_thresh %g reads map_saver's unknown pixels (205) as free, as "
                     "map_server does; 0.196 keeps them unknown", path, free)
    raster = Raster(np.ascontiguousarray(values[::-1]), resolution, (x0, y0))
    return MapFile(path=path, image_path=image_path, raster=raster, mode=mode,
                   negate=bool(negate), occupied_thresh=occupied, free_thresh=free,
                   **project_values(data, path))


def cell_values(gray: np.ndarray, alpha: np.ndarray | None, mode: str, negate: bool,
                occupied_thresh: float, free_thresh: float) -> np.ndarray:
    """Int8 cell values of 8-bit gray pixels as map_server reads them (rows as in the image)."""
    gray = np.asarray(gray, dtype=np.uint8)
    if mode == "raw":
        return np.where(gray <= 100, gray, UNKNOWN).astype(np.int8)
    shade = gray.astype(np.float32) / np.float32(255.0)
    p = shade if negate else np.float32(1.0) - shade
    occupied, free = np.float32(occupied_thresh), np.float32(free_thresh)
    values = np.full(gray.shape, UNKNOWN, dtype=np.int8)
    values[p >= occupied] = OCCUPIED
    values[p <= free] = FREE
    if mode == "scale":
        between = (p > free) & (p < occupied)
        scaled = (p - free) / (occupied - free) * np.float32(100.0)
        values[between] = np.floor(scaled[between] + np.float32(0.5)).astype(np.int8)
    if alpha is not None:
        values[alpha < 255] = UNKNOWN
    return values


def _read_image(image_path: Path, yaml_path: Path,
                resolution: float) -> tuple[np.ndarray, np.ndarray | None]:
    """(8-bit gray, 8-bit alpha or None) of the image, rows as in the file (row 0 = top)."""
    what = f"{yaml_path}: image {image_path}"
    if not image_path.is_file():
        raise MapFileError(f"{what} not found")
    try:
        with Image.open(image_path) as image:
            width, height = image.size
            try:
                check_grid_size(float(width), float(height), resolution,
                                f"{what}: {width} x {height} pixels", "crop the map or save it "
                                "at a coarser resolution")
            except GridTooLargeError as exc:
                raise MapFileError(str(exc)) from None
            image.load()
            return _gray_and_alpha(image)
    except MapFileError:
        raise
    except Image.DecompressionBombError as exc:  # Pillow's own limit, far above ours
        raise MapFileError(f"{what} is too large to hold: {exc}") from None
    except (OSError, UnidentifiedImageError, ValueError) as exc:
        raise MapFileError(f"{what} is not a readable PGM/PNG image: {exc}") from None


def _gray_and_alpha(image: Image.Image) -> tuple[np.ndarray, np.ndarray | None]:
    if image.mode in ("I", "I;16", "I;16B", "I;16L"):  # 16-bit gray: to 8 bits as GraphicsMagick
        wide = np.asarray(image, dtype=np.float64)
        return np.floor(wide / 257.0 + 0.5).clip(0, 255).astype(np.uint8), None
    if image.mode == "P":
        image = image.convert("RGBA" if "transparency" in image.info else "RGB")
    alpha = None
    if image.mode in ("LA", "La", "RGBA", "RGBa", "PA"):
        alpha = np.asarray(image.getchannel("A"), dtype=np.uint8)
    gray = image if image.mode == "L" else image.convert("L")  # RGB: Rec. 601 luma
    return np.asarray(gray, dtype=np.uint8), alpha


# ---------------------------------------------------------------------- writing
def trinary_pixels(values: np.ndarray, occupied_thresh: float = 0.65,
                   free_thresh: float = 0.25) -> np.ndarray:
    """map_saver's trinary pixels of int8 cell values (rows unchanged).

    0 <= value <= round(100 free_thresh) -> 254, value >= round(100 occupied_thresh) -> 0,
    anything else (-1, between, out of range) -> 205.
    """
    values = np.asarray(values).astype(np.int16)
    pixels = np.full(values.shape, UNKNOWN_PIXEL, dtype=np.uint8)
    valid = (values >= 0) & (values <= 100)
    pixels[valid & (values <= round(100 * free_thresh))] = FREE_PIXEL
    pixels[valid & (values >= round(100 * occupied_thresh))] = OCCUPIED_PIXEL
    return pixels


def as_read_back(raster: Raster) -> Raster:
    """The raster that write_map's files of `raster` read back as (map_server's rules)."""
    values = cell_values(trinary_pixels(raster.values), None, "trinary", False,
                         SAVED_OCCUPIED_THRESH, SAVED_FREE_THRESH)
    return Raster(values, raster.resolution, raster.origin)


def write_map(raster: Raster, prefix: str | Path, image_format: str = "pgm",
              extras: dict[str, Any] | None = None) -> tuple[Path, Path]:
    """Write PREFIX.yaml + PREFIX.pgm (or .png) as map_saver does; returns both paths.

    `prefix` may end in .yaml; missing folders are created. `extras`: this project's keys
    (name, description, cell_size, grid_origin, starts, goals, goal) appended after the Nav2
    keys. Each file is written to a temporary name and renamed, so an interrupted save leaves
    the previous map whole.
    MapFileError for an empty raster, a bad resolution/origin or a file that cannot be written.
    """
    prefix = Path(prefix)
    if prefix.suffix.lower() in (".yaml", ".yml"):
        prefix = prefix.with_suffix("")
    yaml_path = prefix.with_name(prefix.name + ".yaml")
    image_format = image_format.lower()
    if image_format not in ("pgm", "png"):
        raise MapFileError(f"{yaml_path}: image format must be pgm or png, got {image_format!r}")
    values = np.asarray(raster.values)
    resolution, (x0, y0) = float(raster.resolution), (float(v) for v in raster.origin)
    if values.ndim != 2 or values.size == 0:
        raise MapFileError(f"{yaml_path}: a map needs a non-empty 2D raster, got shape "
                           f"{values.shape}")
    if not (math.isfinite(resolution) and resolution > 0 and math.isfinite(x0)
            and math.isfinite(y0)):
        raise MapFileError(f"{yaml_path}: resolution must be > 0 and the origin finite, got "
                           f"{resolution!r}, ({x0!r}, {y0!r})")
    image_path = prefix.with_name(prefix.name + "." + image_format)
    pixels = np.ascontiguousarray(trinary_pixels(values)[::-1])  # image row 0 = top
    text = (f"image: {image_path.name}\nmode: trinary\nresolution: {resolution:.12g}\n"
            f"origin: [{x0:.12g}, {y0:.12g}, 0]\nnegate: 0\n"
            f"occupied_thresh: {SAVED_OCCUPIED_THRESH}\nfree_thresh: {SAVED_FREE_THRESH}\n")
    if extras:
        unknown = set(extras) - PROJECT_KEYS
        if unknown:
            raise MapFileError(f"{yaml_path}: unknown extra key(s) {sorted(unknown)}")
        # One top-level key at a time: a mapping of scalars only would be dumped as one
        # flow line ({name: x}), which is no YAML after the block keys above.
        text += ("# This project's keys (amr_common.world.map_file); Nav2's map_server ignores "
                 "them.\n")
        for key, value in _plain(extras).items():
            text += yaml.safe_dump({key: value}, sort_keys=False, default_flow_style=(
                None if isinstance(value, (dict, list)) else False))
    try:
        yaml_path.parent.mkdir(parents=True, exist_ok=True)
        _replace_atomically(image_path, lambda f: _write_image(f, pixels, image_format,
                                                               resolution))
        _replace_atomically(yaml_path, lambda f: f.write(text.encode("utf-8")))
    except OSError as exc:
        raise MapFileError(f"{yaml_path}: cannot write the map: {exc}") from None
    return yaml_path, image_path


def world_as_map(world: World, resolution: float = CONVERT_RESOLUTION
                 ) -> tuple[Raster, dict[str, Any]]:
    """(cells, extras) of any amr_common.world.world.World as a map at `resolution` m per cell.

    The cells are the world's occupancy grid (OccupancyGrid.from_world: cell centres on
    multiples of the resolution, so a wall on such a line is one cell thick around its true
    place, and the free space loses half a cell along each wall); the extras keep its name,
    starts, goals and coverage grid (write_map(raster, prefix, extras=extras)).
    """
    raster = OccupancyGrid.from_world(world, resolution).raster()
    grid_origin = world.grid_origin
    if grid_origin is None and world.boundary is not None:  # the coverage grid's default
        grid_origin = tuple(float(v) for v in world.boundary.min(axis=0))
    extras: dict[str, Any] = {"name": world.name, "description": world.description or
                              f"converted from {world.source}", "cell_size": world.cell_size}
    if grid_origin is not None:
        extras["grid_origin"] = list(grid_origin)
    if world.starts:
        extras["starts"] = world.starts
    if world.goals:
        extras["goals"] = world.goals
    if world.goal is not None and world.goal != next(iter(world.goals.values()), None):
        extras["goal"] = world.goal
    return raster, extras


def _write_image(stream, pixels: np.ndarray, image_format: str, resolution: float) -> None:
    if image_format == "pgm":
        height, width = pixels.shape
        stream.write(f"P5\n# CREATOR: amr map_file.py {resolution:.3f} m/pix\n"
                     f"{width} {height}\n255\n".encode("ascii"))
        stream.write(pixels.tobytes())
    else:
        Image.fromarray(pixels, mode="L").save(stream, format="PNG")


def _replace_atomically(path: Path, write) -> None:
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(temporary, "wb") as stream:
            write(stream)
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def _plain(value: Any) -> Any:
    """Tuples and numpy scalars as lists and floats, for yaml.safe_dump."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return value


__all__ = ["CONVERT_RESOLUTION", "MODES", "MapFile", "MapFileError", "cell_values",
           "map_from_yaml", "read_map", "trinary_pixels", "world_as_map", "write_map"]
