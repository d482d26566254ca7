"""TurnToWatch: turn on the spot to face the open room, its back to the corner, then stop.

Which way is "the room": with a `camera` device (optional; the manifest needs only `drive`), the brightest
bearing seen over a full turn (the door and the lit middle of the room); without one, the `heading` param
(odometry, rad) when given, else half a turn from the heading at start (the Scout arrives facing its corner).
Params: `turn_rate` (0.5 rad/s), `n_regions` (16), `heading` (optional). Heading from odometry.
"""

from __future__ import annotations

import math

from components.behaviors.locate_dark_corner import optional_device, region_bearings, wrap
from drd.runtime.component import Component, Status

ALIGNED = 0.05  # rad


class TurnToWatch(Component):
    def start(self) -> None:
        p = self.ctx.params
        self.turn_rate = float(p.get("turn_rate", 0.5))
        self.n_regions = int(p.get("n_regions", 16))
        self.drive = self.device("drive")
        self.camera = optional_device(self, "camera")
        _, _, h = self.drive.odometry()
        self.target: float | None = None
        if p.get("heading") is not None:
            self.target = float(p["heading"])
        elif self.camera is None:
            self.target = wrap(h + math.pi)
        self.best = (-1.0, h)  # brightest light seen, its absolute bearing
        self.turned = 0.0
        self.last = h

    def step(self, now: float) -> Status:
        _, _, h = self.drive.odometry()
        if self.target is None:  # scanning for the brightest bearing
            self.turned += abs(wrap(h - self.last))
            self.last = h
            lights = self.camera.brightness(self.n_regions)
            for light, b in zip(lights, region_bearings(self.camera.fov, self.n_regions), strict=True):
                if light > self.best[0]:
                    self.best = (light, wrap(h + b))
            if self.turned < 2 * math.pi:
                self.drive.set_velocity(0.0, self.turn_rate)
                return Status.RUNNING
            self.target = self.best[1]
        err = wrap(self.target - h)
        if abs(err) <= ALIGNED:
            self.drive.stop()
            return Status.SUCCESS
        rate = min(self.turn_rate, max(0.1, 2.0 * abs(err)))  # slow down near the target
        self.drive.set_velocity(0.0, math.copysign(rate, err))
        return Status.RUNNING

    def suspend(self) -> None:
        self.drive.stop()

    def terminate(self, status: Status) -> None:
        self.drive.stop()
