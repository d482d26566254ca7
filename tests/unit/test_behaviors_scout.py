"""The Scout's behaviors against the simulator (corridor world): LocateDarkCorner, ServoToGoal, TurnToWatch,
Watch, Observe. The simulator's ground truth (poses, light map, intruders) is used for setup and checks only.

Setup: ranger1 starts in the corridor below door_n4 (open, x 22.5..23.5), facing north, and launches scout1
through the door into room n4 (x 20..26, y 1.25..6.25; dark corner at (20.6, 5.65)), where intruder1 walks
from t = 22 s to 38 s (from the door to (24, 4.5) and back). The Ranger's odometry starts at its world pose,
so odometry coordinates are world coordinates up to the noise.
"""

from __future__ import annotations

import dataclasses
import math

import pytest

from components.behaviors.locate_dark_corner import LocateDarkCorner, wrap
from components.behaviors.observe import Observe
from components.behaviors.servo_to_goal import ServoToGoal
from components.behaviors.turn_to_watch import TurnToWatch
from components.behaviors.watch import Watch
from drd.hw.drivers import drivers_for
from drd.runtime.component import Status
from drd.sim.physics import Simulation
from tests.component_support import Rig

SCOUT = {"camera": ("scout1", "camera"), "drive": ("scout1", "wheels"), "radio": ("scout1", "radio")}
N4 = (20.0, 1.25, 26.0, 6.25)


def in_rect(x: float, y: float, rect: tuple[float, float, float, float]) -> bool:
    return rect[0] <= x <= rect[2] and rect[1] <= y <= rect[3]


@pytest.fixture
def rig() -> Rig:
    """scout1 landed in room n4, about (22.5, 3.1), facing north-north-west."""
    rig = Rig()
    world = rig.sim.world
    ranger = dataclasses.replace(world.rangers[0], x=23.4, y=-0.6, heading=math.pi / 2)
    rig.sim = Simulation(dataclasses.replace(world, rangers=(ranger,)), seed=1)
    rig.drivers = drivers_for(rig.cluster, "ranger1", rig.sim, catalog=rig.catalog)
    rig.sim.launch("scout1", 0.25, 3.8)
    rig.sim.run_until(1.0)
    p = rig.sim.pose("scout1")
    assert in_rect(p.x, p.y, N4), p
    return rig


def steps(rig: Rig, comp, seconds: float, period: float = 0.1) -> Status:
    """Step sim and component without terminating it (Rig.run terminates)."""
    status = Status.RUNNING
    end = rig.sim.time + seconds
    while rig.sim.time < end - 1e-9 and status is Status.RUNNING:
        rig.sim.step(period)
        status = comp.step(rig.sim.time)
    return status


def face(rig: Rig, heading: float) -> None:
    comp = rig.start(TurnToWatch, needs={"drive": SCOUT["drive"]}, params={"heading": heading})
    assert rig.run(comp, until=rig.sim.time + 15) is Status.SUCCESS


def test_locate_dark_corner_finds_a_dark_bearing(rig):
    comp = rig.start(LocateDarkCorner, needs=SCOUT, params={"max_light": 0.2})
    assert rig.run(comp, until=20.0) is Status.SUCCESS
    goal = comp.ctx.outputs["goal"]
    assert goal["light"] <= 0.2
    assert in_rect(goal["x"], goal["y"], N4)
    assert rig.sim.light(goal["x"], goal["y"]) < 0.3  # the true light there: dark (n4 is lit at 0.65)
    assert math.hypot(goal["x"] - 20.6, goal["y"] - 5.65) < 1.0  # near n4's dark corner
    assert rig.sim.command("scout1") == (0.0, 0.0)


def test_locate_dark_corner_fails_when_nothing_is_dark_enough(rig):
    comp = rig.start(LocateDarkCorner, needs=SCOUT, params={"max_light": 0.01})
    assert rig.run(comp, until=20.0) is Status.FAILURE
    assert "goal" not in comp.ctx.outputs


def test_servo_to_goal_reaches_the_dark_corner(rig):
    locate = rig.start(LocateDarkCorner, needs=SCOUT)
    assert rig.run(locate, until=20.0) is Status.SUCCESS
    goal = locate.ctx.outputs["goal"]
    servo = rig.start(ServoToGoal, needs=SCOUT, inputs={"goal": goal})
    assert rig.run(servo, until=rig.sim.time + 30) is Status.SUCCESS
    x, y, _ = rig.drivers.robots["scout1"]["wheels"].odometry()
    assert math.hypot(goal["x"] - x, goal["y"] - y) <= 0.3
    p = rig.sim.pose("scout1")
    assert rig.sim.light(p.x, p.y) < 0.3  # hidden in the dark
    assert rig.sim.command("scout1") == (0.0, 0.0)


