"""AlignRanger: go back to where the door was seen, then turn on the spot to face it.

Which door: its input `door` (a Door, in odometry coordinates), as the mission binds it: the door its own
search found (a sibling's output, whatever that sibling is called), or one the mission names explicitly
(`AlignRanger(door: finder.door)`).

Why it may have to drive first: with one Ranger and several RoomSurveillance instances of equal priority,
the Ranger is shared round-robin, so between the slice in which this instance found its door and the one in
which it aligns, other instances may have driven the Ranger further down the corridor. DetectDoor records
where the Ranger stood (`from`, odometry); AlignRanger drives back there (turn towards it, then drive,
correcting the heading) before facing the door, so the Scout is launched square through the doorway.
"""

from __future__ import annotations

import math
from typing import Any

from components.behaviors.scan import wrap
from drd.runtime.component import Component, Status

K_TURN = 1.5
MAX_OMEGA = 1.0
MIN_OMEGA = 0.08
#: Drive back when farther than this (m) from where the door was seen; stop within ARRIVED of it.
AWAY = 0.3
ARRIVED = 0.1
SPEED = 0.4


def own_door(comp: Component) -> dict[str, Any] | None:
    """The door to face: the input `door`, if it is one."""
    door = comp.input("door")
    return door if isinstance(door, dict) and "x" in door and "y" in door else None


def turn_rate(err: float) -> float:
    """Proportional, saturated, and never so slow that friction wins."""
    omega = max(-MAX_OMEGA, min(MAX_OMEGA, K_TURN * err))
    return math.copysign(MIN_OMEGA, err) if abs(omega) < MIN_OMEGA else omega


class AlignRanger(Component):
    """Drive back to the door's viewpoint if the Ranger moved away, then turn until the heading error to the door
    is below `tolerance` radians; FAILURE if there is no door."""

    def start(self) -> None:
        self.door = own_door(self)
        seen = self.door.get("from") if self.door else None
        self.goal: tuple[float, float] | None = (float(seen["x"]), float(seen["y"])) if isinstance(seen, dict) else None
        self.driving = False

    def step(self, now: float) -> Status:
        if self.door is None:
            self.ctx.log("AlignRanger: no door to face (its input door has no door yet)")
            return Status.FAILURE
        drive = self.device("drive")
        x, y, a = drive.odometry()
        if self.goal is not None:
            gx, gy = self.goal
            dist = math.hypot(gx - x, gy - y)
            # checked every cycle, not once: a slice boundary may hand the Ranger to another instance mid-way
            self.driving = dist > (ARRIVED if self.driving else AWAY)
            if self.driving:
                err = wrap(math.atan2(gy - y, gx - x) - a)
                v = min(SPEED, dist) * math.cos(err) if abs(err) < math.pi / 4 else 0.0
                drive.set_velocity(v, turn_rate(err))
                return Status.RUNNING
        err = wrap(math.atan2(self.door["y"] - y, self.door["x"] - x) - a)
        if abs(err) < float(self.ctx.params["tolerance"]):
            drive.stop()
            return Status.SUCCESS
        drive.set_velocity(0.0, turn_rate(err))
        return Status.RUNNING

    def suspend(self) -> None:
        self.device("drive").stop()

    def terminate(self, status: Status) -> None:
        self.device("drive").stop()
