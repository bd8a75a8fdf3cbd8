"""The one switch for the project's compiled loops: numba where installed, else plain Python.

The loops are the LiDAR and wall contacts of amr_sim and the wall follower's perception:
numba's njit, cached on disk, where numba is installed (a pinned dependency); the plain Python
function otherwise. No rclpy import.
"""
from __future__ import annotations

try:
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - numba is a pinned dependency
    HAVE_NUMBA = False


def jit(function):
    """numba.njit(cache=True, nogil=True, error_model="numpy") if numba is there, else `function`.

    error_model="numpy": x/0 gives inf/nan instead of raising, as numpy does.
    """
    if not HAVE_NUMBA:
        return function
    return numba.njit(cache=True, nogil=True, error_model="numpy")(function)
