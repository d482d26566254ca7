"""ServoToGoal: drive to the goal by visual servoing through the Ranger's proxy processing.

The Scout cannot process its frames, so each control cycle its frame goes over the radio to its Ranger,
which sends the steering back. Modelled from the sensors: the camera is read every cycle (the frame sent)
and the steering is computed only while `radio.link_ok()`; when the link is down the Scout stops and waits
(RUNNING) until it comes back. Steering: the bearing to the goal from odometry and the goal.

Where the goal comes from: its input `goal` (a Goal, {x, y}, odometry coordinates) as the mission binds it,
e.g. the `goal` a sibling LocateDarkCorner found.
When the Scout is stopped short of the goal by a wall or an obstacle (driving forward but, by odometry, not
moving for `stall` seconds), it is as close as it can get: it stops and succeeds. The goal of a dark corner
is only an estimate along a bearing (LocateDarkCorner has no depth), so it often lies beyond the corner's
walls: driving into the corner until blocked is the point.
Params: `speed`, `tolerance`, `stall` (their defaults in the manifest). Steering gain and limit: TURN_GAIN, MAX_TURN.
"""

from __future__ import annotations

import math

from components.behaviors.scan import wrap
from drd.runtime.component import Component, Status

# Not parameters (the manifest does not declare them, so no mission can set them): the steering loop's tuning.
#: Turn rate (rad/s) per radian of bearing error.
TURN_GAIN = 1.5
#: Largest turn rate commanded (rad/s).
MAX_TURN = 1.0


class ServoToGoal(Component):
    def start(self) -> None:
        p = self.ctx.params
        self.speed = float(p["speed"])
        self.tolerance = float(p["tolerance"])
        self.drive = self.device("drive")
        self.camera = self.device("camera")
        self.radio = self.device("radio")
        self.goal = self.input("goal")
        self.stall = float(p["stall"])
        self.frames_sent = 0
        self.link_was_ok = True
        self.anchor: tuple[float, float, float] | None = None  # (t, x, y) of the last real progress

    def step(self, now: float) -> Status:
        if not self.goal:
            self.ctx.log("no goal to servo to")
            return Status.FAILURE
        if not self.radio.link_ok():
            if self.link_was_ok:
                self.ctx.log("radio link lost: stopped, waiting for the link to come back")
            self.link_was_ok = False
            self.drive.stop()
            return Status.RUNNING
        if not self.link_was_ok:
            self.ctx.log("radio link back: servoing again")
            self.anchor = None  # waiting was not stalling
        self.link_was_ok = True
        self.camera.brightness(8)  # the frame sent to the Ranger for processing
        self.frames_sent += 1
        x, y, h = self.drive.odometry()
        dx, dy = float(self.goal["x"]) - x, float(self.goal["y"]) - y
        if math.hypot(dx, dy) <= self.tolerance:
            self.drive.stop()
            return Status.SUCCESS
        err = wrap(math.atan2(dy, dx) - h)
        omega = max(-MAX_TURN, min(MAX_TURN, TURN_GAIN * err))
        v = self.speed * math.cos(err) if abs(err) < math.pi / 3 else 0.0  # turn on the spot first
        if v <= 0.05 or self.anchor is None or math.hypot(x - self.anchor[1], y - self.anchor[2]) > 0.05:
            self.anchor = (now, x, y)
        elif now - self.anchor[0] >= self.stall:
            self.drive.stop()
            self.ctx.log(f"blocked {math.hypot(dx, dy):.1f} m short of the goal: as close as it gets")
            return Status.SUCCESS
        self.drive.set_velocity(v, omega)
        return Status.RUNNING

    def suspend(self) -> None:
        self.drive.stop()

    def terminate(self, status: Status) -> None:
        self.drive.stop()
