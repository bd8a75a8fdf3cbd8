"""Mapping episodes in batches: worlds x seeds (x loop closure on/off) on local processes.

    specs = mapping_specs(["lab02", "corridor_loop"], seeds=range(5), duration=300.0)
    results = run_mapping_grid(specs, jobs=2)
    print(mapping_table(results))

Each result is MappingResult.to_dict() (without the estimate rows), or {"error": ...} for an
episode that failed or whose process died, so one bad world does not lose the others.
"""
from __future__ import annotations

import math
import traceback
from dataclasses import asdict, dataclass
from typing import Any, Callable, Iterable

import numpy as np

from amr_evaluation.executors import TaskLost, local_executor, run_tasks
from amr_evaluation.mapping_episode import TYPICAL_DRIFT, OdometryDrift, run_mapping_episode


@dataclass(frozen=True)
class MappingSpec:
    """One mapping episode to run (picklable)."""

    world: str
    seed: int
    duration: float = 300.0
    loop_closure: bool = True
    drift: OdometryDrift | None = TYPICAL_DRIFT
    profile: str = "turtlebot3"
    start: Any = None  # a world's named start or [x, y, theta]; None: its first
    mapper_params: dict[str, Any] | None = None  # Mapper parameter overrides


def mapping_specs(worlds: Iterable[str], seeds: Iterable[int], duration: float = 300.0,
                  loop_closure: Iterable[bool] = (True,), starts: dict[str, Any] | None = None,
                  drift: OdometryDrift | None = TYPICAL_DRIFT,
                  mapper_params: dict[str, Any] | None = None) -> list[MappingSpec]:
    """Every world x loop-closure setting x seed; starts: world -> start for worlds without."""
    starts = starts or {}
    return [MappingSpec(world, int(seed), float(duration), bool(closure), drift,
                        start=starts.get(world), mapper_params=mapper_params)
            for world in worlds for closure in loop_closure for seed in seeds]


def run_mapping_spec(spec: MappingSpec) -> dict[str, Any]:
    """The episode's result dict, or the spec with an "error" (the worker must not die)."""
    try:
        result = run_mapping_episode(spec.world, start=spec.start, profile=spec.profile,
                                     seed=spec.seed, duration=spec.duration,
                                     loop_closure=spec.loop_closure, drift=spec.drift,
                                     mapper_params=spec.mapper_params)
    except Exception as exc:  # noqa: BLE001 - reported per episode, the batch goes on
        return {**asdict(spec), "error": f"{type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc()}
    return result.to_dict()


def run_mapping_grid(specs: list[MappingSpec], jobs: int | None = 2,
                     progress: Callable[[int, int, Any], None] | None = None
                     ) -> list[dict[str, Any]]:
    """Run the specs on `jobs` local processes; results in spec order."""
    def lost(spec: MappingSpec, loss: TaskLost) -> dict[str, Any]:
        return {**asdict(spec), "error": loss.error}

    return run_tasks(run_mapping_spec, specs, local_executor(jobs, len(specs)), lost, progress,
                     preload=("amr_evaluation.mapping_episode",))


_COLUMNS = (("world", "{}"), ("seed", "{}"), ("loop_closure", "{}"),
            ("trajectory_rmse_m", "{:.2f}", 100.0), ("trajectory_max_m", "{:.2f}", 100.0),
            ("odometry_max_error_m", "{:.1f}", 100.0), ("precision", "{:.1f}", 100.0),
            ("recall", "{:.1f}", 100.0), ("loop_closures", "{}"), ("keyframes", "{}"),
            ("update_ms_median", "{:.2f}"), ("loop_closure_ms_median", "{:.1f}"),
            ("loop_closure_ms_max", "{:.1f}"),
            ("cpu_real_time_factor", "{:.0f}"))
_HEADERS = ("world", "seed", "loop closure", "RMSE cm", "max cm", "odometry max cm",
            "precision %", "recall %", "loop closures", "keyframes", "update ms (median)",
            "loop closure ms (median)", "loop closure ms (max)", "x real time (CPU)")


def mapping_table(results: list[dict[str, Any]]) -> str:
    """A markdown table with one row per episode (summary_rows gives the per-world view)."""
    lines = ["| " + " | ".join(_HEADERS) + " |", "|" + "---|" * len(_HEADERS)]
    for result in results:
        if "error" in result:
            lines.append(f"| {result['world']} | {result['seed']} | {result['loop_closure']} | "
                         f"error: {result['error']} |")
            continue
        lines.append("| " + " | ".join(_cell(result, column) for column in _COLUMNS) + " |")
    return "\n".join(lines)


def summary_rows(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per world and loop-closure setting: mean and worst RMSE, max, precision, recall."""
    groups: dict[tuple[str, bool], list[dict[str, Any]]] = {}
    for result in results:
        if "error" not in result:
            groups.setdefault((result["world"], result["loop_closure"]), []).append(result)
    rows = []
    for (world, closure), group in groups.items():
        def values(name):
            return np.array([g[name] for g in group], dtype=np.float64)
        rows.append({"world": world, "loop_closure": closure, "episodes": len(group),
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


__all__ = ["MappingSpec", "mapping_specs", "mapping_table", "run_mapping_grid",
           "run_mapping_spec", "summary_rows"]
