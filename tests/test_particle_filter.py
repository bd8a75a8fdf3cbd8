"""The particle filter's parts without ROS.

Motion model, resampling, free-space sampling, the beam model on the expected-range table, KLD
count, the localized decision; numba and plain Python/numpy paths agree.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.robot import ROBOT_RADIUS
from amr_common.sensors.lidar_models import LDS01
from amr_common.world.world import World
from amr_localization import beam_model, motion_model, pose_search, resampling
from amr_localization.expected_ranges import build_expected_range_table, expected_range_table
from amr_localization.localization_check import (
    CheckSettings,
    LocalizedDecision,
    ScanMatcher,
    dominant_cluster,
)
from amr_localization.motion_model import MotionNoise, sample_motion
from amr_localization.particle_filter import ParticleFilter
from amr_localization.particle_filter_params import check_parameters
from amr_localization.particle_sets import sample_free_poses
from amr_localization.range_sensor import RangeSensor
from amr_localization.scan_beams import ScanBeams, reading_to_mm
from amr_sim.lidar import Lidar


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    """A straight 0.4 m corridor, 2.4 m long, closed at both ends.

    Symmetric under a half turn about its centre, and every beam endpoint of a rotated pose lies on
    SOME wall.
    """
    path = tmp_path_factory.mktemp("worlds") / "corridor.yaml"
    path.write_text("boundary: [[0, 0], [2.4, 0], [2.4, 0.4], [0, 0.4]]\n")
    return World.load(path)


# --- motion model ---------------------------------------------------------------------------

def test_motion_model_moments():
    rng = np.random.default_rng(0)
    count, v, w, dt = 20000, 0.2, 0.5, 0.05
    particles = np.zeros((count, 3))
    noise = MotionNoise(v_per_v=0.1, v_per_w=0.0, w_per_w=0.2, w_per_v=0.0)
    steps = 20
    for _ in range(steps):
        sample_motion(particles, count, v, w, dt, noise, rng)
    sigma_v, sigma_w = noise.sigmas(v, w)
    # Headings: a sum of independent steps, mean w T, variance steps (sigma_w dt)^2.
    assert particles[:, 2].mean() == pytest.approx(w * dt * steps, abs=0.002)
    assert particles[:, 2].std() == pytest.approx(sigma_w * dt * math.sqrt(steps), rel=0.05)
    # Positions: the arc of radius v / w in the mean.
    radius = v / w
    angle = w * dt * steps
    assert particles[:, 0].mean() == pytest.approx(radius * math.sin(angle), abs=0.003)
    assert particles[:, 1].mean() == pytest.approx(radius * (1 - math.cos(angle)), abs=0.003)
    assert particles[:, 0].std() > 0.002
    standing = np.zeros((100, 3))
    sample_motion(standing, 100, 0.0, 0.0, dt, MotionNoise(), rng)
    assert not standing.any(), "no motion, no noise: particles do not diffuse at rest"


def test_motion_kernel_equals_python():
    rng = np.random.default_rng(1)
    particles = rng.uniform(-3, 3, (500, 3))
    normals = rng.standard_normal((500, 2))
    a, b = particles.copy(), particles.copy()
    motion_model.move(a, 500, 0.2, -1.0, 0.05, 0.02, 0.1, normals)
    motion_model.move_python(b, 500, 0.2, -1.0, 0.05, 0.02, 0.1, normals)
    np.testing.assert_allclose(a, b, atol=1e-12)
    assert np.all(np.abs(a[:, 2]) <= math.pi)


# --- resampling -----------------------------------------------------------------------------

def test_low_variance_resampling_keeps_the_weights_expectation():
    rng = np.random.default_rng(2)
    weights = rng.random(50) ** 3
    weights /= weights.sum()
    for count in (50, 1000):
        indices = np.empty(count, dtype=np.int64)
        resampling.low_variance_indices(weights, count, float(rng.random()), indices)
        copies = np.bincount(indices, minlength=50)
        # Low variance: every particle is drawn floor(M w) or ceil(M w) times.
        assert np.all(copies >= np.floor(count * weights) - 1e-9)
        assert np.all(copies <= np.ceil(count * weights) + 1e-9)
        python = np.empty(count, dtype=np.int64)
        resampling.low_variance_indices_python(weights, count, 0.3, python)
        resampling.low_variance_indices(weights, count, 0.3, indices)
        assert np.array_equal(python, indices)
    # The expectation over many offsets is exactly M w.
    mean = np.zeros(50)
    for u in np.linspace(0, 1, 400, endpoint=False):
        resampling.low_variance_indices(weights, 10, float(u), indices[:10])
        mean += np.bincount(indices[:10], minlength=50) / 400
    np.testing.assert_allclose(mean, 10 * weights, atol=0.03)


def test_kld_count_grows_with_the_occupied_bins():
    assert resampling.kld_count(1, 0.05, 2.33) == 1
    counts = [resampling.kld_count(k, 0.05, 2.33) for k in (2, 10, 100, 1000)]
    assert counts == sorted(counts) and counts[-1] > 10 * counts[1]
    rng = np.random.default_rng(3)
    spread = np.column_stack([rng.uniform(0, 2, 3000), rng.uniform(0, 2, 3000),
                              rng.uniform(-math.pi, math.pi, 3000)])
    tight = np.column_stack([rng.normal(1.025, 0.005, 3000), rng.normal(1.025, 0.005, 3000),
                             rng.normal(0.08, 0.01, 3000)])  # one bin
    seen = np.zeros(50 * 50 * 37, dtype=np.uint8)
    for kernel in (resampling.occupied_bins, resampling.occupied_bins_python):
        wide = kernel(spread, 3000, 0.0, 0.0, 0.05, 0.1745, 50, 50, 37, seen)
        narrow = kernel(tight, 3000, 0.0, 0.0, 0.05, 0.1745, 50, 50, 37, seen)
        assert wide > 1000 and narrow == 1 and not seen.any()


# --- the map --------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["lab02", "room_obstacles", "twin_maze"])
def test_particles_are_never_drawn_in_walls(name):
    world = World.load(name)
    table = expected_range_table(world)
    poses = sample_free_poses(world, table.grid, 5000, np.random.default_rng(4))
    assert world.contains_points(poses[:, :2]).all()
    assert world.clearances(poses[:, :2]).min() >= ROBOT_RADIUS
    assert np.all(np.abs(poses[:, 2]) <= math.pi)
    # A global search seeded from a scan keeps to the same rule.
    pf = ParticleFilter(world, max_particles=3000)
    pf.set_scan_geometry(0.0, 2 * math.pi / 240, 240, 0.016, 8.0)
    lidar = Lidar(world.segments, 240, 0.0, 2 * math.pi / 240, 0.016, 8.0, math.nan)
    x, y, theta = next(iter(world.starts.values()))
    pf.correct(lidar.scan(x, y, theta))
    assert world.contains_points(pf.particles[:, :2]).all()
    assert world.clearances(pf.particles[:, :2]).min() >= ROBOT_RADIUS - 0.02


def test_expected_range_table_is_the_simulators_lidar_at_cell_centres():
    world = World.load("twin_maze_small")
    table = build_expected_range_table(world, resolution=0.02, angles=360)
    lidar = Lidar(world.segments, 360, 0.0, 2 * math.pi / 360, 0.0, 100.0, math.nan)
    rng = np.random.default_rng(5)
    inside = np.flatnonzero(table.grid.clearance.ravel() > 0.05)
    for cell in rng.choice(inside, 20, replace=False):
        x, y = table.cell_centres()[cell]
        np.testing.assert_allclose(table.cell_ranges(cell) / 1000.0, lidar.scan(x, y, 0.0),
                                   atol=0.0006)


# --- measurement model ----------------------------------------------------------------------

def _scores(world, poses, scan_pose, kernel, lidar_offset=0.0, rays=240, angle_min=0.0,
            sub_cell=False, resolution=0.02, sensor=None):
    table = expected_range_table(world, resolution)
    model = beam_model.BeamModel(table, table.robot_cells(slack=0.02), lidar_offset, 0.03, 0.05,
                                 sub_cell=sub_cell)
    beams = ScanBeams.from_geometry(angle_min, 2 * math.pi / rays, rays, 0.016, 8.0, 60,
                                    table.angles)
    lidar = Lidar(world.segments, rays, angle_min, 2 * math.pi / rays, 0.016, 8.0, math.nan)
    x, y, theta = scan_pose
    ranges = lidar.scan(x + lidar_offset * math.cos(theta), y + lidar_offset * math.sin(theta),
                        theta)
    scales = None if sensor is None else sensor.sigma_scales(ranges)
    return model.scores(np.asarray(poses, float), beams.split(beams.readings_mm(ranges), scales),
                        beams.limits_mm, kernel)


def test_beam_model_ranks_the_true_pose_above_rotated_poses_on_a_symmetric_corridor(corridor):
    truth, twin = (0.71, 0.21, 0.0), (1.69, 0.19, math.pi)  # twin: half turn about the centre
    rotated = [(0.71, 0.21, math.pi), (0.71, 0.21, math.pi / 2), (0.71, 0.21, -math.pi / 2),
               (1.69, 0.19, 0.0)]
    for kernel in (beam_model.log_likelihoods_kernel, beam_model.log_likelihoods_numpy,
                   beam_model.log_likelihoods_python):
        scores = _scores(corridor, [truth, twin] + rotated, truth, kernel)
        assert scores[1] == pytest.approx(scores[0], abs=2.0), "the exact twin fits as well"
        assert np.all(scores[2:] < scores[0] - 20.0), scores
    # The twin's own scan: now the twin ranks first.
    twin_scores = _scores(corridor, [twin, (1.69, 0.19, 0.0)], twin,
                          beam_model.log_likelihoods_kernel)
    assert twin_scores[1] < twin_scores[0] - 20.0


@pytest.mark.parametrize("sub_cell, sensor", [(False, None), (True, None),
                                              (False, RangeSensor(LDS01, 0.03, 0.03, 0.01))])
@pytest.mark.parametrize("rays, angle_min", [(240, 0.0), (230, -3.1)])  # whole / fractional bins
def test_beam_model_paths_agree_and_walls_get_no_weight(rays, angle_min, sub_cell, sensor):
    """The compiled kernel and its twins, with sigma_hit for every beam or the LDS-01's sigmas."""
    world = World.load("lab02")
    rng = np.random.default_rng(6)
    poses = np.column_stack([rng.uniform(-1.3, 1.3, 3000), rng.uniform(-1.3, 1.3, 3000),
                             rng.uniform(-3 * math.pi, 3 * math.pi, 3000)])
    poses[0] = (0.0, -0.8, 0.0)  # on a wall
    poses[1] = (5.0, 5.0, 0.0)  # off the map
    poses[2] = (math.nan, 0.0, 0.0)
    poses[3] = (1.0, -1.0, math.pi / 2)  # the scan's own pose
    scores = {kernel: _scores(world, poses, (1.0, -1.0, math.pi / 2), kernel, lidar_offset=-0.032,
                              rays=rays, angle_min=angle_min, sub_cell=sub_cell, sensor=sensor)
              for kernel in (beam_model.log_likelihoods_kernel, beam_model.log_likelihoods_python,
                             beam_model.log_likelihoods_numpy)}
    jit = scores[beam_model.log_likelihoods_kernel]
    for other in scores.values():  # the same integer sums: equal to the last bit
        np.testing.assert_array_equal(jit, other)
    assert np.all(np.isneginf(jit[:3]))
    assert jit[3] == np.nanmax(jit[np.isfinite(jit)]) and jit[3] > -0.2 * 60
    clear = world.clearances(poses[4:, :2]) < ROBOT_RADIUS - 0.05
    assert np.all(np.isneginf(jit[4:][clear]))


