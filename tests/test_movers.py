"""Movers: round obstacles of a world file that walk on their own.

The world file's `movers:` key and its refusals, the mover's motion (back and forth, round,
start_s), its waiting for the robot, the LiDAR seeing it (compiled kernels against their twins),
contacts counted as the robot's collisions with movers, a map that never has them, and the
plot and /world_markers that show them.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from amr_common.robot import ROBOT_RADIUS
from amr_common.world.map_vs_world import load_map, unmapped_walls
from amr_common.world.movers import collisions_text, walked_time
from amr_common.world.occupancy_grid import OccupancyGrid
from amr_common.world.raycast import (
    cast_circles_kernel,
    cast_circles_numpy,
    cast_circles_python,
    scan_circles_kernel,
    scan_circles_numpy,
    scan_circles_python,
)
from amr_common.world.world import World, WorldError
from amr_sim.contact import ALLOWED_PENETRATION
from amr_sim.moving_obstacles import KEEP_OFF
from amr_sim.simulator import Simulator

WORLDS = Path(__file__).resolve().parent.parent / "evaluations" / "worlds"
ROOM = {"boundary": [[0, 0], [6, 0], [6, 3], [0, 3]],
        "starts": {"west": [0.5, 1.5, 0.0], "east": [5.5, 1.5, math.pi]}}


def write_world(tmp_path, movers, name="room.yaml", **extra) -> str:
    path = tmp_path / name
    path.write_text(yaml.safe_dump({**ROOM, **extra, "movers": movers}))
    return str(path)


# --- the world file -----------------------------------------------------------------------

def test_movers_load_with_their_defaults_and_stay_off_the_walls(tmp_path):
    world = World.load(write_world(tmp_path, [
        {"radius": 0.2, "path": [[2, 0.5], [2, 2.5]], "speed": 0.4},
        {"radius": 0.15, "path": [[3, 1], [4, 1], [4, 2]], "speed": 0.3, "loop": True,
         "start_s": 2, "name": "cart"}]))
    first, cart = world.movers
    assert (first.name, first.radius, first.speed, first.loop, first.start_s) == \
        ("movers[0]", 0.2, 0.4, False, 0.0)
    assert (cart.name, cart.loop, cart.start_s) == ("cart", True, 2.0)
    assert first.length == pytest.approx(2.0)
    assert cart.length == pytest.approx(2.0 + math.sqrt(2.0))  # round: back to the first
    # Movers are no walls: the segments, the free space and the grid are the room's.
    room = World.load(write_world(tmp_path, [], name="empty.yaml"))
    np.testing.assert_array_equal(world.segments, room.segments)
    assert world.contains(2.0, 1.5) and world.clearance(2.0, 1.5) == room.clearance(2.0, 1.5)
    np.testing.assert_array_equal(OccupancyGrid.from_world(world, 0.05).raster().values,
                                  OccupancyGrid.from_world(room, 0.05).raster().values)


@pytest.mark.parametrize("mover, reason", [
    ({"radius": 0, "path": [[2, 1]], "speed": 0.3}, r"movers\[0\]: radius must be in \(0, 1\]"),
    ({"radius": -0.2, "path": [[2, 1]], "speed": 0.3}, r"movers\[0\]: radius must be in"),
    ({"radius": 5, "path": [[2, 1]], "speed": 0.3}, r"movers\[0\]: radius must be in"),
    ({"radius": "big", "path": [[2, 1]], "speed": 0.3}, r"movers\[0\] radius must be a number"),
    ({"radius": float("nan"), "path": [[2, 1]], "speed": 0.3}, r"movers\[0\] radius is not "
                                                                r"finite"),
    ({"radius": 0.2, "path": [], "speed": 0.3}, r"movers\[0\]: path must be a list of at least"),
    ({"radius": 0.2, "path": [[2]], "speed": 0.3}, r"movers\[0\] path\[0\] must be \[x, y\]"),
    ({"radius": 0.2, "path": [[2, float("inf")]], "speed": 0.3},
     r"movers\[0\] path\[0\] y is not finite"),
    ({"radius": 0.2, "path": [[2, 1]], "speed": -0.1}, r"movers\[0\]: speed must be in \[0, 2\]"),
    ({"radius": 0.2, "path": [[2, 1]], "speed": 50}, r"movers\[0\]: speed must be in"),
    ({"radius": 0.2, "path": [[2, 1]], "speed": 0.3, "loop": "yes"},
     r"movers\[0\]: loop must be true or false"),
    ({"radius": 0.2, "path": [[2, 1]], "speed": 0.3, "start_s": -1},
     r"movers\[0\]: start_s must be >= 0"),
    ({"radius": 0.2, "path": [[2, 1]], "speed": 0.3, "sped": 1},
     r"movers\[0\]: unknown key\(s\) \['sped'\]"),
    ({"radius": 0.2, "path": [[2, 1]]}, r"movers\[0\]: missing key 'speed'"),
    ([0.2, [[2, 1]], 0.3], r"movers\[0\] must be a mapping"),
    ({"radius": 0.2, "path": [[2, 1], [7, 1]], "speed": 0.3, "name": "walker"},
     r"movers\[0\] \(walker\): path point \(7, 1\) is outside the boundary"),
    ({"radius": 0.2, "path": [[2, 1], [2, 2.9]], "speed": 0.3},
     r"movers\[0\]: its path comes 0.100 m from the boundary near \(2, 2.9\), closer than "
     r"its radius 0.2 m"),
])
def test_a_bad_mover_is_refused_in_one_line_naming_it(tmp_path, mover, reason):
    path = write_world(tmp_path, [{"radius": 0.1, "path": [[1, 1]], "speed": 0.0}, mover])
    with pytest.raises(WorldError, match=reason.replace(r"movers\[0\]", r"movers\[1\]")) as error:
        World.load(path)
    assert "\n" not in str(error.value) and str(error.value).startswith(path)


def test_movers_must_be_a_list_with_unique_names(tmp_path):
    with pytest.raises(WorldError, match="'movers' must be a list"):
        World.load(write_world(tmp_path, {"radius": 0.2}))
    twice = {"radius": 0.2, "path": [[2, 1]], "speed": 0.0, "name": "ann"}
    with pytest.raises(WorldError, match=r"mover name\(s\) \['ann'\] given twice"):
        World.load(write_world(tmp_path, [twice, twice]))


def test_a_map_never_has_movers(tmp_path):
    """A world file given as --map: its movers are dropped; the world keeps its own."""
    people = World.load(WORLDS / "room_people.yaml")
    assert len(people.movers) == 3
    map_world = load_map(str(WORLDS / "room_people.yaml"), World.load("room_obstacles"))
    assert map_world.movers == () and map_world.name == "room_people"
    assert load_map(None, people) is people  # no map: the world, movers and all
    # Its /map (the planner's and the filter's cells) is the room's: no disc where they walk.
    np.testing.assert_array_equal(OccupancyGrid.from_world(map_world, 0.05).raster().values,
                                  OccupancyGrid.from_world(World.load("room_obstacles"),
                                                           0.05).raster().values)


# --- how a mover walks ----------------------------------------------------------------------

def test_back_and_forth_round_and_a_late_start(tmp_path):
    world = World.load(write_world(tmp_path, [
        {"radius": 0.2, "path": [[1, 1], [3, 1], [3, 2]], "speed": 0.5},
        {"radius": 0.2, "path": [[1, 1], [3, 1], [3, 2]], "speed": 0.5, "loop": True},
        {"radius": 0.2, "path": [[4, 1], [5, 1]], "speed": 0.25, "start_s": 10},
        {"radius": 0.2, "path": [[4, 2]], "speed": 0.4},
        {"radius": 0.2, "path": [[4, 2], [5, 2]], "speed": 0.0}]))
    there_and_back, round_trip, late, standing, still = world.movers
    # 3 m at 0.5 m/s: the last point at 6 s, back at the first at 12 s.
    expected = {0: (1, 1), 2: (2, 1), 4: (3, 1), 5: (3, 1.5), 6: (3, 2), 7: (3, 1.5),
                10: (2, 1), 12: (1, 1), 13: (1.5, 1), 24: (1, 1)}
    for t, point in expected.items():
        assert there_and_back.position_at(t) == pytest.approx(point, abs=1e-12), t
    # Round: 3 m out, then sqrt(5) m straight back to the first point, then again.
    closing = math.sqrt(5.0)
    assert round_trip.position_at(6) == pytest.approx((3, 2), abs=1e-12)
    assert round_trip.position_at(6 + closing) == pytest.approx((2, 1.5), abs=1e-12)
    assert round_trip.position_at(2 * (3 + closing)) == pytest.approx((1, 1), abs=1e-12)
    assert round_trip.position_at(2 * (3 + closing) + 2) == pytest.approx((2, 1), abs=1e-12)
    # start_s: standing at the first point until then.
    assert late.position_at(0) == late.position_at(10) == (4, 1)
    assert late.position_at(12) == pytest.approx((4.5, 1), abs=1e-12)
    # One point or speed 0: standing.
    assert standing.position_at(100) == (4, 2) and not standing.walks
    assert still.position_at(100) == (4, 2) and not still.walks
    # A mover's clock: the run's time minus the waits before it.
    waits = [[2.0, 3.5], [5.0, 6.0]]
    assert [walked_time(t, waits) for t in (1.0, 3.0, 4.0, 5.5, 9.0)] == \
        [1.0, 2.0, 2.5, 3.5, 6.5]


def test_the_simulator_moves_them_as_the_world_says(tmp_path):
    world = World.load(write_world(tmp_path, [
        {"radius": 0.2, "path": [[2, 0.5], [2, 2.5]], "speed": 0.4},
        {"radius": 0.2, "path": [[4, 0.5], [4, 2.5], [5, 2.5]], "speed": 0.3, "loop": True,
         "start_s": 1.0}]))
    sim = Simulator(world, start="west")
    for _ in range(300):  # the robot stands at the west wall: nobody waits
        sim.step(0.0, 0.0)
    for mover, (x, y) in zip(world.movers, sim.movers.positions):
        assert (x, y) == pytest.approx(mover.position_at(sim.time), abs=1e-9)
    assert sim.mover_waits == [[], []]
    assert sim.collisions == sim.collisions_with_movers == 0


def test_a_mover_waits_for_a_robot_parked_on_its_path(tmp_path):
    """It stops short of the robot, so the robot's record stays clean; then walks on."""
    world = World.load(write_world(tmp_path, [
        {"radius": 0.2, "path": [[3, 0.4], [3, 2.6]], "speed": 0.5}],
        starts={"on_the_path": [3.0, 1.5, 0.0], "west": [0.5, 1.5, 0.0]}))
    sim = Simulator(world, start="on_the_path", profile="turtlebot3")
    reach = 0.2 + ROBOT_RADIUS
    gaps = []
    for _ in range(200):  # 10 s parked
        sim.step(0.0, 0.0)
        x, y = sim.movers.positions[0]
        gaps.append(math.hypot(x - 3.0, y - sim.pose[1]) - reach)
    assert sim.collisions == sim.collisions_with_movers == 0
    assert KEEP_OFF <= min(gaps) < KEEP_OFF + 0.5 * 0.05 + 1e-9  # stopped within one step
    # It walks north from y = 0.4 at 0.5 m/s; a step later its edge would be within KEEP_OFF
    # of the robot's (y > 1.5 - 0.306): that step starts at 1.55 s, and it waits ever since.
    (waited,) = sim.mover_waits[0]
    assert waited == pytest.approx([1.55, sim.time], abs=1e-9)
    # The robot drives away east: the mover walks on, its clock behind the run's by its wait.
    for _ in range(60):
        sim.step(0.2, 0.0)
    for _ in range(40):
        sim.step(0.0, 0.0)
    mover = world.movers[0]
    clock = walked_time(sim.time, sim.mover_waits[0])
    assert sim.movers.positions[0] == pytest.approx(mover.position_at(clock), abs=1e-6)
    assert sim.collisions == 0


