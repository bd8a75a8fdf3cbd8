"""The run plots' words: every title within the picture and clear of the others, legends read.

A navigation run on a saved SLAM map (DIR/map.yaml, its map named 'map') with a pose as its
start: the longest titles run_sim.py --plot writes.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from amr_common.world.map_file import world_as_map, write_map
from amr_common.world.world import World
from amr_evaluation.localization_plot import plot_localization
from amr_evaluation.plot import plot_episode

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
import sim_report  # noqa: E402

TITLE = ("lab02_box on map lab02/map.yaml / -1,-0.6,1.57 / turtlebot3_lds02 -> goal (-1, 1): "
         "reached 9.5 s, final error 1.5 cm")


@pytest.fixture
def drawn(monkeypatch) -> list[Figure]:
    """The figures the plots save, drawn (their text has its place on the canvas)."""
    figures: list[Figure] = []
    save = Figure.savefig

    def keep(figure, *args, **kwargs):
        save(figure, *args, **kwargs)
        figures.append(figure)
    monkeypatch.setattr(Figure, "savefig", keep)
    return figures


@pytest.fixture
def saved_map(tmp_path) -> World:
    """lab02 saved as a SLAM run saves it: DIR/map.yaml, named 'map'."""
    raster, _ = world_as_map(World.load("lab02"), 0.02)
    yaml_path, _ = write_map(raster, tmp_path / "lab02" / "map", extras={"name": "map"})
    return World.load(str(yaml_path))


def _titles_fit(figure: Figure) -> None:
    renderer = figure.canvas.get_renderer()
    page = figure.bbox
    titles = [ax.title for ax in figure.axes if ax.get_title()]
    if figure.get_suptitle():
        titles.append(figure._suptitle)
    boxes = [title.get_window_extent(renderer) for title in titles]
    for title, box in zip(titles, boxes):
        assert page.x0 <= box.x0 and box.x1 <= page.x1 and box.y1 <= page.y1, \
            f"clipped: {title.get_text()!r}"
    for i, box in enumerate(boxes):
        for other in boxes[i + 1:]:
            assert not box.overlaps(other), "two titles overlap"


def _legend_texts(figure: Figure) -> list[str]:
    return [text.get_text() for ax in figure.axes if ax.get_legend()
            for text in ax.get_legend().get_texts()]


def test_a_navigation_plot_on_a_saved_map_keeps_its_titles_whole_and_names_the_map(
        tmp_path, drawn, saved_map):
    world = World.load("lab02")
    t = np.linspace(0.0, 10.0, 51)
    truth = np.column_stack([t, np.full_like(t, -1.0), np.linspace(-0.6, 1.0, t.size),
                             np.full_like(t, 1.57)])
    estimate = np.column_stack([truth, (t > 5.0).astype(float)])
    report = {"trajectory": truth.tolist(), "estimate": estimate.tolist(),
              "particles_snapshot": [[-1.0, 0.4, 1.57]], "path": [[-1.0, 0.4], [-1.0, 1.0]],
              "goal": [-1.0, 1.0],
              "localization": {"time_to_localized_s": 5.0, "false_localizations": 0,
                               "tracking_error_mean_m": 0.011, "tracking_error_max_m": 0.014}}
    plot_localization(world, report, tmp_path / "nav.png", title=TITLE, map_world=saved_map)
    [figure] = drawn
    legend = _legend_texts(figure)
    assert "map lab02/map.yaml (occupied cells)" in legend
    assert not any("map map" in text for text in legend)
    _titles_fit(figure)


def test_a_long_episode_title_is_wrapped_within_the_picture(tmp_path, drawn):
    trajectory = [[0.0, 1.0, -1.0, 1.57], [1.0, 1.0, -0.8, 1.57]]
    plot_episode("lab02", trajectory, path=tmp_path / "run.png", title=TITLE)
    _titles_fit(drawn[0])


def test_the_run_line_names_a_saved_map_by_its_folder():
    report = {"world": "lab02", "world_source": "lab02", "map": "map",
              "map_source": "/home/me/maps/lab02/map.yaml"}
    assert sim_report.world_label(report) == "lab02 on map lab02/map.yaml"
    named = {**report, "map": "lab02_slam", "map_source": "/home/me/lab02_slam.yaml"}
    assert sim_report.world_label(named) == "lab02 on map lab02_slam"
