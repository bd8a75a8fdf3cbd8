"""Which LaserScan readings are returns: the one rule every consumer of a scan applies.

A reading r is a return when it is finite, > 0 and within [range_min, range_max] (the scan's own
limits). Everything else means "nothing measured along this ray": NaN and inf (REP 117), 0.0 (the
LDS-01 driver's "no return"), and readings outside the limits. No rclpy import.

    is_return(r, scan.range_min, scan.range_max)        # one reading; compiled (numba kernels
                                                        # call it), callable from Python too
    return_mask(ranges, scan.range_min, scan.range_max)  # a bool array, with numpy
"""
from __future__ import annotations

import math

import numpy as np

from amr_common.jit import jit


def _is_return(r, range_min, range_max):
    """True if the reading r (m) is a return of a scan with these limits (see the module)."""
    # The order of the tests is the kernels' fast path: NaN fails the first comparison.
    return r > 0.0 and r >= range_min and r <= range_max and math.isfinite(r)


# Compiled with numba (where installed) so the kernels that classify readings call the same
# rule; from plain Python it works too (the kernels' Python twins call it).
is_return = jit(_is_return)


def return_mask(ranges, range_min: float, range_max: float) -> np.ndarray:
    """Bool array: which readings of `ranges` (m) are returns (is_return, element-wise)."""
    r = np.asarray(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return (r > 0.0) & (r >= range_min) & (r <= range_max) & np.isfinite(r)


__all__ = ["is_return", "return_mask"]
