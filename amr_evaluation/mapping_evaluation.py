"""Mapping episodes in batches: worlds x seeds (x loop closure on/off) on local processes.

    specs = mapping_specs(["lab02", "corridor_loop"], seeds=range(5), duration=300.0)
    results = run_mapping_grid(specs, jobs=2)
    print(mapping_table(results))

Each result is MappingResult.to_dict() (without the estimate rows), or {"error": ...} for an
episode that failed or whose process died, so one bad world does not lose the others.
`scripts/evaluate.py --slam` is the command line (evaluate_main): its grid of worlds x starts x
profiles x seeds, on all cores or Ray, each episode within --episode-timeout.
"""
from __future__ import annotations

import json
import math
import re
import sys
import time
import traceback
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from amr_common.plugins.link_failure import failure_text
from amr_common.plugins.loader import DEFAULT_MAPPER, link_class
from amr_evaluation.episode import mapper_parameters
from amr_evaluation.executors import TaskLost, local_executor, run_tasks
from amr_evaluation.mapping_episode import AUTO_DRIFT, OdometryDrift, run_mapping_episode
from amr_sim.profiles import get_profile


@dataclass(frozen=True)
class MappingSpec:
    """One mapping episode to run (picklable)."""

    world: str
    seed: int
    duration: float = 300.0
    loop_closure: bool = True
    drift: OdometryDrift | str | None = AUTO_DRIFT
    profile: str = "turtlebot3_clean"
    start: Any = None  # a world's named start or [x, y, theta]; None: its first
    mapper_params: dict[str, Any] | None = None  # Mapper parameter overrides
    controller: str | None = None  # MODULE:CLASS of the explorer; None: the wall follower
    controller_params: tuple[tuple[str, Any], ...] = ()
    mapper: str | None = None  # MODULE:CLASS of the mapper; None: amr_mapping.mapper:Mapper
    world_frame: bool = False  # the map in the world's frame (run_mapping_episode)
    record: bool = False  # the result carries the map ("raster") and both trajectories


def mapping_specs(worlds: Iterable[str], seeds: Iterable[int], duration: float = 300.0,
                  loop_closure: Iterable[bool] = (True,), starts: dict[str, Any] | None = None,
                  drift: OdometryDrift | str | None = AUTO_DRIFT,
                  mapper_params: dict[str, Any] | None = None,
                  mapper: str | None = None) -> list[MappingSpec]:
    """Every world x loop-closure setting x seed; starts: world -> start for worlds without.

    mapper: MODULE:CLASS of an amr_common.plugins.interfaces.Mapper (None: the project's).
    """
    starts = starts or {}
    return [MappingSpec(world, int(seed), float(duration), bool(closure), drift,
                        start=starts.get(world), mapper_params=mapper_params, mapper=mapper)
            for world in worlds for closure in loop_closure for seed in seeds]


def run_mapping_spec(spec: MappingSpec) -> dict[str, Any]:
    """The episode's result dict, or the spec with an "error" (the worker must not die)."""
    try:
        result = run_mapping_episode(spec.world, start=spec.start, profile=spec.profile,
                                     seed=spec.seed, duration=spec.duration,
                                     loop_closure=spec.loop_closure, drift=spec.drift,
                                     mapper_params=spec.mapper_params, mapper=spec.mapper,
                                     controller=_controller(spec), record=spec.record,
                                     world_frame=spec.world_frame)
    except Exception as exc:  # noqa: BLE001 - reported per episode, the batch goes on
        return {**asdict(spec), "error": failure_text(exc), "traceback": traceback.format_exc()}
    return {**result.to_dict(), "raster": result.raster} if spec.record else result.to_dict()


def check_lidar_units(units: Iterable[tuple[str, int]], mapper: str | None = None) -> None:
    """Each simulated LiDAR unit (profile, seed) can be calibrated for the mapper; else ValueError.

    episode.mapper_parameters of each: tens of milliseconds, before anything runs, instead of
    every episode's error.
    """
    cls = link_class(mapper or DEFAULT_MAPPER, "mapper")
    for profile, seed in dict.fromkeys(units):
        mapper_parameters(get_profile(profile), cls, seed)