def test_driving_into_a_mover_is_the_robots_collision(tmp_path):
    world = World.load(write_world(tmp_path, [
        {"radius": 0.2, "path": [[2, 1.5]], "speed": 0.0, "name": "statue"}]))
    sim = Simulator(world, start="west")
    deepest = 0.0
    for _ in range(200):  # straight at it for 10 s
        sim.step(0.2, 0.0)
        deepest = max(deepest, 0.2 + ROBOT_RADIUS - math.dist(sim.pose[:2], (2.0, 1.5)))
    assert sim.collisions == sim.collisions_with_movers == 1
    assert sim.first_collision_time is not None
    assert math.dist(sim.collision_points[0], (1.8, 1.5)) < 0.01  # the statue's west edge
    assert deepest <= ALLOWED_PENETRATION + 1e-4  # stopped as by a wall
    assert sim.min_clearance == pytest.approx(0.5 - ROBOT_RADIUS)  # the walls only: at the start
    # A wall as well: counted in the total, not with the movers.
    sim.teleport((5.7, 1.5, 0.0))
    for _ in range(20):
        sim.step(0.2, 0.0)
    assert (sim.collisions, sim.collisions_with_movers) == (2, 1)
    assert collisions_text(sim.collisions, sim.collisions_with_movers) == "2 (1 with movers)"


