"""Everything the simulator node publishes: its measurements, frames and map.

SimulatorOutputs: /clock, the odometry topic, /scan and /ground_truth, each refilled into one
reused message per step, on the profile's rates in real time; SimulatorTf: /tf, /tf_static,
/map and /map_markers. What the real Burger's bringup publishes (robot_state_publisher's
base_footprint -> base_scan, turtlebot3_node's odom -> base_footprint with each /odom) plus what
only a simulator knows: the true pose on /ground_truth and as map -> base_footprint_truth and,
for viewers when no localization node runs, the perfect map -> odom (`map_to_odom_from_truth`).
The world is published as /map and /map_markers, latched; /world_markers (latched) shows what
the world has beyond the navigation map: the walls it lacks and the movers, updated as they
walk. Publishers are lifecycle publishers of the simulator node, created in its on_configure
and destroyed by `destroy()`.
With a reality-gap profile each /scan carries its own geometry (the LDS-02's changes every scan)
and, in real time, ScanDelivery loses some and delays the others as a Wi-Fi link does.
"""
from __future__ import annotations

from typing import Any

from builtin_interfaces.msg import Time
from nav_msgs.msg import Odometry
from rclpy.clock import Clock, ClockType
from rosgraph_msgs.msg import Clock as ClockMessage
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage

from amr_common.geometry import angle_difference
from amr_common.robot import LIDAR_HEIGHT, step_chord
from amr_common.ros.map_messages import (
    MAP_MARKERS_TOPIC,
    MAP_TOPIC,
    WORLD_MARKERS_TOPIC,
    world_map_messages,
    world_markers,
)
from amr_common.ros.qos import LATCHED, RELIABLE_10, scan_qos
from amr_common.ros.ros_conversions import (
    float32_array,
    laser_scan,
    laser_scan_from_profile,
    odometry_message,
    seconds_to_time,
)
from amr_common.ros.tf import (
    TF_QOS,
    TF_TOPIC,
    StaticTransformBroadcaster,
    map_to_odom,
    planar_transform,
)
from amr_common.world.coverage_grid import GridTooLargeError
from amr_common.world.map_vs_world import load_map, unmapped_walls
from amr_sim.reality import delivery_stream

WORLD_MARKERS_PERIOD_S = 0.1  # simulated time between /world_markers updates while movers walk


def true_velocity(before: tuple, after: tuple, dt: float) -> tuple[float, float]:
    """Body-frame (v, w) that moved the robot from pose `before` to `after` in dt."""
    d_theta = angle_difference(after[2], before[2])
    forward = step_chord(after[0] - before[0], after[1] - before[1], before[2], d_theta)
    return forward / dt, d_theta / dt


