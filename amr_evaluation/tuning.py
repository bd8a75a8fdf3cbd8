"""Parameter search over an episode set with Ray Tune; the best values as a ROS params file.

scripts/tune.py is the command line. A trial is one parameter set: it runs every episode of the
set (amr_evaluation.evaluation.run_one, summaries only) one after the other on one CPU (in a
worker process of the trial: a hanging or crashing controller is its episode's error), and
scores them with the objective; trials run in parallel on the Ray cluster's CPUs.

Search space, one `NAME=SPEC` per parameter:
- `kp=4,8,12`: these values (grid: each one; random and optuna: a choice among them);
- `wall_distance_m=0.15:0.25:5`: 5 evenly spaced values from 0.15 to 0.25, the same way;
- `wall_distance_m=0.15:0.25`: a continuous range (random and optuna only; an integer
  parameter samples integers).
Values are typed like -p NAME:=VALUE and checked against the controller's
`parameter_descriptions()` (a decimal parameter takes integers and stores them as decimals).

The default objective, `safe-exploration`, ranks parameter sets by: first the fewest episodes
that collided, commanded NaN/inf or failed to run; then the most explored (mean explored share);
then the largest worst-case clearance. As one number for the searchers, higher is better:
    score = -2 * bad_episodes + mean(explored_fraction) + min(min_clearance_m) / 100
(exploration plus clearance stays below 2, so one bad episode always outweighs them, and a
clearance difference below 1 m never outweighs 1 % of explored share).
`MODULE:FUNCTION` is any function `f(rows, params) -> float or {"score": float, ...}` over the
trial's evaluate.py rows (results.json "episodes").
"""
from __future__ import annotations

import dataclasses
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from amr_common.plugins.loader import (
    described_parameters,
    load_controller_class,
    parse_value,
)
from amr_evaluation.evaluation import EpisodeSpec, EvaluationError, run_episodes

__all__ = ["SEARCHES", "Dimension", "parse_space", "grid_size", "search_size", "safe_exploration",
           "load_objective", "run_trial", "TrialResult", "run_search", "write_params_file"]

SEARCHES = ("grid", "random", "optuna")
DEFAULT_OBJECTIVE = "safe-exploration"
MAX_GRID = 10_000


@dataclass(frozen=True)
class Dimension:
    """One searched parameter: listed values, or a continuous range [low, high]."""

    name: str
    values: tuple[Any, ...] = ()
    low: float | None = None
    high: float | None = None
    integer: bool = False

    @property
    def is_range(self) -> bool:
        """A continuous range (no listed values)."""
        return not self.values


def parse_space(items: Sequence[str], controller: str) -> list[Dimension]:
    """--space NAME=SPEC items -> dimensions; EvaluationError naming the bad item."""
    described = _described(controller)
    dims: list[Dimension] = []
    for item in items:
        name, sep, spec = item.partition("=")
        name, spec = name.strip(), spec.strip()
        if not sep or not name or not spec:
            raise EvaluationError(f"--space '{item}' must look like NAME=a,b,c or "
                                  "NAME=LOW:HIGH[:N]")
        if described and name not in described:
            raise EvaluationError(f"--space {name}: controller {controller} has no such "
                                  f"parameter; known: {', '.join(sorted(described))}")
        if any(d.name == name for d in dims):
            raise EvaluationError(f"--space {name} is given twice")
        default = described[name][0] if name in described else None
        dims.append(_dimension(name, spec, default))
    if not dims:
        raise EvaluationError("give at least one --space NAME=SPEC")
    return dims


def _described(controller: str) -> dict[str, tuple[Any, str]]:
    return described_parameters(load_controller_class(controller)) or {}


