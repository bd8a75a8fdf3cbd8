"""Batch evaluation of a controller, the results side: rows, files, table, verdict, progress.

Per-episode rows, results.json/.csv files, the aligned text table, the pass/fail verdict with
its exit code, and a terminal progress bar.

Rows come from amr_evaluation.evaluation.EpisodeOutcome; scripts/evaluate.py prints and writes
them.
"""
from __future__ import annotations

import csv
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence, TextIO

from amr_common.world.world import start_label
from amr_evaluation.evaluation import EpisodeOutcome

__all__ = [
    "RESULT_COLUMNS", "NAVIGATION_COLUMNS", "columns_of", "outcome_row", "write_json",
    "write_csv", "format_table", "effects_block", "verdict", "ProgressBar",
]

RESULT_COLUMNS = ("world", "start", "profile", "seed", "sim_time_s", "collisions",
                  "first_collision_time_s", "min_clearance_m", "distance_m", "laps",
                  "explored_fraction", "rms_wall_error_m", "invalid_commands", "wall_time_s",
                  "error")
# Navigation episodes (a goal) have these instead of laps ... rms_wall_error_m.
NAVIGATION_COLUMNS = ("world", "start", "goal", "profile", "seed", "sim_time_s", "collisions",
                      "min_clearance_m", "distance_m", "goal_reached", "localized_time_s",
                      "goal_reached_time_s", "stopped_time_s", "final_position_error_m",
                      "path_length_m", "plans", "stalled", "invalid_commands",
                      "false_localizations", "tracking_error_mean_m", "wall_time_s", "error")
_SPEC_COLUMNS = {"world", "start", "goal", "profile", "seed", "wall_time_s", "error"}


def _finite_or_none(value: Any) -> Any:
    if value is None or isinstance(value, (bool, str)):
        return value
    if hasattr(value, "item"):  # numpy scalar
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def columns_of(outcomes: Sequence[EpisodeOutcome]) -> tuple[str, ...]:
    """The columns of a set of outcomes: navigation ones if any episode has a goal.

    With a map of its own (--map), a map column follows the world's.
    """
    columns = NAVIGATION_COLUMNS if any(o.spec.goal for o in outcomes) else RESULT_COLUMNS
    if any(o.spec.map for o in outcomes):
        columns = (columns[0], "map", *columns[1:])
    return columns


def outcome_row(outcome: EpisodeOutcome) -> dict[str, Any]:
    """The flat per-episode metrics (JSON-safe: non-finite numbers become None)."""
    spec, result = outcome.spec, outcome.result
    world = _name(spec.world)
    row: dict[str, Any] = {"world": world, "start": start_label(spec.start) or None,
                           "profile": spec.profile, "seed": spec.seed}
    if spec.map:  # the filter's and the planner's own map
        row = {"world": world, "map": _name(spec.map), **row}
    columns = NAVIGATION_COLUMNS if spec.goal else RESULT_COLUMNS
    if spec.goal:
        row["goal"] = spec.goal
    for column in columns:
        if column not in _SPEC_COLUMNS:
            # Result fields carry their units in their names, like the columns.
            row[column] = _finite_or_none(getattr(result, column, None))
    row["wall_time_s"] = round(outcome.wall_time_s, 3)
    row["error"] = outcome.error
    if getattr(result, "effects", None):  # the reality-gap effects used (drawn: randomized)
        row["effects"] = result.effects
    return row


def _name(source: str) -> str:
    """A world's or a map's name for the table: a bundled name, or the file's stem."""
    return Path(source).stem if source.endswith((".yaml", ".yml", ".json")) else source


