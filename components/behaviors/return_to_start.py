"""ReturnToStart: drive back to where the mission started, along odometry.

Home is, in order: the `home` parameter ((x, y) in odometry coordinates), the pose this robot's first
Ranger behavior recorded in the shared data (`home[<drive resource>]`, see `remember_home`), else the
odometry origin (0, 0). It turns toward home, drives, slows down for what the front beams show, and
succeeds within ARRIVED metres.
"""

from __future__ import annotations

import math

from components.behaviors.follow_corridor import remember_home, wrap
from drd.runtime.component import Component, Status

ARRIVED = 0.3
K_TURN = 1.5
#: Body clearance kept ahead (m): the Ranger's radius plus a margin.
BODY = 0.45


class ReturnToStart(Component):
    def start(self) -> None:
        home = self.ctx.params.get("home")
        if home is None:
            homes = self.shared("home")
            home = homes.get(self.ctx.resources.get("drive", "drive")) if isinstance(homes, dict) else None
        self.home = tuple(home) if home is not None else (0.0, 0.0)
        remember_home(self)

    def step(self, now: float) -> Status:
        speed = float(self.ctx.params.get("speed", 0.5))
        drive = self.device("drive")
        x, y, a = drive.odometry()
        dx, dy = self.home[0] - x, self.home[1] - y
        dist = math.hypot(dx, dy)
        if dist < ARRIVED:
            drive.stop()
            return Status.SUCCESS
        err = wrap(math.atan2(dy, dx) - a)
        omega = max(-1.0, min(1.0, K_TURN * err))
        v = 0.0 if abs(err) > 0.6 else min(speed, 0.8 * dist) * math.cos(err)
        if v > 0 and "ranges" in self.ctx.devices:
            scan = self.device("ranges").scan()
            ahead = [r * math.cos(scan.angle(i)) for i, r in enumerate(scan.ranges)
                     if abs(scan.angle(i)) < math.pi / 2 and abs(r * math.sin(scan.angle(i))) < BODY - 0.1]
            free = min(ahead, default=scan.max_range) - BODY
            v = max(0.0, min(v, free))
        drive.set_velocity(v, omega)
        return Status.RUNNING

    def suspend(self) -> None:
        self.device("drive").stop()

    def terminate(self, status: Status) -> None:
        self.device("drive").stop()
