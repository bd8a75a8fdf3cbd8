"""Looking around once in place: where the walls run and which way is open.

The wall follower aims its in-place turns at its heading memory (the direction of the last
well-fitted wall). When that memory is wrong (the robot was carried, or slipped) every quarter
turn can face a wall's corner, so the robot would turn between blocked directions for ever.
IdleTurns notices (too many turns in a row without driving); the robot then turns once around
in place, and LookAround records, at every step of that turn, the free path ahead and the
direction of the followed wall whenever a straight wall is fitted beside it.

`choose()` picks where to go on: the walls' direction (their circular mean modulo a quarter turn,
the course's mazes being rectilinear) turned by the quarter turn whose path ahead was longest,
or, if no straight wall was seen, the heading with the longest path ahead.
No rclpy import.
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.geometry import wrap_angle, wrap_angles

# More in-place turns than this in a row, each after less than IDLE_PROGRESS_M of driving, mean
# the turns lead nowhere.
IDLE_TURNS = 4
IDLE_PROGRESS_M = 0.02


class IdleTurns:
    """Counts in-place turns made without driving in between.

    Each turn is aimed relative to the heading memory, which every turn renews and which only
    driving ages: a wrong memory (the robot was carried) could otherwise keep a robot that never
    drives turning between two blocked directions for ever.
    """

    def __init__(self) -> None:
        self._count = 0
        self._odometer = -math.inf  # at the start of the last turn

    def lead_nowhere(self, odometer: float) -> bool:
        """Count a turn starting at `odometer` (m); True if it is one too many in a row."""
        if odometer - self._odometer >= IDLE_PROGRESS_M:
            self._count = 0
        self._odometer = odometer
        self._count += 1
        if self._count <= IDLE_TURNS:
            return False
        self._count = 0
        return True


class LookAround:
    """What one turn in place saw: path ahead per heading, and the walls' directions."""

    def __init__(self) -> None:
        self._headings: list[float] = []
        self._paths: list[float] = []
        self._wall = 0j  # sum of exp(4 i phi) over the fitted walls' directions phi

    def observe(self, heading: float, path_m: float, fit=None) -> None:
        """Record one step: the heading (rad), the free path ahead (m), the followed wall's fit.

        `fit`: a scan_sectors.WallFit (angle in the robot frame) or None.
        """
        self._headings.append(float(heading))
        self._paths.append(float(path_m))
        if fit is not None and fit.gives_direction:
            self._wall += complex(math.cos(4.0 * (heading + fit.angle_rad)),
                                  math.sin(4.0 * (heading + fit.angle_rad)))

    @property
    def saw_walls(self) -> bool:
        """True if some straight wall was fitted during the turn."""
        return self._wall != 0j

    def choose(self) -> float:
        """The heading to go on along (same frame as the observed headings; nan if none)."""
        if not self._headings:
            return math.nan
        headings, paths = np.array(self._headings), np.array(self._paths)
        if not self.saw_walls:
            return float(headings[int(np.argmax(paths))])
        walls = math.atan2(self._wall.imag, self._wall.real) / 4.0
        best, best_path = math.nan, -math.inf
        for quarter in range(4):
            direction = walls + quarter * 0.5 * math.pi
            off = np.abs(wrap_angles(headings - direction))
            path = float(paths[int(np.argmin(off))])
            if path > best_path:
                best, best_path = wrap_angle(direction), path
        return best
