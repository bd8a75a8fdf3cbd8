#!/usr/bin/env python3
"""Set two evaluate.py result sets side by side: where does one link do better than the other?

Both sets must be of one kind: wall following, localization (--localize), navigation (--goals)
or mapping (--slam). Each side is labelled with the links its episodes ran (from the set's own
metadata). Each row is one world / start [/ goal] / profile (its seeds together), with A's
figure then B's:
  wall following  failed episodes, collisions, the smallest clearance from the walls (cm),
                  laps, the share explored (%), the RMS wall-distance error (cm)
  localization    failed, false localizations (a wrong pose declared localized), episodes
                  localized, time to localized (s), tracking error while localized (cm, mean
                  and the worst p95)
  navigation      failed, false localizations, collisions, goals reached, time to the goal
                  (s), tracking error (cm), smallest clearance (cm)
  mapping         failed, collisions, trajectory RMSE (cm, mean) and max (cm, worst), map
                  precision and recall (%, worst), loop closures (mean), update and loop
                  closure times (ms, median of the episodes' medians)
A '*' marks a row where the two sets differ in a count (failed, collisions, false
localizations, localized, goals). Rows only one set has show '-' for the other.

Examples:
  .venv/bin/python scripts/evaluate.py --worlds lab02,twin_maze --goals all --seeds 0-2 \
      --duration 200 --out out/project
  .venv/bin/python scripts/evaluate.py --worlds lab02,twin_maze --goals all --seeds 0-2 \
      --duration 200 --localizer examples.likelihood_mcl:LikelihoodFieldMcl --out out/mcl
  .venv/bin/python scripts/compare.py out/project/results.json out/mcl/results.json
  .venv/bin/python scripts/compare.py out/slam-project out/slam-odometry   # two --slam sets
Exit code: 0, or 2 for a file that is not an evaluate.py result set (a folder holding none,
not a regular file, over 100 MB, not its JSON) or two sets of different kinds.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path
from typing import Any, Callable

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(REPO))
from link_options import RESULT_KINDS, links_ran  # noqa: E402

from cli_checks import OneLineArgumentParser  # noqa: E402

# A results.json of 20,000 mapping episodes is about 40 MB; a bigger file is not one.
MAX_RESULTS_BYTES = 100_000_000

Column = tuple[str, Callable[[list[dict]], Any], str]


def _sum(key: str) -> Callable[[list[dict]], Any]:
    return lambda rows: sum(r.get(key) or 0 for r in rows)


def _failed(rows: list[dict]) -> int:
    return sum(bool(r.get("error")) for r in rows)


def _of(reduce: Callable[[list[float]], float], key: str, scale: float = 1.0
        ) -> Callable[[list[dict]], float | None]:
    """reduce() of the finite numbers of `key` (scaled), None without any."""
    def figure(rows: list[dict]) -> float | None:
        values = [r[key] * scale for r in rows if isinstance(r.get(key), (int, float))
                  and not isinstance(r.get(key), bool) and math.isfinite(r[key])]
        return reduce(values) if values else None
    return figure


def _mean(values: list[float]) -> float:
    return sum(values) / len(values)


def _share(key: str, reached: Callable[[Any], bool] = bool) -> Callable[[list[dict]], Any]:
    """'k/n': how many of the rows that report `key` have it reached."""
    def figure(rows: list[dict]) -> str | None:
        if not any(key in r for r in rows):
            return None
        return f"{sum(reached(r.get(key)) for r in rows)}/{len(rows)}"
    return figure


# kind -> (header, how a group's rows become one figure, format); counts mark differences
COLUMNS: dict[str, list[Column]] = {
    "wall_following": [
        ("failed", _failed, "{}"), ("collisions", _sum("collisions"), "{}"),
        ("clear_cm", _of(min, "min_clearance_m", 100.0), "{:.1f}"),
        ("laps", _of(_mean, "laps"), "{:.1f}"),
        ("explored_%", _of(_mean, "explored_fraction", 100.0), "{:.0f}"),
        ("wall_err_cm", _of(_mean, "rms_wall_error_m", 100.0), "{:.1f}")],
    "localization": [
        ("failed", _failed, "{}"), ("false", _sum("false_localizations"), "{}"),
        ("localized", _share("time_to_localized_s", lambda v: v is not None), "{}"),
        ("time_s", _of(_mean, "time_to_localized_s"), "{:.1f}"),
        ("track_cm", _of(_mean, "tracking_error_mean_m", 100.0), "{:.1f}"),
        ("p95_cm", _of(max, "tracking_error_p95_m", 100.0), "{:.1f}")],
    "navigation": [
        ("failed", _failed, "{}"), ("false", _sum("false_localizations"), "{}"),
        ("collisions", _sum("collisions"), "{}"), ("goals", _share("goal_reached"), "{}"),
        ("time_s", _of(_mean, "goal_reached_time_s"), "{:.1f}"),
        ("track_cm", _of(_mean, "tracking_error_mean_m", 100.0), "{:.1f}"),
        ("clear_cm", _of(min, "min_clearance_m", 100.0), "{:.1f}")],
    "mapping": [
        ("failed", _failed, "{}"), ("collisions", _sum("collisions"), "{}"),
        ("rmse_cm", _of(_mean, "trajectory_rmse_m", 100.0), "{:.2f}"),
        ("max_cm", _of(max, "trajectory_max_m", 100.0), "{:.2f}"),
        ("precision_%", _of(min, "precision", 100.0), "{:.1f}"),
        ("recall_%", _of(min, "recall", 100.0), "{:.1f}"),
        ("closures", _of(_mean, "loop_closures"), "{:.1f}"),
        ("update_ms", _of(statistics.median, "update_ms_median"), "{:.2f}"),
        ("closure_ms", lambda rows: _of(statistics.median, "loop_closure_ms_median")(
            [r for r in rows if r.get("loop_closures")]), "{:.1f}")],  # of the closures made
}
_DIFFERS = ("failed", "collisions", "false", "localized", "goals")
KIND_NAMES = {"wall_following": "wall-following", "localization": "localization (--localize)",
              "navigation": "navigation (--goals)", "mapping": "mapping (--slam)"}


class ResultSet:
    """An evaluate.py result set: its kind, the links it ran, its episode rows."""

    def __init__(self, path: str) -> None:
        data = read_results(path)
        rows = data.get("episodes") if isinstance(data, dict) else None
        if not isinstance(rows, list) or not all(isinstance(r, dict) and "world" in r
                                                 for r in rows):
            raise ValueError(f"{path}: not an evaluate.py result set (no 'episodes' rows)")
        meta = data.get("meta") or data.get("summary") or {}
        if not isinstance(meta, dict):
            raise ValueError(f"{path}: not an evaluate.py result set (its 'meta' is no mapping)")
        self.path, self.rows = path, rows
        self.kind = meta.get("kind") if meta.get("kind") in RESULT_KINDS else \
            _older_kind(meta, rows)
        # Older sets name only the links the user gave: the project's ran for the others.
        given = {**(meta.get("links") if isinstance(meta.get("links"), dict) else {}),
                 **{link: meta[link] for link in ("controller", "localizer", "mapper")
                    if isinstance(meta.get(link), str)}}
        self.links = links_ran(self.kind, given, str(meta.get("pose_source") or "filter"))

    @property
    def label(self) -> str:
        return ", ".join(f"{link} {spec}" for link, spec in self.links.items())


def read_results(path: str) -> Any:
    """The JSON of a results.json (or of a folder's): ValueError (one line) if it is not one.

    Only a regular file of at most MAX_RESULTS_BYTES is read (a device or a pipe would never
    end), and no more than that even if it grows meanwhile.
    """
    source = Path(path)
    if source.is_dir():
        source = source / "results.json"
    if not source.is_file():
        what = "no such file" if not source.exists() else "not a regular file"
        raise ValueError(f"{source}: not an evaluate.py result set ({what})")
    try:
        size = source.stat().st_size
        if size <= MAX_RESULTS_BYTES:
            with source.open("rb") as stream:
                raw = stream.read(MAX_RESULTS_BYTES + 1)
                size = len(raw)
    except OSError as exc:
        raise ValueError(f"{source}: cannot be read ({exc.strerror or exc})") from None
    if size > MAX_RESULTS_BYTES:
        raise ValueError(f"{source}: larger than {MAX_RESULTS_BYTES / 1e6:.0f} MB: not an "
                         "evaluate.py result set")
    try:
        return json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ValueError(f"{source}: not an evaluate.py result set (not its JSON: "
                         f"{' '.join(str(exc).split())[:120]})") from None


def _older_kind(meta: dict, rows: list[dict]) -> str:
    """The kind of a set written before evaluate.py recorded it, from its keys."""
    if "mapper" in meta or any("trajectory_rmse_m" in r for r in rows):
        return "mapping"
    if meta.get("goals") or any(r.get("goal") for r in rows):
        return "navigation"
    if "localizer" in meta or any("time_to_localized_s" in r for r in rows):
        return "localization"
    return "wall_following"


def group_key(row: dict[str, Any]) -> tuple[str, ...]:
    """world[@map] / start [/ goal] / profile."""
    world = f"{row['world']}@{row['map']}" if row.get("map") else str(row["world"])
    return (world, str(row.get("start")), str(row.get("goal") or "-"), str(row.get("profile")))


def compare(a_rows: list[dict], b_rows: list[dict], kind: str) -> list[list[str]]:
    """The table: a header, then one line per group of either set (in A's order, then B's)."""
    groups: dict[tuple[str, ...], tuple[list, list]] = {}
    for index, rows in enumerate((a_rows, b_rows)):
        for row in rows:
            groups.setdefault(group_key(row), ([], []))[index].append(row)
    columns = COLUMNS[kind]
    goals = kind == "navigation"
    header = ["world", "start", *(["goal"] if goals else []), "profile", "n"] + [
        f"{name} A|B" for name, _, _ in columns] + [""]
    table = [header]
    for key, (a, b) in groups.items():
        key = key if goals else (key[0], key[1], key[3])
        cells, differs = [], False
        for name, figure, fmt in columns:
            values = [figure(rows) if rows else None for rows in (a, b)]
            texts = ["-" if v is None else fmt.format(v) for v in values]
            cells.append(" | ".join(texts))
            differs |= name in _DIFFERS and None not in values and values[0] != values[1]
        counts = f"{len(a) or '-'}|{len(b) or '-'}"
        table.append([*key, counts, *cells, "*" if differs else ""])
    return table


def format_table(table: list[list[str]]) -> str:
    widths = [max(len(line[i]) for line in table) for i in range(len(table[0]))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(line, widths)).rstrip()
                     for line in table)


def totals_line(a: ResultSet, b: ResultSet) -> str:
    """The sets' episodes and failures, and the kind's main counts, A then B."""
    parts = [f"episodes: A {len(a.rows)}, B {len(b.rows)}",
             f"failed: A {_failed(a.rows)}, B {_failed(b.rows)}"]
    if a.kind in ("localization", "navigation"):
        false = [_sum("false_localizations")(s.rows) for s in (a, b)]
        parts.append(f"false localizations: A {false[0]}, B {false[1]}")
    if a.kind != "localization":
        hits = [_sum("collisions")(s.rows) for s in (a, b)]
        parts.append(f"collisions: A {hits[0]}, B {hits[1]}")
    return "; ".join(parts)


def main(argv: list[str] | None = None) -> int:
    parser = OneLineArgumentParser(prog="compare.py", description=__doc__.split("\n\n")[0],
                                   formatter_class=argparse.RawDescriptionHelpFormatter,
                                   epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("a", help="results.json (or its folder) of set A")
    parser.add_argument("b", help="results.json (or its folder) of set B")
    args = parser.parse_args(argv)
    try:
        a, b = ResultSet(args.a), ResultSet(args.b)
        if a.kind != b.kind:
            raise ValueError(f"A ({args.a}) is a {KIND_NAMES[a.kind]} set and B ({args.b}) a "
                             f"{KIND_NAMES[b.kind]} set: compare two sets of one kind")
    except ValueError as exc:
        print(f"compare: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("compare: interrupted", file=sys.stderr)
        return 130
    print(f"{KIND_NAMES[a.kind]} sets\nA: {args.a} ({a.label})\nB: {args.b} ({b.label})")
    print(format_table(compare(a.rows, b.rows, a.kind)))
    print(totals_line(a, b))
    return 0


if __name__ == "__main__":
    from script_endings import run_script  # a closed output loses nothing
    sys.exit(run_script(main))
