"""Observe: record camera frames for `duration` seconds of camera time, then succeed with the frames taken.

Camera time is time holding the camera: while suspended (the camera taken away at a slice boundary, as in
Fig. 8) no frame is taken and the clock does not count, so `Observe(duration: 12s)` always observes 12 s.

One frame per control cycle: the region brightness (the image, coarsely) and the people in it are read
and kept in memory (`self.frames`, `self.detections`: the number of detections over all frames).
Output `observation` {frames}. Param: `duration` (its default in the manifest, as every parameter's).
Its snapshot (camera time observed, frames, detections) lets it go on with them when entered again.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from drd.runtime.component import Component, Status

#: Brightness regions read per frame: the coarse image kept. Not a parameter (no mission can set it, the manifest
#: declares none), so a constant here.
N_REGIONS = 16


class Observe(Component):
    restored: Mapping[str, Any] | None = None

    def restore(self, state: Mapping[str, Any] | None) -> None:
        self.restored = state

    def snapshot(self) -> Mapping[str, Any] | None:
        return {"observed": self.observed, "frames": self.frames, "detections": self.detections}

    def start(self) -> None:
        self.duration = float(self.ctx.params["duration"])
        self.camera = self.device("camera")
        self.observed = 0.0
        self.last: float | None = self.ctx.now()
        self.frames = 0
        self.detections = 0
        state, self.restored = self.restored, None
        if state is not None:
            self.observed, self.frames = float(state["observed"]), int(state["frames"])
            self.detections = int(state["detections"])

    def step(self, now: float) -> Status:
        if self.last is not None:
            self.observed += now - self.last
        self.last = now
        self.camera.brightness(N_REGIONS)
        self.detections += len(self.camera.detections())
        self.frames += 1
        self.ctx.outputs["observation"] = {"frames": self.frames}
        if self.observed >= self.duration - 1e-6:
            self.ctx.log(f"observed {self.frames} frames, {self.detections} detections")
            return Status.SUCCESS
        return Status.RUNNING

    def suspend(self) -> None:
        self.last = None

    def resume(self) -> None:
        self.last = self.ctx.now()
