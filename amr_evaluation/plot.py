"""Pictures for lab reports: worlds, episode trajectories and sheets of many episodes (PNG).

Uses matplotlib's object API with the Agg canvas, never pyplot, so it works headless and does not
touch the backend of a notebook or GUI that imports it.
"""
from __future__ import annotations

import math
import textwrap
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from amr_common.geometry import polyline_length
from amr_common.robot import ROBOT_RADIUS
from amr_common.world.map_vs_world import unmapped_walls
from amr_common.world.movers import walked_time
from amr_common.world.world import World, map_label

_WALL_COLOUR = "#222222"
_MAP_COLOUR = "#66c2a5"  # the map's walls when it is not the world (teal: not an estimate colour)
_MOVER_COLOUR = "#9933cc"  # the world's movers (as their /world_markers)
_UNMAPPED_COLOUR = "#ff8c00"  # the world's walls the map lacks (as their /world_markers)
MOVER_SNAPSHOTS = 4  # a run's movers are drawn where they were at this many times


def draw_world(ax, world: World, show_starts: bool = True, show_grid: bool = False,
               show_goals: bool | None = None, map_world: World | None = None,
               mover_times: Sequence[float] = (0.0,), mover_waits: Sequence | None = None
               ) -> None:
    """Walls and optionally named starts, named goals and the corridor grid on an Axes.

    A map world also shows its cells (free white, unknown light grey, occupied dark grey).
    With `map_world` (the map the filter and the planner used, when it is not the world), the
    map's cells (or its walls, teal) lie under the world's true walls, so their differences
    show, and the world's walls the map lacks are orange; the world's own cells are then not
    drawn. The world's movers: their paths and where
    they were at `mover_times` (draw_movers).

    Goals are shown with the starts unless show_goals says otherwise.
    """
    segs = world.segments.reshape(-1, 2, 2)
    own_map = map_world is not None and map_world is not world
    if own_map:
        _draw_map(ax, map_world)
    elif world.raster is not None:  # a map: its cells as map viewers show them, edges thin
        _draw_cells(ax, world)
    ax.add_collection(LineCollection(segs, colors=_WALL_COLOUR, capstyle="round", zorder=3,
                                     linewidths=2.0 if world.raster is None else 0.8,
                                     label="world (true walls)" if own_map else None))
    for hole in world.holes:
        ax.fill(hole[:, 0], hole[:, 1], color="#bbbbbb", zorder=2)
    if own_map:  # what the map lacks, as /world_markers shows it
        lacked = unmapped_walls(world, map_world)
        if len(lacked):
            ax.add_collection(LineCollection(lacked.reshape(-1, 2, 2), colors=_UNMAPPED_COLOUR,
                                             linewidths=2.5, zorder=3.1,
                                             label="walls the map lacks"))
    draw_movers(ax, world, mover_times, mover_waits)
    xmin, ymin, xmax, ymax = world.bounds
    if own_map:  # the map's walls may lie beyond the world's
        mxmin, mymin, mxmax, mymax = map_world.bounds
        xmin, ymin, xmax, ymax = min(xmin, mxmin), min(ymin, mymin), max(xmax, mxmax), \
            max(ymax, mymax)
    pad = 0.1
    ax.set_xlim(xmin - pad, xmax + pad)
    ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if show_grid:
        cs = world.cell_size
        ax.set_xticks(np.arange(math.floor(xmin / cs), math.ceil(xmax / cs) + 1) * cs, minor=True)
        ax.set_yticks(np.arange(math.floor(ymin / cs), math.ceil(ymax / cs) + 1) * cs, minor=True)
        ax.grid(which="minor", color="#dddddd", linewidth=0.5)
    if show_starts:
        for name, (x, y, th) in world.starts.items():
            _draw_robot(ax, x, y, th, colour="tab:green")
            ax.annotate(name, (x, y), xytext=(6, 6), textcoords="offset points", fontsize=8,
                        color="darkgreen", zorder=6)
    if show_starts if show_goals is None else show_goals:
        for name, (x, y) in world.goals.items():
            _draw_goal(ax, x, y)
            ax.annotate(name, (x, y), xytext=(6, -10), textcoords="offset points", fontsize=8,
                        color="darkred", zorder=6)
        if world.goal is not None and world.goal not in world.goals.values():
            _draw_goal(ax, *world.goal)


