"""Batch localization episodes on a process pool, and their aggregate figures.

Batch localization episodes (worlds x starts x profiles x seeds, optional kidnapping) on a
process pool, and the aggregate figures that say whether the filter can be trusted.

`scripts/evaluate.py --localize` is the command line (evaluate_main). Each episode is
amr_evaluation.localization_episode.run_localization_episode, with the wall follower built as
evaluate.py builds it (its params file, -p overrides, the profile's LiDAR position).
"""
from __future__ import annotations

import math
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from amr_evaluation.evaluation_report import effects_block


@dataclass(frozen=True)
class LocalizationSpec:
    """One localization episode to run (picklable)."""

    world: str
    start: str | None = None
    profile: str = "ideal"
    seed: int = 0
    duration: float = 60.0
    kidnap: tuple[float, float, float, float] | None = None
    filter_params: tuple[tuple[str, Any], ...] = ()
    controller: str = "amr_control.wall_follower:WallFollower"
    controller_params: tuple[tuple[str, Any], ...] = ()
    map: str | None = None  # the filter's map (None: the world)
    localizer: str = "amr_localization.particle_filter:ParticleFilter"  # MODULE:CLASS

    @property
    def label(self) -> str:
        """A short name for logs: world[@map]/start/profile/seed[/kidnap@t]."""
        kidnap = "" if self.kidnap is None else f"/kidnap@{self.kidnap[0]:g}s"
        on_map = f"@{Path(self.map).stem}" if self.map else ""
        return (f"{self.world}{on_map}/{self.start or '-'}/{self.profile}/seed "
                f"{self.seed}{kidnap}")


@dataclass
class LocalizationOutcome:
    """The result of one spec, or the error that stopped it."""

    spec: LocalizationSpec
    result: Any = None
    error: str | None = None
    wall_time_s: float = 0.0
    extra: dict = field(default_factory=dict)


def kidnap_pose(world_name: str, start: str | None, at: float) -> tuple[float, ...] | None:
    """A kidnapping pose for `start` at time `at`.

    A kidnapping for `start`: at time `at`, to the world's next named start (turned by a
    quarter turn, so the view differs), or None if the world has a single start.
    """
    from amr_common.world.world import World
    world = World.load(world_name)
    names = list(world.starts)
    if len(names) < 2:
        return None
    current = names.index(start) if start in names else 0
    x, y, theta = world.starts[names[(current + 1) % len(names)]]
    return (float(at), x, y, math.remainder(theta + math.pi / 2.0, 2.0 * math.pi))


def run_one(spec: LocalizationSpec) -> LocalizationOutcome:
    """Run one episode in this process (an exception becomes the outcome's error)."""
    from amr_common.plugins.loader import load_controller_class
    from amr_evaluation.episode import robot_parameters
    from amr_evaluation.localization_episode import run_localization_episode
    from amr_sim.profiles import get_profile
    started = time.perf_counter()
    try:
        controller_class = load_controller_class(spec.controller)
        params = {**robot_parameters(controller_class, get_profile(spec.profile)),
                  **dict(spec.controller_params)}
        result = run_localization_episode(spec.world, spec.start, profile=spec.profile,
                                          seed=spec.seed, duration=spec.duration,
                                          kidnap=spec.kidnap,
                                          filter_params=dict(spec.filter_params),
                                          controller=controller_class(0.05, **params),
                                          record=False, map=spec.map,
                                          localizer=spec.localizer)
        return LocalizationOutcome(spec, result=result,
                                   wall_time_s=time.perf_counter() - started)
    except Exception as exc:  # one broken episode must not lose the others
        detail = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return LocalizationOutcome(spec, error=detail, wall_time_s=time.perf_counter() - started)


def lost_localization(spec: LocalizationSpec, lost) -> LocalizationOutcome:
    """The outcome of an episode whose process or node died (an executors.TaskLost)."""
    return LocalizationOutcome(spec, error=lost.error, wall_time_s=lost.wall_time_s)


