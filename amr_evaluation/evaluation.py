"""Batch evaluation of a controller, the running side: episode specs, grids, config files, a pool.

scripts/evaluate.py is the command line around it; bench.py and tests use it directly. Each
episode is amr_evaluation.episode.run_episode with the same Simulator and controller classes as
the ROS path; an episode with a goal is a navigation episode
(amr_evaluation.navigation_episode.run_navigation_episode: the controller explores until the
pose source is localized, then the planner and the pure pursuit drive to the goal).
"""
from __future__ import annotations

import math
import os
import re
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
from amr_evaluation.executors import (
    Executor,
    InProcessExecutor,
    TaskLost,
    local_executor,
    run_tasks,
)

__all__ = [
    "DEFAULT_CONTROLLER", "ControllerSpecError", "EvaluationError", "EpisodeSpec",
    "EpisodeOutcome", "parse_name_list", "parse_start_list", "parse_seeds", "parse_overrides",
    "expand_grid", "load_config", "load_ros_params_file", "check_controller", "run_one",
    "run_summary", "lost_episode", "run_episodes", "POSE_SOURCES",
]

CONFIG_KEYS = ("worlds", "starts", "goals", "pose_source", "profiles", "seeds", "duration", "dt",
               "controller", "params_file", "params", "jobs")
POSE_SOURCES = ("filter", "truth")
MAX_EPISODES = 10_000


class EvaluationError(ValueError):
    """Bad evaluation options or config file; the message says which and why."""


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
        """world/start[->goal]/profile/seed N, for tables and progress lines."""
        from amr_common.world import start_label
        goal = f"->{self.goal}" if self.goal else ""
        return (f"{Path(self.world).stem}/{start_label(self.start) or '-'}{goal}/{self.profile}/"
                f"seed {self.seed}")


@dataclass
class EpisodeOutcome:
    """What one episode produced: the run_episode result, or the error that stopped it."""

    spec: EpisodeSpec
    result: Any = None
    error: str | None = None
    wall_time_s: float = 0.0


# --- options and grids ---------------------------------------------------------------------

def parse_name_list(value: str | Sequence[str] | None) -> list[str]:
    """"a,b, c" or ["a", "b,c"] -> ["a", "b", "c"] (order kept, duplicates dropped)."""
    if value is None:
        return []
    if not isinstance(value, (str, list, tuple)):
        raise EvaluationError(f"expected a name or a list of names, got {value!r}")
    items = [value] if isinstance(value, str) else list(value)
    names: list[str] = []
    for item in items:
        for name in str(item).split(","):
            name = name.strip()
            if name and name not in names:
                names.append(name)
    return names


def parse_start_list(value: Any) -> list[str | tuple[float, float, float]]:
    """Start names and x, y, theta poses from a command line or a config file.

    "outer,-1,-1,1.57", ["outer", -1, -1, 1.57] and ["outer", [-1, -1, 1.57]] all give
    ["outer", (-1.0, -1.0, 1.57)] (order kept, duplicates dropped): three numbers in a row are
    one pose (m, m, rad), anything else is a name.
    """
    if value is None:
        return []
    items = [value] if isinstance(value, (str, int, float)) else value
    if not isinstance(items, (list, tuple)):
        raise EvaluationError(f"starts must be 'all', names or x,y,theta poses, got {value!r}")
    tokens: list[Any] = []  # names, numbers and explicit poses, in order
    for item in items:
        if isinstance(item, str):
            tokens += [_number_or_name(part.strip()) for part in item.split(",") if part.strip()]
        elif isinstance(item, (int, float)) and not isinstance(item, bool):
            tokens.append(float(item))
        elif isinstance(item, (list, tuple)):
            tokens.append(_explicit_pose(item))
        else:
            raise EvaluationError(f"start {item!r} is neither a name nor an x,y,theta pose")
    starts: list[str | tuple[float, float, float]] = []
    numbers: list[float] = []
    for token in [*tokens, None]:  # None flushes the last run of numbers
        if isinstance(token, float):
            numbers.append(token)
            continue
        if numbers:
            if len(numbers) % 3 or not all(math.isfinite(n) for n in numbers):
                raise EvaluationError(f"start pose numbers {numbers} are not x,y,theta triples "
                                      "of finite numbers")
            starts += [tuple(numbers[i:i + 3]) for i in range(0, len(numbers), 3)]
            numbers = []
        if token is not None:
            starts.append(token)
    unique: list[str | tuple[float, float, float]] = []
    for start in starts:
        if start not in unique:
            unique.append(start)
    return unique


def _number_or_name(text: str) -> str | float:
    try:
        return float(text)
    except ValueError:
        return text


def _explicit_pose(item: Sequence[Any]) -> tuple[float, float, float]:
    if len(item) != 3 or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                 and math.isfinite(v) for v in item):
        raise EvaluationError(f"start pose {list(item)!r} is not [x, y, theta] with finite "
                              "numbers")
    return (float(item[0]), float(item[1]), float(item[2]))


