"""The Ranger's elementary behaviors against the simulator (tests/component_support.Rig).

Ground truth (`rig.sim.pose`) is used for the assertions only; the behaviors see ranges and odometry.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import yaml

from components.behaviors.align_ranger import AlignRanger
from components.behaviors.avoid_obstacles import AvoidObstacles
from components.behaviors.calibrate import Calibrate
from components.behaviors.detect_door import DetectDoor
from components.behaviors.follow_corridor import FollowCorridor, wrap
from components.behaviors.launch_scout import LaunchScout
from components.behaviors.return_to_start import ReturnToStart
from drd.runtime.component import Status
from tests.component_support import Rig

ROOT = Path(__file__).resolve().parents[2]
RANGER = {"drive": ("ranger1", "drive"), "ranges": ("ranger1", "ranges")}


def doors() -> list[dict]:
    return yaml.safe_load((ROOT / "worlds" / "corridor.yaml").read_text())["doors"]


def test_follow_corridor_keeps_to_the_middle():
    rig = Rig()
    comp = rig.start(FollowCorridor, needs=RANGER, params={"speed": 0.6})
    worst = 0.0
    while rig.sim.time < 38.0:
        rig.sim.step(0.1)
        assert comp.step(rig.sim.time) is Status.RUNNING
        p = rig.sim.pose("ranger1")
        if rig.sim.time > 2.0:
            worst = max(worst, abs(p.y))
        if p.x > 22.0:
            break
    comp.terminate(Status.SUCCESS)
    p = rig.sim.pose("ranger1")
    assert p.x > 21.0, p
    assert worst < 0.15, worst


def run_all(rig: Rig, comps: list, until: float, stop=None) -> None:
    """Step the simulation and `comps` (in layer order) at 10 Hz until `until` or `stop(statuses)`."""
    while rig.sim.time < until:
        rig.sim.step(0.1)
        statuses = [c.step(rig.sim.time) for c in comps]
        if stop and stop(statuses):
            return


def detect(rig: Rig, until: float = 40.0) -> tuple[Status, DetectDoor]:
    follow = rig.start(FollowCorridor, needs=RANGER, params={"speed": 0.6})
    det = rig.start(DetectDoor, needs=RANGER)  # drive: the odometry the door position is given in
    run_all(rig, [follow, det], until, stop=lambda s: s[1] is not Status.RUNNING)
    follow.terminate(Status.SUCCESS)
    status = Status.SUCCESS if "door" in det.ctx.outputs else Status.RUNNING
    det.terminate(status)
    return status, det


def matching_door(found: dict) -> dict:
    return min(doors(), key=lambda d: math.dist(d["at"], (found["x"], found["y"])))


def test_detect_door_finds_the_first_open_door():
    rig = Rig()
    rig.inputs["visited"] = {}
    status, det = detect(rig)
    assert status is Status.SUCCESS
    found = det.ctx.outputs["door"]
    door = matching_door(found)
    assert door["id"] == "door_n1" and door["state"] == "open"
    assert abs(found["x"] - 4.0) < 0.15 and abs(found["y"] - 1.25) < 0.15 and found["side"] == "left"
    assert abs(found["width"] - 1.0) < 0.15
    assert rig.events == [("DoorDetected", {"width": found["width"], "x": found["x"], "y": found["y"]})]
    assert len(rig.inputs["visited"]) == 1


def test_detect_door_skips_known_doors_and_never_finds_a_closed_one():
    rig = Rig()
    rig.inputs["visited"] = {}
    found = []
    for _ in range(3):
        status, det = detect(rig, until=rig.sim.time + 30.0)
        assert status is Status.SUCCESS
        found.append(matching_door(det.ctx.outputs["door"]))
    # n1 (x=4) is skipped once in the DoorLog; s1 (5), n2 and s3 are closed: next are s2 (11, right), n3 (17)
    assert [d["id"] for d in found] == ["door_n1", "door_s2", "door_n3"]
    assert all(d["state"] == "open" for d in found)
    assert len(rig.inputs["visited"]) == 3


def test_detect_door_skips_a_door_already_in_the_doorlog():
    rig = Rig()
    rig.inputs["visited"] = {(4.0, "left"): {"width": 1.0, "x": 4.0, "y": 1.25, "side": "left"}}
    status, det = detect(rig, until=25.0)
    assert status is Status.SUCCESS
    assert matching_door(det.ctx.outputs["door"])["id"] == "door_s2"


def test_align_ranger_faces_the_door_it_is_given():
    rig = Rig()
    rig.inputs["visited"] = {}
    _, det = detect(rig)
    align = rig.start(AlignRanger, needs=RANGER, params={"tolerance": 0.05}, inputs={"door": det.ctx.outputs["door"]})
    assert rig.run(align, until=rig.sim.time + 10.0) is Status.SUCCESS
    p = rig.sim.pose("ranger1")
    bearing = math.atan2(1.25 - p.y, 4.0 - p.x)
    assert abs(p.heading - bearing) < 0.1, (p, bearing)


def test_align_ranger_fails_without_a_door():
    rig = Rig()
    align = rig.start(AlignRanger, needs=RANGER)
    assert rig.run(align, until=1.0) is Status.FAILURE


def test_launch_scout_lands_in_the_room_behind_the_open_door():
    rig = Rig()
    rig.inputs["visited"] = {}
    _, det = detect(rig)
    rig.run(rig.start(AlignRanger, needs=RANGER, inputs={"door": det.ctx.outputs["door"]}), until=rig.sim.time + 10.0)
    launch = rig.start(LaunchScout, needs={"launcher": ("ranger1", "launcher"), "ranges": ("ranger1", "ranges")},
                       robots={"scout": "scout1"})
    assert rig.run(launch, until=rig.sim.time + 1.0) is Status.SUCCESS
    scout = launch.ctx.outputs["scout"]
    assert scout == "scout1"
    name, fields = rig.events[-1]
    assert name == "ScoutLaunched" and fields["scout"] == "scout1" and 1.5 < fields["distance"] <= 6.0
    rig.sim.run_until(rig.sim.time + 5.0)
    p = rig.sim.pose("scout1")
    assert 2.0 < p.x < 8.0 and 1.25 < p.y < 6.25, p  # room n1
    assert rig.sim.magazine("ranger1") == ("scout2", "scout3", "scout4", "scout5", "scout6")


def test_launch_scout_before_a_closed_door_says_what_is_in_the_way():
    """Worlds audit 17, D9: a door closed between its detection and the launch failed the instance with "target out
    of range (0.79 m)", which read as the launcher's range. Turned to face the corridor's end wall 1 m behind it (a
    closed door is a wall to the laser too), it says something is in the way, and throws nothing."""
    rig = Rig()
    rig.sim.set_velocity("ranger1", 0.0, 1.0)
    rig.sim.run_until(math.pi)
    rig.sim.set_velocity("ranger1", 0.0, 0.0)
    assert abs(abs(rig.sim.pose("ranger1").heading) - math.pi) < 0.2  # facing the west end, 1 m away
    launch = rig.start(LaunchScout, needs={"launcher": ("ranger1", "launcher"), "ranges": ("ranger1", "ranges")},
                       robots={"scout": "scout1"})
    assert rig.run(launch, until=rig.sim.time + 1.0) is Status.FAILURE
    assert re.search(r"LaunchScout: something [01]\.\d\d m ahead \(a closed or blocked door, a wall\): no room for a "
                     r"throw of at least 1\.5 m", rig.logs[-1]), rig.logs
    assert rig.sim.magazine("ranger1")[0] == "scout1"


def test_launch_scout_throws_only_the_scout_it_holds():
    """Bound to scout2, it throws scout2 (not the magazine's first); bound to a Scout out of the magazine, it fails
    saying so, throwing none (safety audit 7, D1)."""
    rig = Rig()
    launch = rig.start(LaunchScout, needs={"launcher": ("ranger1", "launcher")}, robots={"scout": "scout2"})
    assert rig.run(launch, until=1.0) is Status.SUCCESS and launch.ctx.outputs["scout"] == "scout2"
    launch = rig.start(LaunchScout, needs={"launcher": ("ranger1", "launcher")}, robots={"scout": "scout2"})
    assert rig.run(launch, until=rig.sim.time + 1.0) is Status.FAILURE
    assert "scout2, the robot it holds, is not in its launcher's magazine" in rig.logs[-1], rig.logs
    assert rig.sim.magazine("ranger1") == ("scout1", "scout3", "scout4", "scout5", "scout6")


def test_launch_scout_fails_on_an_empty_magazine():
    rig = Rig()
    for sid in rig.sim.magazine("ranger1"):
        rig.sim.launch(sid, 0.0, 1.0)
    launch = rig.start(LaunchScout, needs={"launcher": ("ranger1", "launcher")})
    assert rig.run(launch, until=1.0) is Status.FAILURE
    assert not [e for e in rig.events if e[0] == "ScoutLaunched"]


def test_calibrate_measures_the_corridor_width():
    rig = Rig()
    cal = rig.start(Calibrate, needs={"ranges": ("ranger1", "ranges")}, params={"samples": 20})
    assert rig.run(cal, until=5.0) is Status.SUCCESS
    assert abs(cal.ctx.outputs["width"] - 2.5) < 0.03
    assert 0.0 < cal.ctx.outputs["noise"] < 0.03
    assert rig.sim.time < 2.5


def test_return_to_start_drives_back_home():
    rig = Rig()
    follow = rig.start(FollowCorridor, needs=RANGER, params={"speed": 0.6})  # home: where its odometry began
    rig.run(follow, until=10.0)
    assert rig.sim.pose("ranger1").x > 6.0
    back = rig.start(ReturnToStart, needs=RANGER)
    assert rig.run(back, until=40.0) is Status.SUCCESS
    p = rig.sim.pose("ranger1")
    assert math.dist((p.x, p.y), (1.0, 0.0)) < 0.4, p


def test_avoid_obstacles_stops_short_of_a_wall():
    rig = Rig()
    drive = rig.drivers.robots["ranger1"]["drive"]
    drive.set_velocity(0.0, 1.0)
    rig.sim.run_until(math.pi / 2)  # face the north wall, 1.25 m away
    avoid = rig.start(AvoidObstacles, needs=RANGER, params={"margin": 0.3})
    turned = False
    while rig.sim.time < 8.0:
        drive.set_velocity(0.4, 0.0)  # the layer below drives straight on
        avoid.step(rig.sim.time)  # the later layer wins when it commands
        turned |= avoid.ctx.outputs["avoiding"]
        rig.sim.step(0.1)
        p = rig.sim.pose("ranger1")
        assert p.y < 1.25 - 0.3 - 0.05, p
    assert turned


def test_follow_corridor_ends_at_the_end_wall_and_turns_round_when_it_starts_there():
    rig = Rig()
    comp = rig.start(FollowCorridor, needs=RANGER, params={"speed": 0.8})
    assert rig.run(comp, until=80.0) is Status.SUCCESS
    p = rig.sim.pose("ranger1")
    assert p.x > 38.0 and abs(p.y) < 0.4, p  # the east end wall is at x = 40
    assert any("end of the corridor" in line for line in rig.logs)
    back = rig.start(FollowCorridor, needs=RANGER, params={"speed": 0.8})
    rig.run(back, until=rig.sim.time + 12.0)
    q = rig.sim.pose("ranger1")
    assert q.x < p.x - 3.0 and abs(math.cos(q.heading) + 1) < 0.1, q  # turned round, heading west


def test_detect_door_fails_at_the_end_of_the_corridor_when_every_door_is_known():
    rig = Rig()
    rig.inputs["visited"] = {(round(x), "any"): {"x": x, "y": y, "width": 1.0} for x, y in
                             ((4.0, 1.25), (11.0, -1.25), (17.0, 1.25), (23.0, 1.25), (29.0, -1.25), (35.0, -1.25))}
    follow = rig.start(FollowCorridor, needs=RANGER, params={"speed": 0.8})
    det = rig.start(DetectDoor, needs=RANGER)
    statuses: list[Status] = []
    run_all(rig, [follow, det], 80.0, stop=lambda s: statuses.append(s[1]) or s[1] is not Status.RUNNING)
    assert statuses[-1] is Status.FAILURE and "door" not in det.ctx.outputs
    assert rig.sim.pose("ranger1").x > 38.0
    assert any("the corridor ends here, with no new door" in line for line in rig.logs)


def test_detect_door_started_facing_a_wall_sweeps_back_and_fails_only_at_the_far_end():
    """Generated buildings (docs audit 4): a Ranger left facing a wall (at an end, or launched from askew) failed
    every instance that drew it in the first step, before FollowCorridor could turn it round: 203 of 950 instances
    at 50 wings. Now the sweep back goes on; with every door known it ends at the other end, having moved."""
    rig = Rig()
    rig.inputs["visited"] = {(round(x), "any"): {"x": x, "y": y, "width": 1.0} for x, y in
                             ((4.0, 1.25), (11.0, -1.25), (17.0, 1.25), (23.0, 1.25), (29.0, -1.25), (35.0, -1.25))}
    out = rig.start(FollowCorridor, needs=RANGER, params={"speed": 0.8})
    assert rig.run(out, until=80.0) is Status.SUCCESS and rig.sim.pose("ranger1").x > 38.0  # at the east end
    follow = rig.start(FollowCorridor, needs=RANGER, params={"speed": 0.8})
    det = rig.start(DetectDoor, needs=RANGER)
    statuses: list[Status] = []
    run_all(rig, [follow, det], rig.sim.time + 120.0,
            stop=lambda s: statuses.append(s[1]) or s[1] is not Status.RUNNING)
    assert statuses[0] is Status.RUNNING and statuses[-1] is Status.FAILURE, statuses[:3]
    assert rig.sim.pose("ranger1").x < 2.0  # the west end: it swept the whole corridor back
    assert sum("the corridor ends here, with no new door" in line for line in rig.logs) == 1


def test_align_ranger_drives_back_to_where_its_door_was_seen():
    rig = Rig()
    rig.inputs["visited"] = {}
    status, det = detect(rig)
    assert status is Status.SUCCESS
    door = det.ctx.outputs["door"]
    follow = rig.start(FollowCorridor, needs=RANGER)  # another instance drives the Ranger on, 3 m
    rig.run(follow, until=rig.sim.time + 7.0)
    follow.terminate(Status.SUCCESS)
    assert rig.sim.pose("ranger1").x > door["from"]["x"] + 2.0
    align = rig.start(AlignRanger, needs=RANGER, inputs={"door": door})
    assert rig.run(align, until=rig.sim.time + 30.0) is Status.SUCCESS
    p = rig.sim.pose("ranger1")
    assert math.hypot(p.x - door["from"]["x"], p.y - door["from"]["y"]) < 0.35, p
    assert abs(wrap(math.atan2(door["y"] - p.y, door["x"] - p.x) - p.heading)) < 0.1


def test_launch_scout_clears_the_property_that_names_the_carrier():
    """Users audit 15, D4: only a property named `carrier` was cleared at a launch; a team's carried robot that says
    `mothership` stayed aboard for every `where`. `carrier_property` names it."""
    import dataclasses

    for params, key in (({}, "carrier"), ({"carrier_property": "mothership"}, "mothership")):
        rig = Rig()
        launch = rig.start(LaunchScout, needs={"launcher": ("ranger1", "launcher")}, robots={"scout": "scout1"},
                           params=params)
        updates: list[tuple[str, str, object]] = []
        launch.ctx.services = dataclasses.replace(launch.ctx.services, dependencies=lambda r, k, v, out=updates:
                                                  out.append((r, k, v)))
        assert rig.run(launch, until=1.0) is Status.SUCCESS
        assert updates == [("scout1", key, "")]
