"""CPU and wall timings of the Mapper's work and the slam node's callbacks. No rclpy import."""
from __future__ import annotations

import time

import numpy as np


def clocks() -> tuple[float, float]:
    """(wall s, this thread's CPU s) now."""
    return time.perf_counter(), time.thread_time()


def elapsed_ms(started: tuple[float, float]) -> tuple[float, float]:
    """(wall ms, this thread's CPU ms) since `started` (clocks())."""
    return 1e3 * (time.perf_counter() - started[0]), 1e3 * (time.thread_time() - started[1])


def timing_summary(values: list[float]) -> dict[str, float]:
    """count, median, p90, max and total of a list of timings (zeros when empty)."""
    if not values:
        return {"count": 0, "median": 0.0, "p90": 0.0, "max": 0.0, "total": 0.0}
    array = np.asarray(values)
    return {"count": int(array.size), "median": float(np.median(array)),
            "p90": float(np.percentile(array, 90)), "max": float(array.max()),
            "total": float(array.sum())}
