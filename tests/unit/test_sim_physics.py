"""The simulator: driving, ray casts, cameras, launches and jumps from geometry; seeded and reproducible."""

from __future__ import annotations

import math
import random
from dataclasses import replace
from pathlib import Path

import pymunk
import pytest

from drd.sim import DoorState, RobotState, SimError, Simulation, load_world, sensors
from drd.sim.model import SCOUT_RADIUS, Intruder, RangerSpawn, ScoutSpawn, Waypoint, World
from drd.sim.sensors import beam_angles

ROOT = Path(__file__).resolve().parents[2]
CORRIDOR = load_world(ROOT / "worlds" / "corridor.yaml")
UP, DOWN = math.pi / 2, -math.pi / 2


def world_with(rangers: tuple[RangerSpawn, ...] = (), scouts: tuple[ScoutSpawn, ...] = (),
               people: dict[str, tuple[float, float]] | None = None) -> World:
    """The corridor building with robots and standing intruders placed for one test."""
    intruders = tuple(Intruder(i, (Waypoint(0, *at),)) for i, at in (people or {}).items())
    return replace(CORRIDOR, rangers=rangers, scouts=scouts, intruders=intruders)


def ranger_at(x: float, y: float, heading: float, magazine: tuple[str, ...] = ("s1",)) -> RangerSpawn:
    return RangerSpawn("ranger1", x, y, heading, magazine)


def ends(sim: Simulation, robot: str, readings: list[float], fov: float = math.pi) -> list[tuple[float, float]]:
    """Where each beam stopped, in world coordinates."""
    p = sim.pose(robot)
    return [(p.x + d * math.cos(a), p.y + d * math.sin(a))
            for d, a in zip(readings, beam_angles(p.heading, len(readings), fov), strict=True)]


# ---------------------------------------------------------------- driving and ranges


def test_a_ranger_driven_straight_keeps_to_the_corridor_and_sees_its_walls() -> None:
    sim = Simulation(CORRIDOR, seed=1)
    sim.set_velocity("ranger1", 0.5, 0.0)
    gaps = [(d.a[0], d.b[0], d.a[1]) for d in CORRIDOR.doors if d.state is DoorState.OPEN]
    checked = 0
    for _ in range(30):
        sim.step(1.0)
        p = sim.pose("ranger1")
        assert abs(p.y) < 1e-6 and abs(p.heading) < 1e-9  # nothing pushed it: the intruders cross later
        scan = sim.ranges("ranger1", 181, 8.0)
        for beam, wall_y in ((0, -1.25), (180, 1.25)):  # straight right, straight left
            if any(lo - 0.5 < p.x < hi + 0.5 and y == wall_y for lo, hi, y in gaps):
                continue  # looking through an open door
            assert scan[beam] == pytest.approx(abs(wall_y - p.y), abs=5 * sim.noise.range)
            checked += 1
        assert scan[90] == 8.0  # the far end is out of range: max_range exactly, no noise
    assert sim.pose("ranger1").x == pytest.approx(16.0)
    assert checked >= 40
    odo = sim.odometry("ranger1")
    assert odo != sim.pose("ranger1") and math.hypot(odo.x - 16, odo.y) < 1.0  # noisy, but close


def test_wheels_are_limited_to_max_speed_and_walls_stop_a_robot() -> None:
    sim = Simulation(world_with((ranger_at(4.5, 0, UP),)), seed=1)
    sim.set_wheels("ranger1", 2.0, 2.0)
    assert sim.command("ranger1") == (0.8, 0.0)
    sim.set_velocity("ranger1", 0.0, 100.0)  # spin in place: both wheels at max, opposite
    assert sim.command("ranger1") == pytest.approx((0.0, 2 * 0.8 / 0.5))
    sim.set_velocity("ranger1", 0.8, 0.0)
    sim.step(5.0)  # straight at the wall beside door_n1 (3.5..4.5): held at its surface
    assert sim.pose("ranger1").y == pytest.approx(1.25 - 0.3, abs=0.01)



