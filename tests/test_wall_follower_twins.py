"""The wall follower's compiled kernels against their plain-Python twins (amr_common.jit).

Every kernel amr_control compiles (point cloud, obstacle memory, side-wall fit, pose trail) has
its plain function as `py_func`; with those swapped in, a whole wall-following episode under
the reality-gap effects (skewed scans, dropouts, held points, look-around) must drive exactly
the same way.
"""
from __future__ import annotations

import sys

import numpy as np


def _plain_kernels(monkeypatch) -> int:
    """Swap every compiled function bound in an amr_control module for its Python twin."""
    import amr_control.wall_follower  # noqa: F401 - load the modules that bind kernels
    swapped = 0
    for name, module in list(sys.modules.items()):
        if not name.startswith("amr_control.") or module is None:
            continue
        for attr, value in list(vars(module).items()):
            plain = getattr(value, "py_func", None)
            if plain is not None and callable(value):
                monkeypatch.setattr(module, attr, plain)
                swapped += 1
    return swapped


def _episode():
    from amr_evaluation import episode
    return episode.run_episode("twin_maze_small", "north_west",
                               profile="turtlebot3:randomized", seed=7, duration=12.0,
                               record_trajectory=True)


def test_a_wall_following_episode_drives_the_same_with_the_plain_python_kernels(monkeypatch):
    compiled = _episode()
    assert _plain_kernels(monkeypatch) >= 10
    plain = _episode()
    a, b = np.asarray(compiled.trajectory), np.asarray(plain.trajectory)
    assert a.shape == b.shape and a.shape[0] > 200
    assert np.max(np.abs(a - b)) < 1e-9
    assert np.hypot(*(a[-1, 1:3] - a[0, 1:3])) > 0.3  # it drove somewhere
