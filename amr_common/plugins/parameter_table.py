"""Parameter tables: name -> (default, description[, rule]), the form every algorithm declares.

Plain Python (no rclpy). The default's type is the parameter's type (bool, int, float, str, a
list of strings, or another list: a vector of numbers); the optional rule says which values are
allowed (a range, the choices, a vector's lengths). From one table come the defaults, the
constructor checks of the algorithms (`checked_values`), the run scripts' option checks, and
the ROS parameters of the nodes with their ranges (amr_common.ros.parameters: `ros2 param describe`
shows them).

    PARAMETERS = {
        "kp": Param(10.0, "Proportional gain [rad/s/m]", at_least(0.0)),
        "side": Param("right", "Wall kept on this side", one_of("right", "left")),
        "offset_m": (0.0, "Any finite number [m]"),          # a plain pair: no rule
    }
    values = checked_values(PARAMETERS, {"kp": 5}, "WallFollower")  # {"kp": 5.0, ...}
    # A long table whose numbers share a rule: ruled(TABLE, at_least(0.0), offset_m=None)

A Param is still a (default, description) pair (`default, description = entry` works), so
tables of the old form, such as a user's controller's parameter_descriptions(), keep working;
its `rule` is the addition. Checks that involve several parameters stay with their owner.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

# name -> (default, description) or Param(default, description, rule)
ParameterTable = Mapping[str, tuple[Any, str]]

# The largest seed of every seeded part (simulator, filter, evaluate's --seeds, the searchers of
# tune.py): numpy's legacy generators, which Optuna's and Ray Tune's searchers use, take 32 bits,
# and one range keeps a seed valid in every script (a larger one overflowed a ROS parameter).
MAX_SEED = 2**32 - 1


@dataclass(frozen=True)
class Rule:
    """The allowed values of one parameter, beyond its type.

    Numbers (and each number of a vector): within [low, high] (None: unbounded; *_open: the
    bound itself excluded). Strings: one of `choices` (matched without case). Vectors: a
    length in `lengths` (empty: any).
    """

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] = ()
    lengths: tuple[int, ...] = ()

    def allows(self, number: float) -> bool:
        """True if `number` is within the range."""
        if self.low is not None and (number < self.low or (self.low_open and number == self.low)):
            return False
        return self.high is None or not (number > self.high or
                                         (self.high_open and number == self.high))

    def range_text(self) -> str:
        """'>= 0', '> 0', '<= 1', 'in [0, 1]', 'in (0, 1.5708)' ... ('' without bounds)."""
        low, high = _bound(self.low), _bound(self.high)
        if low is not None and high is not None:
            return (f"in {'(' if self.low_open else '['}{low}, {high}"
                    f"{')' if self.high_open else ']'}")
        if low is not None:
            return f"{'>' if self.low_open else '>='} {low}"
        if high is not None:
            return f"{'<' if self.high_open else '<='} {high}"
        return ""

    def text(self) -> str:
        """The whole rule in words (the ROS descriptor's additional_constraints)."""
        parts = []
        if self.choices:
            parts.append("one of: " + ", ".join(self.choices))
        if self.lengths:
            parts.append(_lengths_text(self.lengths))
        if self.range_text():
            parts.append(("each " if self.lengths else "") + self.range_text())
        return "; ".join(parts)


def _bound(value: float | None) -> str | None:
    """A range's bound as a message shows it: an integer in full (4294967295), else %g."""
    if value is None:
        return None
    return str(int(value)) if float(value).is_integer() and abs(value) < 2**53 else f"{value:g}"


def at_least(low: float) -> Rule:
    """Numbers >= low."""
    return Rule(low=low)


def above(low: float) -> Rule:
    """Numbers > low."""
    return Rule(low=low, low_open=True)


def at_most(high: float) -> Rule:
    """Numbers <= high."""
    return Rule(high=high)


def between(low: float, high: float, low_open: bool = False, high_open: bool = False) -> Rule:
    """Numbers in [low, high] (either bound excluded with low_open / high_open)."""
    return Rule(low=low, high=high, low_open=low_open, high_open=high_open)


def one_of(*choices: str) -> Rule:
    """One of these strings (given in any case; the value becomes the listed spelling)."""
    return Rule(choices=tuple(choices))


def vector(*lengths: int, low: float | None = None) -> Rule:
    """A list of finite numbers of one of these lengths, each >= low if given."""
    return Rule(low=low, lengths=tuple(lengths))


class Param(tuple):
    """A table entry: the pair (default, description), plus the `rule` of its allowed values."""

    rule: Rule | None

    def __new__(cls, default: Any, description: str, rule: Rule | None = None) -> "Param":
        """Param(default, description, rule): rule None = any value of the default's type."""
        entry = super().__new__(cls, (default, description))
        entry.rule = rule
        return entry

    def __getnewargs__(self):  # pickling keeps the rule
        return (self[0], self[1], self.rule)


def ruled(table: Mapping[str, tuple[Any, str]], numbers: Rule | None = None,
          **rules: Rule | None) -> dict[str, Param]:
    """The table's entries as Params: `rules` by name, `numbers` for the other numbers.

    For tables whose numbers mostly share a rule (">= 0"): name the exceptions, None for any
    value. A name the table lacks raises (a typo would silently lose its rule).
    """
    unknown = sorted(set(rules) - set(table))
    if unknown:
        raise ValueError(f"rules for unknown parameter(s) {unknown}")
    out = {}
    for name, (default, description, *_) in table.items():
        number = finite(default) and not isinstance(default, bool)
        out[name] = Param(default, description,
                          rules[name] if name in rules else numbers if number else None)
    return out


def rule_of(entry: tuple) -> Rule | None:
    """The rule of a table entry (None for a plain (default, description) pair)."""
    return getattr(entry, "rule", None)


def defaults(table: ParameterTable) -> dict[str, Any]:
    """Name -> default of every parameter."""
    return {name: entry[0] for name, entry in table.items()}


def table_values(table: ParameterTable, overrides: Mapping[str, Any] | None,
                 owner: str) -> dict[str, Any]:
    """Every parameter's default, updated with `overrides` (not checked otherwise).

    Raises ValueError "<owner>: unknown parameter(s) [...]; known: [...]" for a name the table
    does not have.
    """
    overrides = overrides or {}
    unknown = sorted(set(overrides) - set(table))
    if unknown:
        raise ValueError(f"{owner}: unknown parameter(s) {unknown}; known: {sorted(table)}")
    values = defaults(table)
    values.update(overrides)
    return values


def check_values(table: ParameterTable, values: Mapping[str, Any]
                 ) -> tuple[dict[str, Any], list[str]]:
    """`values` (names of `table`) checked against their types and rules, and normalised.

    Returns (values, problems): floats as float, integers as int (an integral float is taken),
    booleans as bool (also 'true' / 'false'), choices in their listed spelling, vectors as
    tuples of floats; a value with a problem keeps its raw form, and its problem names it.
    """
    checked: dict[str, Any] = {}
    problems: list[str] = []
    for name, value in values.items():
        checked[name], problem = check_value(name, table[name], value)
        if problem:
            problems.append(problem)
    return checked, problems


def checked_values(table: ParameterTable, overrides: Mapping[str, Any] | None,
                   owner: str | None = None) -> dict[str, Any]:
    """Every parameter's value (defaults updated with `overrides`), checked and normalised.

    ValueError naming every problem (prefixed "<owner>: " if given), or the unknown names.
    """
    values, problems = check_values(table, table_values(table, overrides, owner or "parameters"))
    if problems:
        raise ValueError((f"{owner}: " if owner else "") + "; ".join(problems))
    return values


def check_value(name: str, entry: tuple, value: Any) -> tuple[Any, str | None]:
    """(normalised value, None) or (value, the problem) for one parameter (check_values)."""
    default, rule = entry[0], rule_of(entry) or Rule()
    if isinstance(default, bool):
        return _boolean(name, value)
    if isinstance(default, str):
        return _string(name, value, rule)
    if isinstance(default, (list, tuple)) and default and \
            all(isinstance(item, str) for item in default):  # a list of strings
        if isinstance(value, (list, tuple)) and all(isinstance(item, str) for item in value):
            return list(value), None
        return value, f"{name} must be a list of strings (got {value!r})"
    if isinstance(default, (list, tuple)):
        return _vector(name, value, rule)
    if isinstance(default, int):
        if not (finite(value) and int(value) == value):
            return value, f"{name} must be an integer (got {value!r})"
        value = int(value)
    elif isinstance(default, float):
        if not finite(value):
            return value, f"{name} must be a finite number (got {value!r})"
        value = float(value)
    else:
        return value, None
    if not rule.allows(value):
        return value, f"{name} must be {rule.range_text()} (got {value!r})"
    return value, None


def _boolean(name: str, value: Any) -> tuple[Any, str | None]:
    if isinstance(value, bool):
        return value, None
    if isinstance(value, str) and value.strip().lower() in ("true", "false"):
        return value.strip().lower() == "true", None
    return value, f"{name} must be true or false (got {value!r})"


def _string(name: str, value: Any, rule: Rule) -> tuple[Any, str | None]:
    if not isinstance(value, str):
        return value, f"{name} must be a string (got {value!r})"
    if not rule.choices:
        return value, None
    for choice in rule.choices:
        if value.strip().lower() == choice.lower():
            return choice, None
    return value, f"{name} must be one of {list(rule.choices)} (got {value!r})"


def _vector(name: str, value: Any, rule: Rule) -> tuple[Any, str | None]:
    try:
        items = list(value)
        ok = all(finite(v) for v in items) and (not rule.lengths or len(items) in rule.lengths)
    except TypeError:
        ok = False
    if not ok:
        shape = _lengths_text(rule.lengths) if rule.lengths else "a list of finite numbers"
        return value, f"{name} must be {shape} (got {value!r})"
    if not all(rule.allows(v) for v in items):
        return value, f"{name} must have each number {rule.range_text()} (got {items})"
    return tuple(float(v) for v in items), None


def _lengths_text(lengths: tuple[int, ...]) -> str:
    return " or ".join("[]" if n == 0 else f"{n} finite numbers" for n in lengths)


def finite(value: Any) -> bool:
    """True for a finite int or float (not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and \
        math.isfinite(value)


__all__ = ["ParameterTable", "Rule", "Param", "at_least", "above", "at_most", "between",
           "one_of", "vector", "ruled", "rule_of", "defaults", "table_values", "check_values",
           "check_value", "checked_values", "finite"]
