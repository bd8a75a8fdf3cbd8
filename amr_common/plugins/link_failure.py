"""A link of the chain that failed: one rule for the nodes, the headless episodes, the scripts.

A link (a class of amr_common.plugins.interfaces: the controller, localizer, planner, follower or
mapper) fails when a call raises where its interface allows no exception, or returns what its
interface forbids: None, a wrong shape, NaN where finite numbers are due. Its output is then
worth nothing, and neither is the run: it fails.
- The nodes (GuardedLifecycleNode.fail_link) log the failure once (an error), stop using the
  link (the commanding nodes command zero, the planner publishes an empty path, the slam node
  maps no more and keeps the map it saved) and keep it in `link_failure`; the run scripts end
  the run there, failed (run_sim.py, run_robot.py: exit code 3, the reason in the summary line
  and the report).
- The headless episodes raise it: the episode is evaluate.py's FAILED one (exit code 3).

    v, w = checked_commands("controller", link_call("controller", "compute_commands",
                                                    controller.compute_commands, z, v, w))
"""
from __future__ import annotations

import math
import traceback
from numbers import Real
from typing import Any, Callable, Mapping

import numpy as np

LINK_FAILED = 3  # the exit code of a run whose link failed (evaluate.py's failed episode's too)


class LinkFailure(RuntimeError):
    """A link raised or returned what its interface forbids; the run it belongs to failed.

    `link`: "controller", "localizer", "planner", "follower" or "mapper"; `reason`: one line
    (which call, what it did); `time_s`: when (simulated or node time, s); `spec`: its class as
    MODULE:CLASS.
    """

    def __init__(self, link: str, reason: str, time_s: float | None = None,
                 spec: str | None = None) -> None:
        self.link, self.reason, self.time_s, self.spec = link, reason, time_s, spec
        super().__init__(str(self))

    def __str__(self) -> str:
        spec = f" '{self.spec}'" if self.spec else ""
        when = f" at t={self.time_s:.2f} s" if self.time_s is not None else ""
        return f"{self.link}{spec} failed{when}: {self.reason}"

    def __reduce__(self):  # pickled across worker processes with its fields
        return LinkFailure, (self.link, self.reason, self.time_s, self.spec)

    def placed(self, time_s: float | None = None, spec: str | None = None) -> "LinkFailure":
        """The same failure with its time and class filled in where it had none."""
        return LinkFailure(self.link, self.reason,
                           self.time_s if self.time_s is not None else time_s,
                           self.spec or spec)


def class_spec(obj: Any) -> str:
    """MODULE:CLASS of an object (a link's class in failure messages)."""
    cls = obj if isinstance(obj, type) else type(obj)
    return f"{cls.__module__}:{cls.__qualname__}"


def link_call(link: str, member: str, function: Callable[..., Any], *args: Any,
              allowed: tuple[type[BaseException], ...] = (), **kwargs: Any) -> Any:
    """function(*args, **kwargs); what it raises becomes a LinkFailure of `link`.

    Except the exceptions its interface allows (`allowed`: the planner's ValueError for "no
    path", ...), which pass through, and a LinkFailure, which stays as it is.
    """
    try:
        return function(*args, **kwargs)
    except LinkFailure:
        raise
    except allowed:
        raise
    except Exception as exc:  # a user's class may raise anything
        raise LinkFailure(link, f"{member} raised {_exception(exc)}") from exc


def checked_commands(link: str, out: Any) -> tuple[float, float]:
    """compute_commands' (v, w) as two floats; LinkFailure unless two finite numbers."""
    try:
        v, w = out
        finite = _real(v) and _real(w) and math.isfinite(v) and math.isfinite(w)
    except (TypeError, ValueError):
        finite = False
    if not finite:
        raise LinkFailure(link, f"compute_commands returned {shown(out)}, not (v, w) as two "
                                "finite numbers")
    return float(v), float(w)


def checked_path(plan: Any) -> np.ndarray:
    """The (K, 2) finite points (K >= 1) of Planner.plan's result; LinkFailure otherwise."""
    points = getattr(plan, "points", None)
    if points is None:
        raise LinkFailure("planner", f"plan returned {shown(plan)}, not a path with points")
    try:
        array = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise LinkFailure("planner", f"plan's points are {shown(points)}, not numbers") \
            from None
    if array.ndim != 2 or array.shape[1] != 2 or len(array) == 0:
        raise LinkFailure("planner", f"plan's points have shape {array.shape}, not (K, 2) "
                                     "with K >= 1")
    if not np.isfinite(array).all():
        raise LinkFailure("planner", "plan's points are not all finite")
    return array


def checked_estimate(estimate: Any) -> Any:
    """Mapper.update's MappingEstimate, checked; LinkFailure if it is not one.

    A `status` text and, unless it says "rejected", a `pose` of three finite numbers.
    """
    status = getattr(estimate, "status", None)
    if not isinstance(status, str):
        raise LinkFailure("mapper", f"update returned {shown(estimate)}, not an estimate with "
                                    "a status text and a pose")
    if status.startswith("rejected"):
        return estimate
    checked_pose("mapper", f"update's pose (status {status!r})",
                 getattr(estimate, "pose", None))
    return estimate


