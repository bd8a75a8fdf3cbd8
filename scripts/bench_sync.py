"""Per-add cost of our ApproximateTimeSynchronizer vs the reference's exhaustive search.

Usage: .venv/bin/python scripts/bench_sync.py [--adds N]
`main()` returns the figures as a dict (used by scripts/bench.py).

Workloads, queue_size 10, slop 50 ms:
- streams:  2 or 3 sensors at 50/30/20 Hz with +-5 ms stamp jitter and random transport order
            (the normal case: few candidates per arrival, most arrivals emit or wait briefly);
- no-match: 3 or 4 inputs whose queues are full of candidates that never form a set (one
            input's stamps lie >= 32 ms before, another's >= 25 ms after the arriving stamps):
            the reference's worst case, a walk of the whole product (queue_size ** (inputs - 1)
            tuples per arrival).
Rows: ours through the public API (PointStamped messages, header parsing, lock), our pure
matcher (amr_common.ros.time_matching), and the reference search written out literally (the
oracle of tests/sync_reference.py) on the same arrivals, in the same run; ratio = reference /
ours (pure matcher against the equally pure reference).
"""
from __future__ import annotations

import argparse
import random
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(REPO))

from amr_common.ros.ros_env import isolate_local_graph  # noqa: E402

NS = 1_000_000_000
QUEUE_SIZE = 10
SLOP_S = 0.05
SLOP_NS = 50_000_000


def stream_arrivals(num_inputs: int, adds: int, seed: int = 1) -> list[tuple[int, int]]:
    """(input, stamp_ns) in arrival order for sensors at 50/30/20 Hz with jitter."""
    rng = random.Random(seed)
    periods = [NS // 50, NS // 30, NS // 20][:num_inputs]
    events = []
    for i, period in enumerate(periods):
        for k in range(adds):
            stamp = 10 * NS + k * period + rng.randint(-5_000_000, 5_000_000)
            events.append((stamp + rng.randint(0, 15_000_000), i, stamp))  # transport delay
    events.sort()
    return [(i, stamp) for _, i, stamp in events[:adds]]


def no_match_arrivals(num_inputs: int, adds: int) -> list[tuple[int, int]]:
    """Fill inputs 1.. with candidates that never fit in one set, then add on input 0.

    Input 0 stamps lie within 1 us of t0; input 1 holds t0-50..t0-32 ms, input 2 t0+25..t0+43 ms,
    input 3 t0-10..t0+8 ms: all are candidates (<= 50 ms away), but any set with one stamp from
    inputs 1 and 2 spans >= 57 ms. Needs 3 or more inputs (with 2, a candidate always pairs).
    """
    t0 = 10 * NS
    first_stamps = {1: t0 - SLOP_NS, 2: t0 + 25_000_000, 3: t0 - 10_000_000}
    arrivals = [(i, first_stamps[i] + k * 2_000_000)
                for k in range(QUEUE_SIZE) for i in range(1, num_inputs)]
    return arrivals + [(0, t0 + k) for k in range(adds)]


def _time_per_add(run, arrivals_count: int, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return best / arrivals_count * 1e6


def measure(num_inputs: int, arrivals: list[tuple[int, int]], repeats: int = 5) -> dict:
    from geometry_msgs.msg import PointStamped

    from amr_common.ros import time_matching
    from amr_common.ros.message_filters import ApproximateTimeSynchronizer, SimpleFilter
    from tests.sync_reference import ReferenceApproximateSync

    messages = []
    for _, stamp in arrivals:
        msg = PointStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, NS)
        messages.append(msg)
    emitted = {"api": 0, "core": 0, "reference": 0}

    def run_api():
        inputs = [SimpleFilter() for _ in range(num_inputs)]
        sync = ApproximateTimeSynchronizer(inputs, QUEUE_SIZE, SLOP_S)
        count = [0]
        sync.registerCallback(lambda *msgs: count.__setitem__(0, count[0] + 1))
        for (i, _), msg in zip(arrivals, messages):
            inputs[i].signalMessage(msg)
        emitted["api"] = count[0]

    def run_core():
        matcher = time_matching.ApproximateTimeMatcher(num_inputs, QUEUE_SIZE, SLOP_NS)
        count = 0
        for (i, stamp), msg in zip(arrivals, messages):
            count += matcher.add(i, stamp, msg) is not None
        emitted["core"] = count

    def run_reference():
        reference = ReferenceApproximateSync(num_inputs, QUEUE_SIZE, SLOP_NS)
        count = 0
        for (i, stamp), msg in zip(arrivals, messages):
            count += reference.add(msg, stamp, reference.queues[i], i) is not None
        emitted["reference"] = count

    figures = {
        "ours_api_us": _time_per_add(run_api, len(arrivals), repeats),
        "ours_core_us": _time_per_add(run_core, len(arrivals), repeats),
        "reference_us": _time_per_add(run_reference, len(arrivals), repeats),
    }
    if len(set(emitted.values())) != 1:
        raise RuntimeError(f"implementations disagree on the number of sets: {emitted}")
    figures["sets_emitted"] = emitted["core"]
    figures["adds"] = len(arrivals)
    figures["ratio_reference_over_core"] = figures["reference_us"] / figures["ours_core_us"]
    return figures


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--adds", type=int, default=2000, help="arrivals per workload")
    args = parser.parse_args(argv if argv is not None else [])
    isolate_local_graph()  # rclpy is imported (messages, logging); keep any graph on loopback

    results = {}
    print(f"per-add cost in us (queue_size {QUEUE_SIZE}, slop {SLOP_S} s), best of 5 runs")
    print(f"{'workload':22s} {'ours API':>9s} {'ours core':>10s} {'reference':>10s} "
          f"{'ratio':>7s} {'sets':>6s}")
    # The reference walks 1000 tuples per arrival for 4 inputs: fewer arrivals there.
    cases = [("streams", stream_arrivals, 2, 1), ("streams", stream_arrivals, 3, 1),
             ("no-match", no_match_arrivals, 3, 1), ("no-match", no_match_arrivals, 4, 10)]
    for workload, make, num_inputs, fewer in cases:
        arrivals = make(num_inputs, max(args.adds // fewer, 10))
        figures = measure(num_inputs, arrivals)
        name = f"{num_inputs}_inputs_{workload}"
        results[name] = figures
        print(f"{name:22s} {figures['ours_api_us']:9.2f} {figures['ours_core_us']:10.2f} "
              f"{figures['reference_us']:10.2f} {figures['ratio_reference_over_core']:6.1f}x "
              f"{figures['sets_emitted']:6d}")
    return results


if __name__ == "__main__":
    from script_endings import guard_output  # a closed output loses nothing
    guard_output()
    main(sys.argv[1:])
