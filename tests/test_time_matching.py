"""amr_common.ros.time_matching against an oracle: the reference algorithm written out literally.

`ReferenceApproximateSync` (tests/sync_reference.py) is the Jazzy message_filters
ApproximateTimeSynchronizer.add search as specified in shared/notes/message_filters.md
(exponential itertools.product walk), on integer-nanosecond stamps. Our polynomial search must
emit the same sets, in the same order, and leave the same queues, for every input sequence.
scripts/bench_sync.py times both.
"""
from __future__ import annotations

import itertools
import random

import pytest

from amr_common.ros import time_matching as tm
from tests.sync_reference import ReferenceApproximateSync, random_scenario


def run_both(num_inputs, queue_size, slop_ns, arrivals, unindexed_every=0):
    """Feed arrivals to the oracle and to ours; return (oracle sets, our sets, queues each)."""
    oracle = ReferenceApproximateSync(num_inputs, queue_size, slop_ns)
    ours = tm.ApproximateTimeMatcher(num_inputs, queue_size, slop_ns)
    oracle_sets, our_sets = [], []
    for msg_id, (i, stamp) in enumerate(arrivals):
        unindexed = unindexed_every and msg_id % unindexed_every == unindexed_every - 1
        index = None if unindexed else i
        emitted = oracle.add(msg_id, stamp, oracle.queues[i], index)
        if emitted is not None:
            oracle_sets.append((msg_id, emitted))
        if unindexed:  # the reference's add(msg, my_queue) without index, via the functions
            tm.insert_and_evict(ours.queues[i], stamp, msg_id, queue_size)
            stamps = tm.find_approximate_match(ours.queues, stamp, slop_ns, None)
            emitted = None if stamps is None else tm.pop_messages(ours.queues, stamps)
        else:
            emitted = ours.add(i, stamp, msg_id)
        if emitted is not None:
            our_sets.append((msg_id, emitted))
    oracle_queues = [list(q.items()) for q in oracle.queues]
    our_queues = [list(q.items()) for q in ours.queues]
    return oracle_sets, our_sets, oracle_queues, our_queues


@pytest.mark.parametrize("num_inputs,scenarios,max_queue", [
    (2, 1500, 10), (3, 1500, 10), (4, 300, 6), (5, 150, 4)])
def test_same_sets_as_reference_on_random_sequences(num_inputs, scenarios, max_queue):
    rng = random.Random(20260 + num_inputs)
    emitted_total = 0
    for n in range(scenarios):
        queue_size, slop_ns, arrivals = random_scenario(rng, num_inputs, max_queue)
        oracle_sets, our_sets, oracle_queues, our_queues = run_both(
            num_inputs, queue_size, slop_ns, arrivals, unindexed_every=(n % 4 == 3) * 7)
        context = f"scenario {n}: queue_size={queue_size} slop_ns={slop_ns} arrivals={arrivals}"
        assert our_sets == oracle_sets, context
        assert our_queues == oracle_queues, context
        emitted_total += len(oracle_sets)
    assert emitted_total > scenarios  # the scenarios do exercise matching, not only misses


def test_first_valid_tuple_matches_product_order_on_random_lists():
    """The pruned depth-first search returns exactly the first valid product tuple."""
    rng = random.Random(7)
    for _ in range(4000):
        slop_ns = rng.randint(0, 12)
        lists = [rng.sample(range(0, 24), rng.randint(1, 6)) for _ in range(rng.randint(0, 5))]
        fixed = rng.choice([None, rng.randint(0, 24)])
        expected = None
        for combo in itertools.product(*lists):
            values = list(combo) + ([] if fixed is None else [fixed])
            if values and max(values) - min(values) < slop_ns:
                expected = list(combo)
                break
        assert tm.first_valid_tuple(lists, slop_ns, fixed) == expected, (lists, slop_ns, fixed)


