"""The particle filter's exhaustive pose searches, started on one scan and finished later.

On a big map the exhaustive pose search takes seconds (885,000 positions on a 40 x 40 m floor:
~3 s), during which a node doing it in one callback answers nothing while the robot drives on
its last command. So the filter scores a slice per correct() call (pose_search.SearchJob) and
uses the result once the search is done: a global search's particles wait for the search of its
first scan (SEED), a candidate pose for the check that no other pose explains its scan (CHECK),
a converged pose that does not explain the scan for the rivals that might (DOUBT). The result
describes poses at the searched scan; the robot has moved since, so they are carried by the
odometry since that scan (the mid-point integration of the filter's own predict). A course
maze's search is one slice: done in the call that starts it and carried by nothing, so the
filter's results there are those of a search in one go.

PendingSearch is one search in progress; FilterSearches, the part of ParticleFilter that starts,
resumes and uses them (a mixin: it works on the filter's own particles, tracks and decision).
No rclpy import.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from amr_common.geometry import wrap_angles
from amr_common.robot import ROBOT_RADIUS
from amr_localization.ambiguity import TRACK_ANGLE_RAD, TRACK_DISTANCE_M
from amr_localization.particle_sets import gaussian_poses, sample_free_poses
from amr_localization.pose_search import Alternative, SearchJob, close_poses
from amr_localization.scan_input import TakenScan

SEED, CHECK, DOUBT = "seed", "check", "doubt"  # what the filter does with a finished search


@dataclass
class PendingSearch:
    """A search in progress: its job, the scan it searches and what the filter knew then.

    kind: SEED (the particles of a global search), CHECK (no rival before declaring the
    estimate), DOUBT (rivals of a converged pose that does not explain the scan).
    """

    kind: str
    job: SearchJob
    scan: TakenScan  # the scan searched (de-skewed, its tolerances and beams: scan_input)
    estimate: tuple[float, float, float]  # the filter's estimate at that scan
    # Odometry since that scan: (dx, dy, dtheta) in the frame of a robot pose at that scan.
    motion: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])

    def advance(self) -> bool:
        """Score the next slice of the search; True once it is done."""
        return self.job.advance()

    def predict(self, v: float, w: float, dt: float) -> None:
        """Add an odometry twist (v m/s, w rad/s over dt s) to the motion since the scan."""
        dx, dy, dtheta = self.motion
        mid = dtheta + 0.5 * w * dt
        self.motion = [dx + v * dt * math.cos(mid), dy + v * dt * math.sin(mid),
                       dtheta + w * dt]

    def carry(self, poses: np.ndarray) -> np.ndarray:
        """(K, 3) poses at the searched scan, moved by the motion since (each in its frame)."""
        dx, dy, dtheta = self.motion
        if dx == 0.0 and dy == 0.0 and dtheta == 0.0:
            return poses
        x, y, theta = poses[:, 0], poses[:, 1], poses[:, 2]
        cos, sin = np.cos(theta), np.sin(theta)
        return np.column_stack([x + dx * cos - dy * sin, y + dx * sin + dy * cos,
                                wrap_angles(theta + dtheta)])

    def carry_pose(self, pose) -> tuple[float, float, float]:
        """One pose at the searched scan, moved by the motion since."""
        x, y, theta = self.carry(np.array([pose], dtype=np.float64))[0]
        return float(x), float(y), float(theta)

    def carry_alternatives(self, alternatives: list[Alternative]) -> list[Alternative]:
        """The alternatives (poses at the searched scan) at their poses now."""
        if not alternatives:
            return alternatives
        poses = self.carry(np.array([a.pose for a in alternatives], dtype=np.float64))
        return [Alternative(tuple(float(v) for v in pose), a.match_fraction)
                for pose, a in zip(poses, alternatives)]


class FilterSearches:
    """ParticleFilter's exhaustive searches: started, resumed a slice per call, then used.

    Works on the filter's attributes (params, _scan: the scan taken for the update under way,
    search, matcher, guard, check, particles, weights, estimate, rng, world, table, _pending,
    _seed_pending, _last_doubt, events, total_updates, localized) and its _set_particles,
    _take_scan and update_due.
    """

    def _scan_to_weigh(self, ranges: np.ndarray, age_s: float, force: bool,
                       new_scan: bool) -> np.ndarray | None:
        """The scan's de-skewed ranges if a measurement update happens now, else None.

        A global search's particles wait for the search of its first scan (SEED); otherwise a
        search in progress scores its next slice, then the update is due or not (update_due).
        """
        if self._seed_pending:
            if self._pending is None:  # the global search's first scan: search it
                ranges = self._take_scan(ranges, age_s)
                if self._run_search(SEED, ranges) is None:
                    return None  # the particles wait for the search of that scan
                return ranges
            if self._run_search(None, ranges) is None:
                return None
        else:
            if self._pending is not None:  # a search of an earlier scan: its next slice
                event = self._run_search(None, ranges)
                if event:
                    self.events.append((event, self.total_updates))
            if not (force or self.update_due(new_scan)):
                return None
        return self._take_scan(ranges, age_s)

    def _doubt(self, ranges: np.ndarray) -> None:
        """Search for rivals (DOUBT) of a converged pose that does not explain the scan.

        If the true pose lost its particles earlier (a symmetric maze), the exhaustive search
        finds it again; at most once every localize_updates updates.
        """
        p = self.params
        if not self.localized and self.cluster_share >= p["cluster_min_share"] and \
                self.match_fraction < p["ambiguity_match_fraction"] and \
                self._pending is None and \
                self.total_updates - self._last_doubt >= p["localize_updates"]:
            self._last_doubt = self.total_updates
            self._run_search(DOUBT, ranges)

    def _switch_to_rival(self, ranges: np.ndarray) -> bool:
        """True if a rival track explains the scans better: the particles moved to it."""
        if self.localized or not self.guard.tracks:
            return False
        winner = self.guard.observe(self.estimate, self.match_fraction, self.matcher, ranges,
                                    self._scan.tolerances, self.particles, self.weights,
                                    self._searcher(ranges))
        if winner is None:
            return False
        self._move_to(winner.pose)
        self.events.append(("switch", self.total_updates))
        return True

    def _move_to(self, pose) -> None:
        """Move every particle to a rival that explains the scans better.

        All particles around `pose` (a rival that explains the scans better than the
        estimate did), the rival tracks kept: not localized.
        """
        count = len(self.particles)
        self._pending = None  # a search about the particle set it replaces
        self.particles = gaussian_poses([pose], (0.02, 0.02, 0.03), count, self.rng)
        self.weights = np.full(count, 1.0 / count)
        self.check.reset()
        self.estimate = tuple(float(v) for v in pose)

    def _run_search(self, kind: str | None, ranges: np.ndarray) -> str | None:
        """Start a search of this scan (`kind`) or resume the one in progress (None): a slice.

        Returns None while it goes on; once done, what using it decided (_finish_search).
        """
        if kind is not None:  # `ranges` are those of the scan taken (self._scan)
            scan, p = self._scan, self.params
            z_mm = scan.beams.readings_mm(ranges)
            seeded = int(round(p["max_particles"] * (1.0 - p["seed_uniform_share"])))
            job = self.search.start(seeded, scan.beams, z_mm) if kind == SEED else \
                self.search.start_alternatives(scan.beams, z_mm)
            self._pending = PendingSearch(kind, job, scan, tuple(self.estimate))
        if not self._pending.advance():
            return None
        return self._finish_search()

    def _seed(self, pending: PendingSearch) -> None:
        """Seed a global search from the finished exhaustive pose search of its first scan.

        Particles of a global search: the best-fitting grid poses of that scan (share
        1 - seed_uniform_share), carried by the odometry since, and uniform ones (the rest).

        Uniform particles alone are too sparse: 8,000 of them over a 2.4 m maze leave ~1 within
        5 cm and 10 degrees of any pose, and the first updates collapse onto the luckiest one,
        in a symmetric maze often a rotated copy of the truth.
        """
        count = self.params["max_particles"]
        poses = pending.carry(self.search.best_poses(pending.job, self.rng))
        poses = poses[self.world.clearances(poses[:, :2]) >= ROBOT_RADIUS]
        uniform = sample_free_poses(self.world, self.table.grid, count - len(poses), self.rng)
        self._set_particles(np.concatenate([poses, uniform]))
        self._seed_pending = False

    def _check_ambiguity(self, ranges: np.ndarray) -> str:
        """The candidate's check: known rivals alive, or the search of this scan (CHECK).

        Returns "ambiguous" (rivals), "localized" (a search done at once found none) or ""
        (a search in progress: the declaration waits for it).
        """
        if self._pending is not None:  # a search in progress: the candidate waits for it
            return ""
        p = self.params
        live = [t for t in self.guard.open_tracks if t.last_match >= p["ambiguity_match_fraction"]]
        if live:  # known rivals still explain the scan: no need to search again
            self.check.reject()
            return "ambiguous"
        return self._run_search(CHECK, ranges) or ""

    def _finish_search(self) -> str:
        """Use the finished search: seed the particles, or judge the rivals it found.

        Declare the candidate (CHECK) only if no other pose explains its scan as well,
        otherwise add particles at those poses (the filter must then tell them apart); rivals
        of a doubtful estimate (DOUBT) get particles too. Returns "localized", "ambiguous" or "".
        """
        pending, self._pending = self._pending, None
        if pending.kind == SEED:
            self._seed(pending)
            return ""
        scan = pending.scan
        self.matcher.set_ray_angles(scan.angles)  # refined on the searched scan's rays
        found = self.search.alternatives(pending.job, pending.estimate, self.matcher,
                                         scan.ranges, scan.tolerances)
        self.matcher.set_ray_angles(self._scan.angles)
        self.last_alternatives = pending.carry_alternatives(found)
        rivals = self.guard.unresolved(self.last_alternatives)
        if rivals:
            if pending.kind == CHECK:
                self.check.reject()
            self._inject([a.pose for a in rivals])
            return "ambiguous" if pending.kind == CHECK else ""
        # No rival of the candidate at its scan: declare it if the filter still holds it (the
        # same pose, carried, and its last update passed the test); else the next candidate
        # is searched again.
        if pending.kind == CHECK and self.check.good_streak > 0 and close_poses(
                self.estimate, pending.carry_pose(pending.estimate), TRACK_DISTANCE_M,
                TRACK_ANGLE_RAD):
            self.check.confirm()
            return "localized"
        return ""

    def _alternatives(self, ranges: np.ndarray) -> list:
        """The best poses away from the estimate for this scan, searched at once."""
        scan = self._scan
        job = self.search.start_alternatives(scan.beams, scan.beams.readings_mm(ranges))
        self.last_alternatives = self.search.alternatives(
            job.finish(), self.estimate, self.matcher, ranges, scan.tolerances)
        return self.last_alternatives

    def _searcher(self, ranges: np.ndarray):
        """best_near(pose) of PoseSearch for this scan, over a rival track's neighbourhood."""
        scan = self._scan
        z_mm = scan.beams.readings_mm(ranges)
        return lambda pose: self.search.best_near(
            pose, TRACK_DISTANCE_M, TRACK_ANGLE_RAD, scan.beams, z_mm, self.matcher, ranges,
            scan.tolerances)

    def _inject(self, poses) -> None:
        """Replace a share of the particles by Gaussians around `poses` (equal weights)."""
        p = self.params
        per_pose = max(int(p["inject_share"] * len(self.particles) / len(poses)), 1)
        sx, sy, st = p["initial_pose_sigma"]
        new = gaussian_poses(poses, (min(sx, 0.03), min(sy, 0.03), min(st, 0.05)), per_pose,
                             self.rng)
        replace = self.rng.choice(len(self.particles), size=min(len(new), len(self.particles)),
                                  replace=False)
        self.particles[replace] = new[:len(replace)]
        self.weights = np.full(len(self.particles), 1.0 / len(self.particles))


__all__ = ["PendingSearch", "FilterSearches", "SEED", "CHECK", "DOUBT"]
