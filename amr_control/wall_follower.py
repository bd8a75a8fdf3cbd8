"""Wall following that explores a maze without touching a wall (no rclpy: plain Python + numpy).

Policy (deterministic): follow ONE side (`follow_side`; right-hand rule by default). At every
decision point the robot prefers, in order: the followed side, straight ahead, the other side,
turning back. In a maze whose walls all connect to the outer boundary this visits every corridor
cell; in a ring it laps forever. The only switch: when the robot is back at a pose it passed with
the same heading after a full lap that turned +2 pi toward the followed side, it has circled an
island (a free-standing obstacle or wall group, e.g. lab02's inner maze seen from the ring); it
then turns away from it and drives straight to the next wall ("turn_escape", "escape").
An enclosing boundary (-2 pi per lap) is lapped forever.

States (the `state` attribute):
- follow_wall: PD control of the distance to the followed wall; the distance and the wall angle
  come from a line fitted to the scan points beside the robot, so the derivative is the rate
  the distance changes at cruise speed given the measured wall angle (no finite difference).
- outer_corner: the followed wall ended (a gap wide enough for the robot): drive straight until
  the robot is `outer_corner_advance_m` past the wall's end, slowing down over the last
  `corner_slowdown_m` (a real drive's latency and lag carry a robot at cruise speed past the
  turn point, off the new corridor's centre), then
- turn_outer: turn in place 90 deg toward the followed side, then
- approach: drive straight until the wall is beside the robot again (a new corridor's wall
  starts ahead after such a turn); if it never comes, take the next outer corner.
- turn_inner: wall ahead, followed side blocked, other side open: turn in place 90 deg away.
- turn_around: dead end (ahead and both sides blocked): turn in place 180 deg.
- settle: after turn_inner / turn_around, drive straight briefly so the next decisions use scans
  taken after the turn (the real LDS-01 smears scans taken while turning).
- find_wall: no wall on the followed side within reach: drive straight.
- no_data: the newest scan had no valid reading at all: stop until data returns.
- turn_clear, turn_free: the turns lead nowhere (look_around.IdleTurns: the heading memory is
  wrong): forget it, turn once around in place (look_around), then turn to the walls' direction
  with the longest free path seen, and settle.

Turns are in place (the Burger is round: turning never reduces its clearance), measured by
integrating the odometry's angular velocity, and aimed relative to the direction of the last
well-fitted wall so heading errors do not accumulate (wall_follower_turns.py). Between scans
(the LDS-01 refreshes at 5 Hz, the controller runs at 20 Hz) the scan points are carried
along with the odometry; each ray is de-skewed to the scan's stamp with the odometry
(`scan_revolution_s`: a real LiDAR takes its rays over 0.2 s), and the points of the last
seconds stay obstacles for the swept path (`memory_time_s`: a thin wall's end seen end-on
returns no ray; point_memory_kernels.py).
Four outer-corner turns in a row with no wall followed in between (circling an empty junction)
end in the look-around.
Input checks and the output limits live in wall_follower_inputs.py, the turn states, the
heading memory and the island check in wall_follower_turns.py; what is left here is the state
machine's transitions and the wall following itself, kept together so they read in one place.
"""
from __future__ import annotations

import logging
import math
from typing import Any

from amr_common.python_logging import ThrottledLogger
from amr_control.look_around import IdleTurns, LookAround
from amr_control.pose_trail import PoseTrail
from amr_control.scan_sectors import (
    LocalPointCloud,
    Perception,
    PerceptionSpec,
    ScanGeometry,
    ScanTiming,
)
from amr_control.wall_follower_inputs import as_ranges, checked_odometry, limit_to_free_path
from amr_control.wall_follower_params import PARAMETERS, check_parameters
from amr_control.wall_follower_turns import InPlaceTurns

_LOG = logging.getLogger(__name__)