def test_the_sub_cell_correction_places_the_robot_within_a_4_cm_cell():
    """Without it every pose whose LiDAR is in the same cell scores the same (a 4 cm plateau)."""
    world = World.load("lab02")
    truth = (1.013, -0.987, 0.3)
    xs = np.arange(0.99, 1.037, 0.002)
    poses = np.column_stack([xs, np.full(xs.size, truth[1]), np.full(xs.size, truth[2])])
    for sub_cell in (True, False):
        scores = _scores(world, poses, truth, beam_model.log_likelihoods_kernel, rays=360,
                         sub_cell=sub_cell, resolution=0.04)
        best = xs[scores == scores.max()]
        if sub_cell:
            assert np.all(np.abs(best - truth[0]) <= 0.006), best
        else:
            assert best.max() - best.min() >= 0.025, "a plateau over the cell"


def test_scan_beams_fall_on_whole_table_bins_for_the_course_scans():
    for rays in (240, 360):
        beams = ScanBeams.from_geometry(0.0, 2 * math.pi / rays, rays, 0.12, 3.5, 60, 360)
        assert beams.count == 60 and not beams.fractional
        assert np.array_equal(beams.whole, np.arange(0, 360, 6))
    odd = ScanBeams.from_geometry(-3.1, 2 * math.pi / 230, 230, 0.12, 3.5, 60, 360)
    assert odd.fractional and np.allclose(odd.whole + odd.fraction, odd.bins)
    assert np.all((odd.fraction >= 0) & (odd.fraction < 1)) and odd.limits_mm == (120, 3500)
    z_mm = reading_to_mm(np.array([0.0, math.nan, math.inf, 0.1, 0.5, 3.6, 3.5]), 0.12, 3.5)
    assert z_mm.tolist() == [-1, -1, -1, -1, 500, -1, 3500]
    with pytest.raises(ValueError, match="geometry"):
        ScanBeams.from_geometry(0.0, 0.0, 360, 0.12, 3.5, 60, 360)


