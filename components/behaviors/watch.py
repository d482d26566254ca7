"""Watch: for `duration` seconds, emit MotionDetected(area, x, y) for every person moving in the camera's view.

From the sensors only: `Camera.detections()` reports people in the field of view, in line of sight (never
through a wall or a closed door) and in enough light. The `area` is the fraction of the image a person
covers, from their angular width at the detected distance (a person is taken as `PERSON_WIDTH`, 0.5 m,
wide): `2 atan(w / 2d) / fov`; only people covering at least `threshold` count. The position is estimated
from the bearing and distance and the robot's odometry when a `drive` device is given (optional: the
manifest needs only `camera`); without one, x and y are in the robot's own frame (x ahead, y to the left).

One event when a person first shows up, then one each time they have moved `MIN_MOVE` (0.5 m) since the
last event about them, so a person standing still is not reported over and over.
Params: `duration`, `threshold` (their defaults in the manifest).

Its snapshot (when it began, the events emitted, where each person was last reported) lets a Watch entered again
by a new controller go on with its count and its deadline instead of reporting everyone again.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from components.behaviors.locate_dark_corner import optional_device
from drd.runtime.component import Component, Status

# Not parameters (the manifest does not declare them, so no mission can set them): constants of the behavior.
#: The width (m) a person is taken to have, to tell the fraction of the image they cover.
PERSON_WIDTH = 0.5
#: How far (m) a person must move after an event about them before the next one.
MIN_MOVE = 0.5


class Watch(Component):
    restored: Mapping[str, Any] | None = None

    def restore(self, state: Mapping[str, Any] | None) -> None:
        self.restored = state

    def snapshot(self) -> Mapping[str, Any] | None:
        return {"t0": self.t0, "events": self.events,
                "reported": {k: [x, y] for k, (x, y) in self.reported.items()}}

    def start(self) -> None:
        p = self.ctx.params
        self.duration = float(p["duration"])
        self.threshold = float(p["threshold"])
        self.camera = self.device("camera")
        self.drive = optional_device(self, "drive")
        self.t0 = self.ctx.now()
        self.reported: dict[str, tuple[float, float]] = {}  # label -> position of its last event
        self.events = 0
        state, self.restored = self.restored, None
        if state is not None:
            self.t0, self.events = float(state["t0"]), int(state["events"])
            self.reported = {str(k): (float(v[0]), float(v[1])) for k, v in dict(state["reported"]).items()}

    def step(self, now: float) -> Status:
        x0, y0, h = self.drive.odometry() if self.drive is not None else (0.0, 0.0, 0.0)
        for d in self.camera.detections():
            dist = max(d.distance, 0.05)
            area = 2 * math.atan(PERSON_WIDTH / (2 * dist)) / self.camera.fov
            if area < self.threshold:
                continue
            x, y = x0 + dist * math.cos(h + d.bearing), y0 + dist * math.sin(h + d.bearing)
            last = self.reported.get(d.label)
            if last is not None and math.hypot(x - last[0], y - last[1]) < MIN_MOVE:
                continue
            self.reported[d.label] = (x, y)
            self.events += 1
            self.ctx.emit("MotionDetected", area=round(area, 3), x=round(x, 2), y=round(y, 2))
        return Status.SUCCESS if now - self.t0 >= self.duration - 1e-6 else Status.RUNNING
