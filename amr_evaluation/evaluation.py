"""Batch evaluation of a controller, the running side: episode specs, grids, a pool (names, seeds
and config files are read by amr_evaluation.evaluation_config).

scripts/evaluate.py is the command line around it; bench.py and tests use it directly. Each episode
is amr_evaluation.episode.run_episode with the same Simulator and controller classes as the ROS path.
"""
from __future__ import annotations

import math
import multiprocessing
import os
import signal
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from amr_common.controller_loader import (
    DEFAULT_CONTROLLER,
    ControllerSpecError,
    load_controller_class,
    parse_overrides,
)
from amr_evaluation.evaluation_config import (
    MAX_EPISODES,
    EvaluationError,
    load_config,
    load_ros_params_file,
    parse_name_list,
    parse_seeds,
    parse_start_list,
)

__all__ = [
    "DEFAULT_CONTROLLER", "ControllerSpecError", "EvaluationError", "EpisodeSpec", "EpisodeOutcome",
    "parse_name_list", "parse_start_list", "parse_seeds", "parse_overrides", "expand_grid",
    "load_config", "load_ros_params_file", "check_controller", "run_episodes",
]


@dataclass(frozen=True)
class EpisodeSpec:
    """One episode to run: picklable, so it can be sent to a worker process."""

    world: str
    start: str | tuple[float, float, float] | None = None  # a name, a pose, None: the first
    profile: str = "ideal"
    seed: int = 0
    duration: float = 600.0
    dt: float = 0.05
    controller: str = DEFAULT_CONTROLLER
    params: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        if isinstance(self.params, Mapping):
            object.__setattr__(self, "params", tuple(sorted(self.params.items())))
        if self.start is not None and not isinstance(self.start, str):
            object.__setattr__(self, "start", tuple(float(v) for v in self.start))
        duration = self.duration
        if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
            raise EvaluationError(f"episode duration must be a positive number of seconds, "
                                  f"got {duration!r}")
        if not (isinstance(self.dt, (int, float)) and math.isfinite(self.dt) and 0 < self.dt <= 1.0):
            raise EvaluationError(f"dt must be in (0, 1] s, got {self.dt!r}")

    @property
    def label(self) -> str:
        from amr_common.world import start_label
        return (f"{Path(self.world).stem}/{start_label(self.start) or '-'}/{self.profile}/"
                f"seed {self.seed}")


@dataclass
class EpisodeOutcome:
    """What one episode produced: the run_episode result, or the error that stopped it."""

    spec: EpisodeSpec
    result: Any = None
    error: str | None = None
    wall_time_s: float = 0.0


# --- options and grids ---------------------------------------------------------------------

def expand_grid(worlds: str | Sequence[str], starts: str | Sequence[str] = "all",
                profiles: str | Sequence[str] = ("ideal",), seeds: Any = (0,),
                duration: float = 600.0, dt: float = 0.05, controller: str = DEFAULT_CONTROLLER,
                params: Mapping[str, Any] | None = None) -> list[EpisodeSpec]:
    """Every combination of world x start x profile x seed, in that nesting order.

    `worlds` "all" means every bundled world; `starts` "all" means every named start of each world.
    A start name applies to the worlds that have it; a name no chosen world has is an error. A pose
    (x, y, theta; see parse_start_list) applies to every world. A world without named starts
    (the course's map JSON) needs poses.
    """
    from amr_common.world import World, WorldError, bundled_worlds
    from amr_sim.profiles import get_profile

    world_names = parse_name_list(worlds)
    if world_names == ["all"]:
        world_names = bundled_worlds()
    if not world_names:
        raise EvaluationError("no worlds given")
    profile_names = parse_name_list(profiles) or ["ideal"]
    for name in profile_names:
        try:
            get_profile(name)
        except (KeyError, ValueError) as exc:
            raise EvaluationError(f"profile '{name}': {exc}") from None
    seed_list = parse_seeds(seeds)
    start_list = parse_start_list(starts) or ["all"]
    poses = [s for s in start_list if not isinstance(s, str)]
    start_names = [s for s in start_list if isinstance(s, str)]
    loaded: dict[str, list[str | tuple[float, float, float]]] = {}
    for name in world_names:
        try:
            world = World.load(name)
            for pose in poses:  # a pose applies to every world: it must be free in each
                world.resolve_start(pose)
        except WorldError as exc:
            raise EvaluationError(str(exc)) from None
        available = list(world.starts)
        everything = "all" in start_names
        named = available if everything else [s for s in start_names if s in available]
        if everything and not named and not poses:
            raise EvaluationError(f"world '{name}' names no start poses, so 'all' is none: "
                                  "give poses, e.g. --starts X,Y,THETA")
        chosen: list[str | tuple[float, float, float]] = [*named, *poses]
        if not chosen:
            raise EvaluationError(f"world '{name}' has none of the starts "
                                  f"{', '.join(start_names)} (its starts: "
                                  f"{', '.join(available) or 'none'})")
        loaded[name] = chosen
    unused = [s for s in start_names if s != "all" and not any(s in v for v in loaded.values())]
    if unused:
        raise EvaluationError(f"start(s) {', '.join(unused)} exist in none of the worlds "
                              f"{', '.join(world_names)}")
    specs = [EpisodeSpec(world=w, start=s, profile=p, seed=seed, duration=duration, dt=dt,
                         controller=controller, params=dict(params or {}))
             for w in world_names for s in loaded[w] for p in profile_names for seed in seed_list]
    if len(specs) > MAX_EPISODES:
        raise EvaluationError(f"{len(specs)} episodes requested; the limit is {MAX_EPISODES}")
    return specs