def _dimension(name: str, spec: str, default: Any) -> Dimension:
    integer = isinstance(default, int) and not isinstance(default, bool)
    if ":" in spec:
        parts = [part.strip() for part in spec.split(":")]
        numbers = [parse_value(p) for p in parts]
        if len(parts) not in (2, 3) or not all(
                isinstance(n, (int, float)) and not isinstance(n, bool) for n in numbers):
            raise EvaluationError(f"--space {name}={spec}: a range is LOW:HIGH or LOW:HIGH:N "
                                  "with numbers")
        low, high = float(numbers[0]), float(numbers[1])
        if not low < high:
            raise EvaluationError(f"--space {name}={spec}: LOW must be below HIGH")
        if len(parts) == 2:
            return Dimension(name, low=low, high=high, integer=integer)
        points = numbers[2]
        if not isinstance(points, int) or not 2 <= points <= MAX_GRID:
            raise EvaluationError(f"--space {name}={spec}: N must be an integer from 2 to "
                                  f"{MAX_GRID}, got {points}")
        raw = [low + (high - low) * k / (points - 1) for k in range(points)]
        values = [round(v, 12) for v in raw]
    else:
        values = [parse_value(part) for part in spec.split(",") if part.strip()]
    typed = tuple(dict.fromkeys(_typed(name, v, default) for v in values))
    return Dimension(name, values=typed, integer=integer)


def _typed(name: str, value: Any, default: Any) -> Any:
    """The value in the parameter's own type (int -> float for a decimal), or an error."""
    value = value.item() if hasattr(value, "item") else value
    if default is None:
        return value
    if isinstance(default, bool) or isinstance(value, bool):
        ok = isinstance(default, bool) and isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float))
        value = float(value) if ok else value
    elif isinstance(default, int):
        ok = isinstance(value, int) or (isinstance(value, float) and value.is_integer())
        value = int(value) if ok else value
    else:
        ok = isinstance(value, type(default))
    if not ok:
        raise EvaluationError(f"--space {name}: {value!r} is not a {type(default).__name__} "
                              f"like its default {default!r}")
    return value


def grid_size(dims: Sequence[Dimension]) -> int:
    """Parameter sets of a grid search (EvaluationError for a range without N points)."""
    ranges = [d.name for d in dims if d.is_range]
    if ranges:
        raise EvaluationError(f"--search grid needs values or LOW:HIGH:N points, not a "
                              f"continuous range ({', '.join(ranges)})")
    return math.prod(len(d.values) for d in dims)


def search_size(dims: Sequence[Dimension], search: str, samples: int) -> int:
    """Parameter sets the search tries; EvaluationError beyond 1 to MAX_GRID."""
    if search == "grid":
        total = grid_size(dims)
        if total > MAX_GRID:
            raise EvaluationError(f"--search grid: {total} parameter sets; at most {MAX_GRID} "
                                  "(fewer values, or --search random/optuna with --samples)")
        return total
    if not 1 <= samples <= MAX_GRID:
        raise EvaluationError(f"--samples must be from 1 to {MAX_GRID}, got {samples}")
    return samples


def _tune_space(dims: Sequence[Dimension], search: str) -> dict[str, Any]:
    from ray import tune
    space: dict[str, Any] = {}
    for d in dims:
        if search == "grid":
            space[d.name] = tune.grid_search(list(d.values))
        elif d.values:
            space[d.name] = tune.choice(list(d.values))
        elif d.integer:
            space[d.name] = tune.randint(int(math.ceil(d.low)), int(math.floor(d.high)) + 1)
        else:
            space[d.name] = tune.uniform(d.low, d.high)
    return space


# --- objectives ----------------------------------------------------------------------------

def safe_exploration(rows: Sequence[Mapping[str, Any]], params: Mapping[str, Any]) -> dict:
    """No collision, then exploration, then clearance (see the module docstring)."""
    bad = sum(1 for r in rows if r.get("error") or (r.get("collisions") or 0) > 0
              or (r.get("invalid_commands") or 0) > 0)
    explored = [r["explored_fraction"] for r in rows if r.get("explored_fraction") is not None]
    clearances = [r["min_clearance_m"] for r in rows if r.get("min_clearance_m") is not None]
    explored_mean = sum(explored) / len(explored) if explored else 0.0
    worst_clearance = min(clearances) if clearances else 0.0
    return {"score": -2.0 * bad + explored_mean + min(max(worst_clearance, 0.0), 1.0) / 100.0,
            "bad_episodes": bad, "explored_mean": explored_mean,
            "worst_clearance_m": worst_clearance}


