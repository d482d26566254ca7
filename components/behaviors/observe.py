"""Observe: record camera frames for `duration` seconds, then succeed with the number of frames taken.

One frame per control cycle: the region brightness (the image, coarsely) and the people in it are read
and kept in memory (`self.frames`, `self.detections`: the number of detections over all frames).
Output `observation` {frames}. Params: `duration` (10 s), `n_regions` (16).
"""

from __future__ import annotations

from drd.runtime.component import Component, Status


class Observe(Component):
    def start(self) -> None:
        self.duration = float(self.ctx.params.get("duration", 10.0))
        self.n_regions = int(self.ctx.params.get("n_regions", 16))
        self.camera = self.device("camera")
        self.t0 = self.ctx.now()
        self.frames = 0
        self.detections = 0

    def step(self, now: float) -> Status:
        self.camera.brightness(self.n_regions)
        self.detections += len(self.camera.detections())
        self.frames += 1
        self.ctx.outputs["observation"] = {"frames": self.frames}
        if now - self.t0 >= self.duration - 1e-6:
            self.ctx.log(f"observed {self.frames} frames, {self.detections} detections")
            return Status.SUCCESS
        return Status.RUNNING
