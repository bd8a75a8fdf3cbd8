"""The `planner` lifecycle node: a path on the map from the localized /pose to a goal, on /path.

/path is a nav_msgs/Path in frame map, transient local: late subscribers get it.

- Plans once, on the first localized /pose, toward the `goal` parameter ([x, y]), the world's
  named goal `goal_name`, or else the world's default goal.
- Plans again on each /goal_pose (geometry_msgs/PoseStamped in frame map, the "2D Goal Pose" of
  RViz and Foxglove): at once if localized, else on the next localized /pose.
- Replans when /pose becomes localized again after localization was lost (the pure pursuit
  stops on the loss; the wall follower explores until the filter relocalizes).
- A goal inside a wall, too close to one or unreachable, or no goal at all: a clear logged error
  and an EMPTY path (the pursuit then commands zero), never a crash. A planner that raises
  anything else or returns no (K, 2) finite points has failed (amr_common.plugins.link_failure): an
  empty path, no more planning, and the run scripts end the run.
The path is stamped with the /pose it was planned from. The algorithm is the `planner`
parameter's class (MODULE:CLASS of amr_common.plugins.interfaces.Planner; default
amr_planning.planner.Planner); its tuning values are parameters of this node.
"""
from __future__ import annotations

import math
import sys
import time
from typing import Any

from geometry_msgs.msg import PoseStamped as GoalPoseStamped
from nav_msgs.msg import Path
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn

from amr_common.geometry import polyline_length
from amr_common.navigation_behaviour import Handover
from amr_common.plugins.interfaces import Planner
from amr_common.plugins.link_failure import LinkFailure, checked_path, class_spec, link_call
from amr_common.plugins.loader import DEFAULT_PLANNER
from amr_common.plugins.parameter_table import Param, ruled, vector
from amr_common.ros.lifecycle_node import GuardedLifecycleNode
from amr_common.ros.node_runner import run_lifecycle_node
from amr_common.ros.parameters import declare_link, declare_parameters, read_parameters
from amr_common.ros.qos import LATCHED, RELIABLE_10
from amr_common.ros.ros_conversions import path_message, time_to_nanoseconds
from amr_common.world.world import World

_NODE_PARAMETERS: dict[str, Param] = ruled({
    "world": ("lab02", "Bundled world name or path to a world .yaml / course map .json / Nav2 "
                       "map .yaml (the simulator's and the particle filter's map)"),
    "goal": ([], "Goal [x, y] in metres; [] = goal_name, else the world's default goal"),
    "goal_name": ("", "A named goal of the world (used when `goal` is [])"),
    "planner": (DEFAULT_PLANNER, "Planner class as MODULE:CLASS implementing "
                                 "amr_common.plugins.interfaces.Planner (its tuning values become "
                                 "parameters of this node)"),
    "replan_on_relocalization": (True, "Plan again from the pose when /pose becomes localized "
                                       "after localization was lost"),
    "frame_id": ("map", "Frame of /pose, /goal_pose and /path"),
    "pose_topic": ("/pose", "amr_msgs/PoseStamped input (the particle filter's estimate)"),
    "goal_pose_topic": ("/goal_pose", "geometry_msgs/PoseStamped goal input"),
    "path_topic": ("/path", "nav_msgs/Path output (transient local)"),
}, goal=vector(0, 2))


