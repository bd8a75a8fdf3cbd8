"""The world's movers inside the simulator: their clocks, waits, contacts and LiDAR circles.

Each mover (amr_common.world.movers) has its own clock. Every step, before the robot moves, each
mover's clock advances by dt unless the position that gives would come within KEEP_OFF of the
robot's body where it stands: then the mover waits this step (logged in `waits`). So a mover
never walks into the robot, and every contact with one is the robot's doing.

During the robot's motion the movers stand like walls: the robot's velocity is limited towards
them as towards the walls (amr_sim.contact.constrain_velocity), so it ends at most
ALLOWED_PENETRATION inside one, and nothing can push it deeper (a mover never steps towards it,
and turning does not move a disc). Contacts are therefore counted here, as pymunk counts the
walls': a contact begins when the robot's disc and a mover's overlap, and ends when they part.
The movers are no pymunk bodies: two small compiled kernels do the walking and the contacts
(about a microsecond a step for a few movers, where pymunk's per-body Python calls cost ~10).

`circles` (rows [x, y, radius]) is the array the LiDAR casts against
(amr_common.world.raycast.cast_circles / scan_circles), updated in place.
"""
from __future__ import annotations

import numpy as np

from amr_common.jit import jit
from amr_common.robot import ROBOT_RADIUS
from amr_common.world.movers import Mover, path_position

KEEP_OFF = 0.001  # m: a mover keeps this gap to the robot's body, so it never starts a contact


def advance_python(walked, stations, first, speeds, starts, loops, walking, clocks, circles,
                   robot_x, robot_y, robot_radius, keep_off, now, dt, wait_from, ended):
    """Walk each mover one step, now -> now + dt, unless it would come too near the robot.

    Mover i's path is walked[first[i]:first[i + 1]] with its stations; a mover with
    walking[i] False stands. wait_from[i]: when its current wait began (NaN: not waiting);
    a wait that ends this step is moved to ended[i] ([t_from, t_to]); returns how many ended.
    """
    count = 0
    for i in range(clocks.shape[0]):
        if not walking[i]:
            continue
        clock = clocks[i] + dt
        a, b = first[i], first[i + 1]
        x, y = path_position(walked[a:b], stations[a:b], loops[i], speeds[i], starts[i], clock)
        reach = circles[i, 2] + robot_radius + keep_off
        moves = x != circles[i, 0] or y != circles[i, 1]  # not before start_s
        if moves and (x - robot_x) ** 2 + (y - robot_y) ** 2 < reach * reach:
            if wait_from[i] != wait_from[i]:  # NaN: a wait begins
                wait_from[i] = now
            continue
        if wait_from[i] == wait_from[i]:  # a wait ends
            ended[i, 0] = wait_from[i]
            ended[i, 1] = now
            wait_from[i] = np.nan
            count += 1
        clocks[i] = clock
        circles[i, 0] = x
        circles[i, 1] = y
    return count


def contacts_python(circles, x, y, radius, touching, points):
    """Contacts of the robot's disc at (x, y) with the movers' discs that began this step.

    touching[i] keeps whether the robot touched mover i; the point where each new contact
    began (on the mover's edge) goes to points[k]; returns how many began.
    """
    count = 0
    for i in range(circles.shape[0]):
        dx = x - circles[i, 0]
        dy = y - circles[i, 1]
        distance = np.sqrt(dx * dx + dy * dy)
        now = distance < circles[i, 2] + radius
        if now and not touching[i]:
            scale = circles[i, 2] / distance if distance > 0.0 else 0.0
            points[count, 0] = circles[i, 0] + dx * scale
            points[count, 1] = circles[i, 1] + dy * scale
            count += 1
        touching[i] = now
    return count


advance_kernel = jit(advance_python)
contacts_kernel = jit(contacts_python)