def test_the_robot_may_not_start_on_a_mover_and_lands_on_one_without_a_collision(tmp_path):
    """A start is checked before the run; a kidnap lands where a mover may walk by then."""
    world = World.load(write_world(tmp_path, [
        {"radius": 0.2, "path": [[0.7, 1.5], [0.7, 2.5]], "speed": 0.3, "name": "ann"}]))
    with pytest.raises(WorldError, match=r"start \(0.5, 1.5\) touches ann \(radius 0.2 m, now "
                                         r"at \(0.70, 1.50\)\)"):
        Simulator(world, start="west")
    sim = Simulator(world, start="east")
    sim.teleport((0.75, 1.6, 0.0))  # onto ann: she waits, the robot drives off east
    for _ in range(20):
        sim.step(0.0, 0.0)
    assert sim.movers.positions[0] == pytest.approx((0.7, 1.5))
    for _ in range(60):
        sim.step(0.2, 0.0)
    assert sim.movers.positions[0][1] > 1.5  # walking again
    assert sim.collisions == sim.collisions_with_movers == 0
    assert sim.mover_waits[0][0][0] == pytest.approx(0.0)


def test_compiled_mover_kernels_equal_their_twins():
    from amr_common.world.movers import path_position, path_position_python
    from amr_sim.contact import constrain_velocity, constrain_velocity_python
    from amr_sim.moving_obstacles import (
        MovingObstacles,
        advance_kernel,
        advance_python,
        contacts_kernel,
        contacts_python,
    )
    world = World.load(WORLDS / "room_people.yaml")
    movers = MovingObstacles(world.movers)
    rng = np.random.default_rng(5)
    for mover in world.movers:
        for t in rng.uniform(0.0, 100.0, 50):
            assert path_position(mover.walked, mover.stations, mover.loop, mover.speed,
                                 mover.start_s, t) == \
                path_position_python(mover.walked, mover.stations, mover.loop, mover.speed,
                                     mover.start_s, t)
    # Walking and waiting: the robot at random places, some of them in a mover's way.
    states = [(movers.clocks.copy(), movers.circles.copy(), np.full(3, np.nan), np.zeros((3, 2)))
              for _ in range(2)]
    waited = 0
    for k in range(400):
        robot = (1.5, 2.3) if k % 50 < 25 else tuple(rng.uniform(0.0, 4.0, 2))
        ended = [advance(movers._walked, movers._stations, movers._first, movers._speeds,
                         movers._starts, movers._loops, movers._walking, clocks, circles,
                         *robot, ROBOT_RADIUS, KEEP_OFF, 0.05 * k, 0.05, wait_from, out)
                 for advance, (clocks, circles, wait_from, out) in
                 zip((advance_kernel, advance_python), states)]
        assert ended[0] == ended[1]
        waited += ended[0]
        for a, b in zip(*states):
            np.testing.assert_array_equal(a, b)
    assert waited >= 5  # the visitor waited for the robot, and walked on
    touching = [np.zeros(3, dtype=bool), np.zeros(3, dtype=bool)]
    points = [np.zeros((3, 2)), np.zeros((3, 2))]
    circles = states[0][1]
    for x, y in [(circles[0, 0] + 0.3, circles[0, 1]), (circles[0, 0] + 0.31, circles[0, 1]),
                 (circles[0, 0] + 0.2, circles[0, 1]), (0.5, 0.5)]:
        counts = [contacts(circles, x, y, ROBOT_RADIUS, t, p) for contacts, t, p in
                  zip((contacts_kernel, contacts_python), touching, points)]
        assert counts[0] == counts[1]
        np.testing.assert_array_equal(touching[0], touching[1])
        np.testing.assert_array_equal(points[0][:counts[0]], points[1][:counts[1]])
    # The robot's velocity towards a disc: as towards a wall, never deeper than allowed.
    segments = np.array([[0.0, 0.0, 4.0, 0.0]])
    disc = np.array([[1.0, 1.0, 0.2]])
    for px, py, vx, vy in [(0.69, 1.0, 0.3, 0.0), (0.78, 0.78, 0.2, 0.2), (1.0, 0.685, 0.0, 0.3),
                           (1.0, 0.115, 0.1, -0.3)]:  # the last one: the wall
        fast = constrain_velocity(segments, disc, px, py, vx, vy, 0.05, 0.105, 0.0005)
        slow = constrain_velocity_python(segments, disc, px, py, vx, vy, 0.05, 0.105, 0.0005)
        assert fast == pytest.approx(slow, abs=1e-12)
        x, y = px + 0.05 * fast[0], py + 0.05 * fast[1]
        assert math.dist((x, y), (1.0, 1.0)) >= 0.2 + 0.105 - 0.0005 - 1e-12
        assert y >= 0.105 - 0.0005 - 1e-12
        assert math.hypot(*fast) < math.hypot(vx, vy)  # slowed
    assert constrain_velocity(segments, disc, 2.0, 2.0, 0.2, 0.1, 0.05, 0.105, 0.0005) == \
        pytest.approx((0.2, 0.1))  # nothing within reach: as commanded


