"""Time matching behind our drop-in ``message_filters`` synchronizers (pure Python, no rclpy).

`amr_common.ros.message_filters` wraps this in the ROS 2 Jazzy ``message_filters`` API
(``from amr_common.ros import message_filters``); this module holds only the queue and search
logic, so it also serves offline use (e.g. pairing messages read from a bag) and fast tests.

Queues are dicts ``{stamp_ns: message}`` in insertion order, exactly like the reference, and
stamps are integer nanoseconds, so slop edges are compared without float rounding.

Approximate matching of a message with stamp ``t`` (the reference semantics, see
shared/notes/message_filters.md): for every other input, the candidates are its queued stamps
``s`` with ``|s - t| <= slop``, stably sorted by ``|s - t|``; the emitted set is the FIRST tuple in
``itertools.product`` order over those lists (with ``t`` at its own input's place) whose
``max - min < slop``. The reference enumerates the product (``queue_size ** (inputs - 1)``
tuples); we walk the same order depth-first but only enter a branch when an exact test (nearest
stamps on each side, `_DepthFirstSearch.completable`) says it can still complete, so the first
tuple reached is the reference's first valid tuple, in polynomial time; an arrival that cannot
match is usually settled by that test alone.
"""
from __future__ import annotations

import bisect
import math
import numbers
import operator
from typing import Any, Hashable, Sequence

NS_PER_S = 1_000_000_000
_MAX_NS = 2**63 - 1  # rcl time points and durations are int64 nanoseconds
_NO_STAMP = 2**64  # distance to a stamp that does not exist: beyond any slack
_WALK_WITHOUT_TEST = 16  # product sizes searched without the completion test first

Queue = dict  # {stamp_ns: message}, insertion ordered


class InvalidStampError(ValueError):
    """A message header stamp that no ROS time can hold (negative, non-finite, out of range)."""


def seconds_to_ns(seconds: float) -> int:
    """Seconds -> integer nanoseconds, truncated like ``rclpy.duration.Duration(seconds=...)``.

    Truncation (not rounding) keeps slop edges identical to the reference synchronizer.
    """
    return int(seconds * NS_PER_S)


def validate_queue_size(queue_size: Any) -> int:
    """Return queue_size as an int >= 1, or raise ValueError saying what is wrong."""
    try:
        value = operator.index(queue_size)
    except TypeError:
        if isinstance(queue_size, float) and math.isfinite(queue_size) \
                and queue_size == int(queue_size):
            value = int(queue_size)
        else:
            raise ValueError(f"queue_size must be an integer >= 1, got {queue_size!r}") from None
    if isinstance(queue_size, bool) or value < 1:
        raise ValueError(f"queue_size must be an integer >= 1, got {queue_size!r}")
    return value


def validate_slop(slop: Any) -> int:
    """Return the slop (seconds, int or float) in integer nanoseconds, or raise ValueError.

    A slop of 0 is accepted but never matches anything (the set spread must be < slop), as in
    the reference; use an exact TimeSynchronizer for identical stamps.
    """
    if isinstance(slop, bool) or not isinstance(slop, numbers.Real):
        raise ValueError(f"slop must be a number of seconds, got {slop!r}")
    seconds = float(slop)
    if not math.isfinite(seconds) or seconds < 0.0:
        raise ValueError(f"slop must be a finite number of seconds >= 0, got {slop!r}")
    if seconds > _MAX_NS / NS_PER_S:
        raise ValueError(f"slop of {slop!r} s does not fit a ROS duration (int64 ns)")
    slop_ns = seconds_to_ns(seconds)
    if slop_ns > _MAX_NS:
        raise ValueError(f"slop of {slop!r} s does not fit a ROS duration (int64 ns)")
    return slop_ns


def message_stamp_ns(msg: Any) -> int | None:
    """The header stamp of `msg` in integer nanoseconds; None when it has no header or stamp.

    Accepts builtin_interfaces/Time (sec, nanosec) and anything with a `nanoseconds` attribute
    (rclpy.time.Time), like the reference. Raises InvalidStampError for a stamp no ROS time can
    hold (negative, NaN, beyond int64 ns).
    """
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None) if header is not None else None
    if stamp is None:
        return None
    nanoseconds = getattr(stamp, "nanoseconds", None)
    if nanoseconds is not None:
        total = _whole_ns(nanoseconds, 1, stamp)
    else:
        sec = getattr(stamp, "sec", None)
        nanosec = getattr(stamp, "nanosec", None)
        if sec is None or nanosec is None:
            raise InvalidStampError(f"header stamp {stamp!r} has neither sec/nanosec nor "
                                    f"nanoseconds")
        total = _whole_ns(sec, NS_PER_S, stamp) + _whole_ns(nanosec, 1, stamp)
    if total > _MAX_NS:
        raise InvalidStampError(f"header stamp {stamp!r} is beyond the int64 ns range of ROS time")
    return total


