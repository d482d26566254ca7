"""What a real-robot host serves a recording client (`drd.cluster.observe.DriverTap`): each new scan a behavior reads,
once, at most one a control cycle; each robot's pose as its Drive reads it; a Drive that cannot say is left out."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from drd.cluster.observe import DriverTap
from drd.hw.interfaces import HardwareError, Scan
from drd.sim.service import WorldObserve


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class Laser:
    def __init__(self) -> None:
        self.latest = Scan((1.0, 8.0, 2.0), -math.pi / 2, math.pi / 2, 8.0)

    def scan(self) -> Scan:
        return self.latest


class Drive:
    def __init__(self, pose: tuple[float, float, float] | None) -> None:
        self.pose = pose

    def odometry(self) -> tuple[float, float, float]:
        if self.pose is None:
            raise HardwareError("no message on /ranger2/odom")
        return self.pose

    def set_velocity(self, v: float, omega: float) -> None:
        raise AssertionError("never commanded by the tap")


@dataclass
class Drivers:
    robots: dict[str, dict[str, object]] = field(default_factory=dict)


def test_each_new_scan_is_kept_once_at_most_one_a_control_cycle() -> None:
    clock, laser = Clock(), Laser()
    tap = DriverTap(clock)
    tap.attach(Drivers({"ranger1": {"ranges": laser}}))
    first = laser.scan()
    assert first is laser.latest  # the behavior still gets the driver's own scan
    clock.t = 100.2
    laser.scan()  # the same scan again, two cycles later: not kept twice
    laser.latest = Scan((3.0, 3.0, 3.0), -math.pi / 2, math.pi / 2, 8.0)
    clock.t = 100.22
    laser.scan()
    laser.latest = Scan((4.0, 4.0, 4.0), -math.pi / 2, math.pi / 2, 8.0)
    clock.t = 100.25
    laser.scan()  # a new one, but within the control cycle of the last kept: left out
    clock.t = 100.35
    laser.scan()
    reply = tap.observe(WorldObserve(0))
    scans = [r for r in reply.readings if r["reading"] == "scan"]
    assert [(s["at"], s["ranges"]) for s in scans] == [(100.0, [1.0, 8.0, 2.0]), (100.22, [3.0, 3.0, 3.0]),
                                                           (100.35, [4.0, 4.0, 4.0])]
    assert scans[0]["robot"] == "ranger1" and scans[0]["max_range"] == 8.0 and scans[0]["fov"] == math.pi
    assert tap.observe(WorldObserve(reply.next)).readings == []  # a reader's cursor goes on from `next`
    beyond = tap.observe(WorldObserve(10 ** 30))  # wire audit 10, D4: echoed back, no encoder could write it
    assert beyond.readings == [] and beyond.next == reply.next
    from drd.bus import decode, encode

    assert decode(encode(beyond)) == beyond


def test_poses_are_what_each_drive_reads_now_and_a_drive_that_cannot_say_is_left_out() -> None:
    clock = Clock()
    tap = DriverTap(clock)
    tap.attach(Drivers({"ranger1": {"drive": Drive((2.0, 0.5, 0.1))}, "ranger2": {"drive": Drive(None)}}))
    reply = tap.observe(WorldObserve(0))
    assert reply.poses == {"ranger1": [2.0, 0.5, 0.1]} and reply.time == 100.0
    tap.attach(Drivers({"ranger3": {"drive": Drive((0.0, 0.0, 0.0))}}))  # a new world: the old drivers are gone
    assert tap.observe(WorldObserve(0)).poses == {"ranger3": [0.0, 0.0, 0.0]}