class SimulatorOutputs:
    """The simulator node's lifecycle publishers and the messages they reuse.

    Creates /clock, the odometry topic, /scan, /ground_truth (with publish_ground_truth) in
    `publishers` and the SimulatorTf (`tf`) on construction (in on_configure); `destroy()`
    releases them all. If the map cannot be built, what was created is released and the
    exception propagates.
    """

    def __init__(self, node, simulator, p: dict[str, Any], odometry_topic: str,
                 realtime: bool) -> None:
        self._node = node
        self._simulator = simulator
        self._params = p
        self._realtime = realtime
        self.odometry_topic = odometry_topic
        profile = simulator.profile
        # One message per output, refilled every step: building Odometry messages dominated
        # the step time (publish copies the message, so reuse is safe).
        self._messages = {"clock": ClockMessage(), "truth": Odometry(), "odom": Odometry(),
                          "scan": LaserScan(), "stamp": Time()}
        create = node.create_lifecycle_publisher
        self.publishers = {
            "clock": create(ClockMessage, "/clock", RELIABLE_10),
            "odom": create(Odometry, odometry_topic, RELIABLE_10),
            "scan": create(LaserScan, "/scan",
                           scan_qos(5 if profile.odom_topic == "/odom" else 10)),
        }
        if p["publish_ground_truth"]:
            self.publishers["truth"] = create(Odometry, "/ground_truth", RELIABLE_10)
        self.tf: SimulatorTf | None = None
        self._world_markers = None
        try:
            self.tf = SimulatorTf(node, simulator, p)
            if p["publish_world_markers"]:
                self._world_markers = WorldMarkers(node, simulator, p)
        except Exception:  # a map that cannot be built: release what exists, then report
            self.destroy()
            raise
        scan_time = profile.scan_period if realtime and profile.scan_period else p["dt"]
        # A real scanner's scan: its revolution, the geometry of each scan (the LDS-02's).
        self._real_scanner = profile.lidar_model is not None
        if self._real_scanner:
            scan_time = profile.lidar_model.revolution_s
        else:
            laser_scan_from_profile(simulator.last_scan, profile, stamp=Time(),
                                    frame_id=p["scan_frame"], scan_time=scan_time,
                                    message=self._messages["scan"])
        self._scan_time = scan_time
        self._next_publish = {"odom": 0.0, "scan": 0.0}
        effects = simulator.effects
        self._delivery = ScanDelivery(node, self.publishers["scan"], delivery_stream(p["seed"]),
                                      effects.scan_loss_share, effects.scan_jitter_s) \
            if realtime and effects is not None else None

    def publish_first(self, z_scan, z_v: float, z_w: float) -> None:
        """/tf_static and the map, then the current measurement (it starts a lockstep loop).

        In real time each sensor's schedule restarts from now.
        """
        simulator = self._simulator
        self.tf.publish_static(seconds_to_time(simulator.time))  # before the measurement
        if self._world_markers is not None:
            self._world_markers.publish(seconds_to_time(simulator.time))
        self.publish(z_scan, z_v, z_w, simulator.pose, simulator.pose, True, True)
        if self._realtime:
            profile = simulator.profile
            self._next_publish = {"odom": simulator.time + (profile.odom_period or 0.0),
                                  "scan": simulator.time + (profile.scan_period or 0.0)}

    def due(self, sensor: str, period: float | None) -> bool:
        """Real-time rate of one sensor: due when simulated time reaches its next slot."""
        now = self._simulator.time
        if period is None:
            return True
        if now + 1e-9 < self._next_publish[sensor]:
            return False
        self._next_publish[sensor] += period
        if self._next_publish[sensor] <= now + 1e-9:  # fell behind: no burst to catch up
            self._next_publish[sensor] = now + period
        return True

    def publish(self, z_scan, z_v: float, z_w: float, pose_before: tuple, pose: tuple,
                publish_odom: bool, publish_scan: bool) -> None:
        """One step's messages, stamped with the simulated time.

        /clock and /ground_truth always (while anyone subscribes), /tf and the odometry topic
        if `publish_odom`, /scan if `publish_scan`.
        """
        simulator, p, messages = self._simulator, self._params, self._messages
        publishers = self.publishers
        stamp = seconds_to_time(simulator.time, messages["stamp"])  # shared: publish copies
        # /clock and /ground_truth only while someone listens (each costs ~40 us per step, a
        # tenth of a lockstep round trip). /clock first: a use_sim_time subscriber then has
        # the time before the measurements.
        if publishers["clock"].get_subscription_count() > 0:
            messages["clock"].clock = stamp
            publishers["clock"].publish(messages["clock"])
        if "truth" in publishers and publishers["truth"].get_subscription_count() > 0:
            velocity = true_velocity(pose_before, pose, simulator.dt)
            publishers["truth"].publish(odometry_message(
                stamp, p["world_frame"], p["base_frame"], pose, velocity, messages["truth"]))
        if self._world_markers is not None:
            self._world_markers.update(stamp)
        if publish_odom:
            self.tf.publish(stamp, pose)
            # The real robot's /odom carries a pose only; /odometry also the twist.
            twist = (z_v, z_w) if self.odometry_topic == "/odometry" else None
            publishers["odom"].publish(odometry_message(
                stamp, p["odom_frame"], p["base_frame"], simulator.odometry_pose, twist,
                messages["odom"]))
        if publish_scan and self._real_scanner:
            angle_min, increment, _, range_min, range_max = simulator.scan_geometry
            # A new message and stamp: a late scan is published after `stamp` is reused.
            scan = laser_scan(z_scan, stamp=seconds_to_time(simulator.time),
                              frame_id=p["scan_frame"],
                              angle_min=angle_min, angle_increment=increment,
                              range_min=range_min, range_max=range_max,
                              scan_time=self._scan_time)
            if self._delivery is not None:  # real time: lost or late, as over Wi-Fi
                self._delivery.send(scan)
            else:
                publishers["scan"].publish(scan)
        elif publish_scan:
            # Every other field was filled in on construction.
            scan = messages["scan"]
            scan.header.stamp = stamp
            scan.ranges = float32_array(z_scan)
            publishers["scan"].publish(scan)

    def cancel_late_scans(self) -> None:
        """Drop the real-time scans still on their way (deactivate: nothing arrives later)."""
        if self._delivery is not None:
            self._delivery.destroy()

    def destroy(self) -> None:
        """Destroy every publisher this object created (pending late scans too). Idempotent."""
        self.cancel_late_scans()
        for publisher in self.publishers.values():
            self._node.destroy_lifecycle_publisher(publisher)
        self.publishers = {}
        if self.tf is not None:
            self.tf.destroy()
            self.tf = None
        if self._world_markers is not None:
            self._node.destroy_lifecycle_publisher(self._world_markers.publisher)
            self._world_markers = None


