"""The pose graph of keyframes, optimized incrementally by GTSAM's iSAM2.

Nodes are keyframe poses (x, y, theta) in the map frame; the first is anchored by a tight prior.
Each new keyframe comes with a chain link to the one before (its scan-matched relative pose);
loop closures add links between distant keyframes, with a Huber loss so one bad closure cannot
bend the whole map. iSAM2 (Kaess et al. 2012) re-solves only the part of the Bayes tree a new
factor touches: a keyframe costs a fraction of a millisecond and a loop closure a few
milliseconds, where batch Levenberg-Marquardt on a 500-pose chain takes ~140 ms
(../shared/notes/mapping.md).
"""
from __future__ import annotations

import gtsam
import numpy as np

_ANCHOR_SIGMAS = np.array([1e-4, 1e-4, 1e-5])
_HUBER_K = 10.0
_RELINEARIZE_STEPS = 2  # extra iSAM2 passes after a loop closure (relinearization settles)


def _pose(pose: tuple[float, float, float]) -> gtsam.Pose2:
    return gtsam.Pose2(float(pose[0]), float(pose[1]), float(pose[2]))


class PoseGraph:
    """Keyframe poses and the links between them, solved by iSAM2 after every change."""

    def __init__(self, sequential_sigmas: tuple[float, float],
                 loop_sigmas: tuple[float, float]) -> None:
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(0.001)
        params.relinearizeSkip = 1
        self._isam = gtsam.ISAM2(params)
        self._sequential = gtsam.noiseModel.Diagonal.Sigmas(
            np.array([sequential_sigmas[0], sequential_sigmas[0], sequential_sigmas[1]]))
        self._loop = gtsam.noiseModel.Robust.Create(
            gtsam.noiseModel.mEstimator.Huber.Create(_HUBER_K),
            gtsam.noiseModel.Diagonal.Sigmas(
                np.array([loop_sigmas[0], loop_sigmas[0], loop_sigmas[1]])))
        self._count = 0
        self._poses = np.zeros((0, 3))

    def __len__(self) -> int:
        return self._count

    @property
    def poses(self) -> np.ndarray:
        """(K, 3) current estimate of every keyframe pose [x, y, theta] (a copy)."""
        return self._poses[:self._count].copy()

    def pose(self, index: int) -> tuple[float, float, float]:
        """The current estimate of one keyframe (index -1: the latest)."""
        x, y, th = self._poses[index if index >= 0 else self._count + index]
        return float(x), float(y), float(th)

    def add_keyframe(self, pose: tuple[float, float, float],
                     link: tuple[float, float, float] | None = None,
                     sigmas: tuple[float, float] | None = None) -> int:
        """Add a keyframe at `pose` (its initial estimate); returns its index.

        link: the pose relative to the previous keyframe (required after the first);
        sigmas (m, rad): its standard deviations (default: the sequential ones).
        """
        index = self._count
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        values.insert(index, _pose(pose))
        if index == 0:
            graph.add(gtsam.PriorFactorPose2(
                0, _pose(pose), gtsam.noiseModel.Diagonal.Sigmas(_ANCHOR_SIGMAS)))
        else:
            if link is None:
                raise ValueError("a keyframe after the first needs its link to the previous one")
            noise = self._sequential if sigmas is None else gtsam.noiseModel.Diagonal.Sigmas(
                np.array([sigmas[0], sigmas[0], sigmas[1]]))
            graph.add(gtsam.BetweenFactorPose2(index - 1, index, _pose(link), noise))
        self._isam.update(graph, values)
        self._count += 1
        latest = self._isam.calculateEstimatePose2(index)
        if index >= len(self._poses):  # room for more, doubling: appending stays O(1)
            grown = np.zeros((max(2 * len(self._poses), 64), 3))
            grown[:index] = self._poses[:index]
            self._poses = grown
        self._poses[index] = (latest.x(), latest.y(), latest.theta())
        return index

    def add_loop(self, earlier: int, later: int, relative: tuple[float, float, float]) -> None:
        """Link keyframe `later` to `earlier` by its pose relative to it, and re-solve."""
        graph = gtsam.NonlinearFactorGraph()
        graph.add(gtsam.BetweenFactorPose2(int(earlier), int(later), _pose(relative),
                                           self._loop))
        self._isam.update(graph, gtsam.Values())
        for _ in range(_RELINEARIZE_STEPS):
            self._isam.update()
        self._read_all()

    def _read_all(self) -> None:
        estimate = self._isam.calculateEstimate()
        for k in range(self._count):
            pose = estimate.atPose2(k)
            self._poses[k] = (pose.x(), pose.y(), pose.theta())


__all__ = ["PoseGraph"]
