"""TurnToWatch: turn on the spot to face the open room, its back to the corner, then stop.

Which way is "the room": with a `camera` device (optional; the manifest needs only `drive`), the brightest
bearing seen over a full turn (the door and the lit middle of the room); without one, the `heading` param
(odometry, rad) when given, else half a turn from the heading at start (the Scout arrives facing its corner).
Params: `turn_rate` (its default in the manifest), `heading` (optional, no default: a manifest cannot declare
an optional float without one, so it is read only when given). Heading from odometry.
"""

from __future__ import annotations

import math

from components.behaviors.locate_dark_corner import optional_device
from components.behaviors.scan import region_bearings, wrap
from drd.runtime.component import Component, Status

ALIGNED = 0.05  # rad
#: Brightness regions sampled per frame. Not a parameter (the manifest declares none), so a constant.
N_REGIONS = 16


class TurnToWatch(Component):
    def start(self) -> None:
        p = self.ctx.params
        self.turn_rate = float(p["turn_rate"])
        self.drive = self.device("drive")
        self.camera = optional_device(self, "camera")
        _, _, h = self.drive.odometry()
        self.target: float | None = None
        heading = p.get("heading")
        if heading is not None:
            self.target = float(heading)
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
            lights = self.camera.brightness(N_REGIONS)
            for light, b in zip(lights, region_bearings(self.camera.fov, N_REGIONS), strict=True):
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