class PlannerNode(GuardedLifecycleNode):
    """Plans from the localized /pose to the goal and publishes /path (module docstring).

    Configure builds the planner (grid, costs, compiled search), the /path lifecycle publisher
    and the /pose and /goal_pose subscriptions; activate starts planning with the next
    localized /pose; deactivate stops planning (the published path stays latched); cleanup and
    shutdown release everything (release()). It commands no motion: nothing is sent on the way
    down.
    """

    def __init__(self, node_name: str = "planner", **kwargs) -> None:
        """Declare the parameters; nothing is built before on_configure."""
        super().__init__(node_name, **kwargs)
        declare_parameters(self, _NODE_PARAMETERS)
        self._planner_class, self._tuning = declare_link(self, "planner", _NODE_PARAMETERS)
        self._reset_runtime()

    def _reset_runtime(self) -> None:
        self.planner: Planner | None = None
        self.planner_map: World | None = None
        self.goal: tuple[float, float] | None = None
        self.last_plan = None
        self.last_error: str | None = None  # why the newest planning gave no path (run scripts)
        self._path_publisher = None
        self._subscriptions: list = []
        self._handover = Handover()
        self._pose = None  # (x, y) of the newest localized /pose
        self._pose_stamp = None
        self._plan_pending = True  # plan on the next localized /pose

    # --- lifecycle -------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the world and build the planner, then create /path and the subscriptions.

        The grid and its costs are built and the search compiled here (so the first plan does
        not stall a lockstep loop); then the /path lifecycle publisher and the /pose and
        /goal_pose subscriptions. FAILURE with a logged reason on a bad world or parameter.
        """
        self._reset_runtime()
        p, problems = read_parameters(self, _NODE_PARAMETERS)
        tuning, tuning_problems = read_parameters(self, self._tuning)
        if self._planner_class is None:
            tuning_problems.append(f"planner '{p['planner']}' cannot be loaded (see the error "
                                   "above)")
        if problems + tuning_problems:
            self.get_logger().error("configure failed: " + "; ".join(problems + tuning_problems))
            return TransitionCallbackReturn.FAILURE
        try:
            world = World.load(p["world"])
            self.goal = _configured_goal(world, p["goal"], p["goal_name"])
            self.planner = self._planner_class(world, **tuning)
            self.planner_map = world
            self.planner.warm_up()
        except Exception as exc:  # WorldError, bad values: user errors, reported
            self.get_logger().error(f"configure failed: {exc}")
            self._reset_runtime()
            return TransitionCallbackReturn.FAILURE
        self.params = p
        self._handover = Handover(bool(p["replan_on_relocalization"]))
        from amr_msgs.msg import PoseStamped
        self._path_publisher = self.create_lifecycle_publisher(Path, p["path_topic"], LATCHED)
        self._subscriptions = [
            self.create_subscription(PoseStamped, p["pose_topic"], self._on_pose, RELIABLE_10),
            self.create_subscription(GoalPoseStamped, p["goal_pose_topic"], self._on_goal_pose,
                                     RELIABLE_10)]
        goal = "none (waiting for /goal_pose)" if self.goal is None else \
            f"({self.goal[0]:.3f}, {self.goal[1]:.3f})"
        self.get_logger().info(f"configured: world '{world.name}', {p['planner']}: "
                               f"{self.planner.describe()}, goal {goal}")
        return TransitionCallbackReturn.SUCCESS

    def release(self) -> None:
        """Destroy the /path publisher and the /pose and /goal_pose subscriptions; drop the grid.

        Nothing to send on the way down: the planner commands no motion.
        """
        for subscription in self._subscriptions:
            self.destroy_subscription(subscription)
        if self._path_publisher is not None:
            self.destroy_lifecycle_publisher(self._path_publisher)
        self._reset_runtime()

    # --- inputs ----------------------------------------------------------------------------
    def _on_pose(self, message) -> None:
        if not self.is_active:
            return
        x, y = message.pose.position.x, message.pose.position.y  # the heading is not needed
        if message.localized and not (math.isfinite(x) and math.isfinite(y)):
            self.get_logger().warning("/pose ignored: not finite", throttle_duration_sec=2.0)
            return
        # When to plan is the Handover's rule (shared with the headless episodes).
        if self._handover.plans(self._handover.update(message.localized)):
            self._plan_pending = True
        if not message.localized:
            return
        self._pose, self._pose_stamp = (x, y), message.header.stamp
        if self._plan_pending:
            self._plan_pending = False
            self._plan()

    def _on_goal_pose(self, message: GoalPoseStamped) -> None:
        if not self.is_active:
            return
        frame = message.header.frame_id
        x, y = message.pose.position.x, message.pose.position.y
        if frame not in (self.params["frame_id"], ""):
            self.get_logger().error(f"/goal_pose in frame '{frame}' ignored: expected "
                                    f"'{self.params['frame_id']}'")
            return
        if not (math.isfinite(x) and math.isfinite(y)):
            self.get_logger().error(f"/goal_pose ({x}, {y}) ignored: not finite")
            return
        self.goal = (float(x), float(y))
        self.get_logger().info(f"new goal ({x:.3f}, {y:.3f})")
        if self._handover.localized and self._pose is not None:
            self._plan()
        else:
            self._plan_pending = True

    # --- planning --------------------------------------------------------------------------
    def _plan(self) -> None:
        """Plan from the newest localized pose to the goal; publish the path (empty if none)."""
        start = self._pose
        if self.goal is None:
            self._fail("no goal: set the `goal` or `goal_name` parameter, give the world a "
                       "goal, or send /goal_pose")
            return
        if self.link_failure is not None:
            return  # the planner failed: the empty path stays
        began = time.perf_counter()
        try:
            plan = link_call("planner", "plan", self.planner.plan, start, self.goal,
                             allowed=(ValueError,))
            points = checked_path(plan)
        except ValueError as exc:  # PlanningError: no path, the message says why
            self._fail(str(exc), "no path: ")
            return
        except LinkFailure as failure:  # a bug, None, a wrong shape: the planner failed
            stamp = self._pose_stamp
            self.fail_link(failure, None if stamp is None else time_to_nanoseconds(stamp) * 1e-9,
                           class_spec(self.planner), "publishing an empty path")
            self.last_plan = None
            self._publish([])
            return
        elapsed_ms = (time.perf_counter() - began) * 1e3
        self.last_plan, self.last_error = plan, None
        self.get_logger().info(
            f"path from ({start[0]:.3f}, {start[1]:.3f}) to ({self.goal[0]:.3f}, "
            f"{self.goal[1]:.3f}): {len(points)} poses, {polyline_length(points):.2f} m, min "
            f"clearance {float(self.planner_map.clearances(points).min()):.3f} m, planned in "
            f"{elapsed_ms:.1f} ms")
        self._publish(points)

    def _fail(self, reason: str, prefix: str = "") -> None:
        """Log why there is no path, keep it in last_error and publish an empty path."""
        self.get_logger().error(f"{prefix}{reason}; publishing an empty path")
        self.last_plan, self.last_error = None, reason
        self._publish([])

    def _publish(self, points) -> None:
        stamp = self._pose_stamp if self._pose_stamp is not None else \
            self.get_clock().now().to_msg()
        self._path_publisher.publish(path_message(points, stamp, self.params["frame_id"]))


def _configured_goal(world: World, goal: Any, goal_name: str) -> tuple[float, float] | None:
    """The goal the parameters ask for (`goal` passed its rule); ValueError for an unknown name.

    Not checked against the walls here: a goal in a wall is reported when planning.
    """
    if goal is not None and len(goal) > 0:
        return float(goal[0]), float(goal[1])
    if goal_name:
        if goal_name not in world.goals:
            raise ValueError(f"goal_name '{goal_name}' is not a goal of world '{world.name}' "
                             f"(named goals: {', '.join(world.goals) or 'none'})")
        return world.goals[goal_name]
    return world.goal


def main(args: list[str] | None = None) -> int:
    return run_lifecycle_node(PlannerNode, args)


if __name__ == "__main__":
    sys.exit(main())
