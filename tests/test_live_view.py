"""LiveView draws the maze, robot, scan and trail where they are, headless (SDL dummy driver)."""
from __future__ import annotations

import math
import subprocess
import sys
import time
from types import SimpleNamespace

import numpy as np
import pytest

from amr_sim import live_view
from amr_sim.live_view import LiveView

# A 2 m x 2 m box with an inner wall from (1.0, 0.0) to (1.0, 1.2).
SEGMENTS = np.array([[0, 0, 2, 0], [2, 0, 2, 2], [2, 2, 0, 2], [0, 2, 0, 0], [1.0, 0.0, 1.0, 1.2]],
                    dtype=float)


def _world():
    return SimpleNamespace(name="box", segments=SEGMENTS, bounds=(0.0, 0.0, 2.0, 2.0))


def _sim(x=0.5, y=1.0, theta=0.0, t=0.0, rays=360, no_return=0.0):
    profile = SimpleNamespace(angle_min=0.0, angle_increment=2 * math.pi / rays,
                              range_min=0.12, range_max=3.5, no_return=no_return)
    return SimpleNamespace(pose=(x, y, theta), time=t, collisions=0, collision_points=[],
                           min_clearance=0.3, profile=profile)


@pytest.fixture
def headless(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")


def _colour(view, x, y):
    return tuple(view.screen.get_at(view.to_pixels(x, y)))[:3]


def test_import_does_not_load_pygame():
    code = "import sys, amr_sim.live_view; print('pygame' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={"PATH": "/usr/bin:/bin"}, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_walls_robot_and_heading_are_drawn_where_they_are(headless):
    with LiveView(_world(), scale_px_per_m=200) as view:
        sim = _sim(x=0.5, y=1.0, theta=math.pi / 2)  # facing +y (up on screen)
        assert view.update(sim) is True
        assert view.frames == 1
        assert _colour(view, 2.0, 1.0) == live_view.WALL        # outer wall
        assert _colour(view, 1.0, 0.6) == live_view.WALL        # inner wall
        assert _colour(view, 1.5, 1.6) == live_view.BACKGROUND  # free space
        assert _colour(view, 1.0, 1.5) == live_view.BACKGROUND  # beyond the inner wall's end
        assert _colour(view, 0.5, 1.0) in (live_view.ROBOT, live_view.HEADING)
        assert _colour(view, 0.5, 1.07) == live_view.HEADING     # heading line points up
        assert _colour(view, 0.5, 0.93) == live_view.ROBOT       # the back of the robot
        assert _colour(view, 0.57, 1.0) == live_view.ROBOT
        assert _colour(view, 0.5, 1.13) == live_view.BACKGROUND  # outside the 0.105 m footprint
        # y up in the world is up on the screen
        assert view.to_pixels(0.5, 1.5)[1] < view.to_pixels(0.5, 1.0)[1]


def test_scan_rays_and_hits_skip_invalid_returns(headless):
    rays = 360
    ranges = np.full(rays, 0.6)
    ranges[80:101] = np.nan     # around +90 deg: no hit drawn
    ranges[170:191] = 0.0       # LDS-01 no return
    ranges[260:281] = 5.0       # beyond range_max
    with LiveView(_world(), scale_px_per_m=200) as view:
        sim = _sim(x=1.5, y=1.0, theta=0.0, rays=rays)
        view.update(sim, scan=ranges)
        assert _colour(view, 1.5 + 0.6, 1.0) == live_view.HIT    # ray 0 ends ahead at 0.6 m
        assert _colour(view, 1.5 + 0.35, 1.0) == live_view.RAY   # the ray itself
        assert _colour(view, 1.5, 1.0 + 0.6) == live_view.BACKGROUND    # NaN ray skipped
        assert _colour(view, 1.5, 1.0 + 0.35) == live_view.BACKGROUND
        assert _colour(view, 1.5 - 0.35, 1.0) == live_view.BACKGROUND   # 0.0 ray skipped
        assert _colour(view, 1.5, 1.0 - 0.35) == live_view.BACKGROUND   # out of range skipped
        diagonal = math.radians(45)
        assert _colour(view, 1.5 + 0.6 * math.cos(diagonal),
                       1.0 + 0.6 * math.sin(diagonal)) == live_view.HIT


def test_trail_follows_the_robot(headless):
    with LiveView(_world(), scale_px_per_m=200, max_fps=1e6) as view:
        for k in range(40):
            view.update(_sim(x=0.2 + 0.015 * k, y=0.4, t=0.05 * k))
        assert _colour(view, 0.3, 0.4) == live_view.TRAIL         # behind the robot (at x=0.785)
        assert _colour(view, 0.3, 0.5) == live_view.BACKGROUND


def test_redraws_are_throttled_by_wall_clock(headless):
    with LiveView(_world(), scale_px_per_m=100, max_fps=30) as view:
        start = time.monotonic()
        for k in range(3000):
            assert view.update(_sim(t=0.05 * k))
        elapsed = time.monotonic() - start
        assert 1 <= view.frames <= elapsed * 30 + 2


def test_closing_the_window_stops_updates(headless):
    view = LiveView(_world(), scale_px_per_m=100, max_fps=1e6)
    assert view.update(_sim())
    import pygame
    pygame.event.post(pygame.event.Event(pygame.QUIT))
    assert view.update(_sim(t=0.1)) is False
    assert view.closed and view.update(_sim(t=0.2)) is False
    view.close()  # idempotent


def test_screenshot_is_saved(headless, tmp_path):
    import pygame
    with LiveView(_world(), scale_px_per_m=150) as view:
        view.update(_sim(), scan=np.full(360, 0.5))
        path = view.save_screenshot(tmp_path / "view.png")
        image = pygame.image.load(str(path))
        assert image.get_size() == view.size
        assert tuple(image.get_at(view.to_pixels(0.5, 0.93)))[:3] == live_view.ROBOT


def test_bad_input_is_rejected_clearly(headless):
    bad = SimpleNamespace(name="bad", segments=np.array([[0, 0, np.nan, 1]]), bounds=(0, 0, 1, 1))
    with pytest.raises(ValueError, match="no finite wall segments"):
        LiveView(bad)
    with pytest.raises(ValueError, match="max_fps"):
        LiveView(_world(), max_fps=0)
    with pytest.raises(ValueError, match="scale"):
        LiveView(_world(), scale_px_per_m=float("inf"))
    with LiveView(_world(), scale_px_per_m=100) as view:  # a NaN pose draws nothing, no crash
        assert view.update(_sim(x=float("nan")), scan=np.full(360, np.nan))


def test_draws_a_real_simulation(headless, tmp_path):
    from amr_sim.simulator import Simulator
    sim = Simulator("lab02", start="outer", profile="turtlebot3", seed=1)
    with LiveView(sim.world, title="lab02", max_fps=1e6) as view:
        scan, _, _ = sim.measure()
        for _ in range(20):
            assert view.update(sim, scan)
            scan, _, _ = sim.step(0.1, 0.0)
        assert view.update(sim, scan)
        x, y, theta = sim.pose
        back = (x - 0.07 * math.cos(theta), y - 0.07 * math.sin(theta))
        assert _colour(view, *back) == live_view.ROBOT
        valid = np.flatnonzero((scan >= sim.profile.range_min) & (scan <= sim.profile.range_max))
        assert valid.size > 0
        lx, ly = sim.lidar_position     # 32 mm behind the centre on the Burger
        hits = [(lx + scan[i] * math.cos(theta + i * sim.profile.angle_increment),
                 ly + scan[i] * math.sin(theta + i * sim.profile.angle_increment)) for i in valid]
        drawn = sum(_colour(view, hx, hy) == live_view.HIT for hx, hy in hits)
        assert drawn >= 0.9 * len(hits)  # a few hits are covered by later rays
        view.save_screenshot(tmp_path / "lab02.png")