def run_localization_specs(specs: Sequence[LocalizationSpec], jobs: int | None = None,
                           progress: Callable[[int, int, LocalizationOutcome], None] | None
                           = None, executor=None,
                           episode_timeout_s: float | None = None) -> list[LocalizationOutcome]:
    """Run every spec, results in spec order.

    On `executor` (amr_evaluation.executors, e.g. a RayExecutor), else on `jobs` local
    processes (None: all cores), each episode limited to `episode_timeout_s` of wall-clock
    time (None: episode_time_limit of the longest duration; 0: no limit).
    """
    from amr_evaluation.executors import episode_time_limit, local_executor, run_tasks
    specs = list(specs)
    if not specs:
        return []
    if executor is None:
        if episode_timeout_s is None:
            episode_timeout_s = episode_time_limit(max(spec.duration for spec in specs))
        executor = local_executor(max(int(jobs), 1) if jobs is not None else None, len(specs),
                                  episode_timeout_s)
    return run_tasks(run_one, specs, executor, lost_localization, progress,
                     preload=("amr_evaluation.localization_episode",))


def summarize(outcomes: Sequence[LocalizationOutcome], within_s: float = 30.0,
              relocalize_within_s: float = 30.0) -> dict[str, Any]:
    """Aggregate figures over the episodes that ran."""
    results = [o.result for o in outcomes if o.result is not None]
    times = [r.time_to_localized_s for r in results if r.time_to_localized_s is not None]
    errors = [r.tracking_error_mean_m for r in results if r.tracking_error_mean_m is not None]
    kidnapped = [r for r in results if r.kidnap is not None]
    reported = [r.loss_reported_after_s for r in kidnapped if r.loss_reported_after_s is not None]
    relocalized = [r for r in kidnapped if r.relocalized_after_s is not None and
                   r.relocalized_after_s <= relocalize_within_s]
    sim_time = sum(r.sim_time_s for r in results)
    wall = sum(r.wall_time_s for r in results)

    def pct(values, q):
        return float(np.percentile(values, q)) if values else None

    return {
        "episodes": len(outcomes), "failed": sum(o.error is not None for o in outcomes),
        "false_localizations": sum(r.false_localizations for r in results),
        "localized": len(times), f"localized_within_{within_s:g}s": sum(t <= within_s
                                                                        for t in times),
        "time_to_localized_median_s": pct(times, 50), "time_to_localized_p90_s": pct(times, 90),
        "tracking_error_mean_m": float(np.mean(errors)) if errors else None,
        "tracking_error_worst_mean_m": max(errors) if errors else None,
        "tracking_error_p95_max_m": max((r.tracking_error_p95_m for r in results
                                         if r.tracking_error_p95_m is not None), default=None),
        "tracking_error_max_m": max((r.tracking_error_max_m for r in results
                                     if r.tracking_error_max_m is not None), default=None),
        "heading_error_p95_max_deg": max((r.heading_error_p95_deg for r in results
                                          if r.heading_error_p95_deg is not None), default=None),
        "kidnapped": len(kidnapped), "loss_reported_max_s": max(reported, default=None),
        f"relocalized_within_{relocalize_within_s:g}s": len(relocalized),
        "real_time_factor": sim_time / wall if wall > 0 else None,
    }


def outcome_row(outcome: LocalizationOutcome) -> dict[str, Any]:
    """One table/CSV row: the spec and the metrics (no per-step data)."""
    spec, result = outcome.spec, outcome.result
    row: dict[str, Any] = {"world": spec.world, "start": spec.start, "profile": spec.profile,
                           "seed": spec.seed, "kidnap_s": spec.kidnap[0] if spec.kidnap else None}
    if spec.map:  # the filter's own map: its column (the world's map otherwise)
        row = {"world": spec.world, "map": spec.map, **row}
    if result is None:
        row["error"] = outcome.error
        return row
    data = result.to_dict()
    for key in ("time_to_localized_s", "distance_to_localized_m", "false_localizations",
                "false_localized_s", "tracking_error_mean_m", "tracking_error_p95_m",
                "tracking_error_max_m", "heading_error_p95_deg", "relocalization_times_s",
                "loss_reported_after_s", "relocalized_after_s", "global_searches",
                "particles_max", "particles_final", "collisions", "distance_m"):
        row[key] = data[key]
    row["real_time_factor"] = round(result.real_time_factor, 1)
    if data.get("effects"):  # the reality-gap effects used (drawn: randomized)
        row["effects"] = data["effects"]
    return row