class SimulatorTf:
    """Creates the publishers on construction (in on_configure); `destroy()` releases them."""

    def __init__(self, node, simulator, p: dict[str, Any]) -> None:
        self._node = node
        self._simulator = simulator
        self._frames = (p["world_frame"], p["odom_frame"], p["base_frame"], p["truth_frame"])
        self._map_to_odom = bool(p["map_to_odom_from_truth"])
        self._scan_frame = p["scan_frame"]
        self._map_messages = None
        if p["publish_map"]:
            try:
                self._map_messages = world_map_messages(simulator.world, p["map_resolution"],
                                                        p["world_frame"])
            except GridTooLargeError as exc:  # a huge world still simulates, without /map
                node.get_logger().warning(f"no /map: {exc}")
        create = node.create_lifecycle_publisher
        self._tf = create(TFMessage, TF_TOPIC, TF_QOS)
        self._static = StaticTransformBroadcaster(node, create)
        self._map_publishers = [] if self._map_messages is None else [
            create(type(message), topic, LATCHED)
            for message, topic in zip(self._map_messages, (MAP_TOPIC, MAP_MARKERS_TOPIC))]
        # Reused every step (publish copies): odom -> base, map -> truth[, map -> odom].
        self._message = TFMessage(transforms=[
            planar_transform(None, "", "", 0.0, 0.0, 0.0)
            for _ in range(3 if self._map_to_odom else 2)])

    def publish_static(self, stamp) -> None:
        """base_footprint -> base_scan at the profile's LiDAR position, then the map."""
        lidar_x = self._simulator.profile.lidar_offset_x
        self._static.send([planar_transform(stamp, self._frames[2], self._scan_frame,
                                            lidar_x, 0.0, 0.0, LIDAR_HEIGHT)])
        if self._map_messages is not None:
            grid, markers = self._map_messages
            grid.header.stamp = grid.info.map_load_time = stamp
            for marker in markers.markers:
                marker.header.stamp = stamp
            for publisher, message in zip(self._map_publishers, self._map_messages):
                publisher.publish(message)

    def publish(self, stamp, true_pose: tuple[float, float, float]) -> None:
        """The moving frames at `stamp`, while anyone subscribes to /tf (cheap otherwise)."""
        if self._tf.get_subscription_count() == 0:
            return
        world, odom, base, truth = self._frames
        odometry_pose = self._simulator.odometry_pose
        transforms = self._message.transforms
        planar_transform(stamp, odom, base, *odometry_pose, message=transforms[0])
        planar_transform(stamp, world, truth, *true_pose, message=transforms[1])
        if self._map_to_odom:
            planar_transform(stamp, world, odom, *map_to_odom(true_pose, odometry_pose),
                             message=transforms[2])
        self._tf.publish(self._message)

    def destroy(self) -> None:
        """Destroy every publisher this object created."""
        for publisher in [self._tf, self._static.publisher, *self._map_publishers]:
            self._node.destroy_lifecycle_publisher(publisher)
        self._map_publishers = []


class WorldMarkers:
    """/world_markers: the walls the navigation map lacks and the movers where they are.

    Creates its latched publisher on construction; loading `navigation_map` may raise
    (WorldError), then nothing was created.
    """

    def __init__(self, node, simulator, p: dict[str, Any]) -> None:
        world = simulator.world
        unmapped = unmapped_walls(world, load_map(p["navigation_map"] or None, world))
        self._simulator = simulator
        self._message = world_markers(unmapped, simulator.movers.circles, p["world_frame"])
        self._next = 0.0
        self.publisher = node.create_lifecycle_publisher(type(self._message),
                                                         WORLD_MARKERS_TOPIC, LATCHED)

    def publish(self, stamp) -> None:
        """The markers as they are now (on activation: latched for late subscribers)."""
        world_markers((), self._simulator.movers.circles, stamp=stamp, message=self._message)
        self.publisher.publish(self._message)
        self._next = self._simulator.time + WORLD_MARKERS_PERIOD_S

    def update(self, stamp) -> None:
        """The movers' new positions, every WORLD_MARKERS_PERIOD_S while anyone listens."""
        simulator = self._simulator
        if (len(simulator.movers) and simulator.time >= self._next - 1e-9
                and self.publisher.get_subscription_count() > 0):
            self.publish(stamp)


class ScanDelivery:
    """Best-effort /scan over a lossy link: some scans lost, the others late.

    Each scan is lost with probability `loss`; the others are published after a random delay
    in [0, jitter] s (a one-shot steady-clock timer each). `destroy()` drops the scans still
    on their way (on deactivate/cleanup nothing is sent late).
    """

    def __init__(self, node, publisher, rng, loss: float, jitter: float) -> None:
        self._node = node
        self._publisher = publisher
        self._rng = rng
        self._loss = float(loss)
        self._jitter = float(jitter)
        self._timers: list = []
        self.sent = 0
        self.lost = 0

    def send(self, message) -> None:
        """Publish `message` now, later, or never."""
        if self._rng.random() < self._loss:
            self.lost += 1
            return
        delay = self._jitter * self._rng.random()
        if delay <= 0.0:
            self._publish(message)
            return
        timer = None

        def deliver() -> None:
            self._forget(timer)
            self._publish(message)

        timer = self._node.create_timer(delay, deliver,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._timers.append(timer)

    def _publish(self, message) -> None:
        self.sent += 1
        self._publisher.publish(message)

    def _forget(self, timer) -> None:
        if timer in self._timers:
            self._timers.remove(timer)
            timer.cancel()
            self._node.destroy_timer(timer)

    def destroy(self) -> None:
        """Cancel the scans still on their way."""
        for timer in list(self._timers):
            self._forget(timer)