def draw_movers(ax, world: World, times: Sequence[float] = (0.0,),
                waits: Sequence | None = None) -> None:
    """Each mover's path (dotted) and its disc where it was at each of `times` (s).

    `waits`: per mover the intervals [t_from, t_to] it waited for the robot (the simulator's
    mover_waits; a run's report keeps them), so the discs are where it really was; without
    them, where it would have been had it never waited. Later times are drawn darker.
    """
    times = sorted(float(t) for t in times)
    for i, mover in enumerate(world.movers):
        path = mover.path_segments()
        ax.add_collection(LineCollection(path.reshape(-1, 2, 2), colors=_MOVER_COLOUR,
                                         linestyles=":", linewidths=1.2, zorder=2.5,
                                         label="movers (path, where at t)" if i == 0 else None))
        mover_waits = waits[i] if waits is not None and i < len(waits) else None
        labels: list[tuple[float, float, list[str]]] = []  # one per place (a mover may return)
        for k, t in enumerate(times):
            x, y = mover.position_at(walked_time(t, mover_waits))
            disc = _circle(x, y, mover.radius)
            alpha = 0.15 + 0.45 * (k + 1) / len(times)
            ax.fill(disc[:, 0], disc[:, 1], color=_MOVER_COLOUR, alpha=alpha, zorder=2.6,
                    linewidth=0)
            near = [label for label in labels if math.dist(label[:2], (x, y)) < 0.5 * mover.radius]
            if near:
                near[0][2].append(f"{t:.0f}")
            else:
                labels.append((x, y, [f"{t:.0f}"]))
        if len(times) > 1:
            for x, y, texts in labels:
                ax.annotate(", ".join(texts) + " s", (x, y), ha="center", va="center",
                            fontsize=6, color="black", zorder=2.7)


def snapshot_times(trajectory: np.ndarray, count: int = MOVER_SNAPSHOTS) -> list[float]:
    """`count` times spread over a run's trajectory [[t, ...], ...] (its first and last)."""
    if len(trajectory) == 0:
        return [0.0]
    return list(np.linspace(float(trajectory[0, 0]), float(trajectory[-1, 0]), count))


def draw_raster(ax, raster, zorder: float = 1) -> None:
    """A raster's cells as map viewers show them: free white, unknown light, occupied dark."""
    rows, cols = raster.values.shape
    shade = np.where(raster.values == 0, 1.0, np.where(raster.values == -1, 0.8, 0.35))
    x0, y0 = raster.origin
    ax.imshow(shade, cmap="gray", vmin=0.0, vmax=1.0, origin="lower", zorder=zorder,
              interpolation="nearest", extent=(x0, x0 + cols * raster.resolution,
                                               y0, y0 + rows * raster.resolution))


def _draw_cells(ax, world: World, zorder: float = 1) -> None:
    """A map world's cells: free white, unknown light grey, occupied dark grey."""
    draw_raster(ax, world.raster, zorder)


def _draw_map(ax, map_world: World) -> None:
    """The map of the filter and the planner, under the world: its cells, else its walls."""
    if map_world.raster is not None:
        _draw_cells(ax, map_world, zorder=0.5)
        ax.fill([], [], color="0.35", label=f"map {_map_name(map_world)} (occupied cells)")
        return
    for hole in map_world.holes:
        ax.fill(hole[:, 0], hole[:, 1], color=_MAP_COLOUR, alpha=0.25, zorder=0.5)
    ax.add_collection(LineCollection(map_world.segments.reshape(-1, 2, 2), colors=_MAP_COLOUR,
                                     linewidths=4.0, alpha=0.6, zorder=0.6,
                                     label=f"map {_map_name(map_world)} (walls)"))


def _map_name(map_world: World) -> str:
    return map_label(map_world.name, map_world.source)


def fitted_title(text: str, width_in: float, fontsize: float) -> str:
    """`text` broken between words into lines that fit `width_in` inches at `fontsize` points.

    A title wider than its axes is clipped at the figure's edge or runs into its neighbour's.
    """
    chars = max(20, int(width_in * 72.0 / (0.6 * fontsize)))  # 0.6 em: a wide average glyph
    return "\n".join(textwrap.fill(line, chars, break_on_hyphens=False) or line
                     for line in text.split("\n"))


def draw_navigation(ax, planned_path: Any = None, goal: Sequence[float] | None = None) -> None:
    """The planned path (dashed) and the goal (a star) on an Axes, where given."""
    if planned_path is not None and len(planned_path):
        plan = np.asarray(planned_path, dtype=np.float64).reshape(-1, 2)
        ax.plot(plan[:, 0], plan[:, 1], linestyle="--", color="tab:red", linewidth=1.2,
                zorder=5, label="planned path")
    if goal is not None:
        _draw_goal(ax, goal[0], goal[1], label="goal")