def checked_pose(link: str, what: str, pose: Any) -> tuple[float, float, float]:
    """A pose (x, y, theta) of three finite numbers as floats; LinkFailure naming `what`."""
    if not _finite_numbers(pose, 3):
        raise LinkFailure(link, f"{what} is {shown(pose)}, not three finite numbers")
    return tuple(float(v) for v in pose)  # type: ignore[return-value]


def checked_raster(raster: Any) -> Any:
    """Mapper.occupancy_raster's Raster, checked; LinkFailure if it is not one.

    2-D integer values of at least one cell, a finite resolution > 0, a finite (x, y) origin.
    """
    values = getattr(raster, "values", None)
    resolution = getattr(raster, "resolution", None)
    if not (isinstance(values, np.ndarray) and values.ndim == 2 and values.size
            and values.dtype.kind in "iu"):
        raise LinkFailure("mapper", f"occupancy_raster returned {shown(raster)}, not a Raster "
                                    "(amr_common.world.map_raster) with 2-D integer values")
    if not (_real(resolution) and math.isfinite(resolution) and resolution > 0
            and _finite_numbers(getattr(raster, "origin", None), 2)):
        raise LinkFailure("mapper", f"occupancy_raster returned a resolution of "
                                    f"{shown(resolution)} m and an origin of "
                                    f"{shown(getattr(raster, 'origin', None))}: not a finite "
                                    "resolution > 0 and (x, y)")
    return raster


def checked_statistics(stats: Any) -> Mapping[str, Any]:
    """Mapper.statistics' mapping; LinkFailure for anything else."""
    if not isinstance(stats, Mapping):
        raise LinkFailure("mapper", f"statistics returned {shown(stats)}, not a dict")
    return stats


def checked_localization(estimate: Any, localized: Any) -> tuple[tuple[float, float, float],
                                                                 bool]:
    """A Localizer's (estimate, localized), checked; LinkFailure if they are not.

    Three numbers (NaN while it has none) and a flag, never localized on a non-finite estimate.
    """
    if not _finite_numbers(estimate, 3, allow_nan=True):
        raise LinkFailure("localizer", f"estimate is {shown(estimate)}, not (x, y, theta)")
    if not (isinstance(localized, (bool, np.bool_)) or (_real(localized)
                                                         and localized in (0, 1))):
        raise LinkFailure("localizer", f"localized is {shown(localized)}, not True or False")
    pose = tuple(float(v) for v in estimate)
    if localized and not all(math.isfinite(v) for v in pose):
        raise LinkFailure("localizer", f"localized is True with the estimate {shown(pose)}")
    return pose, bool(localized)  # type: ignore[return-value]


def checked_covariance(covariance: Any) -> np.ndarray:
    """A Localizer's covariance as a 3 x 3 array (NaN if unknown); LinkFailure otherwise."""
    try:
        array = np.asarray(covariance, dtype=np.float64)
    except (TypeError, ValueError):
        array = None
    if array is None or array.shape != (3, 3):
        raise LinkFailure("localizer", f"covariance is {shown(covariance)}, not 3 x 3")
    return array


def checked_particles(particles: Any) -> np.ndarray:
    """A Localizer's particles as an (N, 3) finite array; LinkFailure otherwise."""
    try:
        array = np.asarray(particles, dtype=np.float64)
    except (TypeError, ValueError):
        array = None
    if array is None or array.ndim != 2 or array.shape[1] != 3 or \
            not np.isfinite(array).all():
        raise LinkFailure("localizer", f"particles are {shown(particles)}, not (N, 3) finite "
                                       "[x, y, theta] rows")
    return array


def failure_text(exc: BaseException) -> str:
    """One line for an episode's error: a LinkFailure as it says, else 'Type: message'."""
    if isinstance(exc, LinkFailure):
        return str(exc)
    return traceback.format_exception_only(type(exc), exc)[-1].strip()


def shown(value: Any, limit: int = 60) -> str:
    """A value as a failure message shows it: an array by its shape, else a short repr."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape}"
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _exception(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _real(value: Any) -> bool:
    return isinstance(value, (Real, np.integer, np.floating)) and \
        not isinstance(value, (bool, np.bool_))


def _finite_numbers(values: Any, count: int, allow_nan: bool = False) -> bool:
    try:
        items = list(values)
    except TypeError:
        return False
    if len(items) != count or not all(_real(v) for v in items):
        return False
    return all(math.isfinite(v) or (allow_nan and math.isnan(v)) for v in items)


__all__ = ["LINK_FAILED", "LinkFailure", "checked_commands", "checked_covariance",
           "checked_estimate", "checked_localization", "checked_particles", "checked_path",
           "checked_pose", "checked_raster", "checked_statistics", "class_spec", "failure_text",
           "link_call", "shown"]