def load_objective(spec: str) -> Callable[..., Any]:
    """'safe-exploration' or MODULE:FUNCTION."""
    if spec == DEFAULT_OBJECTIVE:
        return safe_exploration
    module_name, sep, function_name = spec.partition(":")
    if not sep:
        raise EvaluationError(f"--objective '{spec}' must be {DEFAULT_OBJECTIVE} or "
                              "MODULE:FUNCTION")
    import importlib
    try:
        function = getattr(importlib.import_module(module_name), function_name)
    except (ImportError, AttributeError) as exc:
        raise EvaluationError(f"--objective '{spec}': {exc}") from None
    if not callable(function):
        raise EvaluationError(f"--objective '{spec}' is not a function")
    return function


def run_trial(config: dict[str, Any], specs: Sequence[EpisodeSpec], objective: str,
              episode_timeout_s: float | None = None) -> dict:
    """One parameter set over every episode (a Ray Tune function trainable).

    The episodes run one after the other in a worker process of the trial's (a local pool
    of one): a controller that hangs past `episode_timeout_s` (None: episode_time_limit; 0:
    no limit) or ends its process is that episode's error, and the trial is still scored.
    """
    from amr_evaluation.evaluation_report import outcome_row
    started = time.perf_counter()
    config = _plain(config)
    outcomes = run_episodes([dataclasses.replace(spec, params={**dict(spec.params), **config})
                             for spec in specs], jobs=1, trajectory=False,
                            episode_timeout_s=episode_timeout_s)
    rows = [outcome_row(outcome) for outcome in outcomes]
    metrics = load_objective(objective)(rows, dict(config))
    metrics = dict(metrics) if isinstance(metrics, Mapping) else {"score": float(metrics)}
    metrics["episodes"] = len(rows)
    metrics["errors"] = sum(1 for r in rows if r.get("error"))
    metrics["trial_wall_time_s"] = time.perf_counter() - started
    return metrics


# --- the search ----------------------------------------------------------------------------

@dataclass
class TrialResult:
    """One parameter set's outcome: its metrics, or the error that stopped the trial."""

    params: dict[str, Any]
    metrics: dict[str, Any]
    error: str | None = None

    @property
    def score(self) -> float:
        """The objective's score; -inf for a failed trial."""
        value = self.metrics.get("score")
        return float(value) if isinstance(value, (int, float)) and math.isfinite(value) \
            else -math.inf


def run_search(specs: Sequence[EpisodeSpec], dims: Sequence[Dimension], search: str = "grid",
               samples: int = 20, seed: int = 0, objective: str = DEFAULT_OBJECTIVE,
               storage: Path | None = None,
               progress: Callable[[int, int, TrialResult], None] | None = None,
               episode_timeout_s: float | None = None) -> list[TrialResult]:
    """Run the search on the Ray instance this process is connected to; trials best first.

    `episode_timeout_s`: each episode's wall-clock limit (see run_trial).
    """
    import ray
    from ray import tune
    from ray.tune.search.basic_variant import BasicVariantGenerator

    if search not in SEARCHES:
        raise EvaluationError(f"--search must be one of {', '.join(SEARCHES)}, got {search!r}")
    if not ray.is_initialized():
        raise EvaluationError("run_search needs a Ray connection (RayExecutor.connect())")
    # Trials need the CPUs that idle warm episode workers of evaluate.py runs still hold.
    from amr_evaluation.ray_workers import release_idle_warm_workers
    release_idle_warm_workers(ray)
    # Tune's own tables and hints off (verbose=0 with its classic reporter): progress() reports.
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    total = search_size(dims, search, int(samples))
    if search == "optuna":
        from ray.tune.search.optuna import OptunaSearch
        searcher = OptunaSearch(seed=seed)
    else:
        searcher = BasicVariantGenerator(random_state=seed)
    trainable = tune.with_resources(tune.with_parameters(
        run_trial, specs=list(specs), objective=objective,
        episode_timeout_s=episode_timeout_s), {"cpu": 1})
    reporter = _reporter(total, progress)
    tuner = tune.Tuner(
        trainable, param_space=_tune_space(dims, search),
        tune_config=tune.TuneConfig(metric="score", mode="max", search_alg=searcher,
                                    num_samples=1 if search == "grid" else total,
                                    # One worker process runs trial after trial: ~3x
                                    # faster for short trials than a new one each.
                                    reuse_actors=True),
        run_config=tune.RunConfig(
            name="tune", storage_path=str(Path(storage).resolve()) if storage else None,
            verbose=0, callbacks=[reporter],
            # A trial whose worker died is run once more, as evaluate.py --ray retries a task.
            failure_config=tune.FailureConfig(max_failures=1)))
    grid = tuner.fit()
    trials = [_trial_result(grid[i]) for i in range(len(grid))]
    return sorted(trials, key=lambda t: t.score, reverse=True)


