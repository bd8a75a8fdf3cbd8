"""Pictures of mapping runs: the map SLAM built under the true walls, both trajectories.

plot_mapping takes a run_sim.py --slam report (`trajectory` [t, x, y, theta] of the truth,
`estimate` [t, x, y, theta] of the SLAM pose, `slam` figures) and the map (a Raster) in the
world's frame; plot_mapping_sheet draws many mapping episodes (evaluate.py --slam) side by side.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from amr_common.world.map_raster import Raster
from amr_common.world.world import World
from amr_evaluation.plot import draw_raster


def draw_mapping(ax, world: World, truth: Any, estimate: Any, raster: Raster | None,
                 small: bool = False) -> None:
    """The built map (cells), the true walls over it (red), the true and SLAM trajectories."""
    truth = np.asarray(truth, dtype=np.float64).reshape(-1, 4)
    estimate = np.asarray(estimate if estimate is not None else [],
                          dtype=np.float64).reshape(-1, 4)
    if raster is not None:
        draw_raster(ax, raster)
    ax.add_collection(LineCollection(world.segments.reshape(-1, 2, 2), colors="tab:red",
                                     linewidths=0.5 if small else 0.7, alpha=0.8, zorder=3,
                                     label="true walls"))
    if len(truth):
        ax.plot(truth[:, 1], truth[:, 2], color="0.45", linewidth=1.2 if small else 1.8,
                label="truth", zorder=4)
    if len(estimate):
        ax.plot(estimate[:, 1], estimate[:, 2], color="tab:blue", linewidth=0.6 if small else 0.9,
                label="SLAM pose", zorder=5)
    if len(truth):
        ax.plot(truth[0, 1], truth[0, 2], "o", color="tab:green", markersize=4 if small else 7,
                zorder=6, label="start")
    xmin, ymin, xmax, ymax = world.bounds
    ax.set_xlim(xmin - 0.2, xmax + 0.2)
    ax.set_ylim(ymin - 0.2, ymax + 0.2)
    ax.set_aspect("equal")


def figures_line(figures: dict[str, Any], short: bool = False) -> str:
    """The SLAM figures in words ('' without them); `short` for a sheet's panels."""
    if figures.get("trajectory_rmse_m") is None:
        return ""
    closures = figures.get("loop_closures")
    closures = "n/a" if closures is None else closures
    if short:
        return (f"RMSE {100 * figures['trajectory_rmse_m']:.2f} cm, prec "
                f"{100 * figures['precision']:.1f} %, rec {100 * figures['recall']:.1f} %, "
                f"{closures} closures")
    return (f"SLAM pose error RMSE {100 * figures['trajectory_rmse_m']:.2f} cm, max "
            f"{100 * figures['trajectory_max_m']:.2f} cm; map precision "
            f"{100 * figures['precision']:.1f} %, recall {100 * figures['recall']:.1f} %; "
            f"{closures} loop closures")


def plot_mapping(world: World, report: dict[str, Any], raster: Raster | None,
                 path: str | Path, title: str | None = None) -> Path:
    """One run: draw_mapping with the run's figures in the title, the legend below."""
    fig = Figure(figsize=(7.5, 7.0), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    draw_mapping(ax, world, report["trajectory"], report.get("estimate"), raster)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    lines = [title or world.name, figures_line(report.get("slam") or {})]
    ax.set_title("\n".join(line for line in lines if line), fontsize=9)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=4, fontsize=8,
              frameon=False)
    fig.tight_layout()
    return _save(fig, path)


def plot_mapping_sheet(episodes: Sequence[tuple[World, dict[str, Any]]], path: str | Path,
                       title: str | None = None) -> Path:
    """Many mapping episodes, one panel each.

    `episodes`: (world, result dict with trajectory, estimate, raster and the figures, as
    mapping_evaluation's rows carry them).
    """
    n = max(1, len(episodes))
    columns = min(4, math.ceil(math.sqrt(n)))
    rows = math.ceil(n / columns)
    fig = Figure(figsize=(3.6 * columns, 3.4 * rows + 0.6), dpi=110)
    FigureCanvasAgg(fig)
    for index, (world, result) in enumerate(episodes):
        ax = fig.add_subplot(rows, columns, index + 1)
        draw_mapping(ax, world, result.get("trajectory") or [], result.get("estimate"),
                     result.get("raster"), small=True)
        start = result["start"] if isinstance(result["start"], str) else \
            "(" + ", ".join(f"{c:.1f}" for c in result["start"]) + ")"
        ax.set_title(f"{result['world']}/{start}/{result['profile']} s{result['seed']}\n"
                     f"{figures_line(result, short=True)}", fontsize=7)
        ax.tick_params(labelsize=6)
        ax.set_xlabel("x [m]", fontsize=6)
        ax.set_ylabel("y [m]", fontsize=6)
    key = "cells: the map built (dark occupied, grey unknown); red: the true walls; grey line: " \
        "the true path, blue: the SLAM pose"
    fig.suptitle(f"{title}\n{key}" if title else key, fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def _save(fig: Figure, path: str | Path) -> Path:
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


__all__ = ["draw_mapping", "figures_line", "plot_map_trajectory", "plot_mapping",
           "plot_mapping_sheet"]
