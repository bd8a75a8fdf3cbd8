"""Pictures of a localization run: the estimate beside the truth, and its error over time.

Takes a run_sim.py --localize report (or a LocalizationResult's to_dict()): `trajectory`
[t, x, y, theta] of the truth, `estimate` [t, x, y, theta, localized] and `particles_snapshot`
[x, y, theta] (the particles when the filter first declared a pose).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from amr_common.world.world import World
from amr_evaluation.localization_episode import FALSE_POSITION_M, pose_errors
from amr_evaluation.plot import draw_navigation, draw_world, fitted_title, snapshot_times


def plot_localization(world: World | str, report: dict[str, Any], path: str | Path,
                      title: str | None = None, map_world: World | None = None) -> Path:
    """Map (truth, estimate while localized / searching, particles) and errors over time.

    `map_world`: the filter's map when it is not the world, drawn under the world's walls.
    """
    world = world if isinstance(world, World) else World.load(world)
    truth = np.asarray(report["trajectory"], dtype=np.float64).reshape(-1, 4)
    estimate = np.asarray(report["estimate"], dtype=np.float64).reshape(-1, 5)
    particles = np.asarray(report.get("particles_snapshot") or [], dtype=np.float64)
    fig = Figure(figsize=(12, 5.6), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 2, 1)
    draw_world(ax, world, show_starts=False, map_world=map_world,
               mover_times=snapshot_times(truth), mover_waits=report.get("mover_waits"))
    ax.plot(truth[:, 1], truth[:, 2], color="0.55", linewidth=2.2, label="truth", zorder=4)
    draw_navigation(ax, report.get("path"), report.get("goal"))  # navigation runs have them
    localized = estimate[:, 4] > 0.5
    searching = np.where(localized, np.nan, estimate[:, 1])
    ax.plot(searching, estimate[:, 2], ".", color="tab:orange", markersize=2, alpha=0.5,
            label="estimate, not localized", zorder=5)
    ax.plot(np.where(localized, estimate[:, 1], np.nan), estimate[:, 2], color="tab:blue",
            linewidth=1.2, label="estimate, localized", zorder=6)
    if len(particles):
        ax.quiver(particles[:, 0], particles[:, 1], np.cos(particles[:, 2]),
                  np.sin(particles[:, 2]), color="tab:red", alpha=0.5, scale=40, width=0.002,
                  zorder=7, label="particles when first localized")
    first = np.flatnonzero(localized)
    if first.size:
        x, y = estimate[first[0], 1:3]
        ax.plot(x, y, marker="*", markersize=14, color="gold", markeredgecolor="k", zorder=8,
                label=f"first localized, {estimate[first[0], 0]:.1f} s")
    ax.plot(truth[0, 1], truth[0, 2], "o", color="tab:green", markersize=8, zorder=8,
            label="start")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8,
              frameon=False)
    # The run's title spans both panels (beside each other, one panel's long title would be
    # clipped at the figure's edge and run into the other's).
    fig.suptitle(fitted_title(title or world.name, 11.5, 10), fontsize=10)
    ax.set_title("truth and estimate" + (" on the filter's map" if map_world is not None
                                         and map_world is not world else ""), fontsize=9)
    _plot_errors(fig.add_subplot(1, 2, 2), truth, estimate, localized,
                 report.get("localization") or {})
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def _plot_errors(err: Any, truth: np.ndarray, estimate: np.ndarray, localized: np.ndarray,
                 metrics: dict[str, Any]) -> None:
    """Position and heading errors over time (log scale), the localized spans, the figures."""
    index = np.clip(np.searchsorted(truth[:, 0], estimate[:, 0] - 1e-6), 0, len(truth) - 1)
    position, heading = pose_errors(truth[index], estimate)
    err.semilogy(estimate[:, 0], np.maximum(position, 1e-4) * 100, color="tab:blue",
                 linewidth=1, label="position error [cm]")
    err.semilogy(estimate[:, 0], np.maximum(np.degrees(heading), 1e-3), color="tab:purple",
                 linewidth=0.8, alpha=0.7, label="heading error [deg]")
    err.axhline(FALSE_POSITION_M * 100, color="tab:red", linestyle="--", linewidth=0.8,
                label="10 cm / 10 deg: a localized pose this wrong is a false localization")
    for start, end in _spans(estimate[:, 0], localized):
        err.axvspan(start, end, color="tab:green", alpha=0.12, linewidth=0)
    summary = []
    if metrics.get("time_to_localized_s") is not None:
        summary.append(f"localized after {metrics['time_to_localized_s']:.1f} s")
    summary.append(f"false localizations {metrics.get('false_localizations', 0)}")
    if metrics.get("tracking_error_mean_m") is not None:
        summary.append(f"error mean {100 * metrics['tracking_error_mean_m']:.1f} cm, "
                       f"max {100 * metrics['tracking_error_max_m']:.1f} cm")
    err.set_title("estimate errors (green: localized)\n" + ", ".join(summary), fontsize=9)
    err.set_xlabel("time [s]")
    err.set_ylim(1e-2, 1e3)
    err.grid(True, which="both", alpha=0.3)
    err.legend(loc="upper right", fontsize=7)


def _spans(t: np.ndarray, flags: np.ndarray) -> list[tuple[float, float]]:
    spans, begin = [], None
    for time, flag in zip(t, flags):
        if flag and begin is None:
            begin = time
        elif not flag and begin is not None:
            spans.append((begin, time))
            begin = None
    if begin is not None:
        spans.append((begin, float(t[-1]) if len(t) else begin))
    return spans


__all__ = ["plot_localization"]
