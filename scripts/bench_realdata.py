#!/usr/bin/env python3
r"""SLAM on a real log: every scan and its odometry pose into the Mapper, the field's measures out.

    DATA=../shared/data/realdata
    .venv/bin/python scripts/bench_realdata.py $DATA/intel-prefix.clf \
        --relations $DATA/intel.relations --map-out out/intel --plot out/intel.png

Reads a CARMEN log (amr_tools.carmen_log: FLASER, ROBOTLASER1), feeds each scan in file order
with the odometry pose of its line and its own stamp to amr_mapping.mapper.Mapper with only the
sensor's facts set (`--resolution` 0.05 m, `--max-range` 50 m: the LiDAR's; the laser's place
from the log's PARAM robot_frontlaser_offset) and every other parameter at its default
(`--param NAME:=VALUE` to change one), then prints:
- the relation error (Kuemmerle et al. 2009, with --relations; amr_evaluation.relation_error)
  of the final, optimized trajectory (a pose for every scan, at the scan's stamp), and of the
  raw odometry for comparison;
- the map's self-consistency: share of the returns within 20 m that, drawn from the
  trajectory, end within 10 cm of an OCCUPIED cell of the map;
- how many scans got a pose (every scan should), the Mapper's counts (matched, odometry only,
  out of order, loop closures);
- speed: CPU seconds of the mapping (this process: the Mapper's updates and the final map) and
  the log's duration per CPU second ("x real time"), median and p99 of one update (CPU ms).
`--map-out DIR` writes DIR/map.yaml + map.pgm (Nav2 map files); `--plot F.png` the map with the
trajectory and the odometry's path beside it; `--report F.json` the figures and the trajectory.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

SENSOR_FACTS = {"resolution_m": 0.05, "max_range_m": 50.0}


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("log", type=Path, help="CARMEN log (.clf / .log)")
    parser.add_argument("--relations", type=Path, help="Kuemmerle relations file "
                        "(t1 t2 x y z roll pitch yaw)")
    parser.add_argument("--resolution", type=float, default=SENSOR_FACTS["resolution_m"],
                        help="map cell size [m] (default 0.05)")
    parser.add_argument("--max-range", type=float, default=SENSOR_FACTS["max_range_m"],
                        help="returns used up to this range [m] (default 50)")
    parser.add_argument("--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="a Mapper parameter (repeatable; default: every other at its "
                        "default)")
    parser.add_argument("--scans", type=int, default=None, help="only the first N scans")
    parser.add_argument("--map-out", type=Path, help="write DIR/map.yaml + map.pgm")
    parser.add_argument("--plot", type=Path, help="PNG of the map with the trajectory")
    parser.add_argument("--report", type=Path, help="JSON of the figures and the trajectory")
    parser.add_argument("--quiet", action="store_true", help="no progress line")
    return parser.parse_args(argv)


def mapper_params(args: argparse.Namespace, lidar_offset_x_m: float) -> dict:
    """The sensor's facts, the laser's place from the log, then --param."""
    from link_options import check_mapper_params
    params = {"resolution_m": args.resolution, "max_range_m": args.max_range,
              "lidar_offset_x_m": lidar_offset_x_m}
    params.update(check_mapper_params(args.param, None))
    return params


def read_scans(args: argparse.Namespace) -> list:
    """The log's scans (the first --scans), its malformed lines printed; ValueError if none."""
    from amr_tools.carmen_log import read_carmen_log
    log = read_carmen_log(args.log)
    scans = log.scans[:args.scans] if args.scans else log.scans
    if not scans:
        raise ValueError(f"{args.log}: no FLASER or ROBOTLASER1 scan in the log")
    for problem in log.problems[:5]:
        print(f"left out: {problem}")
    if len(log.problems) > 5:
        print(f"... {len(log.problems)} malformed lines left out in all")
    stamps = np.array([s.stamp for s in scans])
    print(f"{args.log.name}: {len(scans)} scans over {np.ptp(stamps):.1f} s, "
          f"{int(np.count_nonzero(np.diff(stamps) <= 0))} stamped at or before the one before")
    return scans