def test_pose_scores_paths_agree():
    world = World.load("twin_maze_small")
    table = expected_range_table(world)
    search = pose_search.PoseSearch(table, table.robot_cells(slack=0.02), 0.0, headings=36)
    lidar = Lidar(world.segments, 240, 0.0, 2 * math.pi / 240, 0.016, 8.0, math.nan)
    ranges = lidar.scan(1.8, 0.2, math.pi)
    beams = ScanBeams.from_geometry(0.0, 2 * math.pi / 240, 240, 0.016, 8.0, 60, table.angles)
    z_mm = beams.readings_mm(ranges)
    tolerance_mm = 60 + 10 * (np.arange(beams.count) % 5)  # per beam (range_sensor)
    outputs = []
    for kernel in (pose_search.score_poses_kernel, pose_search.score_poses_numpy,
                   pose_search.score_poses_python):
        out = np.empty((len(search.cells), 36), dtype=np.int32)
        kernel(search.centres, 36, table.ranges, table.rows, table.angles, table.x0, table.y0,
               table.resolution, table.nx, -0.032, beams.bins, z_mm, tolerance_mm, 16, 8000, 15,
               out)
        outputs.append(out)
    assert np.array_equal(outputs[0], outputs[2])
    assert np.array_equal(outputs[0], outputs[1])
    assert outputs[0].max() == 60


