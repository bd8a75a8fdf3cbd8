"""Movers: round obstacles of a world that walk on their own (people, a cart).

A world YAML lists them under `movers:` (read and checked by amr_common.world.world_file; their
paths against the boundary by amr_common.world.polygons)::

    movers:
      - radius: 0.2              # m, (0, MAX_RADIUS]
        path: [[x, y], ...]      # m, >= 1 point; one point: it stands there
        speed: 0.4               # m/s, [0, MAX_SPEED]; 0: it stands at the first point
        loop: true               # optional (default false): round the path (last -> first)
        start_s: 5.0             # optional (default 0): stands at the first point until then
        name: visitor            # optional (default movers[i]): in errors, plots and markers

A mover walks its path back and forth (first point -> last -> first ...) at `speed`, or round
it with `loop`. Its position is a pure function of its own clock (`Mover.position_at`, the
compiled `path_position` with its plain twin): the same in a headless episode and in the ROS
graph. The simulator (amr_sim) advances each mover's
clock by dt every step except while its next position would touch the robot: then it waits, so
every contact is the robot's doing. Movers pass through walls and through each other: keeping
their paths clear is the world author's part; each path must stay inside the boundary with the
mover's radius.

Movers are the simulated world only: never walls, never in /map, the planner's or the particle
filter's map (a world file given as a map has its movers dropped: amr_common.world.map_vs_world).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from amr_common.jit import jit

MAX_RADIUS = 1.0  # m: a person, a cart; not a room
MAX_SPEED = 2.0  # m/s: a brisk walk (the Burger drives 0.22 m/s)
MOVER_KEYS = ("radius", "path", "speed", "loop", "start_s", "name")


@dataclass(frozen=True, eq=False)
class Mover:
    """One mover: its radius, path, speed, and how it walks the path."""

    name: str
    radius: float  # m
    path: np.ndarray  # (K, 2) points, m
    speed: float  # m/s
    loop: bool = False
    start_s: float = 0.0  # s: stands at path[0] until then
    label: str = ""  # how errors name it: "movers[1] (cart)"; "" = its name
    walked: np.ndarray = field(init=False, repr=False)  # the points walked (+ the first: loop)
    stations: np.ndarray = field(init=False, repr=False)  # arc length (m) at each walked point

    def __post_init__(self) -> None:
        points = np.asarray(self.path, dtype=np.float64).reshape(-1, 2)
        if self.loop and len(points) > 1:
            points = np.vstack([points, points[:1]])  # round: back to the first point
        steps = np.hypot(*np.diff(points, axis=0).T) if len(points) > 1 else np.zeros(0)
        object.__setattr__(self, "walked", np.ascontiguousarray(points))
        object.__setattr__(self, "stations", np.concatenate([[0.0], np.cumsum(steps)]))

    @property
    def length(self) -> float:
        """Length of one walk along the path (m): first to last point, or round with loop."""
        return float(self.stations[-1])

    @property
    def walks(self) -> bool:
        """False for a mover that never leaves its first point (one point, or speed 0)."""
        return self.speed > 0.0 and self.length > 0.0

    def position_at(self, t: float) -> tuple[float, float]:
        """Where the mover is at time t (s) of its own clock, had it never waited."""
        x, y = path_position(self.walked, self.stations, self.loop, self.speed, self.start_s,
                             float(t))
        return (float(x), float(y))

    def path_segments(self) -> np.ndarray:
        """The path as (N, 4) segments [x1, y1, x2, y2] (with the closing one for a loop)."""
        pts = self.walked
        if len(pts) == 1:
            return np.hstack([pts, pts])
        return np.hstack([pts[:-1], pts[1:]])


def path_position_python(points, stations, loop, speed, start_s, t):
    """(x, y) at time t on a path walked back and forth (or round with loop) at speed.

    points: (K, 2) walked points (a loop's with the first repeated at the end); stations: the
    arc length at each. Standing at the first point until start_s, and for good when the
    path has no length or speed is 0.
    """
    n = points.shape[0]
    travelled = speed * (t - start_s)
    length = stations[n - 1]
    if not (travelled > 0.0 and length > 0.0):
        return points[0, 0], points[0, 1]
    period = length if loop else 2.0 * length  # back and forth: there and back
    s = min(max(travelled - period * math.floor(travelled / period), 0.0), period)
    if s > length:
        s = 2.0 * length - s
    low = 1
    high = n - 1
    while low < high:  # the first point beyond s (the last if none): segment k-1 -> k
        middle = (low + high) // 2
        if stations[middle] > s:
            high = middle
        else:
            low = middle + 1
    s0 = stations[low - 1]
    s1 = stations[low]
    u = (s - s0) / (s1 - s0) if s1 > s0 else 0.0
    return (points[low - 1, 0] + u * (points[low, 0] - points[low - 1, 0]),
            points[low - 1, 1] + u * (points[low, 1] - points[low - 1, 1]))


path_position = jit(path_position_python)


def walked_time(t: float, waits: list[list[float]] | None) -> float:
    """A mover's clock at simulated time t, given the intervals [t_from, t_to] it waited."""
    clock = t
    for t_from, t_to in waits or ():
        if t_from >= t:
            break
        clock -= min(t_to, t) - t_from
    return clock


def collisions_text(collisions: int, with_movers: int | None) -> str:
    """'3' or '3 (2 with movers)': every collision, then the part with movers if any."""
    return f"{collisions} ({with_movers} with movers)" if with_movers else f"{collisions}"


__all__ = ["MAX_RADIUS", "MAX_SPEED", "MOVER_KEYS", "Mover", "collisions_text", "path_position",
           "path_position_python", "walked_time"]
