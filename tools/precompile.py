#!/usr/bin/env python3
"""Compile the project's numba kernels at set-up, so that the first run is as fast as the next.

numba compiles a kernel on its first call and caches the machine code beside its source
(`__pycache__/*.nbi`, `*.nbc`: amr_common/jit.py asks for cache=True). Without this step a
newcomer's first `make run` spent ~15 s compiling. The kernels are compiled by what calls them,
with the argument types they get there: short headless episodes of every kind (wall following
on both sensor profiles, the particle filter's global localization, navigation with both
planner algorithms and the pure pursuit, mapping, the reality-gap profiles, and wall following
in a Nav2 map world with a SLAM map's speckles, which is ray-marched through its cells, and in a
world with movers) run the same kernels as the ROS nodes.

The project's old cache files are removed first: numba checks only the source file of the
kernel it loads, not the files of the kernels that one calls, so after an edit an outdated one
could survive. The Makefile runs this when a kernel's source changed (its stamp depends on
every file that compiles kernels), after the dependencies and messages are installed.

Usage:
  .venv/bin/python tools/precompile.py           # remove the cache files, compile, report
  .venv/bin/python tools/precompile.py --check   # and exit 1 if a kernel stayed uncompiled
  python3 tools/precompile.py --sources          # the files the Makefile's stamp depends on
"""
from __future__ import annotations

import argparse
import importlib
import re
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(REPO))

PACKAGES = ("amr_common", "amr_sim", "amr_control", "amr_localization", "amr_planning",
            "amr_mapping")
CACHE_SUFFIXES = (".nbi", ".nbc")


def kernel_sources(repo: Path = REPO) -> list[Path]:
    """The project's Python files that compile kernels (they use amr_common.jit)."""
    return sorted(path for package in PACKAGES for path in (repo / package).rglob("*.py")
                  if "__pycache__" not in path.parts
                  and "amr_common.jit import" in path.read_text(encoding="utf-8"))


def stamp_sources(repo: Path = REPO) -> list[Path]:
    """What the compiled kernels are made of (the files the Makefile's stamp depends on).

    Their files, the project modules those import (constants such as the robot's radius are
    compiled in), jit.py and this file.
    """
    found = set(kernel_sources(repo))
    for path in list(found):
        text = path.read_text(encoding="utf-8")
        for module in re.findall(r"^(?:from|import) (amr_\w+(?:\.\w+)*)", text, re.MULTILINE):
            candidate = repo.joinpath(*module.split(".")).with_suffix(".py")
            if candidate.is_file():
                found.add(candidate)
    return sorted({*found, repo / "amr_common" / "jit.py", Path(__file__).resolve()})


def cache_files(repo: Path = REPO) -> list[Path]:
    """Numba's cache files of the project's kernels."""
    return sorted(path for package in PACKAGES for path in (repo / package).rglob("*")
                  if path.suffix in CACHE_SUFFIXES and path.parent.name == "__pycache__")


def kernels(repo: Path = REPO) -> dict[str, object]:
    """Every numba kernel the project defines: 'module.name' -> its dispatcher."""
    from numba.core.dispatcher import Dispatcher
    found: dict[str, object] = {}
    for path in kernel_sources(repo):
        name = ".".join(path.relative_to(repo).with_suffix("").parts)
        module = importlib.import_module(name)
        for attribute, value in vars(module).items():
            if isinstance(value, Dispatcher) and value.py_func.__module__ == name:
                found[f"{name}.{attribute}"] = value
    return found


def speckled_map_world():
    """lab02 as a 2 cm Nav2 map with a SLAM map's speckles.

    A map world with walls enough to be ray-marched and kept in buckets (World.march_grid,
    World.wall_grid: the simulator's contacts and the clearances through the buckets).
    """
    import numpy as np

    from amr_common.world.map_export import world_as_map
    from amr_common.world.map_raster import FREE, OCCUPIED, Raster
    from amr_common.world.world import BUCKETS_ABOVE_SEGMENTS, MARCH_ABOVE_SEGMENTS, World
    lab02 = World.load("lab02")
    raster, extras = world_as_map(lab02)
    values = raster.values.copy()
    xs, ys = raster.centres()
    start_x, start_y, _ = lab02.starts["outer"]
    far = np.hypot(xs - start_x, ys - start_y) > 0.3
    speckles = (values == FREE) & far & (np.arange(values.size).reshape(values.shape) % 17 == 0)
    values[speckles] = OCCUPIED
    world = World.from_raster(Raster(values, raster.resolution, raster.origin), name="lab02",
                              starts={"outer": lab02.starts["outer"]})
    assert len(world.segments) > max(MARCH_ABOVE_SEGMENTS, BUCKETS_ABOVE_SEGMENTS)
    assert world.march_grid is not None and world.wall_grid is not None
    return world


def warm_up() -> None:
    """Run what calls every kernel: short headless episodes of each kind."""
    from amr_evaluation.episode import run_episode
    from amr_evaluation.localization_episode import run_localization_episode
    from amr_evaluation.mapping_episode import run_mapping_episode
    from amr_evaluation.navigation_episode import run_navigation_episode
    for profile, algorithm in (("ideal", "astar"), ("turtlebot3_clean", "wavefront")):
        run_episode("lab02", "outer", profile=profile, duration=3.0, record_trajectory=False)
        run_navigation_episode("lab02", "outer", "inner_far", profile=profile, duration=3.0,
                               pose_source="truth", record_trajectory=False,
                               planner_params={"algorithm": algorithm})
        run_localization_episode("twin_maze_small", None, profile=profile, duration=3.0,
                                 record=False)
    run_mapping_episode("lab02", "outer", profile="turtlebot3_clean", duration=3.0)
    for profile in ("turtlebot3", "turtlebot3_lds02"):  # the reality gap's kernels
        run_episode("lab02", "outer", profile=profile, duration=1.0, record_trajectory=False)
        run_localization_episode("twin_maze_small", None, profile=profile, duration=1.0,
                                 record=False)  # the filter's LDS models and de-skew
    run_mapping_episode("lab02", "outer", profile="turtlebot3", duration=2.0)  # the smoothing
    map_world = speckled_map_world()
    run_episode(map_world, "outer", profile="ideal", duration=1.0, record_trajectory=False)
    run_localization_episode(map_world, "outer", profile="ideal", duration=1.0, record=False)
    people = REPO / "evaluations" / "worlds" / "room_people.yaml"  # movers: walked, scanned
    for profile in ("ideal", "turtlebot3"):
        run_episode(str(people), "middle", profile=profile, duration=1.0, record_trajectory=False)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="exit 1 if a kernel stayed uncompiled (the tests use it)")
    parser.add_argument("--sources", action="store_true",
                        help="print the files the compiled kernels depend on (relative paths; "
                        "no import: any Python runs it)")
    args = parser.parse_args(argv)
    if args.sources:
        print(" ".join(str(path.relative_to(REPO)) for path in stamp_sources()))
        return 0
    started = time.perf_counter()
    old = cache_files()
    for path in old:
        path.unlink(missing_ok=True)
    warm_up()
    compiled = kernels()
    missing = sorted(name for name, dispatcher in compiled.items()
                     if not dispatcher.signatures)
    print(f"precompile: {len(compiled) - len(missing)} of {len(compiled)} numba kernels "
          f"compiled and cached in {time.perf_counter() - started:.1f} s ({len(old)} old "
          "cache files removed)")
    if missing:
        print(f"precompile: not called by the warm-up (compiled on first use): "
              f"{', '.join(missing)}", file=sys.stderr)
        return 1 if args.check else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