class MovingObstacles:
    """The movers of one simulation: `advance(t, x, y, dt)` walks them one step."""

    def __init__(self, movers: tuple[Mover, ...] | list[Mover]) -> None:
        self.movers = tuple(movers)
        n = len(self.movers)
        self.clocks = np.zeros(n)
        self.circles = np.zeros((n, 3))  # rows [x, y, radius], updated in place
        self.time = 0.0  # the end of the last step walked
        self._waits: list[list[list[float]]] = [[] for _ in range(n)]  # the ended ones
        paths = [m.walked for m in self.movers] or [np.zeros((0, 2))]
        self._walked = np.ascontiguousarray(np.vstack(paths))
        self._stations = np.concatenate([m.stations for m in self.movers] or [np.zeros(0)])
        self._first = np.concatenate([[0], np.cumsum([len(p) for p in paths])]).astype(np.int64)
        self._speeds = np.array([m.speed for m in self.movers], dtype=np.float64)
        self._starts = np.array([m.start_s for m in self.movers], dtype=np.float64)
        self._loops = np.array([m.loop for m in self.movers], dtype=np.bool_)
        self._walking = np.array([m.walks for m in self.movers], dtype=np.bool_)
        self._wait_from = np.full(n, np.nan)
        self._ended = np.zeros((n, 2))
        self._touching = np.zeros(n, dtype=np.bool_)
        self.contact_points = np.zeros((n, 2))  # where the new contacts began (new_contacts)
        for i, mover in enumerate(self.movers):
            self.circles[i] = (*mover.position_at(0.0), mover.radius)

    def __len__(self) -> int:
        return len(self.movers)

    def touching(self, x: float, y: float) -> Mover | None:
        """The first mover a robot at (x, y) would touch where the movers are now, or None."""
        for (cx, cy, radius), mover in zip(self.circles, self.movers):
            if np.hypot(cx - x, cy - y) < radius + ROBOT_RADIUS + KEEP_OFF:
                return mover
        return None

    def advance(self, now: float, robot_x: float, robot_y: float, dt: float) -> None:
        """Walk each mover from simulated time `now` to now + dt, or let it wait for the robot.

        It waits while its next position would be within KEEP_OFF of the robot at
        (robot_x, robot_y); a mover that does not move this step (before start_s) never waits.
        """
        ended = advance_kernel(self._walked, self._stations, self._first, self._speeds,
                               self._starts, self._loops, self._walking, self.clocks,
                               self.circles, robot_x, robot_y, ROBOT_RADIUS, KEEP_OFF, now, dt,
                               self._wait_from, self._ended)
        self.time = now + dt
        if ended:  # rare: log the waits that ended
            for i, mover_waits in enumerate(self._waits):
                if self._ended[i, 1] == now:
                    mover_waits.append([float(self._ended[i, 0]), float(now)])

    def new_contacts(self, robot_x: float, robot_y: float) -> int:
        """How many contacts of the robot at (robot_x, robot_y) with movers began since last asked.

        Where each began: contact_points[:count].
        """
        return contacts_kernel(self.circles, robot_x, robot_y, ROBOT_RADIUS, self._touching,
                               self.contact_points)

    @property
    def waits(self) -> list[list[list[float]]]:
        """Per mover, the intervals [t_from, t_to] (s) it waited for the robot.

        The current wait runs until now (the end of the last step).
        """
        return [[*[list(w) for w in waits], *([[float(since), self.time]] if since == since
                                              else [])]
                for waits, since in zip(self._waits, self._wait_from)]

    @property
    def positions(self) -> list[tuple[float, float]]:
        """Where each mover is now (x, y)."""
        return [(float(x), float(y)) for x, y, _ in self.circles]

    @property
    def in_contact(self) -> bool:
        """True while the robot touches a mover."""
        return bool(self._touching.any())


__all__ = ["KEEP_OFF", "MovingObstacles", "advance_kernel", "advance_python",
           "contacts_kernel", "contacts_python"]
