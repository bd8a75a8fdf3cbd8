"""Drop-in replacement for ROS 2 Jazzy ``message_filters`` (Python), which is not on PyPI.

Write ``from amr_common.ros import message_filters`` (instead of ``import message_filters``) or
``from amr_common.ros.message_filters import ApproximateTimeSynchronizer, Subscriber``; the rest of
the code stays as in the course material::

    odom_sub = message_filters.Subscriber(node, Odometry, "odom")
    scan_sub = message_filters.Subscriber(node, LaserScan, "scan", qos_profile_sensor_data)
    sync = message_filters.ApproximateTimeSynchronizer([odom_sub, scan_sub], 10, 0.05)
    sync.registerCallback(on_odom_and_scan)

For any input sequence the synchronizers emit the same message sets, in the same order, as the
Jazzy reference (semantics: shared/notes/message_filters.md; logic:
`amr_common.ros.time_matching`). Differences, all on the reference's weak spots:
- the approximate search is polynomial instead of exponential in the number of inputs;
- callbacks run after the queue lock is released (a callback may call back into the filter);
- headerless messages (allow_headerless=True) are stamped with the node's clock, so
  use_sim_time holds; the node is taken from the first input that has one (Subscriber.node);
- dropped messages (headerless when not allowed, invalid stamps) give a throttled warning
  instead of one per message or an exception in the executor;
- bad queue_size / slop raise ValueError at construction;
- Subscriber accepts the QoS positionally too and can be destroyed (close()/destroy()), which
  lifecycle nodes need in on_cleanup.
"""
from __future__ import annotations

import itertools
import threading
import time
from typing import Any, Callable, Sequence

import rclpy.logging
from rclpy.clock import ROSClock
from rclpy.duration import Duration

from amr_common.ros import time_matching

__all__ = ["SimpleFilter", "Subscriber", "TimeSynchronizer", "ApproximateTimeSynchronizer"]


class SimpleFilter:
    """Base filter: holds callbacks and signals messages to them."""

    def __init__(self) -> None:
        self.callbacks: dict[int, tuple[Callable[..., Any], tuple]] = {}
        self._connection_ids = itertools.count()

    def registerCallback(self, cb: Callable[..., Any], *args: Any) -> int:  # noqa: N802
        """Call `cb(*messages, *args)` on every output of this filter; return a connection id."""
        if not hasattr(self, "_connection_ids"):  # a subclass that skipped __init__
            self._connection_ids = itertools.count(len(getattr(self, "callbacks", {})))
        connection = next(self._connection_ids)  # unique even after entries were removed
        self.callbacks[connection] = (cb, args)
        return connection

    def signalMessage(self, *msg: Any) -> None:  # noqa: N802
        """Call every registered callback with the messages followed by its extra args."""
        for cb, args in list(self.callbacks.values()):  # a callback may register another
            cb(*(msg + args))


class Subscriber(SimpleFilter):
    """A ROS 2 subscription as the first filter of a chain: every message is signalled on.

    `qos_profile` may be given positionally or by keyword (default depth 10); other keyword
    arguments (callback_group, event_callbacks, ...) go to `node.create_subscription`.
    Attributes of the rclpy Subscription are reachable through this object, as in the reference.
    """

    def __init__(self, node: Any, msg_type: Any, topic: str, qos_profile: Any = 10,
                 **kwargs: Any) -> None:
        SimpleFilter.__init__(self)
        self.node = node
        self.topic = topic
        self.sub = node.create_subscription(msg_type, topic, self.callback, qos_profile,
                                            **kwargs)

    def callback(self, msg: Any) -> None:
        """The subscription's callback: pass the message on to the connected filters."""
        self.signalMessage(msg)

    def getTopic(self) -> str:  # noqa: N802
        """The subscribed topic name (reference API)."""
        return self.topic

    def close(self) -> None:
        """Destroy the subscription (e.g. in a lifecycle node's on_cleanup). Idempotent."""
        sub, self.sub = self.sub, None
        if sub is not None:
            self.node.destroy_subscription(sub)

    destroy = close

    def __getattr__(self, key: str) -> Any:
        sub = self.__dict__.get("sub")
        if sub is None or key.startswith("__"):
            raise AttributeError(f"{type(self).__name__!s} has no attribute {key!r}")
        return getattr(sub, key)


class _ThrottledWarning:
    """Logs the first warning at once, then at most one per period with a suppressed count."""

    def __init__(self, period_s: float = 5.0) -> None:
        self.period_s = period_s
        self._last_logged: float | None = None
        self._suppressed = 0

    def __call__(self, logger: Any, text: str) -> None:
        now = time.monotonic()
        if self._last_logged is not None and now - self._last_logged < self.period_s:
            self._suppressed += 1
            return
        if self._suppressed:
            text += f" ({self._suppressed} more since the last warning)"
        logger.warning(text)
        self._last_logged = now
        self._suppressed = 0