# --- the localized decision -----------------------------------------------------------------

def test_dominant_cluster_needs_one_heavy_group():
    rng = np.random.default_rng(7)
    a = np.column_stack([rng.normal(0.5, 0.01, 500), rng.normal(0.5, 0.01, 500),
                         rng.normal(3.1, 0.02, 500)])
    a[:, 2] = np.remainder(a[:, 2] + math.pi, 2 * math.pi) - math.pi  # straddles +-pi
    b = a + [1.0, 0.0, 0.0]
    both = np.vstack([a, b])
    half = dominant_cluster(both, np.full(1000, 1e-3), 0.1, 0.35)
    assert half.share == pytest.approx(0.5, abs=0.01)
    weights = np.r_[np.full(500, 0.0019), np.full(500, 0.0001)]
    heavy = dominant_cluster(both, weights, 0.1, 0.35)
    assert heavy.share == pytest.approx(0.95, abs=0.01)
    assert heavy.pose[0] == pytest.approx(0.5, abs=0.005)
    assert abs(abs(heavy.pose[2]) - 3.1) < 0.01, "circular mean across +-pi"


def test_localized_decision_streaks():
    decision = LocalizedDecision(CheckSettings(localize_updates=3, lost_updates=2,
                                               reinit_updates=2))
    assert decision.update(0.95, 0.99) == "" and decision.update(0.95, 0.99) == ""
    assert decision.update(0.5, 0.99) == "", "two hypotheses: the streak restarts"
    assert [decision.update(0.95, 0.98) for _ in range(3)] == ["", "", "candidate"]
    assert not decision.localized
    decision.confirm()
    assert decision.localized
    assert decision.update(0.95, 0.5) == "" and decision.update(0.95, 0.9) == ""
    assert decision.update(0.95, 0.5) == "" and decision.update(0.95, 0.5) == "lost"
    assert not decision.localized
    assert decision.update(0.99, 0.3) == "" and decision.update(0.99, 0.3) == "reinit"


