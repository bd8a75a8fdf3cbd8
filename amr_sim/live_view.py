"""A live pygame window on a running simulation: maze, robot, LiDAR rays, trail and timing.

`LiveView.update(sim, scan)` is meant to be called after every simulation step. It redraws at most
`max_fps` times per second of wall clock and returns at once in between (it only extends the
trail), so the simulation keeps running at nearly full speed. pygame is imported when a view is
created, never at module import: headless code and machines without a display can import this.
Headless use (tests, CI, screenshots): set SDL_VIDEODRIVER=dummy.
"""
from __future__ import annotations

import math
import os
import time
from collections import deque
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from amr_common.robot import ROBOT_RADIUS
from amr_common.sensors.scan_returns import return_mask

DEFAULT_MAX_WINDOW_PX = (1000, 800)
MARGIN_M = 0.25
TEXT_BAR_PX = 30
MAX_RAYS_DRAWN = 90

BACKGROUND = (250, 250, 250)
WALL = (30, 30, 30)
ROBOT = (40, 110, 220)
HEADING = (255, 255, 255)
RAY = (255, 170, 170)
HIT = (220, 30, 30)
TRAIL = (60, 170, 90)
COLLISION = (230, 120, 0)
TEXT = (20, 20, 20)
TEXT_BAR = (225, 225, 230)


