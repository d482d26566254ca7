"""LocateDarkCorner: turn on the spot, sampling the camera's region brightness, and pick the darkest bearing.

Works from the sensors only: `Camera.brightness(n)` while the wheels turn the robot through a full turn,
and the wheels' odometry for the bearing of each region. The camera has no depth, and a Scout has no
range finder, so the distance to the corner is an estimate: a fixed `STEP` (3 m, about
the distance from a Scout landed in a room to its back wall) along the darkest bearing. The goal is in
odometry coordinates (the Ranger's odometry frame, which is the world frame at start).

Needs: `camera` (manifest) and, to turn and locate itself, a `drive`. Without a `drive` device it samples the
current view only and gives the goal in the robot's own frame (x ahead, y to the left).
"""

from __future__ import annotations

import math
from typing import Any

from components.behaviors.scan import circular_mean, region_bearings, wrap
from drd.runtime.component import Component, Status


def optional_device(comp: Component, need: str) -> Any:
    """The device of `need`, or None when the component was given none."""
    try:
        return comp.device(need)
    except LookupError:
        return None


# Not parameters (the manifest declares only `max_light`, so no mission can set them): constants of the behavior.
#: Brightness regions sampled per frame.
N_REGIONS = 16
#: How far along the darkest bearing (m) the goal is put: the camera has no depth.
STEP = 3.0
#: Turning rate (rad/s) while sampling.
TURN_RATE = 0.6


class LocateDarkCorner(Component):
    """Param: `max_light` (its default in the manifest).
    Output `goal` {x, y, light}; SUCCESS, or FAILURE when no bearing is as dark as `max_light` after a full turn."""

    def start(self) -> None:
        p = self.ctx.params
        self.max_light = float(p["max_light"])
        self.camera = self.device("camera")
        self.drive = optional_device(self, "drive")
        self.samples: list[tuple[float, float, float, float]] = []  # light, absolute bearing, x, y
        self.turned = 0.0
        self.last_heading: float | None = None

    def _sample(self) -> None:
        x, y, h = self.drive.odometry() if self.drive is not None else (0.0, 0.0, 0.0)
        if self.last_heading is not None:
            self.turned += abs(wrap(h - self.last_heading))
        self.last_heading = h
        lights = self.camera.brightness(N_REGIONS)
        for light, b in zip(lights, region_bearings(self.camera.fov, N_REGIONS), strict=True):
            self.samples.append((light, wrap(h + b), x, y))

    def step(self, now: float) -> Status:
        self._sample()
        if self.drive is not None and self.turned < 2 * math.pi:
            self.drive.set_velocity(0.0, TURN_RATE)
            return Status.RUNNING
        if self.drive is not None:
            self.drive.stop()
        return self._choose()

    def _choose(self) -> Status:
        darkest = min(s[0] for s in self.samples)
        if darkest > self.max_light:
            self.ctx.log(f"no bearing darker than {self.max_light} (darkest {darkest:.2f})")
            return Status.FAILURE
        near = [s for s in self.samples if s[0] <= darkest + 0.03]  # smooth the noise over the dark spot
        bearing = circular_mean([s[1] for s in near])
        x, y = self.samples[-1][2], self.samples[-1][3]
        goal = {"x": x + STEP * math.cos(bearing), "y": y + STEP * math.sin(bearing),
                "light": sum(s[0] for s in near) / len(near)}
        self.ctx.outputs["goal"] = goal
        self.ctx.log(f"dark corner at bearing {math.degrees(bearing):.0f} deg, light {goal['light']:.2f}")
        return Status.SUCCESS

    def suspend(self) -> None:
        if self.drive is not None:
            self.drive.stop()

    def terminate(self, status: Status) -> None:
        if self.drive is not None and status is Status.RUNNING:
            self.drive.stop()