def write_json(path: str | os.PathLike, outcomes: Sequence[EpisodeOutcome],
               meta: Mapping[str, Any]) -> Path:
    """results.json: {"meta": {...}, "episodes": [row, ...]} (strict JSON, no NaN)."""
    path = Path(path)
    payload = {"meta": dict(meta), "episodes": [outcome_row(o) for o in outcomes]}
    path.write_text(json.dumps(payload, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    return path


def write_csv(path: str | os.PathLike, outcomes: Sequence[EpisodeOutcome]) -> Path:
    """results.csv: one row per episode (columns_of), empty cells for missing values."""
    path = Path(path)
    rows = [outcome_row(outcome) for outcome in outcomes]
    effects = ("effects",) if any("effects" in row for row in rows) else ()
    with path.open("w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, fieldnames=columns_of(outcomes) + effects,
                                extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            if "effects" in row:
                row["effects"] = _effects_summary(row["effects"])
            writer.writerow({k: ("" if v is None else v) for k, v in row.items()})
    return path


def _effects_summary(effects: Mapping[str, float]) -> str:
    from amr_sim.effects import Effects
    return Effects(**effects).summary()


def effects_block(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """Lines listing each episode's reality-gap effects (drawn from its seed when randomized)."""
    rows = [row for row in rows if row.get("effects")]
    if not rows:
        return []
    return (["effects (docs/reality-gap.md):"]
            + [f"  {_short(row)}: {_effects_summary(row['effects'])}" for row in rows])


_TABLE = (  # header, row key, formatter
    ("world", "world", str), ("start", "start", lambda v: v or "-"), ("profile", "profile", str),
    ("seed", "seed", str), ("sim s", "sim_time_s", lambda v: f"{v:.0f}"),
    ("collisions", "collisions", str),
    ("1st coll. s", "first_collision_time_s", lambda v: f"{v:.1f}"),
    ("min clear. cm", "min_clearance_m", lambda v: f"{v * 100:.1f}"),
    ("distance m", "distance_m", lambda v: f"{v:.1f}"), ("laps", "laps", str),
    ("explored %", "explored_fraction", lambda v: f"{v * 100:.0f}"),
    ("RMS err. cm", "rms_wall_error_m", lambda v: f"{v * 100:.1f}"),
    ("invalid cmds", "invalid_commands", str),
    ("wall s", "wall_time_s", lambda v: f"{v:.1f}"),
)
_NAVIGATION_TABLE = (
    ("world", "world", str), ("start", "start", lambda v: v or "-"), ("goal", "goal", str),
    ("profile", "profile", str), ("seed", "seed", str),
    ("collisions", "collisions", str),
    ("min clear. cm", "min_clearance_m", lambda v: f"{v * 100:.1f}"),
    ("localized s", "localized_time_s", lambda v: f"{v:.1f}"),
    ("reached s", "goal_reached_time_s", lambda v: f"{v:.1f}"),
    ("stopped s", "stopped_time_s", lambda v: f"{v:.1f}"),
    ("final err. cm", "final_position_error_m", lambda v: f"{v * 100:.1f}"),
    ("path m", "path_length_m", lambda v: f"{v:.2f}"), ("plans", "plans", str),
    ("wall s", "wall_time_s", lambda v: f"{v:.1f}"),
)
_LEFT_ALIGNED = {"world", "map", "start", "goal", "profile"}


def format_table(rows: Iterable[Mapping[str, Any]]) -> str:
    """Aligned text table of outcome rows; an episode that failed shows its error instead."""
    rows = list(rows)
    table = _NAVIGATION_TABLE if any(r.get("goal") for r in rows) else _TABLE
    if any(r.get("map") for r in rows):
        table = (table[0], ("map", "map", str), *table[1:])
    cells = [[h for h, _, _ in table]]
    errors: list[str] = []
    for row in rows:
        line = []
        for _, key, fmt in table:
            value = row.get(key)
            line.append("-" if value is None else fmt(value))
        cells.append(line)
        if row.get("error"):
            errors.append(f"  {row['world']}/{row['start'] or '-'}/{row['profile']}/seed "
                          f"{row['seed']}: ERROR {row['error']}")
    widths = [max(len(r[i]) for r in cells) for i in range(len(table))]
    lines = []
    for r in cells:
        lines.append("  ".join(c.ljust(w) if table[i][1] in _LEFT_ALIGNED else c.rjust(w)
                               for i, (c, w) in enumerate(zip(r, widths))).rstrip())
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines + errors + effects_block(rows))


def verdict(outcomes: Sequence[EpisodeOutcome]) -> tuple[str, int]:
    """One summary line and the exit code.

    0 clean, 1 any collision, invalid command (NaN, inf, not a number: the simulator stopped
    the robot instead) or navigation goal not reached, 3 any episode failed.
    """
    rows = [outcome_row(o) for o in outcomes]
    failed = [r for r in rows if r["error"]]
    collided = [r for r in rows if not r["error"] and (r["collisions"] or 0) > 0]
    invalid = [r for r in rows if not r["error"] and (r["invalid_commands"] or 0) > 0]
    navigating = [r for r in rows if r.get("goal") and not r["error"]]
    missed = [r for r in navigating if not r["goal_reached"]]
    clear = [r for r in rows if r["min_clearance_m"] is not None]
    parts = []
    if invalid:
        names = ", ".join(f"{_short(r)} ({r['invalid_commands']})" for r in invalid[:5])
        more = f" and {len(invalid) - 5} more" if len(invalid) > 5 else ""
        parts.append(f"INVALID COMMANDS in {len(invalid)}/{len(rows)} episodes: {names}{more}")
    if collided:
        names = ", ".join(f"{_short(r)} ({r['collisions']})" for r in collided[:5])
        more = f" and {len(collided) - 5} more" if len(collided) > 5 else ""
        parts.append(f"COLLISIONS in {len(collided)}/{len(rows)} episodes: {names}{more}")
    else:
        parts.append(f"no collisions in {len(rows) - len(failed)}/{len(rows)} episodes")
    if clear:
        worst = min(clear, key=lambda r: r["min_clearance_m"])
        parts.append(f"worst clearance {worst['min_clearance_m'] * 100:.1f} cm ({_short(worst)})")
    if navigating:
        reached = len(navigating) - len(missed)
        errors = [r["final_position_error_m"] for r in navigating if r["goal_reached"]]
        parts.append(f"goal reached in {reached}/{len(navigating)} episodes"
                     + (f" (final error <= {max(errors) * 100:.1f} cm)" if errors else "")
                     + ("; NOT reached: " + ", ".join(_short(r) for r in missed[:5])
                        if missed else ""))
    if failed:
        parts.append(f"{len(failed)} episode(s) FAILED to run")
    code = 3 if failed else 1 if collided or invalid or missed else 0
    return "verdict: " + "; ".join(parts), code


def _short(row: Mapping[str, Any]) -> str:
    goal = f"->{row['goal']}" if row.get("goal") else ""
    return f"{row['world']}/{row['start'] or '-'}{goal}/{row['profile']}/seed {row['seed']}"


class ProgressBar:
    """A one-line progress bar redrawn in place, drawn only when the stream is a terminal."""

    def __init__(self, total: int, stream: TextIO | None = None, width: int = 30) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = bool(getattr(self.stream, "isatty", lambda: False)())
        self.total, self.width = max(int(total), 1), width
        self.start = time.monotonic()

    def __call__(self, done: int, total: int, outcome: EpisodeOutcome | None = None) -> None:
        """Redraw the bar for `done` of `total` episodes (the run_episodes progress hook)."""
        if not self.enabled:
            return
        fraction = min(done / max(total, 1), 1.0)
        filled = int(round(fraction * self.width))
        elapsed = time.monotonic() - self.start
        eta = elapsed * (total - done) / done if done else 0.0
        self.stream.write(f"\r[{'#' * filled}{'-' * (self.width - filled)}] {done}/{total} "
                          f"episodes  {elapsed:5.0f} s elapsed, ~{eta:4.0f} s left ")
        self.stream.flush()

    def finish(self) -> None:
        """Erase the bar."""
        if self.enabled:
            self.stream.write("\r" + " " * (self.width + 60) + "\r")
            self.stream.flush()
