"""amr_common.ros.message_filters: the message_filters API, reference-identical output, ROS use."""
from __future__ import annotations

import math
import random
import sys
import threading
import time

import pytest
from builtin_interfaces.msg import Time as TimeMsg
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from rclpy.lifecycle import LifecycleNode
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from std_msgs.msg import String

from amr_common.ros import message_filters
from amr_common.ros.message_filters import (
    ApproximateTimeSynchronizer,
    SimpleFilter,
    Subscriber,
    TimeSynchronizer,
)
from tests.sync_reference import ReferenceApproximateSync, random_scenario

NS = 1_000_000_000


def stamped(stamp_ns: int, frame: str = "") -> PointStamped:
    msg = PointStamped()
    msg.header.stamp = TimeMsg(sec=stamp_ns // NS, nanosec=stamp_ns % NS)
    msg.header.frame_id = frame
    return msg


def stamp_ns_of(msg) -> int:
    return msg.header.stamp.sec * NS + msg.header.stamp.nanosec


def make_sync(num_inputs: int, queue_size: int, slop: float, **kwargs):
    """Synchronizer on plain SimpleFilter inputs; returns (inputs, sync, emitted sets)."""
    inputs = [SimpleFilter() for _ in range(num_inputs)]
    sync = ApproximateTimeSynchronizer(inputs, queue_size, slop, **kwargs)
    emitted: list[tuple] = []
    sync.registerCallback(lambda *msgs: emitted.append(msgs))
    return inputs, sync, emitted


def seconds_hitting(slop_ns: int) -> float:
    """A float slop in seconds that rclpy's Duration turns into exactly slop_ns."""
    seconds = slop_ns / NS
    for _ in range(8):
        converted = Duration(seconds=seconds).nanoseconds
        if converted == slop_ns:
            return seconds
        seconds = math.nextafter(seconds, math.inf if converted < slop_ns else -math.inf)
    raise AssertionError(f"no float gives {slop_ns} ns")


@pytest.mark.parametrize("num_inputs,scenarios", [(2, 400), (3, 400)])
def test_public_api_emits_the_reference_sets(num_inputs, scenarios):
    """Through SimpleFilter inputs, real ROS messages and float slops: same sets, same order."""
    rng = random.Random(99 + num_inputs)
    for n in range(scenarios):
        queue_size, slop_ns, arrivals = random_scenario(rng, num_inputs)
        slop = seconds_hitting(slop_ns)
        oracle = ReferenceApproximateSync(num_inputs, queue_size,
                                          Duration(seconds=slop).nanoseconds)
        inputs, sync, emitted = make_sync(num_inputs, queue_size, slop)
        expected = []
        for i, stamp in arrivals:
            msg = stamped(stamp)
            inputs[i].signalMessage(msg)
            out = oracle.add(msg, stamp, oracle.queues[i], i)
            if out is not None:
                expected.append(tuple(out))
        assert len(emitted) == len(expected), f"scenario {n}"
        assert all(a is b for got, want in zip(emitted, expected) for a, b in zip(got, want)), \
            f"scenario {n}: queue_size={queue_size} slop={slop!r} arrivals={arrivals}"


def test_slop_conversion_is_rclpy_durations():
    rng = random.Random(3)
    for slop in [0.1, 0.29, 0.3, 1e-9, 0.05, 1.0, 7] + [rng.uniform(0, 2) for _ in range(2000)]:
        _, sync, _ = make_sync(2, 1, slop)
        assert sync.slop.nanoseconds == Duration(seconds=slop).nanoseconds


def test_exact_stamps_match_and_extra_args_follow_the_messages():
    inputs = [SimpleFilter(), SimpleFilter()]
    sync = ApproximateTimeSynchronizer(inputs, 10, 0.01)
    calls = []
    first = sync.registerCallback(lambda a, b, tag: calls.append((a, b, tag)), "first")
    second = sync.registerCallback(lambda a, b: calls.append((a, b)))
    assert first != second
    a, b = stamped(5 * NS, "a"), stamped(5 * NS, "b")
    inputs[1].signalMessage(b)
    inputs[0].signalMessage(a)
    assert calls == [(a, b, "first"), (a, b)]
    assert sync.queues == [{}, {}]


def test_slop_edges_inclusive_for_candidates_strict_for_the_set():
    inputs, sync, emitted = make_sync(2, 10, 0.05)
    inputs[0].signalMessage(stamped(1 * NS))
    inputs[1].signalMessage(stamped(1 * NS + 50_000_000))  # exactly slop apart: no set
    assert emitted == []
    inside = stamped(1 * NS + 49_999_999)
    inputs[1].signalMessage(inside)
    assert [stamp_ns_of(m) for m in emitted[0]] == [1 * NS, 1 * NS + 49_999_999]
    assert emitted[0][1] is inside


def test_eviction_drops_the_oldest_stamp_beyond_queue_size():
    inputs, sync, emitted = make_sync(2, 3, 0.01)
    for k in [4, 1, 2, 3]:  # out of order: stamp 1 s is the oldest, evicted at the 4th
        inputs[0].signalMessage(stamped(k * NS))
    assert list(sync.queues[0]) == [4 * NS, 2 * NS, 3 * NS]
    inputs[1].signalMessage(stamped(1 * NS))
    assert emitted == []
    inputs[1].signalMessage(stamped(2 * NS))
    assert [stamp_ns_of(m) for m in emitted[0]] == [2 * NS, 2 * NS]


def test_same_stamp_replaces_in_place_and_keeps_queue_position():
    inputs, sync, emitted = make_sync(2, 10, 0.1)
    inputs[1].signalMessage(stamped(100_000_000, "b100"))
    inputs[1].signalMessage(stamped(90_000_000, "b90"))
    newer = stamped(100_000_000, "b100 again")
    inputs[1].signalMessage(newer)
    assert list(sync.queues[1]) == [100_000_000, 90_000_000]
    # a at 95 ms: both b are 5 ms away; the tie goes to queue order, where b100 kept first place.
    inputs[0].signalMessage(stamped(95_000_000, "a95"))
    assert [m.header.frame_id for m in emitted[0]] == ["a95", "b100 again"]


def test_three_inputs_out_of_order_arrival():
    inputs, sync, emitted = make_sync(3, 10, 0.02)
    inputs[2].signalMessage(stamped(2_010_000_000, "c2"))
    inputs[0].signalMessage(stamped(2_000_000_000, "a2"))
    inputs[0].signalMessage(stamped(1_000_000_000, "a1"))  # late arrival of an older stamp
    inputs[1].signalMessage(stamped(1_005_000_000, "b1"))
    assert emitted == []  # no c near 1 s yet
    inputs[2].signalMessage(stamped(1_015_000_000, "c1"))
    inputs[1].signalMessage(stamped(2_001_000_000, "b2"))
    assert [[m.header.frame_id for m in s] for s in emitted] == [["a1", "b1", "c1"],
                                                                ["a2", "b2", "c2"]]
    assert sync.queues == [{}, {}, {}]


def test_time_synchronizer_emits_exact_matches_in_ascending_order():
    inputs = [SimpleFilter(), SimpleFilter()]
    sync = TimeSynchronizer(inputs, 5)
    emitted = []
    sync.registerCallback(lambda a, b: emitted.append((a.header.frame_id, b.header.frame_id)))
    for k in [3, 1, 2]:
        inputs[0].signalMessage(stamped(k * NS, f"a{k}"))
    inputs[1].signalMessage(stamped(1 * NS + 1, "b1+1ns"))  # not exact: waits
    assert emitted == []
    inputs[1].signalMessage(stamped(3 * NS, "b3"))
    inputs[1].signalMessage(stamped(1 * NS, "b1"))
    assert emitted == [("a3", "b3"), ("a1", "b1")]
    assert list(sync.queues[0]) == [2 * NS] and list(sync.queues[1]) == [1 * NS + 1]


def test_headerless_dropped_with_a_throttled_warning_when_not_allowed(capfd):
    inputs, sync, emitted = make_sync(2, 10, 0.1)
    for _ in range(3):
        inputs[0].signalMessage(String(data="no header"))
    inputs[1].signalMessage(stamped(time.time_ns()))
    assert emitted == [] and sync.queues[0] == {}
    err = capfd.readouterr().err
    assert err.count("without header stamp") == 1, err


def test_invalid_stamp_dropped_with_a_warning(capfd):
    inputs, sync, emitted = make_sync(2, 10, 0.1)
    bad = stamped(0)
    bad.header.stamp = TimeMsg(sec=-5, nanosec=0)
    inputs[0].signalMessage(bad)
    inputs[1].signalMessage(stamped(0))
    assert emitted == [] and sync.queues[0] == {}
    assert "negative" in capfd.readouterr().err


def test_headerless_allowed_without_a_node_uses_ros_clock_time():
    inputs, sync, emitted = make_sync(2, 10, 5.0, allow_headerless=True)
    inputs[0].signalMessage(String(data="no header"))
    inputs[1].signalMessage(stamped(time.time_ns()))
    assert len(emitted) == 1 and emitted[0][0].data == "no header"


def test_headerless_allowed_uses_the_node_clock_under_sim_time(ros):
    node = ros.node("sync_sim_time",
                    parameter_overrides=[Parameter("use_sim_time", Parameter.Type.BOOL, True)])
    clock_pub = ros.node("sim_clock").create_publisher(Clock, "/clock", 10)
    sim_now = TimeMsg(sec=1000, nanosec=0)

    def sim_time_received() -> bool:
        clock_pub.publish(Clock(clock=sim_now))
        return node.get_clock().now().nanoseconds == 1000 * NS
    ros.spin_until(sim_time_received, timeout=10.0, message="the node to follow /clock")

    words = Subscriber(node, String, "words")
    points = Subscriber(node, PointStamped, "points", qos_profile=5)
    sync = ApproximateTimeSynchronizer([words, points], 10, 0.1, allow_headerless=True)
    emitted = []
    sync.registerCallback(lambda w, p: emitted.append((w, p)))
    words.callback(String(data="stamped by the sim clock"))  # as if received
    assert list(sync.queues[0]) == [1000 * NS]  # sim time, not wall time
    points.callback(stamped(1000 * NS + 50_000_000))
    assert len(emitted) == 1 and emitted[0][0].data == "stamped by the sim clock"


def test_callbacks_run_outside_the_lock_and_may_reenter():
    inputs, sync, emitted = make_sync(2, 10, 0.1)
    lock_held = []

    def reenter(a, b):
        lock_held.append(sync.lock.locked())
        if len(lock_held) == 1:  # feed the next pair from inside the callback
            inputs[0].signalMessage(stamped(2 * NS))
            inputs[1].signalMessage(stamped(2 * NS))
    sync.registerCallback(reenter)
    done = threading.Event()

    def feed():
        inputs[0].signalMessage(stamped(1 * NS))
        inputs[1].signalMessage(stamped(1 * NS))
        done.set()
    threading.Thread(target=feed, daemon=True).start()
    assert done.wait(5.0), "add deadlocked when a callback re-entered the synchronizer"
    assert lock_held == [False, False] and len(emitted) == 2


def test_concurrent_inputs_emit_every_pair_once():
    """Two threads feed the two inputs: the lock keeps the queues consistent.

    The threads stay within 10 messages of each other, so every stamp pairs exactly once.
    """
    inputs, sync, emitted = make_sync(2, 50, 0.001)
    count = 600
    barrier = threading.Barrier(2)

    def feed(i):
        for k in range(count):
            if k % 10 == 0:
                barrier.wait(timeout=10.0)
            inputs[i].signalMessage(stamped(k * 10_000_000, f"{i}:{k}"))
    threads = [threading.Thread(target=feed, args=(i,), daemon=True) for i in (0, 1)]
    switch_interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads often, to interleave inside add()
    try:
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(timeout=30.0)
    finally:
        sys.setswitchinterval(switch_interval)
    pairs = sorted((stamp_ns_of(a), stamp_ns_of(b)) for a, b in emitted)
    assert pairs == [(k * 10_000_000, k * 10_000_000) for k in range(count)]
    assert sync.queues == [{}, {}]


@pytest.mark.parametrize("kwargs,match", [
    ({"queue_size": 0, "slop": 0.1}, "queue_size"),
    ({"queue_size": 10, "slop": -0.1}, "slop"),
    ({"queue_size": 10, "slop": float("nan")}, "slop"),
    ({"queue_size": 10, "slop": float("inf")}, "slop")])
def test_bad_parameters_raise_value_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ApproximateTimeSynchronizer([SimpleFilter(), SimpleFilter()], **kwargs)
    with pytest.raises(ValueError, match="queue_size"):
        TimeSynchronizer([SimpleFilter()], -1)


def test_odometry_and_best_effort_scan_are_paired_over_ros(ros):
    sender = ros.node("sync_sender")
    odom_pub = sender.create_publisher(Odometry, "sync_odom", 10)
    scan_pub = sender.create_publisher(LaserScan, "sync_scan", qos_profile_sensor_data)
    receiver = ros.node("sync_receiver")
    odom_sub = message_filters.Subscriber(receiver, Odometry, "sync_odom", 10)
    scan_sub = message_filters.Subscriber(receiver, LaserScan, "sync_scan",
                                          qos_profile=qos_profile_sensor_data)
    assert scan_sub.getTopic() == "sync_scan"
    assert scan_sub.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT  # via .sub
    sync = message_filters.ApproximateTimeSynchronizer([odom_sub, scan_sub], 10, 0.02)
    pairs = []
    sync.registerCallback(lambda odom, scan: pairs.append((odom, scan)))
    ros.spin_until(lambda: odom_pub.get_subscription_count() and
                   scan_pub.get_subscription_count(), timeout=10.0, message="discovery")

    sent = [0]

    def publish_and_count() -> bool:
        k = sent[0] = sent[0] + 1
        odom, scan = Odometry(), LaserScan()
        odom.header.stamp = TimeMsg(sec=k, nanosec=0)
        scan.header.stamp = TimeMsg(sec=k, nanosec=7_000_000)  # 7 ms later, within 20 ms
        odom_pub.publish(odom)
        scan_pub.publish(scan)
        ros.spin_for(0.01)
        return len(pairs) >= 5
    ros.spin_until(publish_and_count, timeout=15.0, message="5 synchronized pairs")
    for odom, scan in pairs:
        assert stamp_ns_of(scan) - stamp_ns_of(odom) == 7_000_000
    assert [stamp_ns_of(o) for o, _ in pairs] == sorted(stamp_ns_of(o) for o, _ in pairs)

    odom_sub.close()
    scan_sub.destroy()
    scan_sub.close()  # idempotent
    assert list(receiver.subscriptions) == []


def test_subscriber_can_be_released_by_a_lifecycle_node(ros):
    node = ros.add(LifecycleNode("sync_lifecycle", context=ros.context))
    sub = Subscriber(node, String, "lc_words", QoSProfile(depth=3))
    assert sub.node is node and list(node.subscriptions) == [sub.sub]
    sub.close()  # what on_cleanup does
    assert sub.sub is None and list(node.subscriptions) == []