def parse_seeds(value: str | int | Sequence[Any] | None) -> list[int]:
    """"0,1,2", "0-9" (inclusive), 3, or [0, "4-5"] -> a list of distinct non-negative ints."""
    if value is None:
        return [0]
    items = [value] if isinstance(value, (str, int)) else list(value)
    seeds: list[int] = []
    for item in items:
        if isinstance(item, bool) or not isinstance(item, (int, str)):
            raise EvaluationError(f"seed {item!r} is not an integer")
        parts = ([str(item)] if isinstance(item, int)
                 else [p.strip() for p in item.split(",") if p.strip()])
        for part in parts:
            single = re.fullmatch(r"\d+", part)
            span = re.fullmatch(r"(\d+)\s*-\s*(\d+)", part)
            if single:
                new = [int(part)]
            elif (span and int(span.group(1)) <= int(span.group(2))
                  <= int(span.group(1)) + MAX_EPISODES):
                new = list(range(int(span.group(1)), int(span.group(2)) + 1))
            else:
                raise EvaluationError(f"seed '{part}' is not a non-negative integer or a range "
                                      f"like 0-9")
            for seed in new:
                if seed > 2**32 - 1:
                    raise EvaluationError(f"seed {seed} is out of range 0..2^32-1")
                if seed not in seeds:
                    seeds.append(seed)
    if not seeds:
        raise EvaluationError("no seeds given")
    return seeds


