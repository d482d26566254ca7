"""AvoidObstacles: when something is within `margin` of the Ranger's body straight ahead, stop and turn toward
the more open side; otherwise command nothing (the layer below, e.g. FollowCorridor, keeps the drive).

Clearance is measured from the body: a range beam reads from the robot's centre, so BODY (the Ranger's
radius) is subtracted. Only points inside the swept path (|lateral| < BODY) count.
"""

from __future__ import annotations

import bisect
import math

from drd.runtime.component import Component, Status

BODY = 0.3
TURN = 0.8


class AvoidObstacles(Component):
    def step(self, now: float) -> Status:
        margin = float(self.ctx.params["margin"])
        scan = self.device("ranges").scan()
        b, ranges = scan.beams(), scan.ranges
        # the nearest hit ahead inside the swept path (x > 0, |y| < BODY), and how open each side is
        ahead = min([x for r, c, s in zip(ranges, b.cos, b.sin, strict=True)
                     if (x := r * c) > 0 and -BODY < r * s < BODY], default=math.inf)
        left = sum(ranges[bisect.bisect_right(b.angles, 0.2):bisect.bisect_left(b.angles, 1.4)])  # 0.2 < a < 1.4
        right = sum(ranges[bisect.bisect_right(b.angles, -1.4):bisect.bisect_left(b.angles, -0.2)])
        near = ahead - BODY < margin
        if near:
            self.device("drive").set_velocity(0.0, TURN if left >= right else -TURN)
        self.ctx.outputs["avoiding"] = near
        return Status.RUNNING