def test_servo_to_goal_stops_and_waits_while_the_link_is_lost(rig):
    servo = rig.start(ServoToGoal, needs=SCOUT, inputs={"goal": {"x": 21.0, "y": 5.2}})
    assert steps(rig, servo, 2.0) is Status.RUNNING
    assert rig.sim.command("scout1") != (0.0, 0.0)
    rig.sim.lose("ranger1")  # no Ranger, no proxy processing
    assert not rig.drivers.robots["scout1"]["radio"].link_ok()
    assert steps(rig, servo, 0.2) is Status.RUNNING
    before = rig.sim.pose("scout1")
    assert steps(rig, servo, 3.0) is Status.RUNNING
    after = rig.sim.pose("scout1")
    assert rig.sim.command("scout1") == (0.0, 0.0)
    assert math.hypot(after.x - before.x, after.y - before.y) < 0.02
    assert any("link lost" in line for line in rig.logs)


def test_turn_to_watch_faces_the_given_heading_or_the_brightest_bearing(rig):
    face(rig, 0.0)
    assert abs(wrap(rig.drivers.robots["scout1"]["wheels"].odometry()[2])) <= 0.06
    comp = rig.start(TurnToWatch, needs={"drive": SCOUT["drive"], "camera": SCOUT["camera"]})
    assert rig.run(comp, until=rig.sim.time + 30) is Status.SUCCESS
    assert rig.sim.command("scout1") == (0.0, 0.0)
    ahead = rig.drivers.robots["scout1"]["camera"].brightness(1)[0]
    assert ahead >= 0.6  # the lit room, not the dark corner


def test_watch_reports_the_intruder_walking_through_the_room(rig):
    face(rig, 0.2)  # towards the intruder's path, from the door to (24, 4.5)
    rig.sim.run_until(22.0)
    watch = rig.start(Watch, needs={"camera": SCOUT["camera"], "drive": SCOUT["drive"]}, params={"duration": 12.0})
    assert rig.run(watch, until=40.0) is Status.SUCCESS
    assert 34.0 - 0.11 <= rig.sim.time <= 34.0 + 0.11
    motion = [f for name, f in rig.events if name == "MotionDetected"]
    assert len(motion) >= 3, rig.events
    truth = [(t, x, y) for t, x, y in rig.sim.trajectory("intruder1") if 22.0 <= t <= 34.0]
    for f in motion:
        assert 0.05 <= f["area"] <= 1.0
        assert in_rect(f["x"], f["y"], N4)
        assert min(math.hypot(f["x"] - x, f["y"] - y) for _, x, y in truth) < 0.5  # on the true path


def test_watch_never_sees_an_intruder_behind_a_wall(rig):
    face(rig, math.pi)  # west, towards n3 through the wall x = 20, where intruder1 walks until t = 8 s
    start = rig.sim.time
    watch = rig.start(Watch, needs={"camera": SCOUT["camera"], "drive": SCOUT["drive"]}, params={"duration": 3.0})
    seen_through_wall = 0
    status = Status.RUNNING
    while status is Status.RUNNING:
        rig.sim.step(0.1)
        status = watch.step(rig.sim.time)
        p, (ix, iy) = rig.sim.pose("scout1"), rig.sim.intruders()["intruder1"]
        bearing = wrap(math.atan2(iy - p.y, ix - p.x) - p.heading)
        seen_through_wall += abs(bearing) < math.radians(40) and math.hypot(ix - p.x, iy - p.y) < 10
    assert rig.sim.time - start == pytest.approx(3.0, abs=0.01) and rig.sim.time < 8.0
    assert seen_through_wall > 10  # in the field of view and in range, but behind the wall
    assert not [e for e in rig.events if e[0] == "MotionDetected"]


def test_observe_counts_frames(rig):
    comp = rig.start(Observe, needs={"camera": SCOUT["camera"]}, params={"duration": 5.0})
    assert rig.run(comp, until=rig.sim.time + 10) is Status.SUCCESS
    assert comp.ctx.outputs["observation"] == {"frames": 50}


def test_servo_to_goal_succeeds_when_a_wall_stops_it_short_of_the_goal(rig):
    """A dark corner's goal is a guess along a bearing, often beyond the walls: pressed into them is arrived."""
    servo = rig.start(ServoToGoal, needs=SCOUT, inputs={"goal": {"x": 22.5, "y": 9.0}})  # behind n4's back wall
    assert rig.run(servo, until=rig.sim.time + 40) is Status.SUCCESS
    p = rig.sim.pose("scout1")
    assert p.y > 5.8, p  # at the back wall (y = 6.25), not in the middle of the room
    assert rig.sim.command("scout1") == (0.0, 0.0)
    assert any("short of the goal: as close as it gets" in line for line in rig.logs)