# --- seen by the LiDAR ----------------------------------------------------------------------

def _circles_and_rays(rng, n=700):
    circles = np.column_stack([rng.uniform(-2, 2, 5), rng.uniform(-2, 2, 5),
                               rng.uniform(0.05, 0.5, 5)])
    ox, oy = rng.uniform(-3, 3, (2, n))
    heading = rng.uniform(-math.pi, math.pi, n)
    return circles, ox, oy, np.cos(heading), np.sin(heading)


def test_circle_kernels_equal_their_twins():
    rng = np.random.default_rng(3)
    circles, ox, oy, dx, dy = _circles_and_rays(rng)
    walls = rng.uniform(0.5, 6.0, ox.shape)  # ranges already cast against walls
    walls[::7] = np.inf
    results = []
    for cast in (cast_circles_kernel, cast_circles_python, cast_circles_numpy):
        ranges, cos = walls.copy(), np.full(ox.shape, 0.5)
        cast(circles, ox, oy, dx, dy, ranges, cos)
        results.append((ranges, cos))
    for ranges, cos in results[1:]:
        np.testing.assert_allclose(ranges, results[0][0], rtol=1e-12)
        np.testing.assert_allclose(cos, results[0][1], rtol=0, atol=1e-12)
    ranges, cos = results[0]
    lowered = ranges < walls
    assert 50 < lowered.sum() < len(walls) - 50  # some rays hit a circle first, others not
    hits = np.column_stack([ox + ranges * dx, oy + ranges * dy])[lowered]
    on_a_circle = np.abs(np.hypot(hits[:, None, 0] - circles[:, 0], hits[:, None, 1]
                                  - circles[:, 1]) - circles[:, 2]).min(axis=1)
    assert on_a_circle.max() < 1e-9  # each lowered range ends on a circle's edge
    assert np.all((cos[lowered] >= 0.0) & (cos[lowered] <= 1.0))
    # One origin, angles about a heading: the scan with noise and limits.
    base = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    noise = rng.normal(0.0, 0.01, 360)
    scans = []
    for scan in (scan_circles_kernel, scan_circles_python, scan_circles_numpy):
        out = np.full(360, 3.0)
        out[::5] = np.inf
        scan(circles, 0.3, -0.2, 0.4, np.cos(base), np.sin(base), 0.12, 3.5, 0.0, noise, out)
        scans.append(out)
    for out in scans[1:]:
        np.testing.assert_allclose(out, scans[0], rtol=0, atol=1e-12)
    assert (scans[0] == 0.0).any() and (scans[0] < 2.9).sum() > 10


