#!/usr/bin/env python3
r"""Search a controller's parameters over episodes with Ray Tune; write the best as ROS params.

Each trial (one parameter set) runs every episode of the set headless and is scored by the
objective; trials run in parallel on a Ray cluster, by default a local Ray instance on this
machine (127.0.0.1). The episode set takes evaluate.py's options (--worlds, --starts, --profiles,
--randomize, --seeds, --duration, --dt, --controller, --params-file, -p, --config, --jobs,
--goals with --localizer, --planner, --follower (your own links, amr_common.plugins.interfaces),
--episode-timeout: an episode that hangs or ends its process is a bad episode of its trial; with
--randomize every seed is a robot with its own reality-gap effects, so the default objective
keeps the parameters that hold on all of them). Writes to --out:
best_params.yaml (a ROS 2 params file for the wall_follower node: run_sim.py --params-file and
--ros-args --params-file take it), trials.csv, best.json and Tune's own logs (ray_results/).

Search space (--space, repeatable): NAME=a,b,c (values), NAME=LOW:HIGH:N (N evenly spaced
values), NAME=LOW:HIGH (a continuous range: random and optuna only). Objective: safe-exploration
(default: fewest episodes with a collision, an invalid command or an error; then the most
explored; then the largest worst clearance) or MODULE:FUNCTION (f(rows, params) -> score).
Exit code: 0 a best parameter set was written, 2 bad options, 3 every trial failed; stopped:
130 after SIGTERM (or a Ctrl-C that Ray Tune does not answer itself), 129 after SIGHUP (the
terminal closed).

Examples:
  .venv/bin/python scripts/tune.py --worlds lab02,maze_deadends --profiles turtlebot3 \
      --duration 120 --space kp=5,10,15 --space wall_distance_m=0.16:0.24:3
  .venv/bin/python scripts/tune.py --config evaluations/example.yaml --search optuna \
      --samples 40 --space kp=2:20 --space kd=0:20 --ray auto     # on a running cluster
"""
from __future__ import annotations

import argparse
import csv
import datetime as dt_module
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SCRIPTS = Path(__file__).resolve().parent
for path in (str(REPO), str(SCRIPTS)):
    if path not in sys.path:  # run from a checkout without installing
        sys.path.insert(0, path)

import evaluate  # noqa: E402  (the episode-set options and their checks)
import evaluate_executors  # noqa: E402  (where the trials run)
from script_endings import interruptible, run_script  # noqa: E402

from amr_common.plugins.parameter_table import MAX_SEED  # noqa: E402
from amr_evaluation.evaluation import EvaluationError, check_controller  # noqa: E402
from amr_evaluation.tuning import (  # noqa: E402
    DEFAULT_OBJECTIVE,
    SEARCHES,
    load_objective,
    parse_space,
    run_search,
    search_size,
    write_params_file,
)
from cli_checks import check_output_folder  # noqa: E402


def parse_args(argv: list[str] | None = None) -> tuple[argparse.Namespace, argparse.Namespace]:
    """tune.py's own options, and the episode set's as evaluate.py parses them."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n", 1)[1])
    parser.add_argument("--space", action="append", default=[], metavar="NAME=SPEC",
                        help="a searched parameter (repeatable): a,b,c or LOW:HIGH:N or "
                        "LOW:HIGH")
    parser.add_argument("--search", choices=SEARCHES, default="grid",
                        help="grid (every combination; default), random, or optuna (TPE)")
    parser.add_argument("--samples", type=int, default=None,
                        help="parameter sets tried by random and optuna (default 20; a grid "
                        "tries every combination)")
    parser.add_argument("--search-seed", type=int, default=None,
                        help="seed of the random and optuna searchers (default 0)")
    parser.add_argument("--objective", default=DEFAULT_OBJECTIVE,
                        help=f"{DEFAULT_OBJECTIVE} (default) or MODULE:FUNCTION")
    parser.add_argument("--ray", nargs="?", const="", default="", metavar="ADDRESS",
                        help="the Ray cluster: none (default) starts a local instance; 'auto' "
                        "or HOST:PORT joins a running one")
    parser.add_argument("--ray-runtime-env", default=None, metavar="JSON|FILE",
                        help="Ray runtime_env for the workers (see evaluate.py)")
    parser.add_argument("--out", default=None, help="output folder (default out/tune-<UTC>)")
    own, rest = parser.parse_known_args(argv)
    return own, evaluate.parse_args([*rest, "--no-sheet"])


def check_options(args: argparse.Namespace, episode_args: argparse.Namespace) -> None:
    """tune.py's own option mistakes, and evaluate.py options that mean nothing here."""
    for option, given in (("--localize", episode_args.localize),
                          ("--ray-keep-workers", episode_args.ray_keep_workers is not None)):
        if given:
            raise EvaluationError(f"{option} is not a tune.py option")
    if args.search == "grid":
        for option, value in (("--samples", args.samples), ("--search-seed", args.search_seed)):
            if value is not None:
                raise EvaluationError(f"{option} is for --search random or optuna (a grid "
                                      "search tries every combination once)")
    if args.search_seed is not None and not 0 <= args.search_seed <= MAX_SEED:
        raise EvaluationError(f"--search-seed must be from 0 to {MAX_SEED}, got "
                              f"{args.search_seed}")


