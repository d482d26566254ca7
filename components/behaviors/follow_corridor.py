"""FollowCorridor: keep to the middle of the corridor from the side ranges, driving forward.

Computed in the robot frame from a `Scan` and from odometry, never from ground truth; the scan geometry (wall
fits, clearance, the end wall) is `components.behaviors.scan`, shared with the other perception behaviors.
"""

from __future__ import annotations

import math

from components.behaviors.scan import END, ScanMemo, clearance_ahead, corridor, expected, wall_across, wrap
from drd.runtime.component import Component, Status

#: Gains of the P controller: rad/s per metre off the centre line, and per radian of heading error.
K_LATERAL = 1.2
K_HEADING = 2.0
MAX_OMEGA = 1.0
#: Turning around: rate (rad/s), and how close to the reverse heading (rad) counts as turned.
TURN_RATE, TURNED = 0.8, 0.15


class FollowCorridor(Component):
    """Drive forward at `speed`, steering to the centre line and along the walls, to the end of the corridor.

    The end is a wall across the way less than `END` metres ahead: then it stops and succeeds. Something
    narrower in the way (a person) only stops it until it has passed.
    Started facing an end (a Ranger left there by the previous sweep), it first turns around on the spot.
    """

    def start(self) -> None:
        self.width: float | None = None
        self.expect: tuple[float | None, float | None] = (None, None)
        self.origin: tuple[float, float] | None = None
        self.turn_to: float | None = None  # heading to turn to, when turning around
        self.memo = ScanMemo()  # what the scan helpers derive from this cycle's scan

    def step(self, now: float) -> Status:
        speed = float(self.ctx.params["speed"])
        drive = self.device("drive")
        scan = self.device("ranges").scan()
        x, y, a = drive.odometry()
        if self.turn_to is not None:
            if abs(wrap(self.turn_to - a)) > TURNED:
                drive.set_velocity(0.0, TURN_RATE)
                return Status.RUNNING
            self.turn_to, self.origin = None, (x, y)
        if self.origin is None:
            self.origin = (x, y)
        blocked = clearance_ahead(scan, memo=self.memo) < END
        if blocked and wall_across(scan, memo=self.memo):
            if math.hypot(x - self.origin[0], y - self.origin[1]) < 0.5:  # started facing the end
                self.turn_to = wrap(a + math.pi)
                drive.set_velocity(0.0, TURN_RATE)
                return Status.RUNNING
            drive.stop()
            self.ctx.log("end of the corridor")
            return Status.SUCCESS
        left, right = fitted = corridor(scan, self.expect, memo=self.memo)
        self.expect = expected(fitted, self.expect)
        walls = [w for w in (left, right) if w is not None]
        heading = sum(w.angle for w in walls) / len(walls) if walls else 0.0  # the corridor's direction
        offset = 0.0  # how far left of the centre line the robot is
        if left and right:
            self.width = left.distance + right.distance
            offset = (right.distance - left.distance) / 2
        elif self.width and left:
            offset = self.width / 2 - left.distance
        elif self.width and right:
            offset = right.distance - self.width / 2
        omega = K_HEADING * heading - K_LATERAL * offset
        omega = max(-MAX_OMEGA, min(MAX_OMEGA, omega))
        # something narrower than the corridor in the way (a person, or a wall we are angled into): turn on the
        # spot as the walls say and wait for the way to clear
        drive.set_velocity(0.0 if blocked else speed, omega)
        return Status.RUNNING

    def suspend(self) -> None:
        self.device("drive").stop()

    def terminate(self, status: Status) -> None:
        self.device("drive").stop()
