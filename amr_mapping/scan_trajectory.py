"""The pose of every mapped scan, kept relative to a keyframe so that it follows the pose graph.

A scan that is not a keyframe has no node in the graph; its pose is stored as the pose relative
to the keyframe it was placed from (the latest at the time). When loop closures move the
keyframes, the scans move with them: `rows` gives the trajectory as the graph now has it, the
pose of EVERY scan at its own stamp (a replay's report, the relation error of a benchmark).
"""
from __future__ import annotations

import numpy as np

from amr_common.geometry import compose, inverse


class ScanTrajectory:
    """Stamps and keyframe-relative poses of the mapped scans, in the order they came."""

    def __init__(self) -> None:
        self._stamps: list[float] = []
        self._keyframes: list[int] = []
        self._relative: list[tuple[float, float, float]] = []

    def __len__(self) -> int:
        return len(self._stamps)

    def add(self, stamp: float, keyframe: int, keyframe_pose, pose) -> None:
        """A scan at `pose`, placed from `keyframe` (at keyframe_pose when the scan came)."""
        self._stamps.append(float(stamp))
        self._keyframes.append(int(keyframe))
        self._relative.append(compose(inverse(tuple(keyframe_pose)), tuple(pose)))

    def rows(self, keyframe_poses: np.ndarray) -> np.ndarray:
        """(N, 4) [stamp, x, y, theta]: each scan on its keyframe's pose in keyframe_poses."""
        if not self._stamps:
            return np.zeros((0, 4))
        anchor = np.asarray(keyframe_poses)[np.asarray(self._keyframes)]
        relative = np.asarray(self._relative)
        c, s = np.cos(anchor[:, 2]), np.sin(anchor[:, 2])
        return np.column_stack([
            np.asarray(self._stamps),
            anchor[:, 0] + c * relative[:, 0] - s * relative[:, 1],
            anchor[:, 1] + s * relative[:, 0] + c * relative[:, 1],
            np.remainder(anchor[:, 2] + relative[:, 2] + np.pi, 2 * np.pi) - np.pi])


__all__ = ["ScanTrajectory"]
