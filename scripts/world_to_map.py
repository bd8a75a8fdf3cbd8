#!/usr/bin/env python3
"""Write any world as a Nav2 map (map_server's YAML + PGM), for Nav2 users and for `--world`.

    .venv/bin/python scripts/world_to_map.py lab02 -o maps/lab02   # maps/lab02.yaml + .pgm
    .venv/bin/python scripts/world_to_map.py course_map.json --resolution 0.05 --format png

WORLD is a bundled world name, a world YAML, the course's map JSON or a map YAML. The map holds
the world's occupancy grid at --resolution (default 0.02 m: this project's SLAM and planner cell;
a wall lands within half a cell of its place, so 5 cm, slam_toolbox's default, narrows a 0.4 m
corridor by 5 cm), walls occupied, the outside unknown, with the world's name, starts, goals and
coverage grid as extra keys that Nav2's map_server ignores. `World.load` and every `--world`
option read the result. Bad input: one line on stderr, exit code 2, nothing written.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from amr_common.world.map_file import CONVERT_RESOLUTION, world_as_map, write_map  # noqa: E402
from amr_common.world.world import World  # noqa: E402
from cli_checks import OneLineArgumentParser  # noqa: E402


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = OneLineArgumentParser(prog="world_to_map.py", description=__doc__.split("\n\n")[0],
                                   formatter_class=argparse.RawDescriptionHelpFormatter,
                                   epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("world", help="bundled world name, world YAML, course map JSON or map "
                                      "YAML")
    parser.add_argument("-o", "--output", help="path prefix of the two files (PREFIX.yaml and "
                                               "PREFIX.pgm/.png; default: the world's name in "
                                               "the current directory); an existing folder "
                                               "(or a path ending in '/'): the files go into "
                                               "it, named after the world")
    parser.add_argument("--resolution", type=float, default=CONVERT_RESOLUTION,
                        help=f"cell size in metres (default {CONVERT_RESOLUTION})")
    parser.add_argument("--format", choices=("pgm", "png"), default="pgm",
                        help="image format (default pgm, as map_saver)")
    return parser.parse_args(argv)


def output_prefix(output: str | None, name: str) -> Path:
    """The files' path prefix: -o as given, inside it when it is a folder, else `name`."""
    if not output:
        return Path(name)
    prefix = Path(output).expanduser()
    if prefix.is_dir() or output.endswith(("/", os.sep)):
        return prefix / name
    return prefix


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        if not 0.005 <= args.resolution <= 1.0:  # also refuses NaN
            raise ValueError(f"--resolution must be in [0.005, 1] m, got {args.resolution!r}")
        world = World.load(args.world)
        raster, extras = world_as_map(world, args.resolution)
        yaml_path, image_path = write_map(raster, output_prefix(args.output, world.name),
                                          args.format, extras)
    except ValueError as exc:  # WorldError, MapFileError, GridTooLargeError
        print(f"world_to_map: {exc}", file=sys.stderr)
        return 2
    rows, cols = raster.values.shape
    print(f"wrote {yaml_path} and {image_path}: {cols} x {rows} cells of {raster.resolution:g} m, "
          f"{len(extras.get('starts', {}))} start(s), {len(extras.get('goals', {}))} goal(s)")
    return 0


if __name__ == "__main__":
    from script_endings import run_script  # a closed output loses nothing
    sys.exit(run_script(main))