def map_scans(args: argparse.Namespace, scans: list):
    """(mapper, map raster, CPU s of each update, CPU s in all, CPU s of the map, scans mapped).

    Ctrl-C stops the mapping: the figures are then of the scans mapped so far.
    """
    from amr_mapping.mapper import Mapper
    mapper = Mapper(mapper_params(args, scans[0].lidar_offset_x_m))
    update_cpu = []
    started = time.process_time()
    try:
        for k, scan in enumerate(scans):
            before = time.process_time()
            mapper.update(scan, scan.odometry, scan.stamp)
            update_cpu.append(time.process_time() - before)
            if not args.quiet and (k % 500 == 0 or k == len(scans) - 1):
                print(f"\r{k + 1}/{len(scans)} scans, {time.process_time() - started:.1f} s CPU",
                      end="", file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        print(f"\ninterrupted: the figures of the first {len(update_cpu)} scans",
              file=sys.stderr)
    map_started = time.process_time()
    raster = mapper.occupancy_raster()
    finished = time.process_time()
    if not args.quiet:
        print(file=sys.stderr)
    return (mapper, raster, np.array(update_cpu), finished - started, finished - map_started,
            len(update_cpu))


def measure(args: argparse.Namespace, scans: list, mapper, raster, update_cpu: np.ndarray,
            cpu: float, map_cpu: float, relations: np.ndarray | None) -> dict:
    """The figures of the run (printed too); relations: read_relations' rows, or None."""
    from amr_evaluation.relation_error import relation_errors, self_consistency
    trajectory, stats = mapper.trajectory(), mapper.statistics()
    stamps = np.array([s.stamp for s in scans])
    duration = float(np.ptp(stamps))
    figures: dict = {
        "log": str(args.log), "scans": len(scans), "duration_s": duration,
        "scans_with_pose": len(trajectory), "cpu_s": cpu, "map_cpu_s": map_cpu,
        "x_real_time": duration / cpu if cpu > 0 else math.inf,
        "update_cpu_ms": {"median": 1e3 * float(np.median(update_cpu)),
                          "p99": 1e3 * float(np.percentile(update_cpu, 99)),
                          "max": 1e3 * float(update_cpu.max())},
        "mapper": {key: stats[key] for key in (
            "updates", "matched", "odometry_only", "out_of_order", "odometry_jumps",
            "search_retries", "keyframes", "loop_attempts", "loop_closures", "rejected")
            if key in stats}}
    print(f"scans with a pose: {len(trajectory)} of {len(scans)}; "
          f"mapper: {json.dumps(figures['mapper'])}")
    if relations is not None:
        raw = relation_errors(stamps, np.array([s.odometry for s in scans]), relations)
        slam = relation_errors(trajectory[:, 0], trajectory[:, 1:4], relations)
        figures["relation_error"] = slam.as_dict()
        figures["odometry_relation_error"] = raw.as_dict()
        t2, r2 = slam.translation_squared, slam.rotation_squared
        print(f"relation error (SLAM):     {slam.summary()}; squared {t2[0]:.5f} +- "
              f"{t2[1]:.5f} m^2, {r2[0]:.3f} +- {r2[1]:.3f} deg^2")
        print(f"relation error (odometry): {raw.summary()}")
    if len(trajectory) == len(scans):
        figures["self_consistency"] = share = self_consistency(
            raster, trajectory[:, 1:4], scans, scans[0].lidar_offset_x_m)
        print(f"self-consistency: {100 * share:.1f} % of the returns within 20 m end within "
              "10 cm of an occupied cell")
    timing = figures["update_cpu_ms"]
    print(f"CPU {cpu:.1f} s for {duration:.1f} s of log: {figures['x_real_time']:.1f}x real "
          f"time per CPU second (map {map_cpu:.2f} s); update median {timing['median']:.2f} "
          f"ms, p99 {timing['p99']:.1f} ms, max {timing['max']:.0f} ms")
    return figures


def write_outputs(args: argparse.Namespace, scans: list, raster, trajectory: np.ndarray,
                  figures: dict) -> None:
    """--map-out, --plot and --report."""
    if args.map_out:
        from amr_common.world.map_file import write_map
        yaml_path, _ = write_map(raster, args.map_out / "map")
        print(f"map: {yaml_path}")
    if args.plot:
        from amr_evaluation.mapping_plot import plot_map_trajectory
        title = f"{args.log.name}: {len(scans)} scans"
        if "relation_error" in figures:
            error = figures["relation_error"]
            title += (f"; relation error {error['translation_m'][0]:.4f} m, "
                      f"{error['rotation_deg'][0]:.3f} deg")
        path = plot_map_trajectory(raster, trajectory, args.plot,
                                   np.array([s.odometry for s in scans]), title)
        print(f"plot: {path}")
    if args.report:
        args.report.parent.mkdir(parents=True, exist_ok=True)
        args.report.write_text(json.dumps({**figures, "trajectory": trajectory.tolist()}))
        print(f"report: {args.report}")


def run(args: argparse.Namespace) -> dict:
    """Map the log; the figures (also printed)."""
    from amr_evaluation.relation_error import read_relations
    relations = read_relations(args.relations) if args.relations else None  # before the work
    scans = read_scans(args)
    mapper, raster, update_cpu, cpu, map_cpu, mapped = map_scans(args, scans)
    scans = scans[:mapped]
    figures = measure(args, scans, mapper, raster, update_cpu, cpu, map_cpu, relations)
    write_outputs(args, scans, raster, mapper.trajectory(), figures)
    return figures


def main(argv: list[str] | None = None) -> int:
    """Entry point."""
    args = parse_args(argv)
    from amr_tools.carmen_log import CarmenLogError
    try:
        run(args)
    except (CarmenLogError, ValueError) as exc:
        print(f"bench_realdata: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\nbench_realdata: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
