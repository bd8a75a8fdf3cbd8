"""Where evaluate.py and tune.py run their episodes: the local pool, or Ray (--ray).

make_executor reads the options; ray_executor connects a RayExecutor (a local instance, or a
cluster at an address); check_ray_options and read_runtime_env check --ray's companions before
anything runs. Every problem is an EvaluationError with a one-line reason.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

from amr_evaluation.evaluation import EvaluationError


def add_executor_options(parser: argparse.ArgumentParser) -> None:
    """evaluate.py's --episode-timeout, --jobs, --ray, --ray-runtime-env, --ray-keep-workers."""
    parser.add_argument("--episode-timeout", type=float, default=None, metavar="S",
                        help="wall-clock limit of one episode in s: an episode still running "
                        "then (a controller that hangs) is ended as that episode's error "
                        "(default: the larger of 60 s and twice --duration; 0: no limit)")
    parser.add_argument("--jobs", "-j", type=int, default=None,
                        help="worker processes (default: all cores); with --ray and no address, "
                        "the local Ray instance's CPUs; not with --ray ADDRESS (the cluster's "
                        "CPUs run the episodes)")
    parser.add_argument("--ray", nargs="?", const="", default=None, metavar="ADDRESS",
                        help="run the episodes on Ray: no ADDRESS starts a local Ray "
                        "instance (127.0.0.1, stopped at the end); 'auto' joins the cluster "
                        "this machine is a node of; HOST:PORT the cluster whose head is there "
                        "(needs the cluster extra: requirements-cluster.lock)")
    parser.add_argument("--ray-runtime-env", default=None, metavar="JSON|FILE",
                        help="with --ray: Ray runtime_env for the workers, as JSON text or a "
                        "JSON/YAML file (e.g. a wheel of the project in py_modules)")
    parser.add_argument("--ray-keep-workers", type=float, default=None, metavar="SECONDS",
                        help="with --ray ADDRESS: the workers (one per CPU, each holding it) "
                        "stay this long after the run, imported and ready for the next run "
                        "from this checkout (default 60; 0: they end with the run)")


def make_executor(args: argparse.Namespace, jobs: int | None, episodes: int,
                  timeout: float | None = None):
    """The local pool (default), or Ray with --ray; ValueError with a reason for bad options."""
    from amr_evaluation.executors import local_executor
    if args.ray is None:
        for option, value in (("--ray-runtime-env", args.ray_runtime_env),
                              ("--ray-keep-workers", args.ray_keep_workers)):
            if value is not None:
                raise EvaluationError(f"{option} needs --ray")
        return local_executor(jobs, episodes, timeout)
    keep = 60.0 if args.ray_keep_workers is None else args.ray_keep_workers
    return ray_executor(args.ray, jobs, args.ray_runtime_env, keep, timeout)


def ray_executor(address: str | None, jobs: int | None, runtime_env: str | None,
                 keep_workers_s: float = 0.0, episode_timeout_s: float | None = None):
    """A connected RayExecutor: address ''/None starts a local instance of `jobs` CPUs.

    `runtime_env`: --ray-runtime-env's JSON text or file; `keep_workers_s`:
    --ray-keep-workers; `episode_timeout_s`: the limit of one episode (None or 0: none).
    EvaluationError with the reason (also for `jobs` with an address: a cluster's CPUs are
    its own).
    """
    check_ray_options(address, jobs, keep_workers_s)
    from amr_evaluation.ray_executor import RayExecutor, RaySetupError
    executor = RayExecutor(address or None, num_cpus=jobs,
                           runtime_env=read_runtime_env(runtime_env) if runtime_env else None,
                           keep_workers_s=keep_workers_s, episode_timeout_s=episode_timeout_s)
    try:
        executor.connect()
    except RaySetupError as exc:
        raise EvaluationError(str(exc)) from None
    return executor


def check_ray_options(address: str | None, jobs: int | None, keep_workers_s: float) -> None:
    """--ray's companions, before anything runs (also tune.py's); EvaluationError if wrong."""
    if not math.isfinite(keep_workers_s) or keep_workers_s < 0:
        raise EvaluationError(f"--ray-keep-workers must be a number of seconds >= 0, got "
                              f"{keep_workers_s:g}")
    if address and jobs is not None:  # it was silently ignored
        raise EvaluationError(f"--jobs {jobs} sets the CPUs of a local Ray instance (--ray "
                              "without an address): with --ray ADDRESS the cluster's CPUs run "
                              "the episodes, one per CPU (drop --jobs, or jobs in --config)")


def read_runtime_env(value: str) -> dict:
    """--ray-runtime-env: JSON text, or a JSON/YAML file holding a mapping."""
    import json

    import yaml
    try:
        path = Path(value)
        data = yaml.safe_load(path.read_text(encoding="utf-8")) if path.is_file() \
            else json.loads(value)
    except (OSError, ValueError, yaml.YAMLError) as exc:
        raise EvaluationError(f"--ray-runtime-env: neither a readable file nor JSON: "
                              f"{' '.join(str(exc).split())}") from None
    if not isinstance(data, dict):
        raise EvaluationError(f"--ray-runtime-env must be a mapping (e.g. "
                              f'{{"py_modules": [...]}}), got {data!r}')
    return data
