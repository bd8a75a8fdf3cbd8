"""The ambiguity guard of the localized test: rival poses and the evidence that refutes them.

A single scan in a near-symmetric maze often fits several poses (the same corridor seen from a
pose rotated by 90 or 180 degrees). When the filter is about to declare a pose, PoseSearch looks
for OTHER poses that explain at least `rival_fraction` of the rays. Each one becomes a rival
track (and gets particles, so the filter can switch to it if it is the truth). A rival is REFUTED
only by evidence: at some later measurement update it explains fewer than `rival_fraction` of the
rays (after a local refinement, so odometry drift cannot refute it) while the estimate explains at
least `localize_fraction`. The filter may declare a pose only when every rival the search finds is
one it has refuted. So in a ring corridor whose four sides look alike, the robot is localized after
it passed the one place that tells them apart, and never before.

Tracks move with the odometry between updates and are re-anchored on the particles near them
(the injected particles follow the rival hypothesis with the filter's own noise and weighting).
No rclpy import.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from amr_common.geometry import wrap_angles
from amr_common.robot import arc_step
from amr_localization.localization_check import ScanMatcher, weighted_pose_mean
from amr_localization.pose_search import Alternative, close_poses, refine

TRACK_DISTANCE_M = 0.15  # a rival found this close to a track (and within TRACK_ANGLE) is it
TRACK_ANGLE_RAD = math.radians(15.0)
ANCHOR_DISTANCE_M = 0.1
ANCHOR_ANGLE_RAD = 0.35
ANCHOR_MIN_PARTICLES = 5


@dataclass
class RivalTrack:
    """A pose other than the estimate that explained a scan, followed until refuted."""

    pose: tuple[float, float, float]
    refuted: bool = False
    last_match: float = 1.0


class AmbiguityGuard:
    """Rival tracks: found by check(), moved by predict(), judged by observe()."""

    def __init__(self, rival_fraction: float, localize_fraction: float) -> None:
        self.rival_fraction = float(rival_fraction)
        self.localize_fraction = float(localize_fraction)
        self.tracks: list[RivalTrack] = []

    def clear(self) -> None:
        """Forget every track (after a re-initialization)."""
        self.tracks = []

    @property
    def open_tracks(self) -> list[RivalTrack]:
        """The tracks not refuted yet."""
        return [t for t in self.tracks if not t.refuted]

    def predict(self, v: float, w: float, dt: float) -> None:
        """Move every track by the odometry twist (v, w) over dt (mid-point heading)."""
        for track in self.tracks:
            x, y, theta = arc_step(*track.pose, v * dt, w * dt)
            track.pose = (x, y, math.remainder(theta, 2.0 * math.pi))

    def observe(self, estimate, estimate_match: float, matcher: ScanMatcher, ranges: np.ndarray,
                tolerance: float, particles: np.ndarray, weights: np.ndarray,
                search: Callable[[tuple], Alternative]) -> RivalTrack | None:
        """Judge the open tracks after a measurement update.

        After a measurement update: re-anchor open tracks on their particles, refute those
        that no longer explain the scan while the estimate does.

        Decisions compare locally refined poses (pose_search.refine), so a hypothesis is judged
        by the best pose near it, not by a small error of its current pose; before refuting,
        `search(pose)` (PoseSearch.best_near) must find NO pose within the track's
        neighbourhood (TRACK_DISTANCE_M, TRACK_ANGLE_RAD: the same one that later matches
        rivals to it) that explains the scan. Returns the best open track if the evidence
        turned the other way: it explains at least localize_fraction of the rays while the
        estimate explains fewer than rival_fraction. The caller moves the filter there; the
        old estimate is then a refuted track.
        """
        winner = None
        refined_estimate: float | None = None
        for track in self.open_tracks:
            track.pose = self._anchor(track.pose, particles, weights)
            if close_poses(track.pose, estimate, TRACK_DISTANCE_M, TRACK_ANGLE_RAD):
                self.tracks.remove(track)  # it merged with the estimate: no longer a rival
                continue
            match = matcher.match_fraction(track.pose, ranges, tolerance)
            decisive = match < self.rival_fraction or estimate_match < self.rival_fraction
            if not decisive:
                track.last_match = match
                continue
            if refined_estimate is None:
                refined_estimate = refine(estimate, matcher, ranges, tolerance).match_fraction
            better = refine(track.pose, matcher, ranges, tolerance)
            if better.match_fraction < self.rival_fraction and \
                    refined_estimate >= self.localize_fraction:
                better = search(track.pose)  # the whole neighbourhood, before refuting
            track.pose, match = better.pose, better.match_fraction
            track.last_match = match
            if match < self.rival_fraction and refined_estimate >= self.localize_fraction:
                track.refuted = True
            elif match >= self.localize_fraction and refined_estimate < self.rival_fraction and \
                    (winner is None or match > winner.last_match):
                winner = track
        if winner is not None:
            self.tracks.remove(winner)
            self.tracks.append(RivalTrack(tuple(estimate), refuted=True,
                                          last_match=refined_estimate))
        return winner

    def unresolved(self, alternatives: list[Alternative]) -> list[Alternative]:
        """The rivals among `alternatives` that no refuted track accounts for.

        The rivals among `alternatives` (explaining >= rival_fraction) that no refuted track
        accounts for; each one not near any track becomes an open track (a track keeps its own
        pose: the search's coarse pose may be a neighbour that fits less well).
        """
        left = []
        for alternative in alternatives:
            if alternative.match_fraction < self.rival_fraction:
                continue
            track = next((t for t in self.tracks if close_poses(
                t.pose, alternative.pose, TRACK_DISTANCE_M, TRACK_ANGLE_RAD)), None)
            if track is not None and track.refuted:
                continue
            if track is None:
                self.tracks.append(RivalTrack(alternative.pose,
                                              last_match=alternative.match_fraction))
            left.append(alternative)
        return left

    @staticmethod
    def _anchor(pose, particles: np.ndarray, weights: np.ndarray):
        near = ((particles[:, 0] - pose[0]) ** 2 + (particles[:, 1] - pose[1]) ** 2
                <= ANCHOR_DISTANCE_M ** 2) & \
            (np.abs(wrap_angles(particles[:, 2] - pose[2]))
             <= ANCHOR_ANGLE_RAD)
        if np.count_nonzero(near) < ANCHOR_MIN_PARTICLES:
            return pose
        return weighted_pose_mean(particles[near], weights[near])