@pytest.mark.parametrize("profile", ["ideal", "turtlebot3_clean", "turtlebot3"])
def test_the_lidar_sees_a_mover(tmp_path, profile):
    world = World.load(write_world(tmp_path, [
        {"radius": 0.25, "path": [[1.5, 1.5]], "speed": 0.0}]))
    sim = Simulator(world, start="west", profile=profile, seed=1)
    scan, _, _ = sim.measure()
    angle_min, increment, rays, _, _ = sim.scan_geometry
    ahead = int(round(-angle_min / increment)) % rays  # the ray along the heading
    near = [(ahead + k) % rays for k in range(-2, 3)]  # five rays, all on the disc
    d = 1.5 - sim.lidar_position[0]  # from the LiDAR to the disc's centre
    angles = angle_min + increment * np.array(near)
    expected = d * np.cos(angles) - np.sqrt(0.25 ** 2 - (d * np.sin(angles)) ** 2)
    # The Burger's scanner: range noise (a few cm); with the effects a ray may drop out.
    tolerance = 1e-9 if profile == "ideal" else 0.05
    seen = [abs(scan[i] - e) <= tolerance for i, e in zip(near, expected)]
    assert sum(seen) >= (4 if profile == "turtlebot3" else 5), scan[near]
    # The same room without the mover: those rays reach the east wall or nothing.
    empty = Simulator(write_world(tmp_path, [], name="empty.yaml"), start="west",
                      profile=profile, seed=1).measure()[0]
    assert not any(abs(empty[i] - e) <= 0.5 for i, e in zip(near, expected))


