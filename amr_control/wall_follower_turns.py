"""The wall follower's in-place turns, its heading memory and its island check (no rclpy).

Turns are in place (the Burger is round: turning never reduces its clearance), measured by
integrating the odometry's angular velocity, and aimed relative to the heading memory (the
direction of the last well-fitted wall, or the goal of the last turn) so heading errors do not
accumulate. When the turns lead nowhere (look_around.IdleTurns) the memory is forgotten and the
robot turns once around in place (turn_clear), then toward where look_around.LookAround chooses
(turn_free). Straight legs hold the remembered heading. The island check (pose_trail.PoseTrail)
tells when following has gone once around a free-standing obstacle, which the follower escapes.

InPlaceTurns is a part of wall_follower.WallFollower, split off so the state machine reads in
one module: it works on the follower's attributes (its parameters, the odometry pose `_heading`,
`_x`, `_y`, `_winding`, `_odometer`, the `_reference_*` and `_turn_*` fields, `_trail`,
`_idle_turns`, `_look`, `_last_turn`, `_outer_turns`, `_perception`) and its `_enter(state)`.
"""
from __future__ import annotations

import math

from amr_common.geometry import wrap_angle
from amr_control.look_around import LookAround


class InPlaceTurns:
    """The turn states (turn_*) and the heading memory of WallFollower (see the module doc)."""

    def _reference(self) -> float | None:
        """Heading (odometry frame) the robot should be aligned with, or None.

        The last well-fitted wall's direction or the goal of the last turn, if recent enough.
        """
        if self._odometer - self._reference_odometer <= self.heading_memory_m:
            return self._reference_heading
        return None

    def _set_reference(self, heading: float) -> None:
        self._reference_heading = heading
        self._reference_odometer = self._odometer

    def _start_turn(self, state: str, angle_rad: float) -> None:
        """Turn in place by angle_rad relative to the reference heading.

        So that turns snap back to the walls' directions instead of accumulating heading errors.
        If the turns lead nowhere, a clearing turn instead (turn_clear).
        """
        if self._idle_turns.lead_nowhere(self._odometer):
            self._start_clearing_turn()
            return
        reference = self._reference()
        base = reference if reference is not None else self._heading
        self._enter(state)
        self._turn_goal = base + angle_rad
        self._turn_direction = 1.0 if angle_rad > 0 else -1.0
        self._last_turn = state

    def _start_clearing_turn(self) -> None:
        """Once around in place, then toward where look_around chooses (turn_clear)."""
        # The heading memory is wrong, and so are the poses of the loop detection's trail
        # (the odometry no longer matches the walls): forget both and look around.
        self._reference_odometer = -math.inf
        self._trail.clear()
        self._outer_turns = 0
        self._enter("turn_clear")
        self._turn_direction = self._side
        self._turn_goal = self._heading + self._side * 2.0 * math.pi
        self._look = LookAround()
        self._last_turn = "turn_clear"

    def _hold_heading(self, speed: float) -> tuple[float, float]:
        """Drive straight at `speed`, steering back to the reference heading if there is one."""
        reference = self._reference()
        if reference is None:
            return speed, 0.0
        w = self.heading_gain_per_s * wrap_angle(reference - self._heading)
        limit = self.follow_max_angular_speed_radps
        return speed, max(-limit, min(limit, w))

    def _closed_loop_around_island(self) -> bool:
        """Record the odometry pose every few cm while following, and detect a closed loop.

        When the robot is back at a recorded pose with the same heading it has been once around
        the wall it follows. Seen
        with the wall on the followed side, that loop turned by +2 pi toward that side for an
        island and by -2 pi for an enclosing boundary (which it keeps lapping).
        """
        if not self.escape_islands:
            return False
        turned = self._trail.record_and_close(self._odometer, self._x, self._y, self._heading,
                                              self._winding)
        return turned is not None and turned > math.pi

    def _run_clearing_turn(self) -> tuple[float, float] | None:
        """Once around toward the followed side, then a turn to where look_around chooses."""
        self._look.observe(self._heading, self._perception.path_m, self._perception.fit)
        if self._turn_direction * (self._turn_goal - self._heading) > 0.0:
            return 0.0, self._turn_direction * self.turn_speed_radps
        delta = wrap_angle(self._look.choose() - self._heading)
        self._enter("turn_free")   # an ordinary turn: its goal becomes the heading memory
        self._turn_goal = self._heading + delta
        self._turn_direction = 1.0 if delta > 0.0 else -1.0
        return None

    def _run_turn(self) -> tuple[float, float] | None:
        if self.state == "turn_clear":
            return self._run_clearing_turn()
        direction = self._turn_direction
        remaining = (direction * (self._turn_goal - self._heading)) % (2.0 * math.pi)
        if remaining > 1.5 * math.pi:       # overshot the goal
            remaining = 0.0
        turn_time_limit = 2.0 * math.pi / max(self.min_turn_speed_radps, 0.05)
        if remaining <= 0.02 or self._state_time > turn_time_limit:
            self._set_reference(self._turn_goal)
            after_turn = {"turn_outer": "approach", "turn_escape": "escape"}
            self._enter(after_turn.get(self.state, "settle"))
            return None
        # Slow down over the last part so that the turn ends on target (force control lags).
        speed = min(self.turn_speed_radps, max(self.min_turn_speed_radps, 4.0 * remaining))
        return 0.0, direction * speed
