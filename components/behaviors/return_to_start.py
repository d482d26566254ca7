"""ReturnToStart: drive back to where the mission started, along odometry.

Home is where the robot's odometry began (`Drive.origin()`: where the robot was put when the world started,
on a real robot where it was switched on), else the odometry origin (0, 0). Nothing is read from other
components by name. It turns toward home, drives, slows down for what the front beams show, and succeeds
within ARRIVED metres, or when blocked within NEAR metres of home (odometry drift).
"""

from __future__ import annotations

import math

from components.behaviors.progress import Progress, allowance
from components.behaviors.scan import clearance_ahead, wrap
from drd.runtime.component import Component, Status

ARRIVED = 0.3
#: Blocked this close to home (m) counts as arrived: after a long drive, odometry drifts by that much.
NEAR = 1.5
K_TURN = 1.5
#: Body clearance kept ahead (m): the Ranger's radius plus a margin.
BODY = 0.45


class ReturnToStart(Component):
    def start(self) -> None:
        origin = getattr(self.device("drive"), "origin", None)
        self.home = tuple(origin())[:2] if callable(origin) else (0.0, 0.0)
        self.progress = Progress(allowance=allowance(float(self.ctx.params["speed"])))  # how much nearer home

    def resume(self) -> None:
        self.progress.reset()

    def step(self, now: float) -> Status:
        speed = float(self.ctx.params["speed"])
        drive = self.device("drive")
        x, y, a = drive.odometry()
        dx, dy = self.home[0] - x, self.home[1] - y
        dist = math.hypot(dx, dy)
        if dist < ARRIVED:
            drive.stop()
            return Status.SUCCESS
        if self.progress.stalled(now, -dist):  # behind something it cannot get round (worlds audit 13, D1)
            drive.stop()
            self.ctx.log(f"ReturnToStart: {self.progress.says('nearer home')}, {dist:.2f} m away: something is in the"
                         " way")
            return Status.FAILURE
        err = wrap(math.atan2(dy, dx) - a)
        omega = max(-1.0, min(1.0, K_TURN * err))
        v = 0.0 if abs(err) > 0.6 else min(speed, 0.8 * dist) * math.cos(err)
        if v > 0 and "ranges" in self.ctx.devices:
            free = clearance_ahead(self.device("ranges").scan(), BODY - 0.1) - BODY
            if free <= 0.02 and dist < NEAR:  # odometry drift put home behind the wall: this is home
                drive.stop()
                self.ctx.log(f"home is {dist:.2f} m on, behind what is in the way: stopping here")
                return Status.SUCCESS
            v = max(0.0, min(v, free))
        drive.set_velocity(v, omega)
        return Status.RUNNING

    def suspend(self) -> None:
        self.device("drive").stop()

    def terminate(self, status: Status) -> None:
        self.device("drive").stop()