def test_the_real_scanner_kernels_see_circles_alike():
    """The skewed scan with effects (compiled) and its numpy twin agree with circles too."""
    from amr_sim.lidar_effects import scan_rays_kernel, scan_rays_numpy
    sim = Simulator(str(WORLDS / "room_people.yaml"), start="middle", profile="turtlebot3",
                    seed=4)
    for k in range(13):
        sim.step(0.1, 0.5 * math.sin(k))
    lidar = sim.lidar
    assert lidar.circles.shape == (3, 3)
    rng = np.random.default_rng(0)
    gauss, uniform = rng.standard_normal(360), rng.random(360, dtype=np.float32)
    args = (lidar.walls, lidar.circles, lidar.history, lidar._head, lidar.angles,
            lidar._cos, lidar._sin, lidar.bands, lidar.params, gauss, uniform)
    fast, slow = np.empty(360), np.empty(360)
    scan_rays_kernel(*args, fast)
    scan_rays_numpy(*args, slow)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)
    no_circles = np.empty(360)
    scan_rays_kernel(lidar.walls, np.zeros((0, 3)), *args[2:], no_circles)
    assert (fast < no_circles - 0.05).sum() >= 3  # the visitor, 0.3 m away, hides a wall


# --- shown: what the map lacks, the plot, /world_markers ------------------------------------

def test_the_walls_a_map_lacks():
    box = World.load(WORLDS / "lab02_box.yaml")
    lacked = unmapped_walls(box, World.load("lab02"))
    assert len(lacked) == 4  # the box's four sides, nothing else
    assert lacked[:, [0, 2]].min() == pytest.approx(-0.3) and \
        lacked[:, [0, 2]].max() == pytest.approx(-0.1)
    assert len(unmapped_walls(box, box)) == 0
    moved = unmapped_walls(World.load(WORLDS / "lab02_moved_wall.yaml"), World.load("lab02"))
    # The moved east wall (not its old place) and the ends of the walls lengthened to it.
    assert moved[:, [0, 2]].min() > 1.25
    assert [1.3, -1.2, 1.3, 1.2] in moved.round(9).tolist()


