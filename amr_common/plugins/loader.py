"""Load a user's class for a link of the chain from "MODULE:CLASS"; parse `name:=value` overrides.

One loader for every link (amr_common.plugins.interfaces): the controller (wall follower), the
localizer, the planner, the path follower and the mapper. The same spec works as a node
parameter (`controller`, `localizer`, `planner`, `follower`, `mapper`) and in run_sim.py,
evaluate.py and tune.py (`--controller`, `--localizer`, ...), so users can run their own class
anywhere. A spec that cannot be loaded, or a class that lacks a member of its interface, is a
PluginSpecError naming what is missing.
"""
from __future__ import annotations

import importlib
import math
import re
from typing import Any

from amr_common.plugins import interfaces

DEFAULT_CONTROLLER = "amr_control.wall_follower:WallFollower"
DEFAULT_LOCALIZER = "amr_localization.particle_filter:ParticleFilter"
DEFAULT_PLANNER = "amr_planning.planner:Planner"
DEFAULT_FOLLOWER = "amr_control.pure_pursuit:PurePursuit"
DEFAULT_MAPPER = "amr_mapping.mapper:Mapper"

# link -> (its interface, the project's class)
LINKS: dict[str, tuple[type, str]] = {
    "controller": (interfaces.Controller, DEFAULT_CONTROLLER),
    "localizer": (interfaces.Localizer, DEFAULT_LOCALIZER),
    "planner": (interfaces.Planner, DEFAULT_PLANNER),
    "follower": (interfaces.PathFollower, DEFAULT_FOLLOWER),
    "mapper": (interfaces.Mapper, DEFAULT_MAPPER),
}
_SIGNATURES = {"compute_commands": "compute_commands(z_scan, z_v, z_w)"}


class PluginSpecError(ValueError):
    """A class spec (any link) cannot be loaded; the message says why."""


def load_class(spec: str, link: str = "controller") -> type:
    """Import "package.module:ClassName" for `link` and check it has its interface's members.

    PluginSpecError (one line, naming the link and the spec) for a malformed spec, a module
    that does not import, a missing class, or a class that lacks members of the interface.
    """
    interface, default = LINKS[link]
    module_name, sep, class_name = str(spec).strip().partition(":")
    if not sep or not module_name or not class_name:
        raise PluginSpecError(f"{link} '{spec}' must look like MODULE:CLASS, "
                                  f"e.g. '{default}'")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # ImportError, or whatever the module raises (SyntaxError, ...)
        raise PluginSpecError(f"{link} '{spec}': cannot import module "
                                  f"'{module_name}': {_one_line(exc)}") from exc
    cls = getattr(module, class_name, None)
    if cls is None:
        raise PluginSpecError(f"{link} '{spec}': module '{module_name}' has no "
                                  f"'{class_name}'")
    missing = interfaces.missing_members(cls, interface)
    if missing:
        names = ", ".join(_SIGNATURES.get(name, name) for name in missing)
        raise PluginSpecError(f"{link} '{spec}' has no {names} (the {interface.__name__} "
                                  f"interface, amr_common.plugins.interfaces)")
    return cls


def link_class(spec_or_class: Any, link: str) -> type:
    """A class for `link`: loaded from a "MODULE:CLASS" string, or the class itself."""
    return load_class(spec_or_class, link) if isinstance(spec_or_class, str) else spec_or_class


def load_controller_class(spec: str) -> type:
    """Import "package.module:ClassName" and check it has compute_commands()."""
    return load_class(spec, "controller")


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
            raise PluginSpecError(f"value '{text}' is not finite")
        return value
    return text


def parse_overrides(items: list[str] | None) -> dict[str, Any]:
    """Parse ["kp:=4.0", "follow_side:=left"] into {"kp": 4.0, "follow_side": "left"}."""
    overrides: dict[str, Any] = {}
    for item in items or []:
        name, sep, value = item.partition(":=")
        name = name.strip()
        if not sep or not name:
            raise PluginSpecError(f"override '{item}' must look like name:=value")
        if not _PARAMETER_NAME.match(name):
            raise PluginSpecError(
                f"override '{item}': '{name}' is not a parameter name (letters, digits and '_', "
                f"parts joined by '.'; names starting with '__' are rcl's own arguments)")
        try:
            overrides[name] = parse_value(value)
        except ValueError as exc:
            raise PluginSpecError(f"override '{item}': {exc}") from None
    return overrides


def described_parameters(controller_class: Any) -> dict[str, tuple[Any, str]] | None:
    """The class's tuning parameters: name -> (default, description).

    From its `parameter_descriptions()`; None if the class describes none (then any keyword
    may be valid).
    """
    described = getattr(controller_class, "parameter_descriptions", None)
    return dict(described()) if callable(described) else None


def link_parameters(cls: Any, own: Any = ()) -> dict[str, tuple[Any, str]]:
    """The tuning parameters a node declares for a loaded class: name -> (default, description).

    Its `parameter_descriptions()` without the node's own names (`own`) and use_sim_time.
    """
    table = described_parameters(cls) or {}
    return {name: spec for name, spec in table.items()
            if name not in own and name != "use_sim_time"}

