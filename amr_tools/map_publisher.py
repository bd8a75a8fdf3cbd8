"""The `amr_map_publisher` lifecycle node: a world file as /map and /map_markers, latched.

For the real robot (the simulator publishes its own): give it the course's map JSON, a world
YAML or a Nav2 map YAML (map_saver's, published as its cells, like map_server) by path (or a
bundled world by name) and viewers such as Foxglove draw the walls, and a localization node gets
its map as a nav_msgs/OccupancyGrid:

    .venv/bin/amr_map_publisher --ros-args -p world:=/path/to/map.json -p autostart:=true
"""
from __future__ import annotations

import sys

from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn

from amr_common.plugins.parameter_table import between, ruled
from amr_common.ros.lifecycle_node import GuardedLifecycleNode
from amr_common.ros.map_messages import MAP_MARKERS_TOPIC, MAP_TOPIC, world_map_messages
from amr_common.ros.node_runner import run_lifecycle_node
from amr_common.ros.parameters import declare_parameters, read_parameters
from amr_common.ros.qos import LATCHED
from amr_common.world.world import World

_PARAMETERS = ruled({
    "world": ("lab02", "Bundled world name or path to a world .yaml / the course's map .json / "
                       "a Nav2 map .yaml (published cell for cell)"),
    "resolution": (0.05, "Cell size of /map in metres"),
    "frame_id": ("map", "Frame of the map"),
}, resolution=between(0.005, 1.0))


class MapPublisherNode(GuardedLifecycleNode):
    """Publishes a world's OccupancyGrid on /map and its walls on /map_markers (latched).

    Configure loads the world, builds both messages and creates the two latched lifecycle
    publishers; activate publishes them once; cleanup and shutdown release the publishers
    (release()). Nothing is sent on the way down.
    """

    def __init__(self, node_name: str = "map_publisher", **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        # -p resolution:=1 is fine: numbers take ints for doubles (amr_common.ros.parameters).
        declare_parameters(self, _PARAMETERS)
        self._outputs: dict = {}
        self._messages = None

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the world and build the messages; create the two latched publishers."""
        p, problems = read_parameters(self, _PARAMETERS)
        if problems:
            self.get_logger().error("configure failed: " + "; ".join(problems))
            return TransitionCallbackReturn.FAILURE
        try:
            world = World.load(p["world"])
            stamp = self.get_clock().now().to_msg()
            self._messages = world_map_messages(world, p["resolution"], p["frame_id"], stamp)
        except Exception as exc:  # WorldError and friends: a user's file
            self.get_logger().error(f"configure failed: {exc}")
            return TransitionCallbackReturn.FAILURE
        grid = self._messages[0]
        self._outputs = {
            "map": self.create_lifecycle_publisher(type(grid), MAP_TOPIC, LATCHED),
            "markers": self.create_lifecycle_publisher(type(self._messages[1]),
                                                       MAP_MARKERS_TOPIC, LATCHED)}
        self.get_logger().info(f"configured: world '{world.name}' ({world.source}) as a "
                               f"{grid.info.width} x {grid.info.height} map at "
                               f"{grid.info.resolution} m in frame '{p['frame_id']}'")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the publishers and publish the map and the markers once (they stay latched)."""
        result = super().on_activate(state)
        self._outputs["map"].publish(self._messages[0])
        self._outputs["markers"].publish(self._messages[1])
        return result

    def release(self) -> None:
        """Destroy the two publishers (late subscribers get no map from now on).

        Nothing to send on the way down.
        """
        for publisher in self._outputs.values():
            self.destroy_lifecycle_publisher(publisher)
        self._outputs = {}
        self._messages = None


def main(args: list[str] | None = None) -> int:
    return run_lifecycle_node(MapPublisherNode, args)


if __name__ == "__main__":
    sys.exit(main())
