#!/usr/bin/env python3
"""The SLAM round trip, headless: map each world, save the map, localize and navigate on it.

For every world x seed: 300 s of wall-following exploration map the TRUE world (the Mapper;
--profile, by default turtlebot3: the reality gap, the LiDAR calibrated); the map is saved as
Nav2 map files (OUT/WORLD-seedN.yaml + .pgm) and read back; then the simulator drives the
true world while the particle filter (global localization) and the planner work on the SLAM
map, from a named start to a named goal (amr_evaluation.map_round_trip). Prints one line per
episode and the summary; writes OUT/results.json.
Exit code: 0 no false localization, no collision and goals reached within 5 cm in >= 95 % of
the episodes (corridor_loop, exactly symmetric, left out of that share); 1 otherwise; 2 bad
options; 3 an episode failed to run; 130 after Ctrl-C or SIGTERM, 129 after SIGHUP (the terminal
closed): the maps of the episodes that ended are in OUT, no results.json.

  .venv/bin/python scripts/slam_round_trip.py --worlds all --seeds 0-4 --out out/round_trip
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from script_endings import interruptible, run_script  # noqa: E402

from cli_checks import OneLineArgumentParser, check_output_folder, number_argument  # noqa: E402


def parse_args(argv=None) -> argparse.Namespace:
    parser = OneLineArgumentParser(description=__doc__.split("\n\n")[0],
                                   formatter_class=argparse.RawDescriptionHelpFormatter,
                                   epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--worlds", default="all", help="comma-separated bundled world names, "
                        "or 'all' (default)")
    parser.add_argument("--seeds", default="0-4", help="seeds, e.g. 0,1 or 0-4 (default 0-4)")
    parser.add_argument("--map-duration", type=number_argument(float, 0.0, above=True),
                        default=300.0, help="simulated seconds of mapping (default 300)")
    parser.add_argument("--duration", type=number_argument(float, 0.0, above=True),
                        default=300.0, help="simulated seconds of navigation (default 300)")
    parser.add_argument("--profile", default="turtlebot3",
                        help="the simulated Burger (default turtlebot3: the reality gap at its "
                        "typical values, the LiDAR calibrated; turtlebot3_clean: without it)")
    parser.add_argument("--pf-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="particle filter parameter (default: the filter's own "
                        "defaults, as on the world)")
    parser.add_argument("--jobs", "-j", type=number_argument(int, 1), default=None,
                        help="worker processes (default: all cores)")
    parser.add_argument("--out", default="out/round_trip", help="maps and results.json here")
    args = parser.parse_args(argv)
    from amr_common.plugins.loader import PluginSpecError, parse_overrides
    from amr_common.world.world import World, WorldError, bundled_worlds
    from amr_evaluation.evaluation_config import parse_name_list, parse_seeds
    try:
        args.worlds = bundled_worlds() if args.worlds == "all" else parse_name_list(args.worlds)
        for world in args.worlds:
            World.load(world)
        args.seeds = parse_seeds(args.seeds)
        from amr_evaluation.mapping_evaluation import check_lidar_units
        check_lidar_units((args.profile, seed) for seed in args.seeds)  # (their calibration)
        args.out = check_output_folder(args.out, "--out")
        args.filter_params = parse_overrides(args.pf_param)
        if args.filter_params:
            from amr_localization.particle_filter_params import check_parameters
            check_parameters(args.filter_params)
    except (ValueError, WorldError, PluginSpecError) as exc:
        parser.error(str(exc))
    return args


def main(argv=None) -> int:
    return interruptible("slam_round_trip: interrupted", lambda: _round_trips(argv))


def _round_trips(argv) -> int:
    args = parse_args(argv)
    from amr_evaluation.map_round_trip import round_trip_line, round_trip_summary, run_round_trips
    params = args.filter_params
    print(f"slam_round_trip: {len(args.worlds) * len(args.seeds)} episodes, {args.profile}, "
          f"filter {params or 'defaults'}", flush=True)
    rows = run_round_trips(args.worlds, args.seeds, args.out, args.jobs, args.map_duration,
                           args.duration, params,
                           progress=lambda done, total, row: print(
                               f"[{done}/{total}] {round_trip_line(row)}", flush=True),
                           profile=args.profile)
    summary = round_trip_summary(rows)
    (args.out / "results.json").write_text(json.dumps(
        {"summary": summary, "profile": args.profile, "filter_params": params,
         "episodes": rows}, indent=1,
        default=float))
    print(json.dumps(summary, indent=1, default=float))
    if summary["failed"]:
        return 3
    return 0 if (summary["false_localizations"] == 0 and summary["collisions"] == 0
                 and summary["goal_share"] >= 0.95) else 1


if __name__ == "__main__":
    sys.exit(run_script(main))