def _draw_goal(ax, x: float, y: float, label: str | None = None) -> None:
    ax.plot(x, y, marker="*", markersize=14, color="tab:red", markeredgecolor="k", zorder=6,
            linestyle="none", label=label)


def _draw_robot(ax, x: float, y: float, th: float, colour: str, label: str | None = None) -> None:
    circle = _circle(x, y, ROBOT_RADIUS)
    ax.fill(circle[:, 0], circle[:, 1], color=colour, alpha=0.35, zorder=4, label=label)
    ax.plot(circle[:, 0], circle[:, 1], color=colour, linewidth=1.0, zorder=4)
    ax.plot([x, x + ROBOT_RADIUS * math.cos(th)], [y, y + ROBOT_RADIUS * math.sin(th)],
            color=colour, linewidth=1.5, zorder=5)


def _circle(x: float, y: float, r: float, n: int = 32) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * math.pi, n + 1)
    return np.column_stack([x + r * np.cos(a), y + r * np.sin(a)])


def plot_world(world: World | str, path: str | Path) -> Path:
    """Draw a world (walls, obstacles, named starts, goal, corridor grid) to a PNG."""
    world = world if isinstance(world, World) else World.load(world)
    fig = Figure(figsize=(7, 6), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    draw_world(ax, world, show_starts=True, show_grid=True)
    ax.set_title(f"{world.name}: {len(world.segments)} walls, cell {world.cell_size:g} m\n"
                 f"{world.description}", fontsize=9, wrap=True)
    return _save(fig, path)


def _episode_parts(trajectory: Any, collision_points: Iterable) -> tuple[np.ndarray, list, Any]:
    """(trajectory array (K, 4), collision points, result or None).

    From a list or an EpisodeResult.
    """
    result = None
    if hasattr(trajectory, "trajectory"):  # an EpisodeResult
        result = trajectory
        collision_points = collision_points or result.collision_points
        trajectory = result.trajectory
    elif isinstance(trajectory, dict) and "trajectory" in trajectory:
        from .episode import EpisodeResult

        result = EpisodeResult.from_dict(trajectory)
        collision_points = collision_points or result.collision_points
        trajectory = result.trajectory
    traj = np.asarray(trajectory, dtype=np.float64).reshape(-1, 4)
    return traj, [tuple(p) for p in collision_points], result


def draw_episode(ax, world: World, trajectory: Any, collision_points: Iterable = (),
                 colourbar: bool = True, small: bool = False, planned_path: Any = None,
                 goal: Sequence[float] | None = None,
                 map_world: World | None = None,
                 mover_waits: Sequence | None = None) -> dict[str, float]:
    """Walls, the trajectory coloured by time, start/end markers and collisions on an Axes.

    With navigation also the planned path (dashed) and the goal (a star); with `map_world`
    the map under the world's walls (draw_world); the movers where they were at a few times of
    the run (`mover_waits`, else the result's: draw_movers). Returns the figures shown
    (collisions, min clearance, distance).
    """
    traj, points, result = _episode_parts(trajectory, collision_points)
    if mover_waits is None and result is not None:
        mover_waits = getattr(result, "mover_waits", None)
    draw_world(ax, world, show_starts=False, map_world=map_world,
               mover_times=snapshot_times(traj), mover_waits=mover_waits)
    figures = _figures(world, traj, points, result)
    draw_navigation(ax, planned_path, goal)
    if len(traj) >= 2:
        xy = traj[:, 1:3]
        lines = LineCollection(np.stack([xy[:-1], xy[1:]], axis=1), cmap="viridis",
                               linewidths=1.2 if small else 1.8, zorder=4)
        lines.set_array(traj[1:, 0])
        ax.add_collection(lines)
        if colourbar:
            cbar = ax.figure.colorbar(lines, ax=ax, fraction=0.046, pad=0.04)
            cbar.set_label("time [s]")
    if len(traj):
        _draw_robot(ax, traj[0, 1], traj[0, 2], traj[0, 3], colour="tab:green", label="start")
        _draw_robot(ax, traj[-1, 1], traj[-1, 2], traj[-1, 3], colour="tab:blue", label="end")
    if points:
        pts = np.asarray(points, dtype=np.float64)
        ax.scatter(pts[:, 0], pts[:, 1], marker="x", s=30 if small else 70, linewidths=2,
                   color="red", zorder=7, label=f"collision ({len(pts)})")
    if not small:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=3, fontsize=8,
                  frameon=False)
    return figures


