#!/usr/bin/env python3
"""Set two evaluate.py result sets side by side: where does one link do better than the other?

Each row is one world / start [/ goal] / profile (its seeds together), with A's figure then B's:
false localizations (a wrong pose declared localized), failed episodes (errors), the tracking
error while localized (cm), the smallest clearance from the walls (cm), goals reached, and the
time (to the goal in navigation sets, to localized in --localize sets). A '*' marks a row where
the two sets differ in false localizations, errors or goals reached. Rows only one set has
show '-' for the other.

Examples:
  .venv/bin/python scripts/evaluate.py --worlds lab02,twin_maze --goals all --seeds 0-2 \
      --duration 200 --out out/project
  .venv/bin/python scripts/evaluate.py --worlds lab02,twin_maze --goals all --seeds 0-2 \
      --duration 200 --localizer examples.likelihood_mcl:LikelihoodFieldMcl --out out/mcl
  .venv/bin/python scripts/compare.py out/project/results.json out/mcl/results.json
Exit code: 0, or 2 for a file that is not an evaluate.py result set.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

# (header, how a group's rows become one figure, format)
_COLUMNS = [
    ("false", lambda rows: sum(r.get("false_localizations") or 0 for r in rows), "{}"),
    ("errors", lambda rows: sum(bool(r.get("error")) for r in rows), "{}"),
    ("track_cm", lambda rows: _mean(rows, "tracking_error_mean_m", 100.0), "{:.1f}"),
    ("clear_cm", lambda rows: _least(rows, "min_clearance_m", 100.0), "{:.1f}"),
    ("goals", lambda rows: _goals(rows), "{}"),
    ("time_s", lambda rows: _mean(rows, "goal_reached_time_s")
     if any("goal" in r for r in rows) else _mean(rows, "time_to_localized_s"), "{:.1f}"),
]
_DIFFERS = ("false", "errors", "goals")


def load_results(path: str) -> tuple[list[dict[str, Any]], str]:
    """The episode rows of an evaluate.py results.json (any kind), and a label for the set."""
    source = Path(path)
    if source.is_dir():
        source = source / "results.json"
    try:
        data = json.loads(source.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable results.json ({exc})") from None
    rows = data.get("episodes") if isinstance(data, dict) else None
    if not isinstance(rows, list) or not all(isinstance(r, dict) and "world" in r
                                             for r in rows):
        raise ValueError(f"{path}: not an evaluate.py result set (no 'episodes' rows)")
    meta = data.get("meta") or data.get("summary") or {}
    links = meta.get("links") or {}
    if meta.get("localizer"):
        links = {"localizer": meta["localizer"], **links}
    label = ", ".join(f"{k} {v}" for k, v in links.items()) or "the project's links"
    return rows, label


def group_key(row: dict[str, Any]) -> tuple[str, ...]:
    """world[@map] / start [/ goal] / profile."""
    world = f"{row['world']}@{row['map']}" if row.get("map") else str(row["world"])
    return (world, str(row.get("start")), str(row.get("goal") or "-"), str(row.get("profile")))


def compare(a_rows: list[dict], b_rows: list[dict]) -> list[list[str]]:
    """The table: a header, then one line per group of either set (in A's order, then B's)."""
    groups: dict[tuple[str, ...], tuple[list, list]] = {}
    for index, rows in enumerate((a_rows, b_rows)):
        for row in rows:
            groups.setdefault(group_key(row), ([], []))[index].append(row)
    header = ["world", "start", "goal", "profile", "n"] + [
        f"{name} A|B" for name, _, _ in _COLUMNS] + [""]
    table = [header]
    for key, (a, b) in groups.items():
        cells, differs = [], False
        for name, figure, fmt in _COLUMNS:
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


def _values(rows, key, scale=1.0):
    return [r[key] * scale for r in rows if isinstance(r.get(key), (int, float))
            and not isinstance(r.get(key), bool) and math.isfinite(r[key])]


def _mean(rows, key, scale=1.0):
    values = _values(rows, key, scale)
    return sum(values) / len(values) if values else None


def _least(rows, key, scale=1.0):
    values = _values(rows, key, scale)
    return min(values) if values else None


def _goals(rows):
    if not any("goal_reached" in r for r in rows):
        return None
    return f"{sum(bool(r.get('goal_reached')) for r in rows)}/{len(rows)}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("a", help="results.json (or its folder) of set A")
    parser.add_argument("b", help="results.json (or its folder) of set B")
    args = parser.parse_args(argv)
    try:
        (a_rows, a_label), (b_rows, b_label) = load_results(args.a), load_results(args.b)
    except ValueError as exc:
        print(f"compare: {exc}", file=sys.stderr)
        return 2
    print(f"A: {args.a} ({a_label})\nB: {args.b} ({b_label})")
    print(format_table(compare(a_rows, b_rows)))
    totals = [sum(r.get("false_localizations") or 0 for r in rows) for rows in (a_rows, b_rows)]
    print(f"false localizations: A {totals[0]}, B {totals[1]}; episodes: A {len(a_rows)}, "
          f"B {len(b_rows)}")
    return 0


if __name__ == "__main__":
    from script_endings import run_script  # a closed output loses nothing
    sys.exit(run_script(main))