def test_scan_matcher_explains_the_true_scan_only():
    world = World.load("lab02")
    matcher = ScanMatcher(world.segments, 0.0, 2 * math.pi / 360, 360, 0.12, 3.5, -0.032)
    lidar = Lidar(world.segments, 360, 0.0, 2 * math.pi / 360, 0.12, 3.5, 0.0)
    pose = (0.6, -0.6, 3 * math.pi / 2)
    ranges = lidar.scan(0.6 - 0.032 * math.cos(pose[2]), -0.6 - 0.032 * math.sin(pose[2]),
                        pose[2])
    assert matcher.match_fraction(pose, ranges, 0.03) == 1.0
    assert matcher.match_fraction((0.6, -0.6, math.pi / 2), ranges, 0.03) < 0.6


# --- the filter on its own ------------------------------------------------------------------

def test_parameters_are_checked_with_every_problem_named():
    with pytest.raises(ValueError) as error:
        check_parameters({"beams": 0, "z_random": 1.5, "initial_pose": [1, 2],
                          "min_particles": 900, "max_particles": 100})
    text = str(error.value)
    for name in ("beams", "z_random", "initial_pose", "min_particles"):
        assert name in text
    assert check_parameters({"initial_pose": [1, 2, 3]})["initial_pose"] == (1.0, 2.0, 3.0)
    with pytest.raises(ValueError, match="unknown"):
        check_parameters({"no_such": 1})


@pytest.mark.parametrize("name, value", [("max_particles", 100_000_000),
                                         ("tracking_particles", 10**9), ("beams", 10**6),
                                         ("kld_bin_xy_m", 1e-9), ("cluster_angle_rad", 1e-12),
                                         ("table_resolution_m", 1e-4), ("noise_w_per_v", 1e9)])
def test_values_that_would_cost_absurd_memory_or_time_are_refused(name, value):
    """Caught by the checks run scripts call before starting the nodes .

    max_particles 1e8 spent 75 s in configure; tiny KLD or cluster bins allocated histograms
    beyond the machine's memory.
    """
    with pytest.raises(ValueError, match=rf"{name} must be in \["):
        check_parameters({name: value})


@pytest.mark.parametrize("name", ["max_particles", "min_particles", "tracking_particles"])
def test_one_particle_cap_for_every_count(name):
    """One cap, named once (there were two: 200,000 in the bounds and 1,000,000 after them).

    A count above it got both messages, contradicting each other.
    """
    from amr_localization.particle_filter_params import MAX_PARTICLES
    cap = {"max_particles": MAX_PARTICLES} if name == "min_particles" else {}
    assert check_parameters({name: MAX_PARTICLES, **cap})[name] == MAX_PARTICLES
    with pytest.raises(ValueError) as error:
        check_parameters({name: 100_000_000, **cap})
    assert str(error.value) == f"{name} must be in [1, {MAX_PARTICLES}] (got 100000000)"