def _controller(spec: MappingSpec):
    """The spec's explorer, built as evaluate.py builds controllers, or None (the default)."""
    if spec.controller is None:
        return None
    from amr_common.plugins.loader import load_controller_class
    from amr_evaluation.episode import robot_parameters
    from amr_sim.profiles import get_profile
    controller_class = load_controller_class(spec.controller)
    params = {**robot_parameters(controller_class, get_profile(spec.profile)),
              **dict(spec.controller_params)}
    return controller_class(0.05, **params)  # the episode's dt


def run_mapping_grid(specs: list[MappingSpec], jobs: int | None = 2,
                     progress: Callable[[int, int, Any], None] | None = None,
                     executor=None) -> list[dict[str, Any]]:
    """Run the specs; results in spec order.

    On `executor` (amr_evaluation.executors, e.g. Ray's), else on `jobs` local processes.
    """
    def lost(spec: MappingSpec, loss: TaskLost) -> dict[str, Any]:
        return {**asdict(spec), "error": loss.error}

    if executor is None:
        executor = local_executor(jobs, len(specs))
    return run_tasks(run_mapping_spec, specs, executor, lost, progress,
                     preload=("amr_evaluation.mapping_episode",))


_COLUMNS = (("world", "{}"), ("start", "{}"), ("profile", "{}"), ("seed", "{}"),
            ("loop_closure", "{}"),
            ("trajectory_rmse_m", "{:.2f}", 100.0), ("trajectory_max_m", "{:.2f}", 100.0),
            ("odometry_max_error_m", "{:.1f}", 100.0), ("precision", "{:.1f}", 100.0),
            ("recall", "{:.1f}", 100.0), ("loop_closures", "{}"), ("keyframes", "{}"),
            ("update_ms_median", "{:.2f}"), ("loop_closure_ms_median", "{:.1f}"),
            ("loop_closure_ms_max", "{:.1f}"),
            ("cpu_real_time_factor", "{:.0f}"))
_HEADERS = ("world", "start", "profile", "seed", "loop closure", "RMSE cm", "max cm",
            "odometry max cm",
            "precision %", "recall %", "loop closures", "keyframes", "update ms (median)",
            "loop closure ms (median)", "loop closure ms (max)", "x real time (CPU)")


def mapping_table(results: list[dict[str, Any]]) -> str:
    """A markdown table with one row per episode (summary_rows gives the per-world view)."""
    lines = ["| " + " | ".join(_HEADERS) + " |", "|" + "---|" * len(_HEADERS)]
    for result in results:
        if "error" in result:
            lines.append(f"| {result['world']} | {result['start']} | {result['profile']} | "
                         f"{result['seed']} | {result['loop_closure']} | error: "
                         f"{result['error']} |")
            continue
        lines.append("| " + " | ".join(_cell(result, column) for column in _COLUMNS) + " |")
    return "\n".join(lines)


