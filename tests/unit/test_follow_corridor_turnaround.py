"""FollowCorridor started near a corridor's end and facing it, off the centre line (review of today's changes): it
turns around and leaves, on a kinematic robot whose scans are cast against the corridor (`test_scan_geometry.cast`).
Its expected wall distances from before the turn (left and right swapped by it) held it spinning for 25-30 s."""

from __future__ import annotations

import math

import pytest

from components.behaviors.follow_corridor import FollowCorridor
from drd.hw.interfaces import Scan
from drd.runtime.component import Context, Status
from tests.unit.test_scan_geometry import cast

#: A corridor 2.5 m wide along x (y = -1.25..1.25), its end wall at x = 2, open far to -x.
WORLD = [((-30.0, 1.25), (2.0, 1.25)), ((-30.0, -1.25), (2.0, -1.25)), ((2.0, -1.25), (2.0, 1.25))]


class Robot:
    """A unicycle: its odometry is its true pose, its laser casts WORLD from it."""

    def __init__(self, x: float, y: float, a: float) -> None:
        self.x, self.y, self.a, self.v, self.w = x, y, a, 0.0, 0.0

    def odometry(self) -> tuple[float, float, float]:
        return self.x, self.y, self.a

    def set_velocity(self, v: float, w: float) -> None:
        self.v, self.w = v, w

    def stop(self) -> None:
        self.v = self.w = 0.0

    def scan(self) -> Scan:
        c, s = math.cos(-self.a), math.sin(-self.a)
        seen = [((c * (ax - self.x) - s * (ay - self.y), s * (ax - self.x) + c * (ay - self.y)),
                 (c * (bx - self.x) - s * (by - self.y), s * (bx - self.x) + c * (by - self.y)))
                for (ax, ay), (bx, by) in WORLD]
        return cast(seen, far=10.0)

    def move(self, dt: float) -> None:
        self.a += self.w * dt
        self.x += self.v * math.cos(self.a) * dt
        self.y += self.v * math.sin(self.a) * dt


@pytest.mark.parametrize("off", [0.0, 0.3, 0.4])
def test_started_facing_the_end_it_turns_around_and_leaves(off: float) -> None:
    robot = Robot(0.7, off, 0.0)
    fc = FollowCorridor()
    fc.setup(Context("t", {"speed": 0.5}, {}, lambda *a, **k: None, lambda text: None, lambda: 0.0,
                     devices={"drive": robot, "ranges": robot}))
    fc.start()
    t = 0.0
    while t < 15.0:
        assert fc.step(t) is Status.RUNNING
        robot.move(0.1)
        t += 0.1
    assert robot.x < -2.0, (robot.x, robot.y, math.degrees(robot.a))  # 3 m back up the corridor within 15 s