def _whole_ns(value: Any, scale: int, stamp: Any) -> int:
    """Value * scale as int ns (float parts truncated like rclpy.time.Time); rejects <0 and NaN."""
    if isinstance(value, int):
        result = value * scale
    else:
        try:
            as_float = float(value)
        except (TypeError, ValueError):
            raise InvalidStampError(f"header stamp {stamp!r} is not numeric") from None
        if not math.isfinite(as_float):
            raise InvalidStampError(f"header stamp {stamp!r} is not finite")
        result = int(as_float * scale)
    if value < 0:
        raise InvalidStampError(f"header stamp {stamp!r} is negative; ROS time starts at 0")
    return result


def insert_and_evict(queue: Queue, stamp_ns: int, msg: Any, queue_size: int) -> None:
    """Queue msg under its stamp, then drop the smallest stamps beyond queue_size.

    A same-stamp message is replaced in place, keeping its slot. Stamps are dropped while more
    than queue_size are held, as the reference does, even if that drops msg itself.
    """
    queue[stamp_ns] = msg
    while len(queue) > queue_size:
        del queue[min(queue)]


def candidate_stamps(queue: Queue, stamp_ns: int, slop_ns: int) -> list[int]:
    """Stamps s of queue with |s - stamp_ns| <= slop_ns, nearest first (ties in queue order)."""
    low, high = stamp_ns - slop_ns, stamp_ns + slop_ns
    near = [s for s in queue if low <= s <= high]
    if len(near) > 1:
        near.sort(key=lambda s: abs(s - stamp_ns))  # list.sort is stable
    return near


def first_valid_tuple(lists: Sequence[Sequence[int]], slop_ns: int,
                      fixed: int | None = None) -> list[int] | None:
    """First tuple of itertools.product(*lists) spanning less than slop_ns; None if none.

    The span includes `fixed` when given (max - min < slop_ns).

    Integer stamps only. Returns one stamp per list (the fixed stamp is not included).
    """
    width = slop_ns - 1  # integer stamps: max - min < slop  <=>  max - min <= slop - 1
    if width < 0:
        return None
    search = _DepthFirstSearch(lists, width)
    if fixed is not None:
        return search.run(0, fixed, fixed) if search.completable(0, fixed, fixed) else None
    for first in lists[0] if lists else ():  # no lists: nothing to match
        if len(lists) < 3 or search.completable(1, first, first):
            rest = search.run(1, first, first)
            if rest is not None:
                return [first] + rest
    return None


class _DepthFirstSearch:
    """Depth-first walk of the product in itertools order, entering only completable branches.

    An exact test says whether a branch can complete, so the first leaf reached is the first
    valid tuple of the whole product and no branch is abandoned half-way:
    O(levels * list length * test) per search.
    """

    def __init__(self, lists: Sequence[Sequence[int]], width: int) -> None:
        self.lists = lists
        self.width = width
        self._ascending: dict[int, list[int]] = {}  # list index -> its stamps sorted

    def run(self, level: int, low: int, high: int) -> list[int] | None:
        """The first choice for lists[level:] fitting with [low, high] in a `width` window.

        None if there is none.
        """
        lists, width = self.lists, self.width
        last = len(lists) - 1
        if level > last:
            return []
        if level == last:  # the last choice only has to fall inside the window left
            lowest, highest = high - width, low + width
            for stamp in lists[level]:
                if lowest <= stamp <= highest:
                    return [stamp]
            return None
        for stamp in lists[level]:
            new_low = stamp if stamp < low else low
            new_high = stamp if stamp > high else high
            if new_high - new_low > width:
                continue
            # Deeper than one more level, enter only completable branches (the exact test keeps
            # the walk polynomial); one more level is a scan as cheap as the test.
            if level + 1 < last and not self.completable(level + 1, new_low, new_high):
                continue
            rest = self.run(level + 1, new_low, new_high)
            if rest is not None:
                return [stamp] + rest
        return None

    def completable(self, start: int, low: int, high: int) -> bool:
        """Whether one stamp from each of lists[start:] fits with [low, high] in a `width` window.

        Fits: max - min <= width.

        A list with a stamp inside [low, high] costs nothing. Otherwise only its nearest stamp
        below low (`under` ns away) and nearest above high (`over` ns away) matter: swapping a
        chosen stamp for the nearest one on the same side never widens the set. Those lists
        must then be split between the two sides with max(over) + max(under) <= slack.
        """
        slack = self.width - (high - low)
        if slack < 0:
            return False
        outside = []  # (over, under) of the lists without a stamp inside [low, high]
        for index in range(start, len(self.lists)):
            values = self._ascending.get(index)
            if values is None:
                values = self._ascending[index] = sorted(self.lists[index])
            i = bisect.bisect_left(values, low)
            if i < len(values) and values[i] <= high:
                continue
            under = low - values[i - 1] if i > 0 else _NO_STAMP
            over = values[i] - high if i < len(values) else _NO_STAMP
            if under > slack and over > slack:
                return False
            outside.append((over, under))
        if len(outside) <= 1:
            return True
        # The lists sent above are those with over <= the largest over allowed: try each.
        outside.sort()
        max_under_from = [0] * (len(outside) + 1)  # max under of outside[k:]
        for k in range(len(outside) - 1, -1, -1):
            max_under_from[k] = max(outside[k][1], max_under_from[k + 1])
        if max_under_from[0] <= slack:
            return True  # all below
        return any(over + max_under_from[k + 1] <= slack for k, (over, _) in enumerate(outside))