_TABLE = [("world", "world", "{}"), ("start", "start", "{}"), ("profile", "profile", "{}"),
          ("seed", "seed", "{}"), ("localized_s", "time_to_localized_s", "{:.1f}"),
          ("dist_m", "distance_to_localized_m", "{:.2f}"),
          ("false", "false_localizations", "{}"),
          ("err_mean_cm", "tracking_error_mean_m", "{:.2f}"),
          ("err_p95_cm", "tracking_error_p95_m", "{:.2f}"),
          ("err_max_cm", "tracking_error_max_m", "{:.2f}"),
          ("hdg_p95_deg", "heading_error_p95_deg", "{:.2f}"),
          ("reloc", "relocalization_times_s", "{}"), ("loss_s", "loss_reported_after_s", "{:.2f}"),
          ("reloc_s", "relocalized_after_s", "{:.1f}"), ("rtf", "real_time_factor", "{:.0f}")]


def format_table(rows: Sequence[dict[str, Any]]) -> str:
    """Aligned text table of outcome rows (errors in cm, relocalizations counted).

    A map column follows the world's when the filter had its own map.
    """
    own_map = any(row.get("map") for row in rows)
    table = [_TABLE[0], ("map", "map", "{}"), *_TABLE[1:]] if own_map else _TABLE
    spec_keys = ["world", "map", "start", "profile", "seed"] if own_map else \
        ["world", "start", "profile", "seed"]
    lines = [[header for header, _, _ in table]]
    for row in rows:
        if "error" in row:
            lines.append([str(row.get(k)) for k in spec_keys] + [f"ERROR {row['error']}"])
            continue
        cells = []
        for _, key, fmt in table:
            value = row.get(key)
            if value is None:
                cells.append("-")
            elif key.endswith("_m") and key.startswith("tracking"):
                cells.append(fmt.format(100 * value))
            elif key == "relocalization_times_s":
                cells.append(str(len(value)))
            else:
                cells.append(fmt.format(value))
        lines.append(cells)
    widths = [max(len(line[i]) for line in lines if i < len(line)) for i in range(len(table))]
    return "\n".join(["  ".join(cell.ljust(w) for cell, w in zip(line, widths)).rstrip()
                      for line in lines] + effects_block(rows))


def evaluate_main(specs, settings: dict[str, Any], args, out: Path, executor=None) -> int:
    """evaluate.py --localize: localization episodes for evaluate.py's grid (EpisodeSpecs).

    Writes results.json (summary + rows) and results.csv to `out`, prints the table and the
    summary; exit code 1 if any episode declared a wrong pose localized, 3 if one failed.
    """
    import csv
    import json

    from amr_common.plugins.loader import parse_overrides
    kidnap_at = getattr(args, "kidnap_at", None)
    filter_params = tuple(sorted(parse_overrides(getattr(args, "pf_param", [])).items()))
    controller_params = tuple(sorted(settings["params"].items()))
    local = [LocalizationSpec(s.world, s.start, s.profile, s.seed, s.duration,
                              kidnap_pose(s.world, s.start, kidnap_at) if kidnap_at else None,
                              filter_params, settings["controller"], controller_params, s.map,
                              s.localizer)
             for s in specs]
    print(f"evaluate: {len(local)} localization episodes of {settings['duration']:g} s, "
          f"localizer {local[0].localizer if local else '-'}"
          + (f", kidnapped at {kidnap_at:g} s" if kidnap_at else "")
          + (f", the filter on map {settings['map']}" if settings.get("map") else ""),
          flush=True)
    started = time.monotonic()

    def progress(done, total, outcome):
        text = outcome.result.summary() if outcome.result is not None else \
            f"{outcome.spec.label}: ERROR {outcome.error}"
        print(f"[{done}/{total}] {text}", flush=True)

    outcomes = run_localization_specs(local, jobs=settings["jobs"], progress=progress,
                                      executor=executor)
    summary = summarize(outcomes)
    summary["wall_time_s"] = round(time.monotonic() - started, 1)
    summary["map"] = settings.get("map")  # the filter's map; None: each world's own
    summary["localizer"] = local[0].localizer if local else None
    # What the set ran, for compare.py: every link, the project's included.
    summary.update(kind="localization", controller=settings["controller"],
                   links=settings.get("links_ran") or {"controller": settings["controller"],
                                                       "localizer": summary["localizer"]})
    rows = [outcome_row(o) for o in outcomes]
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps({"summary": summary, "episodes": rows},
                                                 indent=1, default=float))
    with open(out / "results.csv", "w", newline="") as handle:
        keys = list(dict.fromkeys(k for row in rows for k in row))
        writer = csv.DictWriter(handle, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    print(format_table(rows))
    print(json.dumps(summary, indent=1, default=float))
    print(f"evaluate: results in {out}")
    if summary["failed"]:
        return 3
    return 1 if summary["false_localizations"] else 0
