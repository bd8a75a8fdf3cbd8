"""Simulator API: determinism, bad commands, command limits, episodes, metrics and pictures."""
from __future__ import annotations

import json
import logging
import math

import numpy as np
import pytest

from amr_common.geometry import wrap_angle
from amr_common.world.world import World
from amr_evaluation.episode import EpisodeResult, explored_fraction, run_episode
from amr_evaluation.plot import plot_episode, plot_episodes_sheet, plot_world
from amr_sim.simulator import Simulator


def run(profile, seed, steps=120):
    sim = Simulator("lab02", start="outer", profile=profile, seed=seed)
    scans, poses = [], []
    for k in range(steps):
        z_scan, z_v, z_w = sim.step(0.15, 0.6 * math.sin(0.05 * k))
        scans.append(z_scan.copy())
        poses.append(sim.pose + (z_v, z_w))
    return np.array(scans), np.array(poses), sim


def test_same_seed_same_run_different_seed_different_noise():
    scans_a, poses_a, _ = run("turtlebot3_clean", seed=11)
    scans_b, poses_b, _ = run("turtlebot3_clean", seed=11)
    scans_c, poses_c, _ = run("turtlebot3_clean", seed=12)
    np.testing.assert_array_equal(scans_a, scans_b)
    np.testing.assert_array_equal(poses_a, poses_b)
    assert not np.array_equal(scans_a, scans_c)
    np.testing.assert_array_equal(poses_a, poses_c)  # the noise is in the sensor, not the motion


def test_nan_and_inf_commands_do_not_move_and_output_no_nan(caplog):
    sim = Simulator("lab02", start="outer", profile="ideal")
    before = sim.pose
    with caplog.at_level(logging.WARNING, logger="amr_sim.simulator"):
        for bad in [(math.nan, 0.0), (0.0, math.inf), (-math.inf, math.nan), ("fast", None)] * 25:
            z_scan, z_v, z_w = sim.step(*bad)
            assert math.isfinite(z_v) and math.isfinite(z_w)
    assert sim.pose == pytest.approx(before, abs=1e-12)
    assert np.isfinite(z_scan).all()
    assert all(math.isfinite(c) for c in sim.pose + sim.odometry_pose)
    assert sim.bad_commands == 100
    warnings = [r for r in caplog.records if "non-finite command" in r.getMessage()]
    assert len(warnings) == 1, "warnings are rate-limited"
    sim.step(math.nan, 0.5)  # a half-broken command also stops the robot
    assert sim.executed_command == (0.0, 0.0)


@pytest.mark.parametrize("profile", ["ideal", "turtlebot3"])
def test_huge_commands_are_saturated(profile):
    sim = Simulator("lab02", start="outer", profile=profile)
    for v, w in [(1e300, 0.0), (-1e300, 1e300), (0.0, -1e308)]:
        sim.step(v, w)
        ev, ew = sim.executed_command
        assert abs(ev) <= 0.22 + 1e-12 and abs(ew) <= 2.84 + 1e-12
        assert math.isfinite(ev) and math.isfinite(ew)


def test_turtlebot3_commands_are_truncated_to_0_01():
    sim = Simulator("lab02", start="outer", profile="turtlebot3_clean")  # no latency nor lag
    sim.step(0.157, -0.339)
    assert sim.executed_command == pytest.approx((0.15, -0.33))
    sim.step(-0.009, 0.3)  # int(0.3 * 100) = 30 with the robot's arithmetic
    assert sim.executed_command == pytest.approx((0.0, 0.3))
    ideal = Simulator("lab02", start="outer", profile="ideal")
    ideal.step(0.157, -0.339)
    assert ideal.executed_command == pytest.approx((0.157, -0.339))


def test_properties_and_first_measurement():
    sim = Simulator("lab02", start="inner", dt=0.1)
    z_scan, z_v, z_w = sim.measure()
    assert z_scan.shape == (240,) and z_v == 0.0 and z_w == 0.0
    assert sim.time == 0.0 and sim.steps == 0 and sim.dt == 0.1
    assert sim.pose == pytest.approx((0.6, -0.6, -math.pi / 2))  # 3*pi/2 wrapped to (-pi, pi]
    assert sim.min_clearance == pytest.approx(0.2 - 0.105)
    for _ in range(3):
        sim.step(0.0, 0.0)
    assert sim.time == pytest.approx(0.3) and sim.steps == 3 and sim.collisions == 0
    assert wrap_angle(math.pi) == math.pi and wrap_angle(-math.pi) == math.pi
    with pytest.raises(ValueError, match="dt"):
        Simulator("lab02", dt=0.0)


