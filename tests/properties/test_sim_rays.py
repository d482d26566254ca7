"""The ray-only space (the static shapes alone, balanced) answers as the physics' space does (hypothesis).

A scan casts in it every beam that passes no moving shape's box, and the camera, line of sight and radio cast
only at walls, doors and obstacles, so each of those must give the very numbers a cast in the physics' space
gives: checked on a generated building with robots driving, Scouts landed in rooms, intruders walking and
doors opened and closed.
"""

from __future__ import annotations

import math
import random

import pymunk
from hypothesis import given, settings
from hypothesis import strategies as st

from drd.sim import DoorState, Simulation, sensors
from drd.sim.building import Building, world
from drd.sim.world import parse_world

B = Building(3, 5)
WORLD = parse_world(world(B), B.name)


def busy(seed: int) -> Simulation:
    """The building after some seconds: Rangers driving, a Scout launched into a room, doors toggled."""
    sim = Simulation(WORLD, seed=seed)
    rng = random.Random(seed)
    for wing in range(B.wings):
        sim.set_velocity(B.ranger(wing), rng.uniform(0.2, 0.8), rng.uniform(-0.2, 0.2))
    for _ in range(rng.randint(0, 40)):
        sim.step(0.1)
    sim.launch(B.scout_ids(0)[0], math.pi / 2 * rng.choice([1, -1]), rng.uniform(1.0, 3.0))
    for _ in range(10):
        sim.step(0.1)
    doors = [d.id for d in WORLD.doors]
    for door in rng.sample(doors, 3):
        sim.set_door(door, rng.choice([DoorState.OPEN, DoorState.CLOSED]))
    return sim


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_scans_and_static_casts_match_the_physics_space(seed: int) -> None:
    sim = busy(seed)
    rng = random.Random(seed)
    main, still = sim._rays, sim._still_rays
    left, bottom, right, top = WORLD.bounds
    ids = [B.ranger(w) for w in range(B.wings)] + [B.scout_ids(0)[0]]
    for _ in range(30):
        if rng.random() < 0.5:  # from a robot, through its own group, as its laser does
            rid = rng.choice(ids)
            x, y, heading, group = sim._sensor_pose(rid)
        else:
            x, y, heading, group = rng.uniform(left, right), rng.uniform(bottom, top), rng.uniform(-4, 4), 0
        angles = sensors.beam_angles(heading, 61, rng.choice([math.pi, 2 * math.pi]))
        reach = rng.choice([2.0, 10.0, 30.0])
        plain = sensors.scan(main, (x, y), heading, 61, reach, math.pi, group, random.Random(1), 0.01)
        split = sensors.scan(main, (x, y), heading, 61, reach, math.pi, group, random.Random(1), 0.01,
                             still=still, near=sim._moving_near(x, y, reach, group))
        assert split == plain
        for flt in (sensors.SIGHT, pymunk.ShapeFilter(mask=sensors.TALL | sensors.OBSTACLE)):
            assert still.fan((x, y), angles, reach, flt) == main.fan((x, y), angles, reach, flt)
        a, b = (x, y), (rng.uniform(left, right), rng.uniform(bottom, top))
        assert still.crossings(a, b, sensors.SIGHT) == main.crossings(a, b, sensors.SIGHT)


def test_shadows_cover_every_beam_through_a_box() -> None:
    """A beam whose end lies in a box (so it passes through it) is always among the shadowed ones."""
    rng = random.Random(7)
    for _ in range(2000):
        box = (rng.uniform(-5, 5), rng.uniform(-5, 5))
        box4 = (box[0], box[1], box[0] + rng.uniform(0, 1), box[1] + rng.uniform(0, 1))
        origin = (rng.uniform(-6, 6), rng.uniform(-6, 6))
        shadows = sensors._shadows(origin, [box4])
        if shadows is None:
            continue
        px, py = rng.uniform(box4[0], box4[2]), rng.uniform(box4[1], box4[3])
        a = math.atan2(py - origin[1], px - origin[0]) + rng.choice([0.0, 2 * math.pi, -2 * math.pi])
        assert any(abs(sensors.wrap(a - mid)) <= half for mid, half, _ in shadows)
        assert math.hypot(px - origin[0], py - origin[1]) >= min(d for _, _, d in shadows)


@settings(max_examples=300, deadline=None)
@given(st.floats(-10, 10), st.integers(1, 400), st.sampled_from([0.5, math.pi, 2 * math.pi]),
       st.lists(st.tuples(st.floats(-10, 10), st.floats(0, 1.5)), max_size=6))
def test_shaded_beams_are_every_beam_in_a_shadow(heading: float, n: int, fov: float,
                                                 shadows: list[tuple[float, float]]) -> None:
    """`_shaded`, by index arithmetic, keeps every beam the plain test puts in a shadow, with its nearest one."""
    angles = sensors.beam_angles(heading, n, fov)
    far = [(mid, half, float(k)) for k, (mid, half) in enumerate(shadows)]
    shaded = dict(sensors._shaded(angles, far))
    for i, a in enumerate(angles):
        within = [d for mid, half, d in far if abs(sensors.wrap(a - mid)) <= half]
        if within:
            assert shaded[i] <= min(within)