class TimeSynchronizer(SimpleFilter):
    """Emits one message per input when all inputs hold a message with the SAME header stamp.

    After each arrival every stamp present on all inputs is emitted, in ascending order, and
    those messages are removed; each input keeps at most `queue_size` stamps (smallest dropped).
    The callback is `cb(msg_1, ..., msg_N, *args)`, messages in the order of `fs`.
    """

    _logger_name = "message_filters_exact"

    def __init__(self, fs: Sequence[Any], queue_size: int) -> None:
        SimpleFilter.__init__(self)
        self._queue_size = time_matching.validate_queue_size(queue_size)
        self.lock = threading.Lock()
        self._warn_headerless = _ThrottledWarning()
        self._warn_bad_stamp = _ThrottledWarning()
        self.connectInput(fs)

    @property
    def queue_size(self) -> int:
        """Messages kept per input."""
        return self._queue_size

    @queue_size.setter
    def queue_size(self, value: int) -> None:
        self._queue_size = time_matching.validate_queue_size(value)

    def connectInput(self, fs: Sequence[Any]) -> None:  # noqa: N802
        """Take inputs from the filters `fs` (new, empty queues)."""
        fs = list(fs)
        self.queues: list[dict[int, Any]] = [{} for _ in fs]
        self.input_connections = [f.registerCallback(self.add, q, i_q)
                                  for i_q, (f, q) in enumerate(zip(fs, self.queues))]
        self.node = _first_node(fs)

    def add(self, msg: Any, my_queue: dict, my_queue_index: int | None = None) -> None:
        """Queue `msg` (arrived on the input owning `my_queue`) and emit completed sets."""
        stamp_ns = self._stamp_ns(msg, allow_headerless=False)
        if stamp_ns is None:
            return
        with self.lock:
            time_matching.insert_and_evict(my_queue, stamp_ns, msg, self._queue_size)
            matches = time_matching.pop_exact_matches(self.queues)
        for messages in matches:  # outside the lock
            self.signalMessage(*messages)

    def _stamp_ns(self, msg: Any, allow_headerless: bool) -> int | None:
        """Header stamp in ns, the clock's time for allowed headerless messages, else None."""
        try:
            stamp_ns = time_matching.message_stamp_ns(msg)
        except time_matching.InvalidStampError as error:
            self._warn_bad_stamp(self._logger(), f"dropping a {type(msg).__name__}: {error}")
            return None
        if stamp_ns is not None:
            return stamp_ns
        if not allow_headerless:
            self._warn_headerless(
                self._logger(),
                f"dropping a {type(msg).__name__} without header stamp: time synchronization "
                f"needs one (ApproximateTimeSynchronizer(..., allow_headerless=True) stamps such "
                f"messages with the node's clock on arrival)")
            return None
        return self._now_ns()

    def _now_ns(self) -> int:
        if self.node is not None:
            return self.node.get_clock().now().nanoseconds
        clock = getattr(self, "_fallback_clock", None)
        if clock is None:
            clock = self._fallback_clock = ROSClock()
        return clock.now().nanoseconds

    def _logger(self) -> Any:
        if self.node is not None:
            return self.node.get_logger()
        return rclpy.logging.get_logger(self._logger_name)


class ApproximateTimeSynchronizer(TimeSynchronizer):
    """Emits one message per input when their header stamps lie within `slop` seconds.

    Same API as TimeSynchronizer plus `slop` (seconds) and `allow_headerless` (stamp messages
    without header with the node's clock on arrival; arrival delays make this approximate).
    Each arrival emits at most one set, which contains the new message: the first set in the
    reference's search order whose stamps span less than `slop` (not necessarily the tightest).
    """

    _logger_name = "message_filters_approx"

    def __init__(self, fs: Sequence[Any], queue_size: int, slop: float,
                 allow_headerless: bool = False) -> None:
        self._slop_ns = time_matching.validate_slop(slop)
        TimeSynchronizer.__init__(self, fs, queue_size)
        self.allow_headerless = allow_headerless

    @property
    def slop(self) -> Duration:
        """The slop as an rclpy Duration (as in the reference); assign seconds or a Duration."""
        return Duration(nanoseconds=self._slop_ns)

    @slop.setter
    def slop(self, value: Any) -> None:
        if isinstance(value, Duration):
            if value.nanoseconds < 0:
                raise ValueError(f"slop must be >= 0, got {value.nanoseconds} ns")
            self._slop_ns = value.nanoseconds
        else:
            self._slop_ns = time_matching.validate_slop(value)

    def add(self, msg: Any, my_queue: dict, my_queue_index: int | None = None) -> None:
        """Queue `msg` and emit at most one matched set.

        `msg` arrived on input `my_queue_index`, which owns `my_queue`.
        """
        stamp_ns = self._stamp_ns(msg, self.allow_headerless)
        if stamp_ns is None:
            return
        with self.lock:
            time_matching.insert_and_evict(my_queue, stamp_ns, msg, self._queue_size)
            stamps = time_matching.find_approximate_match(self.queues, stamp_ns, self._slop_ns,
                                                          my_queue_index)
            messages = (None if stamps is None
                        else time_matching.pop_messages(self.queues, stamps))
        if messages is not None:  # outside the lock
            self.signalMessage(*messages)


def _first_node(fs: Sequence[Any]) -> Any:
    """The node of the first input filter that has one (Subscriber.node), else None."""
    for f in fs:
        try:
            node = getattr(f, "node", None)
        except Exception:  # an exotic filter whose attribute lookup fails
            node = None
        if node is not None and hasattr(node, "get_clock"):
            return node
    return None