class CircleDriver:
    """Drives a circle; reports a fake wall error to exercise the RMS metric."""

    def __init__(self, dt):
        self.dt = dt
        self.geometry = None
        self.wall_distance_error = None
        self.calls = 0

    def set_scan_geometry(self, angle_min, angle_increment, range_min, range_max):
        self.geometry = (angle_min, angle_increment, range_min, range_max)

    def compute_commands(self, z_scan, z_v, z_w):
        self.calls += 1
        self.wall_distance_error = 0.02 if self.calls % 2 else None
        return 0.2, 0.2  # radius 1 m


@pytest.fixture(scope="module")
def open_room(tmp_path_factory):
    path = tmp_path_factory.mktemp("worlds") / "open_room.yaml"
    path.write_text("cell_size: 0.4\nboundary: [[-2, -2], [2, -2], [2, 2], [-2, 2]]\n"
                    "starts: {east: [1.0, 0.0, pi/2]}\n")
    return World.load(path)


def test_episode_counts_laps_and_metrics(open_room, tmp_path):
    ctrl = CircleDriver(0.05)
    result = run_episode(open_room, "east", profile="turtlebot3_clean", duration=70.0,
                         controller=ctrl)
    assert ctrl.geometry == pytest.approx((0.0, math.radians(1), 0.12, 3.5))
    assert result.steps == 1400 and result.sim_time_s == pytest.approx(70.0)
    assert result.laps == 2  # 70 s at 0.2 rad/s = 2.2 turns around the room centre
    assert result.collisions == 0 and result.first_collision_time_s is None
    assert result.distance_m == pytest.approx(0.2 * 70.0, rel=1e-3)
    assert result.min_clearance_m == pytest.approx(1.0 - 0.105, abs=1e-6)
    assert result.rms_wall_error_m == pytest.approx(0.02)
    assert len(result.trajectory) == 1401 and result.trajectory[0][0] == 0.0
    assert 0.1 < result.explored_fraction < 0.5  # a 1 m circle in a 4 m x 4 m room
    text = json.dumps(result.to_dict())
    assert EpisodeResult.from_dict(json.loads(text)).laps == 2
    # Pictures: one episode, a sheet and the world.
    for png in (plot_episode(open_room, result, path=tmp_path / "ep.png"),
                plot_episode(open_room, result.trajectory, path=tmp_path / "raw.png", title="raw"),
                plot_world(open_room, tmp_path / "world.png")):
        assert png.stat().st_size > 10_000


def test_episode_records_collisions_and_sheet(tmp_path):
    class Rammer:
        def compute_commands(self, z_scan, z_v, z_w):
            return 0.22, 0.0

    result = run_episode("lab02", "outer", duration=12.0, controller_factory=lambda dt: Rammer(),
                         record_trajectory=False)
    assert result.collisions == 1
    assert result.collision_points[0] == pytest.approx([1.0, 1.2], abs=1e-3)
    # A wall's end: the point is where it touched in the world (the tip), not robot-relative.
    tip = run_episode("lab02", (0.25, -0.02, math.pi), duration=3.0,
                      controller_factory=lambda dt: Rammer(), record_trajectory=False)
    assert tip.collision_points[0] == pytest.approx([0.0, 0.0], abs=1e-3)   # the first contact
    assert result.first_collision_time_s == pytest.approx((2.2 - 0.105) / 0.22, abs=0.06)
    assert result.trajectory == [] and result.rms_wall_error_m is None and result.laps == 0
    assert result.world == "lab02" and result.start == "outer"
    sheet = plot_episodes_sheet([result.to_dict(), run_episode("lab02", "inner", duration=1.0,
                                 controller=Rammer())], tmp_path / "sheet.png")
    assert sheet.stat().st_size > 10_000


def test_explored_fraction_counts_cells_whose_centre_was_passed():
    world = World.load("lab02")
    ring_east = np.column_stack([np.full(50, 1.0), np.linspace(-1.0, 1.0, 50)])
    assert explored_fraction(world, ring_east) == pytest.approx(6 / 36)
    assert explored_fraction(world, np.array([[1.0, -1.0]])) == pytest.approx(1 / 36)
    assert explored_fraction(world, np.array([[1.19, -1.19]])) == 0.0


def test_episode_with_default_wall_follower():
    result = run_episode("lab02", "outer", duration=20.0)
    assert result.steps == 400 and "WallFollower" in result.controller
    assert result.distance_m > 0.5
