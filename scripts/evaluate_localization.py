#!/usr/bin/env python3
"""Sweep the particle filter over worlds, starts, profiles and seeds.

Sweep the particle filter over worlds x starts x profiles x seeds (optionally kidnapped),
headless, on all cores: the figures of the README's "Localize" section.

Each episode runs the simulator, the wall follower (exploring on) and the particle filter with
the same classes as the ROS nodes (amr_evaluation.localization_episode). Prints one row per
episode and the aggregates; --out writes results.json and results.csv.
Exit code 1 if any episode declared a wrong pose localized (error > 10 cm or 10 degrees).

Examples:
  .venv/bin/python scripts/evaluate_localization.py --worlds all --seeds 0-4 --duration 60
  .venv/bin/python scripts/evaluate_localization.py --worlds twin_maze --seeds 0-9 --kidnap-at 25
  .venv/bin/python scripts/evaluate_localization.py --worlds lab02 -p beams:=30
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from amr_common.controller_loader import parse_overrides  # noqa: E402
from amr_common.world import World, bundled_worlds  # noqa: E402
from amr_evaluation.evaluation import parse_name_list, parse_seeds  # noqa: E402
from amr_evaluation.localization_evaluation import (  # noqa: E402
    LocalizationSpec,
    kidnap_pose,
    outcome_row,
    run_localization_specs,
    summarize,
)


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--worlds", default="all", help="comma-separated worlds or 'all'")
    parser.add_argument("--starts", default="all", help="'all' or comma-separated start names")
    parser.add_argument("--profiles", default="ideal,turtlebot3")
    parser.add_argument("--seeds", default="0-2", help="e.g. 0,1,2 or 0-9")
    parser.add_argument("--duration", type=float, default=60.0, help="simulated s per episode")
    parser.add_argument("--kidnap-at", type=float, default=None, help="teleport the robot at "
                        "this simulated time to the world's next named start, turned 90 deg")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="particle filter parameter override (repeatable)")
    parser.add_argument("--jobs", "-j", type=int, default=None)
    parser.add_argument("--out", default=None, help="folder for results.json / results.csv")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    worlds = parse_name_list(args.worlds)
    if worlds == ["all"]:
        worlds = bundled_worlds()
    params = tuple(sorted(parse_overrides(args.param).items()))
    specs = []
    for name in worlds:
        world = World.load(name)
        starts = list(world.starts) if args.starts == "all" else \
            [s for s in parse_name_list(args.starts) if s in world.starts]
        for start in starts:
            kidnap = kidnap_pose(name, start, args.kidnap_at) if args.kidnap_at else None
            for profile in parse_name_list(args.profiles):
                for seed in parse_seeds(args.seeds):
                    specs.append(LocalizationSpec(name, start, profile, seed, args.duration,
                                                  kidnap, params))
    print(f"evaluate_localization: {len(specs)} episodes of {args.duration:g} s", flush=True)
    started = time.monotonic()

    def progress(done, total, outcome):
        if outcome.result is not None:
            print(f"[{done}/{total}] {outcome.result.summary()}", flush=True)
        else:
            print(f"[{done}/{total}] {outcome.spec.label}: ERROR {outcome.error}", flush=True)

    outcomes = run_localization_specs(specs, jobs=args.jobs, progress=progress)
    summary = summarize(outcomes)
    summary["wall_time_s"] = round(time.monotonic() - started, 1)
    print(json.dumps(summary, indent=1))
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        rows = [outcome_row(o) for o in outcomes]
        (out / "results.json").write_text(json.dumps({"summary": summary, "episodes": rows},
                                                     indent=1))
        with open(out / "results.csv", "w", newline="") as handle:
            keys = sorted({k for row in rows for k in row})
            writer = csv.DictWriter(handle, fieldnames=keys)
            writer.writeheader()
            writer.writerows(rows)
        print(f"evaluate_localization: results in {out}")
    return 1 if summary["false_localizations"] else 0


if __name__ == "__main__":
    sys.exit(main())