class WallFollower(InPlaceTurns):
    """Class to safely explore an environment (without crashing) by following walls."""

    def __init__(self, dt: float, **params: Any) -> None:
        """Set up the controller for control period `dt`.

        Args:
        dt: control period [s].
        **params: any name of `parameter_descriptions()`; unknown names raise ValueError.
        """
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"WallFollower: dt must be a positive number of seconds, got {dt!r}")
        self._dt = float(dt)
        # Bad input repeats with every message: each kind of warning at most once per 5 s.
        self._log = ThrottledLogger(_LOG)
        for name, value in check_parameters(params).items():
            setattr(self, name, value)
        self._side = -1.0 if self.follow_side == "right" else 1.0   # sign of the followed side's y

        self._geometry: ScanGeometry | None = None
        # A low percentile ahead, not the minimum: one noisy ray must not trigger a turn early.
        spec = PerceptionSpec(
            self._side, _SECTOR_CENTRES, self.sector_half_width_rad, {"front": 25.0},
            path_half_width_m=self.robot_radius_m + self.path_margin_m,
            side_window_m=self.side_window_half_length_m, side_open_m=self.side_open_distance_m,
            fit_half_length_m=self.wall_fit_half_length_m)
        timing = ScanTiming(self.scan_revolution_s, self.memory_time_s, self.memory_range_m)
        self._cloud = LocalPointCloud(self.invalid_hold_time_s, self.invalid_hold_range_m,
                                      self.lidar_offset_x_m, spec, timing)
        self._perception: Perception | None = None
        self.state = "follow_wall"
        self.wall_distance_error: float | None = None
        self.distances: dict[str, float] = {}
        self._last_v = 0.0
        self._last_w = 0.0
        self._state_time = 0.0          # s in the current state
        self._travelled = 0.0           # m driven in the current state (odometry)
        self._heading = 0.0             # rad, integrated odometry (not wrapped)
        self._x = 0.0                   # m, odometry position (for loop detection)
        self._y = 0.0
        self._winding = 0.0             # rad turned toward the followed side in total
        self._trail = PoseTrail()
        self._island_lap_done = False
        self._reference_heading = 0.0   # rad, see _reference()
        self._reference_odometer = -math.inf
        self._turn_goal = 0.0           # rad, heading that ends the current turn
        self._turn_direction = 1.0
        self._advance_target = 0.0      # m for outer_corner
        self._idle_turns = IdleTurns()  # do the turns lead anywhere?
        self._look = LookAround()       # what turn_clear saw
        self._scan_had_data = False
        self._last_turn: str | None = None   # the last in-place turn, until following resumes
        self._odometer = 0.0            # m driven in total (odometry)
        self._wall_end_x = 0.0          # m ahead of the robot where the followed wall ended ...
        self._wall_end_odometer = -math.inf   # ... when the odometer read this
        self._outer_turns = 0           # outer-corner turns since a wall was last followed

    @classmethod
    def parameter_descriptions(cls) -> dict[str, tuple[Any, str]]:
        """Every tuning parameter: name -> (default value, description with units)."""
        return dict(PARAMETERS)

    def set_scan_geometry(self, angle_min: float, angle_increment: float,
                          range_min: float, range_max: float) -> None:
        """Tell where the rays point and which ranges are valid.

        angle_i = angle_min + i*angle_increment (rad); valid ranges in [range_min, range_max]
        (m). Called per LaserScan by the node, so it may change between scans.
        Absurd values are ignored with a warning (the course convention is used instead).
        """
        geometry = ScanGeometry(float(angle_min), float(angle_increment),
                                float(range_min), float(range_max))
        if not geometry.is_sane():
            self._log.warning("geometry", "WallFollower: ignoring unusable scan geometry %s "
                              "(using the course convention instead)", geometry)
            self._geometry = None
            return
        self._geometry = geometry

    # ---- main entry ----------------------------------------------------------------------
    def compute_commands(self, z_scan: Any, z_v: float, z_w: float) -> tuple[float, float]:
        """One control step.

        Args:
            z_scan: LiDAR ranges [m] (NaN/inf/0.0/out-of-range readings are "no return").
            z_v: odometric linear velocity of the robot centre over the last step [m/s].
            z_w: odometric angular velocity over the last step [rad/s].

        Returns:
            (v, w): linear [m/s] and angular [rad/s] velocity commands, always finite and within
            the robot's limits.
        """
        z_v, z_w = checked_odometry(z_v, z_w, (self._last_v, self._last_w), self._log)
        self._observe(z_scan, z_v, z_w)
        v, w = self._step_state_machine()
        v, w = self._limit(v, w)
        self._last_v, self._last_w = v, w
        return v, w

    # ---- perception ----------------------------------------------------------------------
    def _observe(self, z_scan: Any, z_v: float, z_w: float) -> None:
        dt = self._dt
        self._state_time += dt
        self._travelled += z_v * dt
        self._odometer += abs(z_v) * dt
        mid_heading = self._heading + 0.5 * z_w * dt
        self._x += z_v * dt * math.cos(mid_heading)
        self._y += z_v * dt * math.sin(mid_heading)
        self._heading += z_w * dt
        self._winding += self._side * z_w * dt
        ranges = as_ranges(z_scan, self._log)
        geometry = None
        if ranges is not None:
            geometry = self._geometry or ScanGeometry(0.0, 2.0 * math.pi / ranges.size,
                                                      self.range_min_m, self.range_max_m)
        valid, perception = self._cloud.step(z_v * dt, z_w * dt, dt, ranges, geometry)
        if valid is not None:
            self._scan_had_data = valid > 0
        self._perception = perception
        self.distances = perception.sectors
        self.distances["path"] = perception.path_m

    def _side_distance(self, followed: bool = True) -> float:
        """Lateral distance to the closest point right beside the robot; inf if open.

        On the followed or the other side, |x| within the side window. A box, not an angular
        sector: at a right-angle outer corner the wall leaving sideways lies just behind the
        robot and would keep a +-90 deg sector "closed" long after the followed wall has ended.
        """
        return self._perception.beside_m if followed else self._perception.beside_other_m

    # ---- state machine -------------------------------------------------------------------
    def _enter(self, state: str) -> None:
        self.state = state
        self._state_time = 0.0
        self._travelled = 0.0

    def _step_state_machine(self) -> tuple[float, float]:
        self.wall_distance_error = None
        if not self._scan_had_data:
            if self.state != "no_data":
                self._enter("no_data")
            return 0.0, 0.0
        if self.state == "no_data":
            self._enter("follow_wall")
        if self.state == "follow_wall" and self._island_lap_done:
            self._island_lap_done = False
            # A full lap around something kept on the followed side: an island (a free-standing
            # obstacle or wall group): leave it to find another wall instead of circling it.
            self._trail.clear()
            self._start_turn("turn_escape", -self._side * 0.5 * math.pi)
        # A few transitions may chain in one step (e.g. a turn ends and a decision follows).
        for _ in range(4):
            command = self._run_state()
            if command is not None:
                return command
        return 0.0, 0.0

    def _front_blocked(self) -> bool:
        return (self.distances["front"] < self.front_turn_distance_m
                or self.distances["path"] < self.front_stop_distance_m + 0.02)

    def _run_state(self) -> tuple[float, float] | None:
        state = self.state
        front_blocked = self._front_blocked()
        if state.startswith("turn_"):
            return self._run_turn()
        if state == "outer_corner":
            timed_out = (self._state_time
                         > 3.0 + self._advance_target / max(self.settle_speed_mps, 0.01))
            if front_blocked or self._travelled >= self._advance_target or timed_out:
                self._outer_turns += 1
                if self._outer_turns >= OUTER_TURNS_PER_LAP:
                    # Once around toward the followed side without a wall to follow in between:
                    # circling a post or an empty junction (walls seen far behind look like
                    # wall ends). Look around and go where the walls lead.
                    self._start_clearing_turn()
                    return None
                self._start_turn("turn_outer", self._side * 0.5 * math.pi)
                return None
            return self._hold_heading(self._corner_speed())
        if state == "approach":
            if self._side_distance() <= self.side_open_distance_m:
                self._enter("follow_wall")
                return None
            if front_blocked or self._travelled >= self.outer_corner_advance_m + 0.1:
                self._enter("follow_wall")
                return self._decide(allow_approach=False)
            return self._hold_heading(self.settle_speed_mps)
        if state == "settle":
            if front_blocked or self._state_time >= self.settle_time_s:
                self._enter("follow_wall")
                return None
            return self._hold_heading(self.settle_speed_mps)
        if state == "escape":
            if front_blocked:
                self._enter("follow_wall")
                if self._side_distance(followed=False) > self.side_open_distance_m:
                    self._start_turn("turn_inner", -self._side * 0.5 * math.pi)
                else:
                    self._start_turn("turn_around", -self._side * math.pi)
                return None
            return self._hold_heading(self.max_linear_speed_mps)
        return self._decide(allow_approach=True)

    def _corner_speed(self) -> float:
        """Forward speed toward an outer corner's turn point: down to settle speed near it.

        The robot keeps moving after the turn is commanded (command latency, the motors' lag):
        at cruise speed it would end the turn several cm past the point, off the new
        corridor's centre, where the far wall's end clips the swept path.
        """
        remaining = self._advance_target - self._travelled
        ramp = max(0.0, min(1.0, remaining / max(self.corner_slowdown_m, 1e-3)))
        low = min(self.settle_speed_mps, self.max_linear_speed_mps)
        return low + (self.max_linear_speed_mps - low) * ramp

    def _decide(self, allow_approach: bool) -> tuple[float, float] | None:
        """Right-hand rule (mirrored for the left).

        Followed side > straight > other side > back.
        """
        side = self._side
        front_blocked = self._front_blocked()
        if self._side_distance() > self.side_open_distance_m:
            wall_end, ahead = self._cloud.side_gap(side, self.side_open_distance_m)
            # Prefer where the followed wall was last seen to end, carried along by odometry:
            # a zero-thickness wall seen nearly edge-on returns no points near the robot, so
            # the current scan alone misplaces (or misses) the end.
            since_seen = self._odometer - self._wall_end_odometer
            if since_seen <= 0.3:
                wall_end = self._wall_end_x - since_seen
            # Where the followed wall resumes ahead; a wall leaving the corner sideways (the
            # usual right-angle outer corner) has its points at the corner itself: skip those.
            resume = ahead[ahead > wall_end + 0.05] if wall_end is not None else ahead
            wall_resume = float(resume.min()) if resume.size else math.inf
            if wall_end is not None:
                if wall_resume - wall_end >= self.min_gap_width_m:
                    self._enter("outer_corner")
                    self._advance_target = max(0.0, self.outer_corner_advance_m + wall_end)
                    return None
                return self._follow()          # a narrow gap: keep following across it
            if ahead.size and allow_approach and not front_blocked:
                self._enter("approach")
                return None
            if front_blocked:
                # Nothing on the followed side: put the wall ahead on the followed side.
                self._start_turn("turn_inner", -side * 0.5 * math.pi)
                return None
            if self.state != "find_wall":
                self._enter("find_wall")
            return self._hold_heading(self.max_linear_speed_mps)
        if front_blocked:
            # Straight after a turn-around and still blocked (e.g. it was misjudged at an angle):
            # turn by quarter turns instead, so every direction is tried in turn.
            just_turned_around = self._last_turn == "turn_around"
            if (self._side_distance(followed=False) > self.side_open_distance_m
                    or just_turned_around):
                self._start_turn("turn_inner", -side * 0.5 * math.pi)
            else:
                self._start_turn("turn_around", -side * math.pi)
            return None
        return self._follow()

    def _track_wall_end(self) -> None:
        """Remember how far ahead the wall beside the robot reaches (robot frame, m)."""
        beside = self._side_distance()
        if beside > self.side_open_distance_m:
            return
        reach = self._perception.wall_reach_m
        if reach is not None:
            self._wall_end_x = reach
            self._wall_end_odometer = self._odometer

    def _follow(self) -> tuple[float, float]:
        if self.state != "follow_wall":
            self._enter("follow_wall")
        self._last_turn = None
        side = self._side
        fit = self._perception.fit
        self._track_wall_end()
        if fit is not None:
            error = fit.distance_m - self.wall_distance_m
            rate = side * self.max_linear_speed_mps * math.sin(fit.angle_rad)
            if fit.gives_direction:
                self._outer_turns = 0
                self.wall_distance_error = error
                self._set_reference(self._heading + fit.angle_rad)
                # Only poses taken beside a well-fitted wall are on the wall's contour.
                self._island_lap_done = self._closed_loop_around_island()
        else:
            distance = self._side_distance()
            error = ((distance if math.isfinite(distance) else self.wall_distance_m)
                     - self.wall_distance_m)
            rate = 0.0
        w = side * (self.kp * error + self.kd * rate)
        limit = self.follow_max_angular_speed_radps
        return self.max_linear_speed_mps, max(-limit, min(limit, w))

    # ---- safety --------------------------------------------------------------------------
    def _limit(self, v: float, w: float) -> tuple[float, float]:
        return limit_to_free_path(v, w, self.distances.get("path", math.inf),
                             self.front_stop_distance_m, self.front_slowdown_distance_m,
                             self.max_linear_speed_mps, self.max_angular_speed_radps,
                             self.track_m)


# Outer-corner turns in a row (each a quarter turn toward the followed side) without following a
# straight wall in between: one full lap around something too small to follow.
OUTER_TURNS_PER_LAP = 4
_SECTOR_CENTRES = {"front": 0.0, "left": 0.5 * math.pi, "right": -0.5 * math.pi, "back": math.pi}
