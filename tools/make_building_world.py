#!/usr/bin/env python3
"""Write a generated office-floor world (rooms off corridors) as a world YAML file.

The particle filter's big-map test and benchmark use its output, tests/worlds/building_40m.yaml
(`tools/make_building_world.py 40 --seed 18 > tests/worlds/building_40m.yaml`): a square floor
with three east-west corridors and one north-south corridor (1.6 m wide), rows of rooms of
random widths off the corridors, each with a door (0.9 m) at a random place and 0-2 boxes
(furniture) at random places, so that rooms look different to a 3.5 m LiDAR. Walls lie on a
0.2 m grid; deterministic for a given size and seed.
"""
from __future__ import annotations

import argparse
import random

CORRIDOR = 1.6
DOOR = 0.8
GRID = 0.2


def _snap(value: float) -> float:
    return round(round(value / GRID) * GRID, 3)


def _widths(rng: random.Random, length: float) -> list[float]:
    """Room widths filling `length` (m), each 3.2-4.8 m (the last one at least 2.4 m)."""
    widths: list[float] = []
    left = length
    while left > 0:
        width = rng.choice([3.2, 3.6, 4.0, 4.4, 4.8])
        if left - width < 2.4:
            width = left
        widths.append(_snap(width))
        left = _snap(left - width)
    return widths


def _boxes(rng: random.Random, x0: float, y0: float, x1: float, y1: float,
           door: tuple[float, float]) -> list[list[list[float]]]:
    """0-2 boxes inside the room (x0, y0)-(x1, y1), clear of its walls, its door and each other."""
    boxes: list[tuple[float, float, float, float]] = []
    for _ in range(rng.choice([0, 1, 1, 2, 2])):
        for _attempt in range(30):
            w, h = _snap(rng.uniform(0.4, 1.2)), _snap(rng.uniform(0.4, 1.2))
            bx = _snap(rng.uniform(x0 + 0.8, x1 - 0.8 - w))
            by = _snap(rng.uniform(y0 + 0.8, y1 - 0.8 - h))
            box = (bx, by, bx + w, by + h)
            dx, dy = door
            near_door = bx - 1.2 < dx + DOOR and bx + w + 1.2 > dx and \
                max(by - dy, dy - (by + h)) < 1.8
            apart = all(box[0] > b[2] + 0.8 or box[2] < b[0] - 0.8 or box[1] > b[3] + 0.8
                        or box[3] < b[1] - 0.8 for b in boxes)
            if w > 0 and h > 0 and box[2] < x1 - 0.6 and box[3] < y1 - 0.6 and not near_door \
                    and apart:
                boxes.append(box)
                break
    return [[[b[0], b[1]], [b[2], b[1]], [b[2], b[3]], [b[0], b[3]]] for b in boxes]


def building(size: float, seed: int) -> dict:
    """The world as a dict of world-file keys (see amr_common/world/world_file.py)."""
    rng = random.Random(seed)
    size = _snap(size)
    middle = _snap(size / 2 - CORRIDOR / 2)
    rows = [_snap(size * f - CORRIDOR / 2) for f in (0.25, 0.5, 0.75)]  # corridor south sides
    walls: list[list[list[float]]] = []
    holes: list[list[list[float]]] = []
    # Bands of rooms between the corridors: (y0, y1, doors on the north side?, on the south?)
    edges = [0.0] + [v for r in rows for v in (r, _snap(r + CORRIDOR))] + [size]
    bands = [(edges[2 * i], edges[2 * i + 1]) for i in range(len(edges) // 2)]
    for index, (y0, y1) in enumerate(bands):
        split = index not in (0, len(bands) - 1)
        halves = [(y0, _snap((y0 + y1) / 2), False), (_snap((y0 + y1) / 2), y1, True)] \
            if split else [(y0, y1, index == 0)]
        for ry0, ry1, door_north in halves:
            for x_start, x_end in ((0.0, middle), (_snap(middle + CORRIDOR), size)):
                x = x_start
                for width in _widths(rng, _snap(x_end - x_start)):
                    x1 = _snap(x + width)
                    door_x = _snap(rng.uniform(x + 0.4, x1 - 0.4 - DOOR))
                    wall_y = ry1 if door_north else ry0
                    if wall_y not in (0.0, size):
                        for a, b in ((x, door_x), (_snap(door_x + DOOR), x1)):
                            if b > a:
                                walls.append([[a, wall_y], [b, wall_y]])
                    if x1 != x_end:
                        walls.append([[x1, ry0], [x1, ry1]])
                    holes += _boxes(rng, x, ry0, x1, ry1, (door_x, wall_y))
                    x = x1
            if split and not door_north:
                walls.append([[0.0, ry1], [middle, ry1]])
                walls.append([[_snap(middle + CORRIDOR), ry1], [size, ry1]])
    # The north-south corridor's walls, open onto the east-west corridors.
    for x in (middle, _snap(middle + CORRIDOR)):
        for y0, y1 in bands:
            walls.append([[x, y0], [x, y1]])
    corridor_y = _snap(rows[1] + CORRIDOR / 2)
    return {
        "name": f"building_{size:g}m",
        "description": f"Generated office floor, {size:g} x {size:g} m "
                       f"(tools/make_building_world.py {size:g} --seed {seed})",
        "cell_size": 0.4,
        "boundary": [[0.0, 0.0], [size, 0.0], [size, size], [0.0, size]],
        "walls": walls,
        "holes": holes,
        "starts": {"corridor_west": [2.0, corridor_y, 0.0],
                   "corridor_crossing": [_snap(size / 2), corridor_y, 1.5708],
                   "corridor_north": [_snap(size - 2.0), _snap(rows[2] + CORRIDOR / 2), 3.1416]},
    }


def to_yaml(world: dict) -> str:
    """The world dict as YAML (flow-style points, one polyline per line)."""
    def points(polyline):
        return "[" + ", ".join(f"[{x:g}, {y:g}]" for x, y in polyline) + "]"
    lines = [f"# {world['description']}", f"name: {world['name']}",
             f"description: {world['description']}", f"cell_size: {world['cell_size']}",
             f"boundary: {points(world['boundary'])}", "walls:"]
    lines += [f"  - {points(w)}" for w in world["walls"]]
    lines += ["holes:"] + [f"  - {points(h)}" for h in world["holes"]]
    lines += ["starts:"] + [f"  {name}: [{x:g}, {y:g}, {t:g}]"
                            for name, (x, y, t) in world["starts"].items()]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("size", type=float, help="side of the square floor (m)")
    parser.add_argument("--seed", type=int, default=18)
    args = parser.parse_args(argv)
    print(to_yaml(building(args.size, args.seed)), end="")


if __name__ == "__main__":
    main()
