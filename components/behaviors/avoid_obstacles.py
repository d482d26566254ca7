"""AvoidObstacles: when something is within `margin` of the Ranger's body straight ahead, stop and turn toward
the more open side; otherwise command nothing (the layer below, e.g. FollowCorridor, keeps the drive).

Clearance is measured from the body: a range beam reads from the robot's centre, so BODY (the Ranger's
radius) is subtracted. Only points inside the swept path (|lateral| < BODY) count.
"""

from __future__ import annotations

from components.behaviors.scan import nearest_in_path, openness
from drd.runtime.component import Component, Status

BODY = 0.3
TURN = 0.8
#: The sector (rad, open) whose openness tells the left side from the right (mirrored).
SIDE = (0.2, 1.4)


class AvoidObstacles(Component):
    def step(self, now: float) -> Status:
        margin = float(self.ctx.params["margin"])
        scan = self.device("ranges").scan()
        # the nearest reading ahead inside the swept path (x > 0, |y| < BODY), and how open each side is
        ahead = nearest_in_path(scan, BODY)
        left, right = openness(scan, *SIDE), openness(scan, -SIDE[1], -SIDE[0])
        near = ahead - BODY < margin
        if near:
            self.device("drive").set_velocity(0.0, TURN if left >= right else -TURN)
        self.ctx.outputs["avoiding"] = near
        return Status.RUNNING