def check_controller(spec: str, params: Mapping[str, Any] | None, dt: float) -> type:
    """Load MODULE:CLASS and build it once with `params`, so a bad spec fails before any run."""
    cls = load_controller_class(spec)
    try:
        cls(dt, **dict(params or {}))
    except Exception as exc:  # a user's class may raise anything on bad parameters
        raise ControllerSpecError(f"controller '{spec}' rejected its parameters "
                                  f"{dict(params or {})}: {exc}") from exc
    return cls


# --- running -------------------------------------------------------------------------------

def _init_worker() -> None:
    # Ctrl-C goes to the whole process group: only the parent handles it (and ends the pool).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # Import once per worker: the simulator's numba kernels load (or compile) here, not per episode.
    try:
        import amr_evaluation.episode  # noqa: F401
    except Exception:  # noqa: BLE001 - an initializer that raises makes Pool respawn workers forever;
        pass           # run_one imports it again and reports the error per episode instead


def _run_indexed(item: tuple[int, EpisodeSpec]) -> tuple[int, EpisodeOutcome]:
    index, spec = item
    return index, run_one(spec)


def run_one(spec: EpisodeSpec) -> EpisodeOutcome:
    """Run one episode in this process; an exception becomes the outcome's error text."""
    from amr_evaluation.episode import robot_parameters, run_episode
    from amr_sim.profiles import get_profile

    start = time.perf_counter()
    try:
        controller_class = load_controller_class(spec.controller)
        # The simulated robot's own values (LiDAR position) unless the spec sets them.
        params = {**robot_parameters(controller_class, get_profile(spec.profile)),
                  **dict(spec.params)}
        result = run_episode(spec.world, spec.start, profile=spec.profile, seed=spec.seed,
                             duration=spec.duration, dt=spec.dt,
                             controller_factory=lambda dt: controller_class(dt, **params))
        return EpisodeOutcome(spec, result=result, wall_time_s=time.perf_counter() - start)
    except Exception as exc:  # one broken episode must not lose the others' results
        detail = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return EpisodeOutcome(spec, error=detail, wall_time_s=time.perf_counter() - start)


def _context() -> multiprocessing.context.BaseContext:
    # forkserver, else spawn: no fork of a parent that may hold threads. Workers import the simulator
    # and its numba kernels once (preload / _init_worker) and then run many episodes.
    methods = multiprocessing.get_all_start_methods()
    if "forkserver" in methods:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["amr_evaluation.episode"])
        return ctx
    return multiprocessing.get_context("spawn")


def run_episodes(specs: Sequence[EpisodeSpec], jobs: int | None = None,
                 progress: Callable[[int, int, EpisodeOutcome], None] | None = None) -> list[EpisodeOutcome]:
    """Run all episodes on `jobs` processes (None: all cores; 1: in this process), in spec order."""
    specs = list(specs)
    if not specs:
        return []
    jobs = (os.cpu_count() or 1) if jobs is None else int(jobs)
    if jobs < 1:
        raise EvaluationError(f"jobs must be >= 1, got {jobs}")
    outcomes: list[EpisodeOutcome | None] = [None] * len(specs)
    done = 0
    if jobs == 1 or len(specs) == 1:
        for index, spec in enumerate(specs):
            outcomes[index] = run_one(spec)
            done += 1
            if progress:
                progress(done, len(specs), outcomes[index])
        return outcomes  # type: ignore[return-value]
    with _context().Pool(processes=min(jobs, len(specs)), initializer=_init_worker) as pool:
        for index, outcome in pool.imap_unordered(_run_indexed, enumerate(specs), chunksize=1):
            outcomes[index] = outcome
            done += 1
            if progress:
                progress(done, len(specs), outcome)
    return outcomes  # type: ignore[return-value]
