"""Shared by the TF and map tests.

A probe recording /tf, /tf_static, /map and /map_markers, a simulator started with it, and the
check that a raster matches its world.
"""
from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import OccupancyGrid
from rclpy.lifecycle import TransitionCallbackReturn
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from amr_common.ros import tf
from amr_common.ros.qos import LATCHED
from amr_common.world.map_raster import FREE, OCCUPIED, UNKNOWN, Raster, points_in_polygon
from amr_common.world.world import World
from tests.test_simulator_node import Probe, start_simulator


def planar(t: TransformStamped) -> tuple[float, float, float]:
    q = t.transform.rotation
    return (t.transform.translation.x, t.transform.translation.y,
            math.atan2(2.0 * q.w * q.z, 1.0 - 2.0 * q.z * q.z))


def by_child(message: TFMessage) -> dict[str, TransformStamped]:
    return {t.child_frame_id: t for t in message.transforms}


class FrameProbe:
    def __init__(self, ros) -> None:
        self.node = ros.node("frame_probe")
        self.tf: list[TFMessage] = []
        self.static: list[TFMessage] = []
        self.maps: list[OccupancyGrid] = []
        self.markers: list[MarkerArray] = []
        self.node.create_subscription(TFMessage, "/tf", self.tf.append, tf.TF_QOS)
        self.node.create_subscription(TFMessage, "/tf_static", self.static.append,
                                      tf.TF_STATIC_LISTENER_QOS)
        self.node.create_subscription(OccupancyGrid, "/map", self.maps.append, LATCHED)
        self.node.create_subscription(MarkerArray, "/map_markers", self.markers.append, LATCHED)


def start_with_frames(ros, **parameters):
    probe, frames = Probe(ros), FrameProbe(ros)
    node = start_simulator(ros, probe, activate=False, **parameters)
    ros.spin_until(lambda: node._outputs.tf._tf.get_subscription_count() > 0,
                   message="the /tf subscriber to be matched")
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    return node, probe, frames


def _in(polygon, x: float, y: float) -> bool:
    return bool(points_in_polygon(polygon, np.array([x]), np.array([y]))[0])


def check_raster_matches_world(raster: Raster, world: World) -> None:
    values = raster.values
    cx, cy = raster.centres()
    centres = np.column_stack([cx.ravel(), cy.ravel()])
    clearance = world.clearances(centres).reshape(values.shape)
    inside = np.array([world.contains(x, y) for x, y in centres]).reshape(values.shape)
    res = raster.resolution
    outside = np.array([not _in(world.boundary, x, y) for x, y in centres]).reshape(values.shape)
    # Free space at least a cell from any wall is free; outside the boundary is unknown, inside
    # an obstacle occupied.
    assert np.all(values[inside & (clearance > res)] == FREE)
    assert np.all(values[outside & (clearance > res)] == UNKNOWN)
    assert np.all(values[~inside & ~outside & (clearance > res)] == OCCUPIED)
    # Every point on every wall lies in an occupied cell.
    for x1, y1, x2, y2 in world.segments:
        for t in np.linspace(0.0, 1.0, 25):
            row, col = raster.cell_of(x1 + t * (x2 - x1), y1 + t * (y2 - y1))
            assert values[row, col] == OCCUPIED
    assert 0 < np.count_nonzero(values == OCCUPIED) < np.count_nonzero(values == FREE)