def _figures(world: World, traj: np.ndarray, points: list, result) -> dict[str, float]:
    if result is not None:
        return {"collisions": result.collisions, "min_clearance": result.min_clearance_m,
                "distance": result.distance_m, "time": result.sim_time_s}
    if len(traj) == 0:
        return {"collisions": len(points), "min_clearance": math.nan, "distance": 0.0, "time": 0.0}
    clearance = float(world.clearances(traj[:, 1:3]).min() - ROBOT_RADIUS)
    distance = polyline_length(traj[:, 1:3])
    return {"collisions": len(points), "min_clearance": clearance, "distance": distance,
            "time": float(traj[-1, 0])}


def _title(world: World, result, figures: dict[str, float], title: str | None) -> str:
    if title is None:
        head = world.name
        if result is not None:
            start = result.start if isinstance(result.start, str) else \
                "(" + ", ".join(f"{c:.2f}" for c in result.start) + ")"
            head = f"{world.name} / start {start} / profile {result.profile}"
        title = head
    return (f"{title}\ncollisions {figures['collisions']}, min clearance "
            f"{figures['min_clearance']:.3f} m, distance {figures['distance']:.2f} m in "
            f"{figures['time']:.0f} s")


def plot_episode(world: World | str, trajectory: Any, collision_points: Iterable = (),
                 path: str | Path = "x.png", title: str | None = None,
                 planned_path: Any = None, goal: Sequence[float] | None = None,
                 map_world: World | None = None, mover_waits: Sequence | None = None) -> Path:
    """Draw one episode to a PNG: walls, trajectory coloured by time, start, end, collisions.

    For navigation also the planned path and the goal; with `map_world` (the map of the filter
    and the planner) its cells or walls under the world's true walls; the world's movers
    (`mover_waits`: a report's, see draw_movers).
    `trajectory` is [[t, x, y, theta], ...] or an EpisodeResult (or its to_dict()), whose start,
    profile and figures then go into the title.
    """
    world = world if isinstance(world, World) else World.load(world)
    fig = Figure(figsize=(8, 6.5), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    traj, points, result = _episode_parts(trajectory, collision_points)
    figures = draw_episode(ax, world, traj, points, planned_path=planned_path, goal=goal,
                           map_world=map_world, mover_waits=mover_waits)
    ax.set_title(fitted_title(_title(world, result, figures, title), 6.0, 10), fontsize=10)
    return _save(fig, path)


def plot_episodes_sheet(results: Sequence[Any], path: str | Path, columns: int | None = None,
                        title: str | None = None) -> Path:
    """A grid of episodes (EpisodeResults or their dicts, NavigationResults), one subplot each."""
    from .episode import EpisodeResult

    items = [r if hasattr(r, "trajectory") else EpisodeResult.from_dict(r) for r in results]
    n = max(1, len(items))
    columns = columns or min(4, math.ceil(math.sqrt(n)))
    rows = math.ceil(n / columns)
    fig = Figure(figsize=(3.6 * columns, 3.3 * rows + 0.6), dpi=110)
    FigureCanvasAgg(fig)
    worlds: dict[str, World] = {}
    for i, res in enumerate(items):
        ax = fig.add_subplot(rows, columns, i + 1)
        if res.world not in worlds:  # one load per world, not per episode
            worlds[res.world] = World.load(res.world)
        world = worlds[res.world]
        figures = draw_episode(ax, world, res, colourbar=False, small=True,
                               planned_path=getattr(res, "path", None),
                               goal=getattr(res, "goal", None))
        start = (res.start if isinstance(res.start, str)
                 else "(" + ", ".join(f"{c:.1f}" for c in res.start) + ")")
        ax.set_title(f"{res.world}/{start}/{res.profile} s{res.seed}\n"
                     f"coll {figures['collisions']}, clr {figures['min_clearance']:.3f} m, "
                     f"{figures['distance']:.1f} m", fontsize=7)
        ax.tick_params(labelsize=6)
        ax.set_xlabel("x [m]", fontsize=6)
        ax.set_ylabel("y [m]", fontsize=6)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return _save(fig, path, tight=False)


def _save(fig: Figure, path: str | Path, tight: bool = True) -> Path:
    path = Path(path)
    if not path.suffix:  # what matplotlib would write: return the real file name
        path = path.with_name(path.name + ".png")
    path.parent.mkdir(parents=True, exist_ok=True)
    if tight:
        fig.tight_layout()
    fig.savefig(path)
    return path
