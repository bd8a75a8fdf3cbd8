"""The picture of a mapping run: the map SLAM built under the true walls, both trajectories.

Takes a run_sim.py --slam report (`trajectory` [t, x, y, theta] of the truth, `estimate`
[t, x, y, theta] of the SLAM pose, `slam` figures) and the map (a Raster) in the world's frame.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from amr_common.map_raster import Raster
from amr_common.world import World
from amr_evaluation.plot import draw_raster


def plot_mapping(world: World, report: dict[str, Any], raster: Raster | None,
                 path: str | Path, title: str | None = None) -> Path:
    """The built map (cells), the true walls over it (red), the true and SLAM trajectories."""
    truth = np.asarray(report["trajectory"], dtype=np.float64).reshape(-1, 4)
    estimate = np.asarray(report.get("estimate") or [], dtype=np.float64).reshape(-1, 4)
    fig = Figure(figsize=(7.5, 7.0), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    if raster is not None:
        draw_raster(ax, raster)
    ax.add_collection(LineCollection(world.segments.reshape(-1, 2, 2), colors="tab:red",
                                     linewidths=0.7, alpha=0.8, zorder=3,
                                     label="true walls"))
    ax.plot(truth[:, 1], truth[:, 2], color="0.45", linewidth=1.8, label="truth", zorder=4)
    if len(estimate):
        ax.plot(estimate[:, 1], estimate[:, 2], color="tab:blue", linewidth=0.9,
                label="SLAM pose", zorder=5)
    ax.plot(truth[0, 1], truth[0, 2], "o", color="tab:green", markersize=7, zorder=6,
            label="start")
    xmin, ymin, xmax, ymax = world.bounds
    ax.set_xlim(xmin - 0.2, xmax + 0.2)
    ax.set_ylim(ymin - 0.2, ymax + 0.2)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    figures = report.get("slam") or {}
    lines = [title or world.name]
    if figures.get("trajectory_rmse_m") is not None:
        lines.append(f"SLAM pose error RMSE {100 * figures['trajectory_rmse_m']:.2f} cm, max "
                     f"{100 * figures['trajectory_max_m']:.2f} cm; map precision "
                     f"{100 * figures['precision']:.1f} %, recall {100 * figures['recall']:.1f} "
                     f"%; {figures['loop_closures']} loop closures")
    ax.set_title("\n".join(lines), fontsize=9)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=4, fontsize=8,
              frameon=False)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def plot_map_trajectory(raster: Raster | None, trajectory: np.ndarray, path: str | Path,
                        odometry: np.ndarray | None = None, title: str = "") -> Path:
    """A map with the path that built it and, beside it, the odometry's own path.

    No truth needed (a recording, a benchmark log): trajectory and odometry rows
    [..., x, y, theta] (the last three columns are used), map frame and odometry frame.
    """
    trajectory = np.asarray(trajectory, dtype=np.float64)
    panels = 1 if odometry is None or len(odometry) == 0 else 2
    fig = Figure(figsize=(7.5 * panels, 7.5), dpi=150)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, panels, 1)
    if raster is not None:
        draw_raster(ax, raster)
    if len(trajectory):
        ax.plot(trajectory[:, -3], trajectory[:, -2], color="tab:blue", linewidth=0.5,
                alpha=0.8, label="SLAM path", zorder=3)
        ax.plot(trajectory[0, -3], trajectory[0, -2], "o", color="tab:green", markersize=6,
                zorder=4, label="start")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper right", fontsize=8)
    if panels == 2:
        odometry = np.asarray(odometry, dtype=np.float64)
        side = fig.add_subplot(1, 2, 2)
        side.plot(odometry[:, -3], odometry[:, -2], color="tab:orange", linewidth=0.5)
        side.plot(odometry[0, -3], odometry[0, -2], "o", color="tab:green", markersize=6)
        side.set_aspect("equal")
        side.set_xlabel("x [m]")
        side.set_title("odometry path (odometry frame)", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


__all__ = ["plot_map_trajectory", "plot_mapping"]
