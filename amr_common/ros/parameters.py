"""Typed ROS parameters that take an integer wherever a double is expected.

rclpy types a parameter by its default: after `declare_parameter("kp", 10.0)`, `-p kp:=5`,
`kp: 5` in a params file or a `Parameter("kp", value=5)` override raise
InvalidParameterTypeException in the node's constructor, which kills the executable. Here
numeric parameters (int, double and double-array defaults) are declared with dynamic typing (the
descriptor still names the intended type), an integer given for a double is stored as a double,
and `read_parameters` returns every value in its declared type or names each one that is not, so
on_configure can fail with a reason instead of the constructor raising. The tables are
amr_common.plugins.parameter_table's (plain Python, shared with the algorithms): an entry's rule
becomes the descriptor's floating_point_range / integer_range (and its words
additional_constraints), so `ros2 param describe` shows it and `ros2 param set` outside it is
refused, and read_parameters names every value outside its rule.

    PARAMETERS = {"kp": Param(10.0, "Proportional gain [rad/s/m]", at_least(0.0)), ...}
    declare_parameters(node, PARAMETERS)                     # in __init__
    values, problems = read_parameters(node, PARAMETERS)     # in on_configure

A value given at start-up (-p, a params file) outside its range would make rclpy raise in the
constructor (the process dies): the range is set on the descriptor only once the value fits
it, and on_configure reports the value that does not.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from amr_common.plugins.parameter_table import ParameterTable, Rule, check_value, finite, rule_of

_INT64_MAX = 2 ** 63 - 1

_NUMERIC_TYPES = (ParameterType.PARAMETER_INTEGER, ParameterType.PARAMETER_DOUBLE,
                  ParameterType.PARAMETER_DOUBLE_ARRAY)


def parameter_type(default: Any) -> int:
    """The ParameterType a default value stands for (an empty list: a double array)."""
    if isinstance(default, (list, tuple)) and len(default) == 0:
        return ParameterType.PARAMETER_DOUBLE_ARRAY
    return Parameter.Type.from_parameter_value(default).value


def declare_parameters(node: Node, table: ParameterTable,
                       types: Mapping[str, int] | None = None) -> None:
    """Declare every parameter of `table` not yet declared; numbers accept ints for doubles.

    `types` gives the ParameterType of names whose default does not show it.
    """
    for name, entry in table.items():
        if node.has_parameter(name):
            continue
        default, description = entry
        type_ = (types or {}).get(name, parameter_type(default))
        numeric = type_ in _NUMERIC_TYPES
        node.declare_parameter(name, default, ParameterDescriptor(
            description=description, type=type_, dynamic_typing=numeric))
        value = node.get_parameter(name).value
        if type_ == ParameterType.PARAMETER_DOUBLE and _is_integer(value):
            node.set_parameters([Parameter(name, Parameter.Type.DOUBLE, float(value))])
        rule = rule_of(entry)
        if rule is not None and check_value(name, entry, node.get_parameter(name).value)[1] \
                is None:  # a value outside it stays, for on_configure to report
            node.set_descriptor(name, ranged_descriptor(description, type_, numeric, rule))


def ranged_descriptor(description: str, type_: int, dynamic_typing: bool,
                      rule: Rule) -> ParameterDescriptor:
    """The descriptor of a parameter with a rule: its range and the rule in words.

    ROS ranges are closed: an excluded bound (> 0) is the range's end, and the words say it.
    """
    descriptor = ParameterDescriptor(description=description, type=type_,
                                     dynamic_typing=dynamic_typing,
                                     additional_constraints=rule.text())
    if rule.low is None and rule.high is None:
        return descriptor
    if type_ == ParameterType.PARAMETER_DOUBLE:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=-math.inf if rule.low is None else float(rule.low),
            to_value=math.inf if rule.high is None else float(rule.high), step=0.0)]
    elif type_ == ParameterType.PARAMETER_INTEGER:
        descriptor.integer_range = [IntegerRange(
            from_value=-_INT64_MAX - 1 if rule.low is None else math.ceil(rule.low),
            to_value=_INT64_MAX if rule.high is None else math.floor(rule.high), step=1)]
    return descriptor


def read_parameters(node: Node, table: ParameterTable,
                    types: Mapping[str, int] | None = None) -> tuple[dict[str, Any], list[str]]:
    """Every parameter of `table` in its declared type (ints as floats for doubles).

    Returns (values, problems): a problem names a parameter whose value has the wrong type or
    is outside its rule (it keeps its raw value in `values`).
    """
    return typed_values(table, {name: node.get_parameter(name).value for name in table}, types)


def typed_values(table: ParameterTable, values: Mapping[str, Any],
                 types: Mapping[str, int] | None = None) -> tuple[dict[str, Any], list[str]]:
    """`values` (names of `table`) in their declared types, as a node would read them.

    What read_parameters does for a node's values, for values not yet given to a node (the run
    scripts check -p overrides with it before any node exists). Returns (values, problems).
    """
    typed: dict[str, Any] = {}
    problems: list[str] = []
    for name, value in values.items():
        type_ = (types or {}).get(name, parameter_type(table[name][0]))
        typed[name], problem = _as_declared(name, value, type_)
        if problem is None and rule_of(table[name]) is not None:
            problem = check_value(name, table[name], typed[name])[1]
        if problem:
            problems.append(problem)
    return typed, problems


def _is_integer(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _as_declared(name: str, value: Any, type_: int) -> tuple[Any, str | None]:
    if type_ == ParameterType.PARAMETER_DOUBLE:
        if _is_integer(value) or isinstance(value, float):
            return float(value), None
        return value, f"{name} must be a number (got {value!r})"
    if type_ == ParameterType.PARAMETER_INTEGER:
        if _is_integer(value):
            return value, None
        return value, f"{name} must be an integer (got {value!r})"
    if type_ == ParameterType.PARAMETER_DOUBLE_ARRAY:
        if value is None:
            return [], None
        items = list(value) if isinstance(value, (list, tuple)) or hasattr(value, "tolist") \
            else None
        if items is not None and all(_is_integer(v) or isinstance(v, float) for v in items):
            return [float(v) for v in items], None
        return value, f"{name} must be a list of numbers (got {value!r})"
    # Statically typed: a node's value already has its type (rclpy refuses others); values not
    # yet given to a node may not (rclpy would raise in the node's constructor).
    if type_ == ParameterType.PARAMETER_BOOL and not isinstance(value, bool):
        return value, f"{name} must be true or false (got {value!r})"
    if type_ == ParameterType.PARAMETER_STRING and not isinstance(value, str):
        return value, f"{name} must be a string (got {value!r})"
    return value, None


__all__ = ["ParameterTable", "parameter_type", "declare_parameters", "ranged_descriptor",
           "read_parameters", "typed_values", "finite"]


def declare_link(node: Node, link: str, own: ParameterTable) -> tuple[type | None, dict]:
    """Declare the node's `link` parameter and its class's tuning ones; (class, tuning table).

    The `link` parameter is a MODULE:CLASS (amr_common.plugins.interfaces); the tuning parameters
    come from the class's `parameter_descriptions()`.

    Read at construction so the class's parameters can be declared (and set with -p). A class
    that cannot be loaded is logged, (None, {}) returned: configure then fails with the reason.
    """
    from amr_common.plugins.loader import PluginSpecError, link_parameters, load_class
    declare_parameters(node, {link: own[link]})
    try:
        cls = load_class(str(node.get_parameter(link).value), link)
    except PluginSpecError as exc:
        node.get_logger().error(f"{exc} (configure will fail)")
        return None, {}
    tuning = link_parameters(cls, own)
    declare_parameters(node, tuning)
    return cls, tuning

