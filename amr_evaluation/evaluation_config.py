"""Episode-set options and files for batch evaluation: name lists, start poses, seeds, YAML.

What evaluate.py, tune.py and the tests parse before any episode runs: `"a,b"` name lists, start
lists with poses typed as they are (`-1.0,-1.0,1.57`), seed lists and ranges (`0-9`), the
episode-set YAML config (`--config`) and a ROS params file's values for a controller. Every
problem is an EvaluationError naming the option or file and why (no rclpy import).
"""
from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Any, Sequence

from amr_common.plugins.loader import described_parameters
from amr_common.plugins.parameter_table import MAX_SEED, finite

CONFIG_KEYS = ("worlds", "map", "starts", "goals", "pose_source", "profiles", "seeds", "duration",
               "dt", "controller", "params_file", "params", "jobs", "localizer", "planner",
               "follower", "mapper")
POSE_SOURCES = ("filter", "truth")
MAX_EPISODES = 10_000


class EvaluationError(ValueError):
    """Bad evaluation options or config file; the message says which and why."""


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
    if len(item) != 3 or not all(finite(v) for v in item):
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
                if seed > MAX_SEED:
                    raise EvaluationError(f"seed {seed} is out of range 0..{MAX_SEED}")
                if seed not in seeds:
                    seeds.append(seed)
    if not seeds:
        raise EvaluationError("no seeds given")
    return seeds


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
    for key in ("controller", "localizer", "planner", "follower", "mapper"):
        if key in config and not isinstance(config[key], str):
            raise EvaluationError(f"{path}: '{key}' must be MODULE:CLASS, got "
                                  f"{config[key]!r}")
    for key in ("duration", "dt"):
        if key in config and (isinstance(config[key], bool)
                              or not isinstance(config[key], (int, float))):
            raise EvaluationError(f"{path}: '{key}' must be a number, got {config[key]!r}")
    if "jobs" in config and (isinstance(config["jobs"], bool)
                             or not isinstance(config["jobs"], int) or config["jobs"] < 1):
        raise EvaluationError(f"{path}: 'jobs' must be a positive integer, got {config['jobs']!r}")
    if "map" in config:
        if not isinstance(config["map"], str):
            raise EvaluationError(f"{path}: 'map' must be a map file or a world name, got "
                                  f"{config['map']!r}")
        beside = path.parent / config["map"]  # a relative path is relative to the config file
        if not Path(config["map"]).is_absolute() and beside.is_file():
            config["map"] = str(beside)
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
    names = described_parameters(controller_class)
    if names is not None:
        params = {k: v for k, v in params.items() if k in names}
    return params