@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_wheel_speed_is_refused_and_changes_nothing(bad: float) -> None:
    """Clients audit D1: NaN passed the max-speed clamp (inf became NaN there) and made the pose NaN."""
    sim = Simulation(world_with((ranger_at(4.5, 0, UP),)), seed=1)
    sim.set_velocity("ranger1", 0.3, 0.0)
    with pytest.raises(ValueError, match="wheel speeds must be finite"):
        sim.set_velocity("ranger1", bad, 0.0)
    with pytest.raises(ValueError, match="wheel speeds must be finite"):
        sim.set_wheels("ranger1", 0.1, bad)
    assert sim.command("ranger1") == pytest.approx((0.3, 0.0))
    sim.step(0.5)
    assert all(math.isfinite(v) for v in (sim.pose("ranger1").x, sim.pose("ranger1").y))

@pytest.mark.parametrize("x", [4.6, 5.0, 5.4])
def test_a_ray_never_passes_a_closed_door_and_does_an_open_one(x: float) -> None:
    sim = Simulation(world_with((ranger_at(x, 0, DOWN),)), seed=2)  # facing door_s1 (4.5..5.5), closed
    fov = math.pi / 2  # wide enough to sweep the door, narrow enough to miss door_s2, which is open
    for state in (DoorState.CLOSED, DoorState.BLOCKED):
        sim.set_door("door_s1", state)
        assert min(y for _, y in ends(sim, "ranger1", sim.ranges("ranger1", 361, 8.0, fov), fov)) > -1.25 - 0.05
    sim.set_door("door_s1", DoorState.OPEN)
    scan = sim.ranges("ranger1", 361, 8.0, fov)
    assert scan[180] == pytest.approx(6.25, abs=0.05)  # straight through to the back wall of s1
    assert min(y for _, y in ends(sim, "ranger1", scan, fov)) < -6.0


# ---------------------------------------------------------------- cameras


def test_camera_sees_a_lit_intruder_in_view_and_not_one_behind_a_wall() -> None:
    people = {"in_room": (4.0, 3.5), "behind_wall": (9.0, 3.0), "behind_door": (5.0, -3.5)}
    sim = Simulation(world_with((ranger_at(4.0, 0, UP),), people=people), seed=3)
    assert [d.label for d in sim.camera("ranger1", math.radians(170), 10.0)] == ["in_room"]
    (seen,) = sim.camera("ranger1", math.radians(60), 10.0)
    assert seen.bearing == pytest.approx(0.0, abs=0.03) and seen.distance == pytest.approx(3.5, rel=0.15)
    assert sim.camera("ranger1", math.radians(60), 3.0) == []  # out of range


def test_camera_does_not_see_through_a_closed_door() -> None:
    sim = Simulation(world_with((ranger_at(5.0, 0, DOWN),), people={"x": (5.0, -3.5)}), seed=3)
    assert sim.camera("ranger1", math.radians(60), 10.0) == []
    sim.set_door("door_s1", DoorState.OPEN)
    assert [d.label for d in sim.camera("ranger1", math.radians(60), 10.0)] == ["x"]


def test_an_intruder_in_a_dark_corner_is_not_seen() -> None:
    corner = next(z for z in CORRIDOR.dark if z.x == 7.4 and z.y == 5.65)  # n1's
    people = {"dark": (corner.x, corner.y), "lit": (6.0, 4.0)}
    sim = Simulation(world_with(scouts=(ScoutSpawn("s1", 5.0, 3.0, math.atan2(2.65, 2.4)),), people=people), seed=4)
    assert CORRIDOR.light(corner.x, corner.y) < 0.2 <= CORRIDOR.light(6.0, 4.0)
    assert [d.label for d in sim.camera("s1", math.radians(90), 8.0)] == ["lit"]
    regions = sim.brightness("s1", math.radians(90), 9)
    assert abs(regions.index(min(regions)) - 4) <= 1  # the darkest strips of the image are the corner it faces
    assert min(regions) < 0.2 < max(regions)


