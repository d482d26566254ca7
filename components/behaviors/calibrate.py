"""Calibrate: average `samples` range scans standing still.

Outputs `width` (mean corridor width, m, from the wall fits), `noise` (standard deviation of the wall
points about their fitted lines, m) and `samples` (scans used). A scan without both walls is skipped.
"""

from __future__ import annotations

import math
import statistics
from typing import Any

from components.behaviors.scan import Wall, fit_wall, points
from drd.runtime.component import Component, Status


def residuals(scan: Any, wall: Wall, side: int) -> list[float]:
    """Distances of the beams near a fitted wall to its line (the range noise, seen along the wall)."""
    m = math.tan(side * wall.angle)
    c = wall.distance / math.cos(wall.angle)
    out = []
    for _, x, y in points(scan, -math.pi, math.pi):
        e = (side * y - (m * x + c)) * math.cos(wall.angle)
        if side * y > 0 and abs(e) < 0.1:
            out.append(e)
    return out


class Calibrate(Component):
    def start(self) -> None:
        self.widths: list[float] = []
        self.errors: list[float] = []
        self.scans = 0

    def step(self, now: float) -> Status:
        samples = int(self.ctx.params["samples"])
        scan = self.device("ranges").scan()
        self.scans += 1
        left, right = fit_wall(scan, 1), fit_wall(scan, -1)
        if left and right:
            self.widths.append(left.distance + right.distance)
            self.errors += residuals(scan, left, 1) + residuals(scan, right, -1)
        if len(self.widths) >= samples:
            self.ctx.outputs["width"] = statistics.fmean(self.widths)
            self.ctx.outputs["noise"] = statistics.pstdev(self.errors) if len(self.errors) > 1 else 0.0
            self.ctx.outputs["samples"] = len(self.widths)
            return Status.SUCCESS
        if self.scans >= 3 * samples:
            self.ctx.log(f"Calibrate: only {len(self.widths)} of {samples} scans showed both walls")
            return Status.FAILURE
        return Status.RUNNING