def summary_rows(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per mapper, world and loop-closure setting: mean and worst RMSE, max, precision, recall.

    Figures a mapper does not report (loop closures, their times) are NaN.
    """
    groups: dict[tuple[str, str, bool], list[dict[str, Any]]] = {}
    for result in results:
        if "error" not in result:
            key = (result.get("mapper", DEFAULT_MAPPER), result["world"], result["loop_closure"])
            groups.setdefault(key, []).append(result)
    rows = []
    for (mapper, world, closure), group in groups.items():
        def values(name):  # None (not reported) becomes NaN
            return np.array([g[name] for g in group], dtype=np.float64)
        rows.append({"mapper": mapper, "world": world, "loop_closure": closure,
                     "episodes": len(group),
                     "rmse_mean_m": float(values("trajectory_rmse_m").mean()),
                     "rmse_worst_m": float(values("trajectory_rmse_m").max()),
                     "max_worst_m": float(values("trajectory_max_m").max()),
                     "precision_worst": float(values("precision").min()),
                     "recall_worst": float(values("recall").min()),
                     "loop_closures_mean": float(values("loop_closures").mean()),
                     "update_ms_median": float(np.median(values("update_ms_median"))),
                     "loop_closure_ms_max": float(values("loop_closure_ms_max").max()),
                     "cpu_real_time_factor_min": float(values("cpu_real_time_factor").min())})
    return rows


def _cell(result: dict[str, Any], column: tuple) -> str:
    name, form = column[0], column[1]
    value = result.get(name)
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if len(column) > 2:
        value = value * column[2]
    return form.format(value)


def evaluate_main(specs, settings: dict[str, Any], mapper_params: dict[str, Any], out: Path,
                  executor=None, sheet: bool = True) -> int:
    """evaluate.py --slam: mapping episodes for evaluate.py's grid (EpisodeSpecs).

    Each episode maps in the world's frame; its map goes to out/maps/ (Nav2 map YAML + PGM:
    a --map or --world of later runs). Writes results.json (what the set ran, per world summary
    + one row per episode, the Mapper's statistics and the map's file included), results.csv
    and, with `sheet`, sheet.png (every episode's map under the true walls, with the true and
    SLAM trajectories) to `out`, prints the table; exit code 3 if an episode failed to run or
    its map could not be written, 1 if one collided, else 0.
    """
    controller = settings["controller"]
    mapper = settings.get("links", {}).get("mapper")
    mapping = [MappingSpec(s.world, s.seed, s.duration,
                           bool(mapper_params.get("loop_closure", True)), profile=s.profile,
                           start=list(s.start) if isinstance(s.start, tuple) else s.start,
                           mapper_params=dict(mapper_params) or None,
                           controller=controller, controller_params=s.params, mapper=mapper,
                           world_frame=True, record=True)
               for s in specs]
    described = f"mapper {mapper or DEFAULT_MAPPER}" + (f" {mapper_params}" if mapper_params
                                                        else "")
    print(f"evaluate: {len(mapping)} mapping episodes of {settings['duration']:g} s, "
          f"{described}", flush=True)
    started = time.monotonic()

    def progress(done: int, total: int, result: dict[str, Any]) -> None:
        text = f"{result['world']} seed {result['seed']}: ERROR {result['error']}" \
            if "error" in result else _summary_line(result)
        print(f"[{done}/{total}] {text}", flush=True)

    results = run_mapping_grid(mapping, jobs=settings["jobs"], progress=progress,
                               executor=executor)
    failed = sum("error" in r for r in results)
    collided = sum(r.get("collisions", 0) > 0 for r in results)
    out.mkdir(parents=True, exist_ok=True)
    unsaved = save_maps(results, out, mapper or DEFAULT_MAPPER)
    summary = {"kind": "mapping", "controller": controller,
               "links": settings.get("links_ran") or {"controller": controller,
                                                      "mapper": mapper or DEFAULT_MAPPER},
               "mapper": mapper or DEFAULT_MAPPER, "episodes": len(results), "failed": failed,
               "collided": collided, "maps_not_saved": unsaved,
               "wall_time_s": round(time.monotonic() - started, 1),
               "per_world": summary_rows(results)}
    rows = [{k: v for k, v in r.items() if k not in ("raster", "estimate", "trajectory")}
            for r in results]
    _write_results(out, summary, rows)
    if sheet:
        _draw_sheet(mapping, results, out / "sheet.png", described)
    print(mapping_table(results))
    print(f"evaluate: {len(results)} mapping episodes, {failed} failed, {collided} collided"
          + (f", {unsaved} map(s) NOT saved" if unsaved else "")
          + f", in {summary['wall_time_s']:.1f} s; results and maps in {out}")
    return 3 if failed or unsaved else 1 if collided else 0


def save_maps(results: list[dict[str, Any]], out: Path, mapper: str) -> int:
    """Each result's "raster" as out/maps/WORLD-START-PROFILE-seedN.yaml + .pgm (write_map).

    Sets each row's "map_file" (relative to `out`), or "map_error" with why it could not be
    written (also printed); returns how many could not.
    """
    from amr_common.world.map_file import write_map
    unsaved, used = 0, set()
    for result in results:
        if result.get("raster") is None:
            continue
        stem = _file_stem(result)
        while stem in used:  # the same episode twice in a grid
            stem += "_again"
        used.add(stem)
        truth = result.get("trajectory") or []
        extras = {"name": stem, "description": f"built by {mapper} in evaluate.py --slam "
                  f"({result['sim_time_s']:g} s, seed {result['seed']})"}
        if truth:  # where the robot started, in the world's frame (the map's too)
            extras["starts"] = {"slam_start": [float(v) for v in truth[0][1:4]]}
        try:
            write_map(result["raster"], out / "maps" / stem, "pgm", extras)
            result["map_file"] = f"maps/{stem}.yaml"
        except ValueError as exc:  # MapFileError: disk full, permissions, ...
            result["map_file"], result["map_error"] = None, str(exc)
            unsaved += 1
            print(f"evaluate: map NOT saved: {exc}", file=sys.stderr, flush=True)
    return unsaved


def _file_stem(result: dict[str, Any]) -> str:
    """WORLD-START-PROFILE-seedN with only letters, digits, '.', '_', ',' and '-'."""
    from amr_common.world.world import start_label
    text = (f"{result['world']}-{start_label(result['start'])}-{result['profile']}-seed"
            f"{result['seed']}")
    return re.sub(r"[^\w.,-]+", "_", text)


def _write_results(out: Path, summary: dict[str, Any], rows: list[dict[str, Any]]) -> None:
    """results.json (summary and rows) and results.csv (the rows' flat columns)."""
    import csv
    (out / "results.json").write_text(json.dumps({"summary": summary, "episodes": rows},
                                                 indent=1, default=float))
    with open(out / "results.csv", "w", newline="") as handle:
        keys = list(dict.fromkeys(k for r in rows for k in r
                                  if k not in ("statistics", "drift", "mapper_params",
                                               "traceback")))
        writer = csv.DictWriter(handle, fieldnames=keys, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)


def _draw_sheet(specs: list[MappingSpec], results: list[dict[str, Any]], path: Path,
                title: str) -> None:
    """sheet.png of the episodes that ran (each world loaded once)."""
    import textwrap

    from amr_common.world.world import World
    from amr_evaluation.mapping_plot import plot_mapping_sheet
    ran = [(spec.world, result) for spec, result in zip(specs, results) if "error" not in result]
    worlds = {source: World.load(source) for source in dict.fromkeys(s for s, _ in ran)}
    episodes = [(worlds[source], result) for source, result in ran]
    if episodes:
        sheet = plot_mapping_sheet(episodes, path, textwrap.shorten(title, width=150,
                                                                    placeholder=" ..."))
        print(f"evaluate: maps drawn in {sheet}")


def _summary_line(result: dict[str, Any]) -> str:
    return (f"{result['world']} / {result['start']} / {result['profile']} / seed "
            f"{result['seed']}: RMSE {100 * result['trajectory_rmse_m']:.2f} cm, max "
            f"{100 * result['trajectory_max_m']:.2f} cm, precision "
            f"{100 * result['precision']:.1f} %, recall {100 * result['recall']:.1f} %, "
            f"{_cell(result, ('loop_closures', '{}'))} loop closures, {result['collisions']} "
            "collisions")


__all__ = ["MappingSpec", "check_lidar_units", "evaluate_main", "mapping_specs",
           "mapping_table", "run_mapping_grid", "run_mapping_spec", "save_maps", "summary_rows"]
