"""Parameter tables, name -> (default, description): the form every algorithm and node declares.

Plain Python (no rclpy): the algorithms check their constructor overrides against their table
with `table_values` and `finite`; amr_common.parameters declares the same tables as typed ROS
parameters.

    PARAMETERS = {"kp": (10.0, "Proportional gain [rad/s/m]"), "side": ("right", "...")}
    values = table_values(PARAMETERS, {"kp": 5}, "WallFollower")   # {"kp": 5, "side": "right"}
"""
from __future__ import annotations

import math
from typing import Any, Mapping

# name -> (default, description)
ParameterTable = Mapping[str, tuple[Any, str]]


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
    values = {name: default for name, (default, _) in table.items()}
    values.update(overrides)
    return values


def finite(value: Any) -> bool:
    """True for a finite int or float (not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and \
        math.isfinite(value)


__all__ = ["ParameterTable", "finite", "table_values"]