def find_approximate_match(queues: Sequence[Queue], stamp_ns: int, slop_ns: int,
                           index: int | None) -> list[int] | None:
    """Stamps of the set the reference emits after stamp_ns arrived on input `index`, or None.

    One stamp per queue, in queue order. With index None the new stamp is not forced into the
    set and every queue is searched (the reference's behaviour for
    add(..., my_queue_index=None)).
    """
    low, high = stamp_ns - slop_ns, stamp_ns + slop_ns
    if index is None:
        lists = [candidate_stamps(queue, stamp_ns, slop_ns) for queue in queues]
        return first_valid_tuple(lists, slop_ns) if all(lists) else None
    width = slop_ns - 1
    if width < 0 or stamp_ns not in queues[index]:
        return None  # evicted on arrival: every tuple holds it, so none can be emitted
    lists = []
    for i, queue in enumerate(queues):
        if i != index:
            near = [s for s in queue if low <= s <= high]
            if not near:
                return None
            lists.append(near)
    search = _DepthFirstSearch(lists, width)
    # Most arrivals that emit nothing among many candidates are settled here, before sorting
    # by distance; for a few candidates the walk is cheaper than the test.
    if math.prod(map(len, lists)) > _WALK_WITHOUT_TEST and \
            not search.completable(0, stamp_ns, stamp_ns):
        return None
    for near in lists:  # product order: nearest first, ties in queue order (stable sort)
        if len(near) > 1:
            near.sort(key=lambda s: abs(s - stamp_ns))
    chosen = search.run(0, stamp_ns, stamp_ns)
    if chosen is None:
        return None
    chosen.insert(index, stamp_ns)
    return chosen


def pop_messages(queues: Sequence[Queue], stamps: Sequence[Hashable]) -> list[Any]:
    """Remove and return queues[i][stamps[i]] for every input i."""
    messages = [queue[stamp] for queue, stamp in zip(queues, stamps)]
    for queue, stamp in zip(queues, stamps):
        del queue[stamp]
    return messages


def pop_exact_matches(queues: Sequence[Queue]) -> list[list[Any]]:
    """Remove and return every set of messages whose stamp is queued on all inputs, ascending."""
    if not queues:
        return []
    common = set(queues[0]).intersection(*queues[1:])
    return [pop_messages(queues, [stamp] * len(queues)) for stamp in sorted(common)]


class ApproximateTimeMatcher:
    """Approximate-time matching over `num_inputs` queues, without ROS.

    `add(input_index, stamp_ns, msg)` returns the list of messages (one per input) the reference
    ApproximateTimeSynchronizer would emit on this arrival, or None. Not thread-safe.
    """

    def __init__(self, num_inputs: int, queue_size: int, slop_ns: int) -> None:
        if operator.index(num_inputs) < 1:
            raise ValueError(f"num_inputs must be >= 1, got {num_inputs!r}")
        if operator.index(slop_ns) < 0:
            raise ValueError(f"slop_ns must be >= 0, got {slop_ns!r}")
        self.queue_size = validate_queue_size(queue_size)
        self.slop_ns = int(slop_ns)
        self.queues: list[Queue] = [{} for _ in range(num_inputs)]

    def add(self, input_index: int, stamp_ns: int, msg: Any) -> list[Any] | None:
        """Queue `msg` on input `input_index`; the matched set (one per input) or None."""
        stamp_ns = operator.index(stamp_ns)  # float stamps would blur the slop edges
        insert_and_evict(self.queues[input_index], stamp_ns, msg, self.queue_size)
        stamps = find_approximate_match(self.queues, stamp_ns, self.slop_ns, input_index)
        return None if stamps is None else pop_messages(self.queues, stamps)


class ExactTimeMatcher:
    """Exact-stamp matching over `num_inputs` queues, without ROS.

    `add(input_index, stamp_ns, msg)` returns every complete set (ascending stamps) the
    reference TimeSynchronizer would emit on this arrival. Not thread-safe.
    """

    def __init__(self, num_inputs: int, queue_size: int) -> None:
        if operator.index(num_inputs) < 1:
            raise ValueError(f"num_inputs must be >= 1, got {num_inputs!r}")
        self.queue_size = validate_queue_size(queue_size)
        self.queues: list[Queue] = [{} for _ in range(num_inputs)]

    def add(self, input_index: int, stamp_ns: int, msg: Any) -> list[list[Any]]:
        """Queue `msg` on input `input_index`; every completed set, oldest first."""
        insert_and_evict(self.queues[input_index], operator.index(stamp_ns), msg,
                         self.queue_size)
        return pop_exact_matches(self.queues)