def test_emits_first_valid_set_in_reference_order_not_the_tightest():
    slop = 10
    matcher = tm.ApproximateTimeMatcher(3, 10, slop)
    assert matcher.add(1, 100, "b100") is None
    assert matcher.add(1, 108, "b108") is None
    assert matcher.add(2, 109, "c109") is None
    # New a@104: b candidates by distance [b100 (4), b108 (4)] (tie: queue order), c [c109].
    # (104, b100, c109) spans 9 < 10 and comes first, though (104, b108, c109) spans only 5.
    assert matcher.add(0, 104, "a104") == ["a104", "b100", "c109"]
    assert [list(q) for q in matcher.queues] == [[], [108], []]


def test_slop_edges_candidates_inclusive_set_strict():
    # b is exactly slop away: a candidate (<=), but the pair spans slop, not < slop.
    matcher = tm.ApproximateTimeMatcher(2, 10, 50)
    assert matcher.add(0, 1000, "a") is None
    assert matcher.add(1, 1050, "b") is None
    assert matcher.add(1, 1049, "b'") == ["a", "b'"]  # one ns inside the slop
    assert [list(q) for q in matcher.queues] == [[], [1050]]


def test_message_evicted_on_arrival_is_never_emitted():
    matcher = tm.ApproximateTimeMatcher(2, 2, 100)
    assert matcher.add(0, 330, "a330") is None
    assert matcher.add(1, 1000, "b1000") is None
    assert matcher.add(1, 1100, "b1100") is None
    # b300 would pair with a330, but it is the smallest stamp of a full queue: evicted at once.
    assert matcher.add(1, 300, "b300") is None
    assert [list(q) for q in matcher.queues] == [[330], [1000, 1100]]


def test_exact_matcher_emits_common_stamps_ascending():
    matcher = tm.ExactTimeMatcher(2, 5)
    assert matcher.add(0, 30, "a30") == []
    assert matcher.add(0, 10, "a10") == []
    assert matcher.add(0, 20, "a20") == []
    assert matcher.add(1, 20, "b20") == [["a20", "b20"]]
    assert matcher.add(1, 30, "b30") == [["a30", "b30"]]
    assert [list(q) for q in matcher.queues] == [[10], []]


@pytest.mark.parametrize("bad", [0, -3, 2.5, "10", None, True, float("nan")])
def test_bad_queue_size_is_rejected(bad):
    with pytest.raises(ValueError, match="queue_size"):
        tm.validate_queue_size(bad)


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf"), "0.1", None, True, 1e300])
def test_bad_slop_is_rejected(bad):
    with pytest.raises(ValueError, match="slop"):
        tm.validate_slop(bad)


def test_slop_is_truncated_to_ns_like_rclpy_duration():
    assert tm.validate_slop(0.1) == 100_000_000
    assert tm.validate_slop(0) == 0
    assert tm.validate_slop(2) == 2 * tm.NS_PER_S


class _Stamp:
    def __init__(self, sec, nanosec):
        self.sec, self.nanosec = sec, nanosec


class _Msg:
    def __init__(self, header):
        self.header = header


class _Header:
    def __init__(self, stamp):
        self.stamp = stamp


def test_message_stamp_ns_reads_headers_and_rejects_impossible_stamps():
    assert tm.message_stamp_ns(_Msg(_Header(_Stamp(12, 345)))) == 12 * tm.NS_PER_S + 345
    assert tm.message_stamp_ns(object()) is None  # no header
    assert tm.message_stamp_ns(_Msg(None)) is None
    assert tm.message_stamp_ns(_Msg(_Header(None))) is None  # header without stamp

    class TimeLike:  # rclpy.time.Time has `nanoseconds`
        nanoseconds = 42
    assert tm.message_stamp_ns(_Msg(_Header(TimeLike()))) == 42
    for bad in (_Stamp(-1, 0), _Stamp(0, -5), _Stamp(float("nan"), 0), _Stamp(2**62, 0),
                _Stamp("x", 0), object()):
        with pytest.raises(tm.InvalidStampError):
            tm.message_stamp_ns(_Msg(_Header(bad)))