def main(argv: list[str] | None = None) -> int:
    # (Ray Tune answers Ctrl-C itself while the search runs.)
    return interruptible("tune: interrupted", lambda: _tune(argv))


def _tune(argv: list[str] | None) -> int:
    args, episode_args = parse_args(argv)
    started = dt_module.datetime.now(dt_module.timezone.utc)
    try:
        check_options(args, episode_args)
        settings = evaluate.resolve_settings(episode_args)
        evaluate_executors.check_ray_options(args.ray, settings["jobs"], 0.0)
        specs = evaluate.episode_specs(settings)
        evaluate.check_filter_maps(specs, {})  # navigation episodes run the particle filter
        dims = parse_space(args.space, settings["controller"])
        for dim in dims:  # the controller must take the ends of every searched range
            for value in (dim.values or (dim.low, dim.high)):
                check_controller(settings["controller"], {**settings["params"],
                                                          dim.name: value}, settings["dt"])
        load_objective(args.objective)
        args.samples = search_size(dims, args.search, 20 if args.samples is None
                                   else args.samples)
        args.search_seed = args.search_seed or 0
        out = check_output_folder(args.out or Path("out") / f"tune-{started:%Y%m%d-%H%M%S}",
                                  "--out")
        executor = evaluate_executors.ray_executor(args.ray, settings["jobs"],
                                                   args.ray_runtime_env)
    except ValueError as exc:  # EvaluationError, PluginSpecError, a bad --out
        print(f"tune: {exc}", file=sys.stderr)
        return 2
    try:
        return search_and_write(args, settings, specs, dims, executor, out)
    finally:
        executor.close()


def search_and_write(args, settings: dict, specs, dims, executor, out: Path) -> int:
    """Run the search, print the trials, write best_params.yaml, trials.csv, best.json."""
    print(f"tune: {args.search} search over {', '.join(d.name for d in dims)}; each trial "
          f"runs {len(specs)} episode(s) of {settings['duration']:g} s; on "
          f"{executor.describe()}; objective {args.objective}", flush=True)

    def progress(done, total, trial):
        values = " ".join(f"{k}={_short(v)}" for k, v in trial.params.items())
        shown = trial.error or ", ".join(f"{k} {_short(v)}" for k, v in trial.metrics.items()
                                         if k not in ("trial_wall_time_s",))
        print(f"[{done}/{total}] {values}: {shown}", flush=True)

    trials = run_search(specs, dims, args.search, args.samples, args.search_seed,
                        args.objective, storage=out / "ray_results", progress=progress,
                        episode_timeout_s=settings["episode_timeout"])
    _write_trials(out / "trials.csv", trials)
    ran = [t for t in trials if t.error is None and t.score > float("-inf")]
    if not ran:
        print("tune: every trial failed; see the Tune logs in " + str(out / "ray_results"),
              file=sys.stderr)
        return 3
    best = ran[0]
    comment = (f"Written by scripts/tune.py ({args.search} search, objective {args.objective})"
               f": best of {len(trials)} parameter sets over {len(specs)} episode(s) of "
               f"{settings['duration']:g} s\n(worlds {settings['worlds']}, starts "
               f"{settings['starts']}, profiles {settings['profiles']}, seeds "
               f"{settings['seeds']}).\nSearched: {', '.join(args.space)}. Score "
               f"{best.score:.4f}: {_metrics_text(best)}.")
    params_file = write_params_file(out / "best_params.yaml", best.params,
                                    settings["params_file"], settings["controller"],
                                    settings["params"], comment)
    (out / "best.json").write_text(json.dumps(
        {"params": best.params, "metrics": best.metrics, "search": args.search,
         "objective": args.objective, "space": args.space, "trials": len(trials),
         "episodes": len(specs)}, indent=1, default=str) + "\n")
    print("tune: best " + " ".join(f"{k}={v}" for k, v in best.params.items())
          + f" (score {best.score:.4f}: {_metrics_text(best)})")
    print(f"tune: wrote {params_file}; try it: .venv/bin/python scripts/run_sim.py "
          f"--params-file {params_file}")
    return 0


def _short(value):
    return f"{value:.4g}" if isinstance(value, float) else value


def _metrics_text(trial) -> str:
    return ", ".join(f"{k} {_short(v)}" for k, v in trial.metrics.items()
                     if k not in ("score", "trial_wall_time_s"))


def _write_trials(path: Path, trials) -> None:
    params = list(dict.fromkeys(k for t in trials for k in t.params))
    metrics = list(dict.fromkeys(k for t in trials for k in t.metrics))
    with path.open("w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        writer.writerow([*params, *metrics, "error"])
        for t in trials:
            writer.writerow([t.params.get(k, "") for k in params]
                            + [t.metrics.get(k, "") for k in metrics] + [t.error or ""])


if __name__ == "__main__":
    sys.exit(run_script(main))