def _crosses(p: tuple[float, float], q: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> bool:
    """Whether segments pq and ab touch: plain orientation tests, independent of pymunk."""
    def orient(o: tuple[float, float], s: tuple[float, float], t: tuple[float, float]) -> float:
        return (s[0] - o[0]) * (t[1] - o[1]) - (s[1] - o[1]) * (t[0] - o[0])
    d1, d2, d3, d4 = orient(a, b, p), orient(a, b, q), orient(p, q, a), orient(p, q, b)
    return d1 * d2 <= 0 and d3 * d4 <= 0


def test_camera_never_sees_through_walls_anywhere() -> None:
    """Random poses and people all over the building: every detection has a clear straight line of sight."""
    rng = random.Random(0)
    solid = [(w.a, w.b) for w in CORRIDOR.walls] + [(d.a, d.b) for d in CORRIDOR.doors if d.state != "open"]
    seen = 0
    for _ in range(60):
        me = (rng.uniform(1, 39), rng.uniform(-0.9, 0.9))
        people = {f"p{i}": (rng.uniform(0, 40), rng.uniform(-6.2, 6.2)) for i in range(8)}
        sim = Simulation(world_with((ranger_at(*me, rng.uniform(-math.pi, math.pi)),), people=people), seed=5)
        for d in sim.camera("ranger1", math.radians(120), 15.0):
            assert not any(_crosses(me, people[d.label], a, b) for a, b in solid), (me, people[d.label])
            assert CORRIDOR.light(*people[d.label]) >= 0.2
            seen += 1
    assert seen > 10  # the check was not vacuous


def test_a_camera_seeds_its_noise_only_when_it_sees_someone_and_then_draws_the_same() -> None:
    """`sensors.detect` takes the reading's generator as a function and asks for it at the first target seen:
    the detections are those of the seeded generator given outright, and a view of nobody never seeds one."""
    people = {"far": (30.0, 0.0), "in_room": (4.0, 3.5), "behind_wall": (9.0, 3.0), "also_in_room": (3.0, 3.0)}
    sim = Simulation(world_with((ranger_at(4.0, 0, UP),), people=people), seed=3)
    rays, origin, fov = sensors.RayCaster(sim.space), (4.0, 0.0), math.radians(170)

    def reading() -> random.Random:
        asked.append(1)
        return random.Random("one reading")

    asked: list[int] = []
    lazy = sensors.detect(rays, CORRIDOR, origin, UP, fov, 10.0, 0.2, people, reading, sensors.Noise())
    given = sensors.detect(rays, CORRIDOR, origin, UP, fov, 10.0, 0.2, people, random.Random("one reading"),
                           sensors.Noise())
    assert [d.label for d in lazy] == ["in_room", "also_in_room"] and lazy == given and asked == [1]
    asked.clear()
    assert sensors.detect(rays, CORRIDOR, origin, -UP, math.radians(60), 10.0, 0.2, people, reading,
                          sensors.Noise()) == []
    assert asked == [], "nobody in view: no generator seeded"


# ---------------------------------------------------------------- launches and jumps


def test_launch_through_an_open_door_lands_in_the_room() -> None:
    sim = Simulation(world_with((ranger_at(4.0, 0, UP, ("s1", "s2")),)), seed=6)
    flight = sim.launch("s1", 0.0, 3.0)
    assert sim.state("s1") is RobotState.FLYING and sim.magazine("ranger1") == ("s2",)
    assert not flight.blocked and flight.t1 - flight.t0 == pytest.approx(math.sqrt(2 * 3.0 / 9.81), rel=0.05)
    sim.step(2.0)
    p = sim.pose("s1")
    assert sim.state("s1") is RobotState.FLOOR and CORRIDOR.room_at(p.x, p.y).id == "n1"  # type: ignore[union-attr]
    assert p.y == pytest.approx(3.0, abs=0.2)


def test_launch_at_a_closed_door_stops_at_the_door() -> None:
    sim = Simulation(world_with((ranger_at(5.0, 0, DOWN),)), seed=6)
    flight = sim.launch("s1", 0.0, 4.0)
    sim.step(2.0)
    p = sim.pose("s1")
    assert flight.blocked and CORRIDOR.room_at(p.x, p.y) is None
    assert -1.25 + SCOUT_RADIUS < p.y < -1.25 + SCOUT_RADIUS + 0.05
    assert all(y > -1.25 for _, _, y in sim.trajectory("s1"))


def test_launch_checks_its_scout_and_distance() -> None:
    sim = Simulation(world_with((ranger_at(4.0, 0, UP),), scouts=(ScoutSpawn("s9", 10, 0, 0),)), seed=6)
    with pytest.raises(SimError, match=r"launch distance must be in \(0, 30\] m, got 31"):
        sim.launch("s1", 0.0, 31)
    with pytest.raises(SimError, match="s9 is not in a magazine"):
        sim.launch("s9", 0.0, 3)


def test_a_scout_jumps_a_low_obstacle_that_stops_it_rolling() -> None:
    # n1's cable tray spans y 2.0..2.4 at x 6.2..7.2 and is 0.15 m high
    world = world_with(scouts=(ScoutSpawn("a", 6.5, 1.7, UP), ScoutSpawn("b", 6.9, 1.7, UP)))
    sim = Simulation(world, seed=7)
    sim.set_velocity("a", 0.3, 0.0)
    sim.step(3.0)
    assert sim.pose("a").y == pytest.approx(2.0 - SCOUT_RADIUS, abs=0.01)  # rolled into it and stopped
    flight = sim.jump("b", 1.0)
    sim.step(1.0)
    assert not flight.blocked and sim.pose("b").y == pytest.approx(2.7, abs=0.01)
    low = Simulation(world, seed=7, jump_height=0.1)  # a weaker foot: the tray is too high
    assert low.jump("b", 1.0).blocked


def test_a_jump_into_a_wall_stops_short() -> None:
    sim = Simulation(world_with(scouts=(ScoutSpawn("s", 5.0, 5.8, UP),)), seed=7)
    flight = sim.jump("s", 1.0)
    assert flight.blocked and flight.end[1] == pytest.approx(6.25 - SCOUT_RADIUS, abs=0.02)


# ---------------------------------------------------------------- radio, loss, intruders, time


def test_radio_range_is_shortened_3db_by_each_wall() -> None:
    sim = Simulation(world_with((ranger_at(5.0, 0, 0.0, ("s1", "s2", "s3")),), scouts=(ScoutSpawn("x", 5.0, 5.0, 0),)),
                     seed=8)
    assert sim.radio_ok("s1", "ranger1", 0.1)  # in the magazine
    one_wall = 5.0 / 10 ** (-3 / 20)  # 5 m through one wall needs 7.06 m in the open
    assert sim.radio_ok("x", "ranger1", one_wall + 0.01) and not sim.radio_ok("x", "ranger1", one_wall - 0.01)
    sim.lose("ranger1")
    assert not sim.radio_ok("x", "ranger1", 100.0) and sim.magazine("ranger1") == ()
    assert {sim.state(s) for s in ("s1", "s2", "s3")} == {RobotState.LOST}
    with pytest.raises(SimError, match="ranger1 is lost"):
        sim.ranges("ranger1", 3, 5.0)


def test_intruders_walk_their_paths_and_leave_trajectories() -> None:
    sim = Simulation(CORRIDOR, seed=9)
    sim.run_until(65.0)
    for intruder in CORRIDOR.intruders:
        assert sim.intruders()[intruder.id] == pytest.approx(intruder.position(sim.time))
        assert len(sim.trajectory(intruder.id)) > 10


def test_a_person_walking_through_a_standing_ranger_is_seen_and_shoves_nothing() -> None:
    """A timed path cannot yield: if people pushed, one walking the corridor would carry a Ranger through a door
    (worlds audit 17, D2). The laser still sees the person, and a Scout on the floor stays put too."""
    walker = Intruder("walker", (Waypoint(0, 0.0, 0.0), Waypoint(16, 8.0, 0.0)))  # through both robots
    world = replace(CORRIDOR, rangers=(ranger_at(5.0, 0.0, math.pi),), scouts=(ScoutSpawn("x", 5.5, 0.0, 0.0),),
                    intruders=(walker,))
    sim = Simulation(world, seed=3)
    sim.step(0.5)
    before = sim.pose("ranger1"), sim.pose("x")
    seen = []
    for _ in range(16):
        sim.step(1.0)
        x = sim.intruders()["walker"][0]
        if 1.0 < 5.0 - x < 7.0:  # ahead of the Ranger, which faces -x: its middle beam stops at the person
            seen.append(sim.ranges("ranger1", 181, 8.0)[90] == pytest.approx(5.0 - x - walker.radius, abs=0.1))
    assert (sim.pose("ranger1"), sim.pose("x")) == before
    assert sim.intruders()["walker"] == pytest.approx((8.0, 0.0))
    assert seen and all(seen)


def test_step_divides_a_long_step_into_fixed_ones() -> None:
    sim = Simulation(CORRIDOR, seed=0, dt=0.05)
    sim.step(0.2)
    sim.step()
    assert sim.steps == 5 and sim.time == pytest.approx(0.25)


def _scenario(seed: int) -> list[object]:
    sim = Simulation(CORRIDOR, seed=seed)
    out: list[object] = []
    sim.set_velocity("ranger1", 0.6, 0.05)
    for i in range(200):
        sim.step()
        if i % 20 == 0:
            out += [sim.pose("ranger1"), sim.odometry("ranger1"), sim.ranges("ranger1", 37, 8.0),
                    sim.camera("ranger1", 1.0, 10.0), sim.brightness("ranger1", 1.0, 4)]
        if i == 50:
            sim.set_velocity("ranger1", 0.4, -0.05)
            out.append(sim.launch("scout1", UP, 3.0))
    out += [sim.pose("scout1"), sim.trajectory("scout1"), sim.trajectory("ranger1")]
    return out


def test_same_seed_same_commands_give_bit_identical_results() -> None:
    first = _scenario(42)
    assert first == _scenario(42)  # exact equality of every float
    assert first != _scenario(43)


def test_a_thousand_steps_of_the_corridor_world() -> None:
    sim = Simulation(CORRIDOR, seed=10)
    sim.set_velocity("ranger1", 0.5, 0.0)
    for _ in range(1000):
        sim.step()
    assert sim.steps == 1000 and sim.time == pytest.approx(50.0)
    assert sim.trajectory("ranger1")[-1][1] > 20


def test_the_lean_ray_caster_agrees_with_pymunks_public_query() -> None:
    sim = Simulation(CORRIDOR, seed=11)
    lean, public = sensors.RayCaster(sim.space), sensors.RayCaster(sim.space, fast=False)
    assert lean._query is not None  # the fast path is in use with the pymunk this project pins
    rng = random.Random(1)
    flt = pymunk.ShapeFilter()
    for _ in range(500):
        a, b = (rng.uniform(0, 40), rng.uniform(-7, 7)), (rng.uniform(0, 40), rng.uniform(-7, 7))
        assert lean.first(a, b, 0.0, flt) == public.first(a, b, 0.0, flt)


# ---------------------------------------------------------------- fast paths agree with the plain ones


def test_the_fast_ray_caster_agrees_with_pymunks_public_api() -> None:
    """`fan` and `crossings` call chipmunk directly; the public API must give the same answers, corners included."""
    sim = Simulation(CORRIDOR, seed=3)
    fast, plain = sensors.RayCaster(sim.space), sensors.RayCaster(sim.space, fast=False)
    rng = random.Random(11)
    x0, y0, x1, y1 = CORRIDOR.bounds
    for _ in range(300):
        a = (rng.uniform(x0, x1), rng.uniform(y0, y1))
        b = (rng.choice([2.0, 8.0, 14.0, rng.uniform(x0, x1)]), rng.choice([1.25, -1.25, 6.25, rng.uniform(y0, y1)]))
        assert fast.crossings(a, b, sensors.SIGHT) == sensors.walls_between(sim.space, a, b), (a, b)
        angles = [rng.uniform(-math.pi, math.pi) for _ in range(7)]
        assert fast.fan(a, angles, 8.0, sensors.SIGHT) == pytest.approx(plain.fan(a, angles, 8.0, sensors.SIGHT))


def test_the_light_index_gives_the_plain_formula() -> None:
    """`World.light` looks only at the rooms and dark corners near the point; the answer must not change."""
    def plain(x: float, y: float) -> float:
        base = next((r.light for r in CORRIDOR.rooms if r.x0 <= x <= r.x1 and r.y0 <= y <= r.y1), CORRIDOR.ambient)
        level = base
        for z in CORRIDOR.dark:
            d = math.hypot(x - z.x, y - z.y)
            if d < z.radius and z.level < base:
                level = min(level, z.level + (base - z.level) * (d / z.radius) ** 2)
        return level

    rng = random.Random(5)
    for _ in range(5000):
        x, y = rng.uniform(-2, 42), rng.uniform(-8, 8)
        assert CORRIDOR.light(x, y) == plain(x, y), (x, y)


def test_one_scan_per_sim_instant_is_shared_by_its_readers() -> None:
    """Behaviors reading the laser in one control cycle get the same Scan; the next instant brings a new one."""
    from drd.hosts import load_hosts
    from drd.hw.drivers import drivers_for
    from drd.manifests import load_catalog

    catalog = load_catalog()
    sim = Simulation(CORRIDOR, seed=1)
    drivers = drivers_for(load_hosts(ROOT / "hosts.yaml", catalog), "ranger1", sim, catalog=catalog)
    laser = drivers.robots["ranger1"]["ranges"]
    first = laser.scan()
    assert laser.scan() is first
    sim.step(0.1)
    second = laser.scan()
    assert second is not first and laser.scan() is second
    sim.set_door("door_n1", DoorState.CLOSED)
    assert laser.scan() is not second


def test_a_reading_is_a_function_of_the_instant_asked_again_early_or_never() -> None:
    """Sensor noise is seeded per instant: reading twice gives the same answer, and reading or not now changes
    no later reading (so the cluster's Creator may read ahead of a component's step; motion noise is unaffected)."""
    people = {"x": (4.0, 3.5)}

    def run(read_now: bool) -> list[object]:
        sim = Simulation(world_with((ranger_at(4.0, 0, UP),), people=people), seed=3)
        sim.set_velocity("ranger1", 0.2, 0.0)
        sim.step(0.1)
        if read_now:
            first = (sim.ranges("ranger1", 61, 8.0), sim.camera("ranger1", 1.0, 10.0),
                     sim.brightness("ranger1", 1.0, 8))
            assert first == (sim.ranges("ranger1", 61, 8.0), sim.camera("ranger1", 1.0, 10.0),
                             sim.brightness("ranger1", 1.0, 8))
        sim.step(0.1)
        return [sim.ranges("ranger1", 61, 8.0), sim.camera("ranger1", 1.0, 10.0), sim.brightness("ranger1", 1.0, 8),
                sim.odometry("ranger1")]

    later = run(read_now=True)
    assert later == run(read_now=False)
    sim = Simulation(world_with((ranger_at(4.0, 0, UP),), people=people), seed=3)
    sim.step(0.1)
    a = sim.ranges("ranger1", 61, 8.0)
    sim.step(0.1)
    assert sim.ranges("ranger1", 61, 8.0) != a, "a new instant draws new noise"


def test_a_step_of_dt_adds_exactly_dt_to_the_time_as_a_lockstep_clock_does() -> None:
    sim, t = Simulation(CORRIDOR, seed=1), 0.0
    for _ in range(30):  # 0.1 s in two sub-steps of 0.05 s: summed, they drift from t + 0.1 by an ulp
        sim.step(0.1)
        t += 0.1
        assert sim.time == t


@pytest.mark.parametrize(("v", "omega"), [(1.7e308, 0.0), (0.0, 1.7e308), (-1.7e308, 1.7e308), (1e300, -1e290)])
def test_a_huge_finite_command_is_clamped_not_refused(v: float, omega: float) -> None:
    """Reverify audit 7, N1: `v ± omega * base / 2` of a finite 1.7e308 overflowed to inf, the wheels refused it, and
    on a cluster that one ROS 2 Twist ended the world. It is the top speed, turning the way it was asked."""
    sim = Simulation(world_with((ranger_at(4.5, 0, UP),)), seed=1)
    sim.set_max_speed("ranger1", 0.5)
    sim.set_velocity("ranger1", v, omega)
    got_v, got_omega = sim.command("ranger1")
    assert all(math.isfinite(x) for x in (got_v, got_omega))
    assert abs(got_v) <= 0.5 + 1e-9 and (got_v, got_omega) != (0.0, 0.0)
    if omega == 0:
        assert got_v == pytest.approx(0.5)  # straight ahead at the top speed
    assert (got_v > 0) == (v > 0) and (got_v < 0) == (v < 0) and (got_omega > 0) == (omega > 0)
    sim.step(0.5)
    assert all(math.isfinite(x) for x in (sim.pose("ranger1").x, sim.pose("ranger1").y))
