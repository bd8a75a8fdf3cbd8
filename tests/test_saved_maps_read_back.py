"""A map the project writes always reads back; --start overrides a map's own start.

`run_sim.py --slam --slam-param resolution_m:=1.0` wrote a map that --world refused ("start
'slam_start' ... not in a free cell"), and --start did not help: the map's named start was
checked when the file was read. A coarse map's cells cannot always take the robot where it
started (at 0.1 m cells, lab02's start touches a wall): the writer names the start only where
the map read back can take it, a map's named start is checked when it is used, and a map with
no free cell (1 m cells on 0.4 m corridors) is not written over an earlier save.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from amr_common.world.map_raster import Raster
from amr_common.world.world import World, WorldError
from amr_mapping.slam_map_files import write_slam_map

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
sys.path.insert(0, str(SCRIPTS))
import run_sim  # noqa: E402


def _room(free_from: int = 2) -> Raster:
    """A 1 x 1 m room of 0.1 m cells: walls around, free inside from row/column `free_from`."""
    values = np.full((10, 10), 100, dtype=np.int8)
    values[free_from:10 - free_from, free_from:10 - free_from] = 0
    return Raster(values, 0.1, (0.0, 0.0))


def test_the_start_is_named_only_where_the_map_read_back_can_take_it(tmp_path):
    yaml_path, no_start = write_slam_map(_room(), {}, tmp_path / "fits", "pgm",
                                         (0.5, 0.5, 0.0), 10)
    assert no_start is None and World.load(yaml_path).starts == {"slam_start": (0.5, 0.5, 0.0)}
    yaml_path, no_start = write_slam_map(_room(), {}, tmp_path / "near", "pgm",
                                         (0.25, 0.5, 0.0), 10)
    assert no_start == ("the start (0.25, 0.5) touches a wall: clearance 0.050 m < robot "
                        "radius 0.105 m")
    world = World.load(yaml_path)  # reads back, naming no start
    assert world.starts == {} and world.resolve_start((0.5, 0.5, 0.0)) == (0.5, 0.5, 0.0)


def test_a_map_without_a_free_cell_is_not_written_over_an_earlier_save(tmp_path):
    write_slam_map(_room(), {}, tmp_path / "map", "pgm", (0.5, 0.5, 0.0), 10)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    with pytest.raises(ValueError, match="the map has no free cell at 0.1 m cells"):
        write_slam_map(_room(free_from=5), {}, tmp_path / "map", "pgm", (0.5, 0.5, 0.0), 10)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


@pytest.mark.slow
def test_a_coarse_slam_map_reads_back_and_start_overrides_a_maps_own_start(tmp_path, capsys):
    maps = tmp_path / "maps"
    assert run_sim.main(["--slam", "--slam-param", "resolution_m:=0.1", "--duration", "20",
                         "--map-out", str(maps)]) == 0
    world = World.load(maps / "map.yaml")  # was: "start 'slam_start' (1, -1) touches a wall"
    assert world.starts == {}  # lab02's start does not fit on its 0.1 m cells
    xs, ys = world.raster.centres()
    x, y = next((x, y) for x, y in zip(xs[world.raster.free], ys[world.raster.free])
                if world.pose_problem(x, y) is None)
    # A map written before names its start anyway (as this project's writer did): refused
    # when used, in one line; --start overrides it.
    old = tmp_path / "old.yaml"
    old.write_text((maps / "map.yaml").read_text().replace("image: map.pgm", f"image: "
                   f"{maps / 'map.pgm'}") + "starts:\n  slam_start: [1.0, -1.0, 1.5708]\n")
    capsys.readouterr()
    assert run_sim.main(["--world", str(old), "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "start 'slam_start' (1, -1) touches a wall" \
        in err and "give a start pose (x, y, theta)" in err, err
    report = tmp_path / "run.json"
    assert run_sim.main(["--world", str(old), "--start", f"{x:.3f},{y:.3f},0", "--duration",
                         "0.5", "--report", str(report)]) == 0
    assert json.loads(report.read_text())["trajectory"][0][1:3] == pytest.approx(
        [round(x, 3), round(y, 3)])
    with pytest.raises(WorldError, match="touches a wall"):
        World.load(old).resolve_start("slam_start")
