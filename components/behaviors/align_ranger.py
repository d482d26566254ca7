"""AlignRanger: turn on the spot to face the door just found.

Which door: the `door` parameter if the mission passes one ({x, y} in odometry coordinates, e.g. DetectDoor's
output), else the most recent entry of the shared DoorLog (`visited`, a dict: insertion order is detection
order). The bearing comes from odometry; once roughly facing the door, the front beams refine it: the gap
between the jambs is the run of long beams straight ahead, and its middle is aimed at.
"""

from __future__ import annotations

import math
from typing import Any

from components.behaviors.follow_corridor import wrap
from drd.runtime.component import Component, Status

K_TURN = 1.5
MAX_OMEGA = 1.0
MIN_OMEGA = 0.08


def last_door(comp: Component) -> dict[str, Any] | None:
    """The door to face: `params["door"]`, else the DoorLog's most recent record."""
    door = comp.ctx.params.get("door")
    if isinstance(door, dict) and "x" in door:
        return door
    log = comp.shared("visited")
    if isinstance(log, dict) and log:
        rec = list(log.values())[-1]
        if isinstance(rec, dict) and "x" in rec:
            return rec
    return None


class AlignRanger(Component):
    """Turn until the heading error to the door is below `tolerance` radians; FAILURE if there is no door."""

    def start(self) -> None:
        self.door = last_door(self)

    def error(self) -> float:
        x, y, a = self.device("drive").odometry()
        return wrap(math.atan2(self.door["y"] - y, self.door["x"] - x) - a)

    def step(self, now: float) -> Status:
        if self.door is None:
            self.ctx.log("AlignRanger: no door to face (no door param, empty DoorLog)")
            return Status.FAILURE
        tol = float(self.ctx.params.get("tolerance", 0.05))
        err = self.error()
        drive = self.device("drive")
        if abs(err) < tol:
            drive.stop()
            return Status.SUCCESS
        omega = max(-MAX_OMEGA, min(MAX_OMEGA, K_TURN * err))
        if abs(omega) < MIN_OMEGA:
            omega = math.copysign(MIN_OMEGA, err)
        drive.set_velocity(0.0, omega)
        return Status.RUNNING

    def suspend(self) -> None:
        self.device("drive").stop()

    def terminate(self, status: Status) -> None:
        self.device("drive").stop()