class LiveView:
    """A window drawing `world` and, on each update, the simulator's robot and scan."""

    def __init__(self, world: Any, scale_px_per_m: float | None = None, title: str = "amr_sim",
                 max_fps: float = 30.0, max_window_px: tuple[int, int] = DEFAULT_MAX_WINDOW_PX,
                 trail_points: int = 50_000) -> None:
        segments = np.asarray(world.segments, dtype=float).reshape(-1, 4)
        if segments.size == 0 or not np.all(np.isfinite(segments)):
            raise ValueError(f"world {getattr(world, 'name', '?')!r} has no finite wall "
                             f"segments to draw")
        if not (math.isfinite(max_fps) and max_fps > 0):
            raise ValueError(f"max_fps must be a positive number, got {max_fps!r}")
        xmin, ymin, xmax, ymax = (float(v) for v in world.bounds)
        # The world point at the map's top-left pixel.
        self._origin = (xmin - MARGIN_M, ymax + MARGIN_M)
        width_m = xmax - xmin + 2 * MARGIN_M
        height_m = ymax - ymin + 2 * MARGIN_M
        if scale_px_per_m is None:
            scale_px_per_m = min(max_window_px[0] / width_m,
                                 (max_window_px[1] - TEXT_BAR_PX) / height_m)
        if not (math.isfinite(scale_px_per_m) and 1.0 <= scale_px_per_m <= 2000.0):
            raise ValueError(f"scale must be 1-2000 px/m, got {scale_px_per_m!r}")
        self.scale = float(scale_px_per_m)
        self.size = (max(int(math.ceil(width_m * self.scale)), 320),
                     int(math.ceil(height_m * self.scale)) + TEXT_BAR_PX)

        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        import pygame  # lazy: only a view needs a display
        self._pg = pygame
        pygame.display.init()
        try:
            self.screen = pygame.display.set_mode(self.size)
        except pygame.error as exc:
            pygame.display.quit()
            raise RuntimeError(f"cannot open a window ({exc}); on a machine without a display "
                               "set SDL_VIDEODRIVER=dummy or run without --gui") from exc
        pygame.display.set_caption(title)
        self._font = self._load_font()
        # Surfaces in the display's pixel format blit several times faster.
        self._background = self._draw_background(segments).convert()
        self._hit_dot = pygame.Surface((5, 5), pygame.SRCALPHA)
        pygame.draw.circle(self._hit_dot, HIT, (2, 2), 2)
        self._hit_dot = self._hit_dot.convert_alpha()
        self._min_interval = 1.0 / max_fps
        self._last_draw = -math.inf
        self._wall_start: float | None = None
        self._sim_start = 0.0
        self._trail: deque[tuple[int, int]] = deque(maxlen=trail_points)
        self._last_sim = None
        self._last_scan = None
        self.frames = 0
        self.closed = False

    # --- geometry ----------------------------------------------------------------------------
    def to_pixels(self, x: float, y: float) -> tuple[int, int]:
        """Window pixel (column, row) of world point (x, y) in metres."""
        return (int(round((x - self._origin[0]) * self.scale)),
                int(round((self._origin[1] - y) * self.scale)) + TEXT_BAR_PX)

    # --- public API ----------------------------------------------------------------------------
    def update(self, sim: Any, scan: Sequence[float] | np.ndarray | None = None) -> bool:
        """Record the robot's position and redraw if the frame interval has passed.

        `scan` is the latest range array (ray 0 at the profile's angle_min, CCW by its
        angle_increment); None keeps the last one drawn. Returns False once the user closed the
        window (or after close()); the caller should then stop.
        """
        if self.closed:
            return False
        now = time.monotonic()
        if self._wall_start is None:
            self._wall_start, self._sim_start = now, float(sim.time)
        x, y, _ = sim.pose
        if math.isfinite(x) and math.isfinite(y):
            point = self.to_pixels(x, y)
            if not self._trail or point != self._trail[-1]:
                self._trail.append(point)
        if scan is not None:
            self._last_scan = scan
        self._last_sim = sim
        if now - self._last_draw < self._min_interval:
            return True
        self._last_draw = now
        if not self._handle_events():
            return False
        self._draw(sim, now)
        return True

    def save_screenshot(self, path: str | os.PathLike) -> Path:
        """Redraw the latest state and save the window as an image (PNG by extension)."""
        if self.closed:
            raise RuntimeError("the live view is closed")
        if self._last_sim is not None:
            self._draw(self._last_sim, time.monotonic())
        path = Path(path)
        self._pg.image.save(self.screen, str(path))
        return path

    def close(self) -> None:
        """Close the window. Idempotent."""
        if self.closed:
            return
        self.closed = True
        self._pg.display.quit()

    def __enter__(self) -> "LiveView":
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()

    # --- drawing -----------------------------------------------------------------------------
    def _load_font(self):
        try:
            self._pg.font.init()
            return self._pg.font.Font(None, 22)
        except Exception:  # a pygame build without fonts: draw without text rather than fail
            return None

    def _draw_background(self, segments: np.ndarray):
        surface = self._pg.Surface(self.size)
        surface.fill(BACKGROUND)
        self._pg.draw.rect(surface, TEXT_BAR, (0, 0, self.size[0], TEXT_BAR_PX))
        width = max(2, int(round(0.02 * self.scale)))  # walls drawn ~2 cm thick, at least 2 px
        for x1, y1, x2, y2 in segments:
            self._pg.draw.line(surface, WALL, self.to_pixels(x1, y1), self.to_pixels(x2, y2),
                               width)
        return surface

    def _handle_events(self) -> bool:
        pg = self._pg
        for event in pg.event.get():
            if event.type == pg.QUIT or (event.type == pg.KEYDOWN
                                         and event.key in (pg.K_ESCAPE, pg.K_q)):
                self.close()
                return False
        return True

    def _draw(self, sim: Any, now: float) -> None:
        pg = self._pg
        screen = self.screen
        screen.blit(self._background, (0, 0))
        if len(self._trail) >= 2:
            pg.draw.lines(screen, TRAIL, False, list(self._trail), 2)
        x, y, theta = (float(v) for v in sim.pose)
        if all(math.isfinite(v) for v in (x, y, theta)):
            if self._last_scan is not None:
                self._draw_scan(sim, x, y, theta)
            centre = self.to_pixels(x, y)
            radius = max(3, int(round(ROBOT_RADIUS * self.scale)))
            pg.draw.circle(screen, ROBOT, centre, radius)
            tip = self.to_pixels(x + ROBOT_RADIUS * math.cos(theta),
                                 y + ROBOT_RADIUS * math.sin(theta))
            pg.draw.line(screen, HEADING, centre, tip, max(2, radius // 4))
        for cx, cy in list(getattr(sim, "collision_points", []) or [])[-200:]:
            px, py = self.to_pixels(cx, cy)
            pg.draw.line(screen, COLLISION, (px - 5, py - 5), (px + 5, py + 5), 2)
            pg.draw.line(screen, COLLISION, (px - 5, py + 5), (px + 5, py - 5), 2)
        self._draw_text(sim, now)
        pg.display.flip()
        self.frames += 1

    def _draw_scan(self, sim: Any, x: float, y: float, theta: float) -> None:
        ranges = np.asarray(self._last_scan, dtype=float).ravel()
        profile = getattr(sim, "profile", None)
        angle_min = float(getattr(profile, "angle_min", 0.0))
        increment = float(getattr(profile, "angle_increment", 2 * math.pi / max(len(ranges), 1)))
        range_min = float(getattr(profile, "range_min", 0.0))
        range_max = float(getattr(profile, "range_max", math.inf))
        index = np.nonzero(return_mask(ranges, range_min, range_max))[0]
        if index.size == 0:
            return
        angles = theta + angle_min + increment * index
        x, y = getattr(sim, "lidar_position", (x, y))   # rays start at the LiDAR
        hx = x + ranges[index] * np.cos(angles)
        hy = y + ranges[index] * np.sin(angles)
        origin = self.to_pixels(x, y)
        ox, oy = self._origin
        cols = np.rint((hx - ox) * self.scale).astype(int)
        rows = np.rint((oy - hy) * self.scale).astype(int) + TEXT_BAR_PX
        # Rays cost ~7 us each to draw: draw at most MAX_RAYS_DRAWN of them (every hit point is
        # drawn), as one polyline origin -> hit -> origin -> hit ...
        stride = max(1, math.ceil(index.size / MAX_RAYS_DRAWN))
        zigzag = np.empty((2 * len(cols[::stride]), 2), dtype=int)
        zigzag[0::2] = origin
        zigzag[1::2, 0], zigzag[1::2, 1] = cols[::stride], rows[::stride]
        self._pg.draw.lines(self.screen, RAY, False, zigzag.tolist(), 1)
        self.screen.blits([(self._hit_dot, (c - 2, r - 2))
                           for c, r in zip(cols.tolist(), rows.tolist())], doreturn=False)

    def _draw_text(self, sim: Any, now: float) -> None:
        if self._font is None:
            return
        elapsed = now - (self._wall_start if self._wall_start is not None else now)
        sim_elapsed = float(sim.time) - self._sim_start
        factor = f"{sim_elapsed / elapsed:.1f}x" if elapsed > 0.2 else "-"
        clearance = getattr(sim, "min_clearance", None)
        finite = isinstance(clearance, (int, float)) and math.isfinite(clearance)
        # + 0.0: no "-0.0"
        clearance_text = (f"   min clearance {round(clearance * 100, 1) + 0.0:.1f} cm"
                          if finite else "")
        text = (f"t = {float(sim.time):7.1f} s   real-time factor {factor}   "
                f"collisions {int(getattr(sim, 'collisions', 0))}{clearance_text}")
        self.screen.blit(self._font.render(text, True, TEXT), (8, 7))