def test_adaptive_count_shrinks_when_tracking():
    """Tracking converges to the minimum count; a search starts at the maximum.

    Tracking from a known pose converges to the minimum count; a global search starts with
    the maximum.
    """
    world = World.load("lab02")
    pose = world.starts["inner"]
    pf = ParticleFilter(world, initial_pose=list(pose), min_particles=200,
                        tracking_particles=3000, lidar_model="exact")  # the course's scan
    assert pf.particle_count == 3000
    pf.set_scan_geometry(0.0, 2 * math.pi / 240, 240, 0.016, 8.0)
    lidar = Lidar(world.segments, 240, 0.0, 2 * math.pi / 240, 0.016, 8.0, math.nan)
    for _ in range(15):
        pf.correct(lidar.scan(*pose), force=True)
    assert pf.particle_count == 200
    # A standing robot: within the expected-range table's 2 cm cells the likelihood is flat.
    assert math.hypot(pf.estimate[0] - pose[0], pf.estimate[1] - pose[1]) < 0.03
    assert pf.localized, "a standing robot is confirmed by repeated updates"
    assert ParticleFilter(world).particle_count == 8000


# --- hostile initial poses --------------------------------------------------------------------

def test_dominant_cluster_of_particles_spread_over_kilometres():
    """A histogram over the particles' extent must not grow with it (was a MemoryError)."""
    from amr_localization import cluster
    rng = np.random.default_rng(8)
    spread = np.column_stack([rng.normal(0.0, 1e4, 2000), rng.normal(0.0, 1e4, 2000),
                              rng.uniform(-math.pi, math.pi, 2000)])
    spread[:300] = rng.normal([5.0, 5.0, 0.5], [0.01, 0.01, 0.02], (300, 3))  # one tight group
    found = dominant_cluster(spread, np.full(2000, 1 / 2000), 0.1, 0.35)
    assert found.pose[:2] == pytest.approx((5.0, 5.0), abs=0.01)
    assert found.share == pytest.approx(0.15, abs=0.01)
    assert np.all(np.isfinite(found.covariance))
    for kernel in (cluster.cluster_kernel, cluster.cluster_python):  # the twins agree
        members, stats = np.zeros(2000, dtype=np.bool_), np.zeros(13)
        kernel(spread, np.full(2000, 1 / 2000), 0.1, 0.35, members, stats)
        assert np.array_equal(members, found.members) and stats[3] == found.share


def test_initial_pose_sigma_is_clamped_to_the_map_and_logged(caplog):
    world = World.load("lab02")
    x, y, theta = world.starts["inner"]
    with caplog.at_level("WARNING", logger="amr_localization.particle_filter"):
        pf = ParticleFilter(world, initial_pose=[x, y, theta],
                            initial_pose_sigma=[1e6, 1e6, 1.0])
    assert "clamped" in caplog.text
    xmin, ymin, xmax, ymax = world.bounds
    assert np.std(pf.particles[:, 0]) <= 1.2 * (xmax - xmin)
    used = pf.initialize_pose((x, y, theta), (1e4, 1e300, 1e9))
    assert used == pytest.approx((xmax - xmin, ymax - ymin, math.pi))
    assert np.std(pf.particles[:, 1]) <= 1.2 * (ymax - ymin)
    assert pf.initialize_pose((x, y, theta), (0.02, 0.03, 0.1)) == (0.02, 0.03, 0.1)


@pytest.mark.parametrize("pose, reason", [((0.0, -0.8, 0.0), "wall"),  # on a wall of lab02
                                          ((0.6, -0.73, 0.0), "wall"),  # 7 cm from one
                                          ((5.0, 5.0, 0.0), "outside"),
                                          ((math.nan, 0.0, 0.0), "finite"),
                                          ((0.6, -0.6, math.inf), "finite")])
def test_an_initial_pose_where_the_robot_cannot_be_is_refused_and_the_state_kept(pose, reason):
    world = World.load("lab02")
    pf = ParticleFilter(world, max_particles=500)
    particles, events = pf.particles.copy(), list(pf.events)
    with pytest.raises(ValueError, match=reason):
        pf.initialize_pose(pose)
    assert np.array_equal(pf.particles, particles) and pf.events == events
    with pytest.raises(ValueError, match="sigma"):
        pf.initialize_pose((0.6, -0.6, 0.0), (0.1, math.nan, 0.1))
    if math.isfinite(pose[0]):
        with pytest.raises(ValueError, match=reason):  # the parameter: configure fails
            ParticleFilter(world, initial_pose=list(pose))
