"""AvoidObstacles: when something is within `margin` of the Ranger's body straight ahead, stop and turn toward
the more open side; otherwise command nothing (the layer below, e.g. FollowCorridor, keeps the drive).

Clearance is measured from the body: a range beam reads from the robot's centre, so BODY (the Ranger's
radius) is subtracted. Only points inside the swept path (|lateral| < BODY) count.
"""

from __future__ import annotations

import math

from drd.runtime.component import Component, Status

BODY = 0.3
TURN = 0.8


class AvoidObstacles(Component):
    def step(self, now: float) -> Status:
        margin = float(self.ctx.params.get("margin", 0.3))
        scan = self.device("ranges").scan()
        ahead = []
        left = right = 0.0
        for i, r in enumerate(scan.ranges):
            a = scan.angle(i)
            x, y = r * math.cos(a), r * math.sin(a)
            if x > 0 and abs(y) < BODY:
                ahead.append(x - BODY)
            if 0.2 < a < 1.4:
                left += r
            elif -1.4 < a < -0.2:
                right += r
        near = min(ahead, default=math.inf) < margin
        if near:
            self.device("drive").set_velocity(0.0, TURN if left >= right else -TURN)
        self.ctx.outputs["avoiding"] = near
        return Status.RUNNING
