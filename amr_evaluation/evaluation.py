"""Batch evaluation of a controller, the running side: episode specs, grids, executors.

Options and files (name lists, starts, seeds, the YAML config, params files) are parsed in
evaluation_config.py (re-exported here); executors.py and ray_executor.py run the episodes.

scripts/evaluate.py is the command line around it; bench.py and tests use it directly. Each
episode is amr_evaluation.episode.run_episode with the same Simulator and controller classes as
the ROS path; an episode with a goal is a navigation episode
(amr_evaluation.navigation_episode.run_navigation_episode: the controller explores until the
pose source is localized, then the planner and the pure pursuit drive to the goal).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from amr_common.plugins.link_failure import failure_text
from amr_common.plugins.loader import (
    DEFAULT_CONTROLLER,
    DEFAULT_FOLLOWER,
    DEFAULT_LOCALIZER,
    DEFAULT_PLANNER,
    PluginSpecError,
    load_controller_class,
    parse_overrides,
)
from amr_evaluation.evaluation_config import (
    MAX_EPISODES,
    POSE_SOURCES,
    EvaluationError,
    load_config,
    load_ros_params_file,
    parse_name_list,
    parse_seeds,
    parse_start_list,
)
from amr_evaluation.executors import (
    Executor,
    TaskLost,
    episode_time_limit,
    local_executor,
    run_tasks,
)

__all__ = [
    "DEFAULT_CONTROLLER", "PluginSpecError", "EvaluationError", "EpisodeSpec",
    "EpisodeOutcome", "parse_name_list", "parse_start_list", "parse_seeds", "parse_overrides",
    "expand_grid", "load_config", "load_ros_params_file", "check_controller", "run_one",
    "run_summary", "lost_episode", "run_episodes", "POSE_SOURCES",
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
    goal: str | None = None  # a named goal or "x,y": a navigation episode
    pose_source: str = "filter"  # of a navigation episode: "filter" or "truth"
    map: str | None = None  # the filter's and the planner's map (None: the world)
    # The links' classes (MODULE:CLASS, amr_common.plugins.interfaces) of a navigation episode.
    localizer: str = DEFAULT_LOCALIZER
    planner: str = DEFAULT_PLANNER
    follower: str = DEFAULT_FOLLOWER

    def __post_init__(self) -> None:
        if isinstance(self.params, Mapping):
            object.__setattr__(self, "params", tuple(sorted(self.params.items())))
        if self.start is not None and not isinstance(self.start, str):
            object.__setattr__(self, "start", tuple(float(v) for v in self.start))
        duration = self.duration
        if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
            raise EvaluationError(f"episode duration must be a positive number of seconds, "
                                  f"got {duration!r}")
        if not (isinstance(self.dt, (int, float)) and math.isfinite(self.dt)
                and 0 < self.dt <= 1.0):
            raise EvaluationError(f"dt must be in (0, 1] s, got {self.dt!r}")

    @property
    def label(self) -> str:
        """world[@map]/start[->goal]/profile/seed N, for tables and progress lines."""
        from amr_common.world.world import start_label
        goal = f"->{self.goal}" if self.goal else ""
        on_map = f"@{Path(self.map).stem}" if self.map else ""
        return (f"{Path(self.world).stem}{on_map}/{start_label(self.start) or '-'}{goal}/"
                f"{self.profile}/seed {self.seed}")


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
                params: Mapping[str, Any] | None = None,
                goals: str | Sequence[str] | None = None,
                pose_source: str = "filter", map: str | None = None,
                warnings: list[str] | None = None,
                links: Mapping[str, str] | None = None) -> list[EpisodeSpec]:
    """Every combination of world x start [x goal] x profile x seed, in that nesting order.

    `worlds` "all" means every bundled world; `starts` "all" means every named start of each world.
    A start name applies to the worlds that have it; a name no chosen world has is an error. A pose
    (x, y, theta; see parse_start_list) applies to every world. A world without named starts
    (the course's map JSON) needs poses. `goals` (navigation episodes): "all" = every named goal
    of each world, or names, applied like the start names; None: wall-following episodes.
    An empty list given for starts, profiles or goals is an error (not 'all' or 'none').
    `map`: the map of the filter and the planner while the simulator drives in the
    world (amr_common.world.map_vs_world; one world only): the goals are checked against it, and
    what the map and the world disagree on (a start the map lacks, a goal the world blocks) is
    appended to `warnings`. `links`: {"localizer" | "planner" | "follower": MODULE:CLASS}.
    """
    from amr_common.world.world import bundled_worlds
    from amr_sim.profiles import get_profile

    world_names = parse_name_list(worlds)
    if world_names == ["all"]:
        world_names = bundled_worlds()
    if not world_names:
        raise EvaluationError("no worlds given")
    profile_names = _given(parse_name_list(profiles), profiles, "profiles", ["ideal"],
                           "give profile names (ideal, turtlebot3)")
    for name in profile_names:
        try:
            get_profile(name)
        except (KeyError, ValueError) as exc:
            raise EvaluationError(f"profile '{name}': {exc}") from None
    seed_list = parse_seeds(seeds)
    loaded, goals_of = _starts_and_goals(world_names, starts)
    goal_names = _given(parse_name_list(goals), goals, "goals", [],
                        "give 'all' or goal names, or leave them out for wall following")
    world_goals = {w: _world_goals(w, goals_of[w], goal_names) for w in world_names}
    missing = [g for g in goal_names if g != "all" and not any(g in v for v in
                                                                world_goals.values())]
    if missing:
        raise EvaluationError(f"goal(s) {', '.join(missing)} exist in none of the worlds "
                              f"{', '.join(world_names)}")
    if map is not None:
        _check_map(map, world_names, loaded, world_goals, warnings)
    if pose_source not in POSE_SOURCES:
        raise EvaluationError(f"pose_source must be one of {', '.join(POSE_SOURCES)}, got "
                              f"{pose_source!r}")
    specs = [EpisodeSpec(world=w, start=s, profile=p, seed=seed, duration=duration, dt=dt,
                         controller=controller, params=dict(params or {}), goal=g,
                         pose_source=pose_source, map=map, **dict(links or {}))
             for w in world_names for s in loaded[w] for g in world_goals[w]
             for p in profile_names for seed in seed_list]
    if len(specs) > MAX_EPISODES:
        raise EvaluationError(f"{len(specs)} episodes requested; the limit is {MAX_EPISODES}")
    return specs


def _starts_and_goals(world_names: list[str], starts: Any) -> tuple[dict, dict]:
    """Each world's chosen starts (names and poses, checked) and goal names, one load each."""
    from amr_common.world.world import World, WorldError
    start_list = _given(parse_start_list(starts), starts, "starts", ["all"],
                        "give 'all', start names or X,Y,THETA poses")
    poses = [s for s in start_list if not isinstance(s, str)]
    start_names = [s for s in start_list if isinstance(s, str)]
    loaded: dict[str, list[str | tuple[float, float, float]]] = {}
    goals_of: dict[str, list[str]] = {}  # each world's goal names (one load per world)
    for name in world_names:
        try:
            world = World.load(name)
            for pose in poses:  # a pose applies to every world: it must be free in each
                world.resolve_start(pose)
        except WorldError as exc:
            raise EvaluationError(str(exc)) from None
        available = list(world.starts)
        goals_of[name] = list(world.goals)
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
    return loaded, goals_of


def _given(parsed: list, value: Any, what: str, default: list, hint: str) -> list:
    """`parsed`, or `default` if the option was not given (None); an empty list is an error."""
    if value is None:
        return default
    if not parsed:
        raise EvaluationError(f"no {what} given (an empty list): {hint}")
    return parsed


def _check_map(map_source: str, world_names: list[str], starts: dict, goals: dict,
               warnings: list[str] | None) -> None:
    """The map loads, stands for one world and takes its goals; warnings for the rest."""
    from amr_common.world.map_vs_world import load_map, resolve_goal_on_map, start_warning
    from amr_common.world.world import World, WorldError
    if len(world_names) != 1:
        raise EvaluationError(f"a map stands for one world: give one world with it (got "
                              f"{', '.join(world_names)})")
    world = World.load(world_names[0])
    try:
        map_world = load_map(map_source, world)
    except WorldError as exc:
        raise EvaluationError(f"map: {exc}") from None
    found = [start_warning(world.resolve_start(s), map_world, world) for s in
             starts[world_names[0]]]
    for goal in goals[world_names[0]]:
        if goal is not None:
            try:
                found.append(resolve_goal_on_map(goal, map_world, world)[1])
            except WorldError as exc:
                raise EvaluationError(f"goal '{goal}' on the map: {exc}") from None
    if warnings is not None:
        warnings += [w for w in found if w is not None and w not in warnings]


def _world_goals(world_name: str, available: list[str],
                 goal_names: list[str]) -> list[str | None]:
    """The goals of one world an episode grid uses: [None] without goals (wall following)."""
    if not goal_names:
        return [None]
    chosen = available if goal_names == ["all"] else [g for g in goal_names if g in available]
    if not chosen:
        raise EvaluationError(f"world '{world_name}' has none of the goals "
                              f"{', '.join(goal_names)} (its goals: "
                              f"{', '.join(available) or 'none'})")
    return list(chosen)


def check_controller(spec: str, params: Mapping[str, Any] | None, dt: float) -> type:
    """Load MODULE:CLASS and build it once with `params`, so a bad spec fails before any run."""
    cls = load_controller_class(spec)
    try:
        cls(dt, **dict(params or {}))
    except Exception as exc:  # a user's class may raise anything on bad parameters
        raise PluginSpecError(f"controller '{spec}' rejected its parameters "
                                  f"{dict(params or {})}: {exc}") from exc
    return cls


# --- running -------------------------------------------------------------------------------

# Imported once per worker before its first episode: the simulator's numba kernels load (or
# compile) there, not per episode.
EPISODE_MODULES = ("amr_evaluation.episode",)


def run_one(spec: EpisodeSpec, trajectory: bool = True) -> EpisodeOutcome:
    """Run one episode in this process; an exception becomes the outcome's error text.

    trajectory=False leaves the result's per-step trajectory empty (the metrics are the same):
    what a sweep sends back is then a summary of a few hundred bytes.
    """
    from amr_evaluation.episode import robot_parameters, run_episode
    from amr_sim.profiles import get_profile

    start = time.perf_counter()
    try:
        controller_class = load_controller_class(spec.controller)
        # The simulated robot's own values (LiDAR position) unless the spec sets them.
        params = {**robot_parameters(controller_class, get_profile(spec.profile)),
                  **dict(spec.params)}
        if spec.goal is not None:
            from amr_evaluation.navigation_episode import run_navigation_episode
            result = run_navigation_episode(
                spec.world, spec.start, spec.goal, profile=spec.profile, seed=spec.seed,
                duration=spec.duration, dt=spec.dt, pose_source=spec.pose_source,
                wall_follower=controller_class(spec.dt, **params),
                record_trajectory=trajectory, map=spec.map, localizer=spec.localizer,
                planner_class=spec.planner, follower=spec.follower)
        else:
            result = run_episode(spec.world, spec.start, profile=spec.profile, seed=spec.seed,
                                 duration=spec.duration, dt=spec.dt,
                                 controller_factory=lambda dt: controller_class(dt, **params),
                                 record_trajectory=trajectory)
        return EpisodeOutcome(spec, result=result, wall_time_s=time.perf_counter() - start)
    except Exception as exc:  # one broken episode must not lose the others' results
        return EpisodeOutcome(spec, error=failure_text(exc),
                              wall_time_s=time.perf_counter() - start)
    except SystemExit as exc:  # a controller calling sys.exit ends its episode, not the run
        return EpisodeOutcome(spec, error=f"the episode called sys.exit({exc.code!r})",
                              wall_time_s=time.perf_counter() - start)


def run_summary(spec: EpisodeSpec) -> EpisodeOutcome:
    """run_one without the per-step trajectory (a picklable task for the executors)."""
    return run_one(spec, trajectory=False)


def lost_episode(spec: EpisodeSpec, lost: TaskLost) -> EpisodeOutcome:
    """The outcome of an episode whose process or node died."""
    return EpisodeOutcome(spec, error=lost.error, wall_time_s=lost.wall_time_s)


def run_episodes(specs: Sequence[EpisodeSpec], jobs: int | None = None,
                 progress: Callable[[int, int, EpisodeOutcome], None] | None = None,
                 executor: Executor | None = None, trajectory: bool = True,
                 episode_timeout_s: float | None = None) -> list[EpisodeOutcome]:
    """Run all episodes, outcomes in spec order.

    On `executor` (amr_evaluation.executors; e.g. a RayExecutor, with its own time limit),
    else on `jobs` local worker processes (None: all cores), each episode limited to
    `episode_timeout_s` of wall-clock time (None: episode_time_limit of the longest
    duration; 0: no limit). trajectory=False: summaries only (see run_one).
    """
    specs = list(specs)
    if not specs:
        return []
    if executor is None:
        if episode_timeout_s is None:
            episode_timeout_s = episode_time_limit(max(spec.duration for spec in specs))
        try:
            executor = local_executor(jobs, len(specs), episode_timeout_s)
        except ValueError as exc:
            raise EvaluationError(str(exc)) from None
    return run_tasks(run_one if trajectory else run_summary, specs, executor, lost_episode,
                     progress, preload=EPISODE_MODULES)
