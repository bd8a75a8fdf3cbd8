"""Load a user's controller class from "MODULE:CLASS" and parse `name:=value` overrides.

The same spec works in the wall_follower node (`controller` parameter), run_sim.py and
evaluate.py (`--controller`), so users can run their own `compute_commands` class anywhere.
"""
from __future__ import annotations

import importlib
import math
import re
from typing import Any

DEFAULT_CONTROLLER = "amr_control.wall_follower:WallFollower"


class ControllerSpecError(ValueError):
    """The controller spec cannot be loaded; the message says why."""


def load_controller_class(spec: str) -> type:
    """Import "package.module:ClassName" and check it has compute_commands()."""
    module_name, sep, class_name = spec.strip().partition(":")
    if not sep or not module_name or not class_name:
        raise ControllerSpecError(f"controller '{spec}' must look like MODULE:CLASS, "
                                  f"e.g. '{DEFAULT_CONTROLLER}'")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # ImportError, or whatever the module raises (SyntaxError, ...)
        raise ControllerSpecError(f"controller '{spec}': cannot import module "
                                  f"'{module_name}': {_one_line(exc)}") from exc
    cls = getattr(module, class_name, None)
    if cls is None:
        raise ControllerSpecError(f"controller '{spec}': module '{module_name}' has no "
                                  f"'{class_name}'")
    if not callable(getattr(cls, "compute_commands", None)):
        raise ControllerSpecError(f"controller '{spec}' has no compute_commands(z_scan, z_v, "
                                  f"z_w) method")
    return cls


def _one_line(exc: BaseException) -> str:
    """'SyntaxError: invalid syntax (ctrl.py, line 3)': the exception's type and message."""
    text = " ".join(str(exc).split())
    if isinstance(exc, ImportError):
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


# A ROS parameter name: words of letters, digits and '_' joined by '.', not starting with '__'
# (rcl's own arguments: __node, __ns, __log_level ...). No remapping syntax (':', '/', '~').
_PARAMETER_NAME = re.compile(r"^(?!__)[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")


def parse_value(text: str) -> Any:
    """Type a command-line value like ROS does: bool, int, float, [list of those], else string.

    `[1.0, 2, 3]` is a list (as `-p name:=[1.0, 2, 3]` in ROS); ValueError for a non-finite
    number.
    """
    stripped = text.strip()
    if stripped.startswith("[") and stripped.endswith("]"):
        inner = stripped[1:-1].strip()
        return [parse_value(item.strip()) for item in inner.split(",")] if inner else []
    lowered = stripped.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    for cast in (int, float):
        try:
            value = cast(text)
        except ValueError:
            continue
        if isinstance(value, float) and not math.isfinite(value):
            raise ControllerSpecError(f"value '{text}' is not finite")
        return value
    return text


def parse_overrides(items: list[str] | None) -> dict[str, Any]:
    """Parse ["kp:=4.0", "follow_side:=left"] into {"kp": 4.0, "follow_side": "left"}."""
    overrides: dict[str, Any] = {}
    for item in items or []:
        name, sep, value = item.partition(":=")
        name = name.strip()
        if not sep or not name:
            raise ControllerSpecError(f"override '{item}' must look like name:=value")
        if not _PARAMETER_NAME.match(name):
            raise ControllerSpecError(
                f"override '{item}': '{name}' is not a parameter name (letters, digits and '_', "
                f"parts joined by '.'; names starting with '__' are rcl's own arguments)")
        try:
            overrides[name] = parse_value(value)
        except ValueError as exc:
            raise ControllerSpecError(f"override '{item}': {exc}") from None
    return overrides


def described_parameters(controller_class: Any) -> dict[str, tuple[Any, str]] | None:
    """The class's tuning parameters: name -> (default, description).

    From its `parameter_descriptions()`; None if the class describes none (then any keyword
    may be valid).
    """
    described = getattr(controller_class, "parameter_descriptions", None)
    return dict(described()) if callable(described) else None
