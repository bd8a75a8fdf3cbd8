"""The oracle for the synchronizer, and random arrival sequences to feed it and ours.

The oracle is the Jazzy message_filters ApproximateTimeSynchronizer.add search written out
literally.

As specified in shared/notes/message_filters.md (exponential itertools.product walk), on
integer-nanosecond stamps. tests/test_time_matching.py and tests/test_message_filters.py compare
against it; scripts/bench_sync.py times it.
"""
from __future__ import annotations

import itertools
import random

from amr_common.ros import time_matching as tm


class ReferenceApproximateSync:
    """The reference search, literally (oracle for tests and the benchmark's baseline)."""

    def __init__(self, num_inputs: int, queue_size: int, slop_ns: int) -> None:
        self.queues = [{} for _ in range(num_inputs)]
        self.queue_size = queue_size
        self.slop_ns = slop_ns

    def add(self, msg, stamp, my_queue, my_queue_index=None):
        """Returns the emitted messages (one per input) or None."""
        my_queue[stamp] = msg
        while len(my_queue) > self.queue_size:
            del my_queue[min(my_queue)]
        if my_queue_index is None:
            search_queues = self.queues
        else:
            search_queues = self.queues[:my_queue_index] + self.queues[my_queue_index + 1:]
        stamps = []
        for queue in search_queues:
            topic_stamps = []
            for s in queue:
                delta = abs(s - stamp)
                if delta > self.slop_ns:
                    continue
                topic_stamps.append((s, delta))
            if not topic_stamps:
                return None
            topic_stamps = sorted(topic_stamps, key=lambda x: x[1])
            stamps.append([s for s, _ in topic_stamps])
        for vv in itertools.product(*stamps):
            vv = list(vv)
            if my_queue_index is not None:
                vv.insert(my_queue_index, stamp)
            qt = list(zip(self.queues, vv))
            if max(vv) - min(vv) < self.slop_ns and all(t in q for q, t in qt):
                msgs = [q[t] for q, t in qt]
                for q, t in qt:
                    del q[t]
                return msgs
        return None


def random_scenario(rng: random.Random, num_inputs: int, max_queue: int = 10):
    """A random (queue_size, slop_ns, arrivals); arrivals are (input, stamp) pairs.

    Stamps lie on a grid so slop edges are hit exactly; duplicated stamps, out-of-order arrival
    and bursts on one input.
    """
    grid = rng.choice([1, 3, 1000, 1_000_000, 33_333_333])
    slop_ns = max(0, rng.randint(0, 6) * grid + rng.choice([0, 0, 0, 1, -1]))
    queue_size = rng.randint(1, max_queue)
    length = rng.randint(1, 60)
    base = rng.choice([0, 1_700_000_000 * tm.NS_PER_S])
    mode = rng.choice(["random", "jittered", "monotone"])
    arrivals = []
    for k in range(length):
        i = rng.randrange(num_inputs)
        if mode == "random":
            step = rng.randint(0, 25)
        elif mode == "jittered":
            step = max(0, k // num_inputs + rng.randint(-2, 2))
        else:
            step = k // num_inputs
        arrivals.append((i, base + step * grid))
    return queue_size, slop_ns, arrivals