def test_the_plot_shows_the_movers_where_they_were(tmp_path):
    from matplotlib.figure import Figure

    from amr_evaluation.plot import draw_episode, plot_episode
    world = World.load(WORLDS / "room_people.yaml")
    trajectory = [[0.0, 1.2, 1.7, 0.0], [30.0, 1.2, 1.7, 0.0]]
    waits = [[[0.0, 30.0]], [], []]  # the visitor waited all along: still at its first point
    ax = Figure().add_subplot(1, 1, 1)
    draw_episode(ax, world, trajectory, mover_waits=waits,
                 map_world=World.load("room_obstacles"))
    labels = ax.get_legend_handles_labels()[1]
    assert "movers (path, where at t)" in labels
    discs = [p for p in ax.patches if p.get_facecolor()[:3] == pytest.approx((0.6, 0.2, 0.8))]
    assert len(discs) == 3 * 4  # three movers at four times of the run
    centres = [tuple(np.round(p.get_xy()[:-1].mean(axis=0), 2)) for p in discs]  # closed
    assert centres.count((1.5, 1.95)) == 4  # the visitor never left its first point
    runner = world.movers[2]
    assert tuple(np.round(runner.position_at(30.0), 2)) in centres
    written = plot_episode(world, trajectory, path=tmp_path / "people.png", mover_waits=waits)
    assert written.stat().st_size > 10_000


def test_world_markers_show_the_movers_as_they_walk(ros):
    from rclpy.lifecycle import TransitionCallbackReturn
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from visualization_msgs.msg import MarkerArray

    from amr_common.ros.ros_conversions import twist_stamped
    from amr_sim.simulator_node import SimulatorNode
    world = str(WORLDS / "room_people.yaml")
    probe = ros.node("probe")
    received = []
    probe.create_subscription(MarkerArray, "/world_markers", received.append, QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    command = probe.create_publisher(type(twist_stamped(0.0, 0.0)), "/cmd_vel", 10)
    node = ros.add(SimulatorNode(context=ros.context, parameter_overrides=[
        Parameter("world", value=world), Parameter("start", value="north_east"),
        Parameter("navigation_map", value="room_obstacles")]))
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    ros.spin_until(lambda: received and command.get_subscription_count() > 0,
                   message="the latched /world_markers")
    first = received[-1]
    movers = [m for m in first.markers if m.ns == "movers"]
    assert [c for m in movers for c in (m.pose.position.x, m.pose.position.y)] == \
        pytest.approx([1.5, 1.95, 2.05, 0.25, 2.3, 2.7])
    assert all(m.scale.x == pytest.approx(0.4) for m in movers)
    # The map (room_obstacles) has every wall of the room: nothing is lacked.
    assert not [m for m in first.markers if m.ns == "unmapped"]
    for _ in range(40):  # 2 s: the visitor walks 0.6 m north, the others have not started
        before = node.simulator.steps
        command.publish(twist_stamped(0.0, 0.0))
        ros.spin_until(lambda: node.simulator.steps > before, message="a step")
    ros.spin_until(lambda: received[-1].markers[0].header.stamp.sec >= 1, message="updates")
    ros.spin_for(0.2)
    last = [m for m in received[-1].markers if m.ns == "movers"]
    assert (last[0].pose.position.x, last[0].pose.position.y) == pytest.approx(
        node.simulator.movers.positions[0], abs=0.3 * 0.1 + 1e-9)  # at most 0.1 s behind
    assert last[0].pose.position.y > 1.95 + 0.4
    assert 2 < len(received) <= 1 + 2.0 / 0.1 + 1  # at most 10 Hz of simulated time
    summary = node.summary()
    assert summary["collisions"] == summary["collisions_with_movers"] == 0


def test_world_markers_show_the_box_the_map_lacks(ros):
    from rclpy.lifecycle import TransitionCallbackReturn
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from visualization_msgs.msg import MarkerArray

    from amr_sim.simulator_node import SimulatorNode
    probe = ros.node("probe")
    received = []
    probe.create_subscription(MarkerArray, "/world_markers", received.append, QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    node = ros.add(SimulatorNode(context=ros.context, parameter_overrides=[
        Parameter("world", value=str(WORLDS / "lab02_box.yaml")),
        Parameter("navigation_map", value="lab02")]))
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    ros.spin_until(lambda: received, message="the latched /world_markers")
    (box,) = received[-1].markers
    assert box.ns == "unmapped" and len(box.points) == 4 * 6  # four sides, two triangles each
    xs = [p.x for p in box.points]
    assert min(xs) == pytest.approx(-0.3) and max(xs) == pytest.approx(-0.1)
