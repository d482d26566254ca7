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
Params: `speed` (0.3 m/s), `tolerance` (0.3 m), `turn_gain` (1.5 /s), `max_turn` (1.0 rad/s), `stall` (1.5 s).
"""

from __future__ import annotations

import math

from components.behaviors.locate_dark_corner import wrap
from drd.runtime.component import Component, Status


class ServoToGoal(Component):
    def start(self) -> None:
        p = self.ctx.params
        self.speed = float(p.get("speed", 0.3))
        self.tolerance = float(p.get("tolerance", 0.3))
        self.turn_gain = float(p.get("turn_gain", 1.5))
        self.max_turn = float(p.get("max_turn", 1.0))
        self.drive = self.device("drive")
        self.camera = self.device("camera")
        self.radio = self.device("radio")
        self.goal = self.input("goal")
        self.stall = float(p.get("stall", 1.5))
        self.frames_sent = 0
        self.link_was_ok = True
        self.anchor: tuple[float, float, float] | None = None  # (t, x, y) of the last real progress

    def step(self, now: float) -> Status:
        if not self.goal:
            self.ctx.log("no goal to servo to")
            return Status.FAILURE
        if not self.radio.link_ok():
            if self.link_was_ok:
                self.ctx.log("radio link lost: stopped, waiting for the Ranger")
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
        omega = max(-self.max_turn, min(self.max_turn, self.turn_gain * err))
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