def expand_grid(worlds: str | Sequence[str], starts: str | Sequence[str] = "all",
                profiles: str | Sequence[str] = ("ideal",), seeds: Any = (0,),
                duration: float = 600.0, dt: float = 0.05, controller: str = DEFAULT_CONTROLLER,
                params: Mapping[str, Any] | None = None,
                goals: str | Sequence[str] | None = None,
                pose_source: str = "filter") -> list[EpisodeSpec]:
    """Every combination of world x start [x goal] x profile x seed, in that nesting order.

    `worlds` "all" means every bundled world; `starts` "all" means every named start of each world.
    A start name applies to the worlds that have it; a name no chosen world has is an error. A pose
    (x, y, theta; see parse_start_list) applies to every world. A world without named starts
    (the course's map JSON) needs poses. `goals` (navigation episodes): "all" = every named goal
    of each world, or names, applied like the start names; None or empty: wall-following
    episodes.
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
    goal_names = parse_name_list(goals)
    world_goals = {w: _world_goals(w, goal_names) for w in world_names}
    missing = [g for g in goal_names if g != "all" and not any(g in v for v in
                                                                world_goals.values())]
    if missing:
        raise EvaluationError(f"goal(s) {', '.join(missing)} exist in none of the worlds "
                              f"{', '.join(world_names)}")
    if pose_source not in POSE_SOURCES:
        raise EvaluationError(f"pose_source must be one of {', '.join(POSE_SOURCES)}, got "
                              f"{pose_source!r}")
    specs = [EpisodeSpec(world=w, start=s, profile=p, seed=seed, duration=duration, dt=dt,
                         controller=controller, params=dict(params or {}), goal=g,
                         pose_source=pose_source)
             for w in world_names for s in loaded[w] for g in world_goals[w]
             for p in profile_names for seed in seed_list]
    if len(specs) > MAX_EPISODES:
        raise EvaluationError(f"{len(specs)} episodes requested; the limit is {MAX_EPISODES}")
    return specs


def _world_goals(world_name: str, goal_names: list[str]) -> list[str | None]:
    """The goals of one world an episode grid uses: [None] without goals (wall following)."""
    if not goal_names:
        return [None]
    from amr_common.world import World
    available = list(World.load(world_name).goals)
    chosen = available if goal_names == ["all"] else [g for g in goal_names if g in available]
    if not chosen:
        raise EvaluationError(f"world '{world_name}' has none of the goals "
                              f"{', '.join(goal_names)} (its goals: "
                              f"{', '.join(available) or 'none'})")
    return list(chosen)


def _read_yaml(path: Path, what: str) -> Any:
    """Parsed YAML of a file; EvaluationError naming the file and `what` it is on failure."""
    import yaml

    try:
        return yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise EvaluationError(f"{path}: cannot read {what}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise EvaluationError(f"{path}: not a text file (a YAML {what} was expected)") from None
    except yaml.YAMLError as exc:  # one line: the problem and where
        problem = getattr(exc, "problem", None) or str(exc)
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise EvaluationError(f"{path}: not valid YAML: {' '.join(problem.split())}{where}") \
            from None


def load_config(path: str | os.PathLike) -> dict[str, Any]:
    """Read an episode-set YAML file; keys as in CONFIG_KEYS (all optional except worlds)."""
    path = Path(path)
    raw = _read_yaml(path, "config")
    if not isinstance(raw, dict):
        raise EvaluationError(f"{path}: expected a mapping with keys {', '.join(CONFIG_KEYS)}")
    unknown = sorted(set(raw) - set(CONFIG_KEYS))
    if unknown:
        raise EvaluationError(f"{path}: unknown key(s) {', '.join(map(str, unknown))}; "
                              f"allowed: {', '.join(CONFIG_KEYS)}")
    if "worlds" not in raw:
        raise EvaluationError(f"{path}: 'worlds' is required (a list of names, or 'all')")
    config = dict(raw)
    for key in ("worlds", "profiles"):
        value = config.get(key)
        if key in config and not (isinstance(value, str) or (
                isinstance(value, list) and all(isinstance(v, str) for v in value))):
            raise EvaluationError(f"{path}: '{key}' must be a name, a list of names or 'all', "
                                  f"got {value!r}")
    if "starts" in config:
        try:
            parse_start_list(config["starts"])
        except EvaluationError as exc:
            raise EvaluationError(f"{path}: 'starts': {exc}") from None
    if "controller" in config and not isinstance(config["controller"], str):
        raise EvaluationError(f"{path}: 'controller' must be MODULE:CLASS, got "
                              f"{config['controller']!r}")
    for key in ("duration", "dt"):
        if key in config and (isinstance(config[key], bool)
                              or not isinstance(config[key], (int, float))):
            raise EvaluationError(f"{path}: '{key}' must be a number, got {config[key]!r}")
    if "jobs" in config and (isinstance(config["jobs"], bool)
                             or not isinstance(config["jobs"], int) or config["jobs"] < 1):
        raise EvaluationError(f"{path}: 'jobs' must be a positive integer, got {config['jobs']!r}")
    params_file = config.get("params_file")
    if params_file is not None:
        if not isinstance(params_file, str):
            raise EvaluationError(f"{path}: 'params_file' must be a path, got {params_file!r}")
        beside = path.parent / params_file  # relative paths are relative to the config file
        if (params_file.lower() != "none" and not Path(params_file).is_absolute()
                and beside.exists()):
            config["params_file"] = str(beside)
    params = config.get("params") or {}
    if not isinstance(params, dict) or not all(isinstance(k, str) for k in params):
        raise EvaluationError(f"{path}: 'params' must map parameter names to values")
    for name, value in params.items():
        if isinstance(value, float) and not math.isfinite(value):
            raise EvaluationError(f"{path}: parameter '{name}' is not finite")
    config["params"] = params
    return config


def load_ros_params_file(path: str | os.PathLike,
                         controller_class: type | None = None) -> dict[str, Any]:
    """Controller parameters from a ROS 2 params YAML (the file run_sim.py gives the node).

    Every node section's `ros__parameters` is merged in file order. With a controller class that
    lists its parameters (`parameter_descriptions()`), node-only parameters such as use_sim_time
    are dropped, so the class gets exactly what the node would pass it.
    """
    path = Path(path)
    raw = _read_yaml(path, "params file")
    sections = [v["ros__parameters"] for v in (raw or {}).values()
                if isinstance(v, dict) and isinstance(v.get("ros__parameters"), dict)] \
        if isinstance(raw, dict) else []
    if not sections:
        raise EvaluationError(f"{path}: no '<node>: ros__parameters:' section")
    if any(str(key).lstrip("/") == "wall_follower" for key in raw):
        # The wall follower's own and wildcard sections, not the other nodes' (pure_pursuit
        # also has a max_linear_speed_mps, for one).
        sections = [v["ros__parameters"] for k, v in raw.items()
                    if (str(k).lstrip("/") == "wall_follower" or "*" in str(k))
                    and isinstance(v, dict) and isinstance(v.get("ros__parameters"), dict)]
    params: dict[str, Any] = {}
    for section in sections:
        params.update(section)
    known = getattr(controller_class, "parameter_descriptions", None)
    if callable(known):
        names = set(known())
        params = {k: v for k, v in params.items() if k in names}
    return params


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
                record_trajectory=trajectory)
        else:
            result = run_episode(spec.world, spec.start, profile=spec.profile, seed=spec.seed,
                                 duration=spec.duration, dt=spec.dt,
                                 controller_factory=lambda dt: controller_class(dt, **params),
                                 record_trajectory=trajectory)
        return EpisodeOutcome(spec, result=result, wall_time_s=time.perf_counter() - start)
    except Exception as exc:  # one broken episode must not lose the others' results
        detail = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return EpisodeOutcome(spec, error=detail, wall_time_s=time.perf_counter() - start)
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
                 executor: Executor | None = None, trajectory: bool = True
                 ) -> list[EpisodeOutcome]:
    """Run all episodes, outcomes in spec order.

    On `executor` (amr_evaluation.executors; e.g. a RayExecutor), else on `jobs` local
    processes (None: all cores; 1: this process). trajectory=False: summaries only (see
    run_one).
    """
    specs = list(specs)
    if not specs:
        return []
    if executor is None:
        try:
            executor = local_executor(jobs)
        except ValueError as exc:
            raise EvaluationError(str(exc)) from None
        if len(specs) == 1:
            executor = InProcessExecutor()
    return run_tasks(run_one if trajectory else run_summary, specs, executor, lost_episode,
                     progress, preload=EPISODE_MODULES)