def _trial_result(result: Any) -> TrialResult:
    params = _plain(result.config or {})
    metrics = {k: v for k, v in (result.metrics or {}).items()
               if k in ("score", "episodes", "errors", "trial_wall_time_s")
               or not _is_tune_bookkeeping(k)}
    error = None
    if result.error is not None:
        error = " ".join(f"{type(result.error).__name__}: {result.error}".split())[:300]
    return TrialResult(params, metrics, error)


def _is_tune_bookkeeping(key: str) -> bool:
    return key in {"timestamp", "checkpoint_dir_name", "done", "training_iteration", "trial_id",
                   "date", "time_this_iter_s", "time_total_s", "pid", "hostname", "node_ip",
                   "config", "time_since_restore", "iterations_since_restore",
                   "experiment_tag", "should_checkpoint"}


def _reporter(total: int, progress: Callable[[int, int, TrialResult], None] | None):
    """A Tune callback calling progress(done, total, TrialResult) as each trial ends."""
    from ray.tune import Callback

    class Reporter(Callback):
        def __init__(self) -> None:
            self.done = 0

        def _report(self, trial: Any, error: str | None) -> None:
            self.done += 1
            if progress:
                metrics = {k: v for k, v in (trial.last_result or {}).items()
                           if not _is_tune_bookkeeping(k)}
                progress(self.done, total, TrialResult(_plain(trial.config), metrics, error))

        def on_trial_complete(self, iteration, trials, trial, **info):
            self._report(trial, None)

        def on_trial_error(self, iteration, trials, trial, **info):
            self._report(trial, "the trial failed (see the Tune logs in --out)")

    return Reporter()


def _plain(config: Mapping[str, Any]) -> dict[str, Any]:
    """Sampled values as plain Python numbers (Tune samples numpy ones)."""
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in config.items()}


# --- the params file -----------------------------------------------------------------------

def write_params_file(path: Path, best: Mapping[str, Any], base_file: str | Path | None,
                      controller: str, fixed: Mapping[str, Any], comment: str,
                      node: str = "wall_follower") -> Path:
    """A ROS 2 params file for the node: the base file's section, -p values, the best values.

    The base file (the one the episodes used) keeps every node parameter (dt, slop, ...); the
    searched parameters are written in their declared types, so `run_sim.py --params-file` and
    `--ros-args --params-file` take the file as it is.
    """
    import yaml
    section: dict[str, Any] = {}
    if base_file:
        raw = yaml.safe_load(Path(base_file).read_text(encoding="utf-8")) or {}
        for key, value in raw.items():
            if str(key).lstrip("/") in (node, "**") and isinstance(value, dict):
                section.update(value.get("ros__parameters") or {})
    section.update(fixed)
    section["controller"] = controller
    section.update(best)
    described = _described(controller)
    for name, value in section.items():
        if name in described:
            section[name] = _typed(name, value, described[name][0])
    header = "".join(f"# {line}\n" for line in comment.splitlines())
    path = Path(path)
    path.write_text(header + yaml.safe_dump({node: {"ros__parameters": section}},
                                            sort_keys=False), encoding="utf-8")
    return path
