"""The `sim` Camera: people in view (field of view, line of sight, light) and region brightness."""

from __future__ import annotations

import dataclasses
import math

from components.sim import SimDriver
from drd.hosts import Device
from drd.hw.interfaces import DetectionLike
from drd.sim import Simulation


class SimCamera(SimDriver):
    """A simulated camera. Options: `fov` (DEGREES in hosts.yaml, default 60), `resolution` (pixels across,
    default 640: bearings are reported to the pixel, regions at most one per pixel), `max_range` (m, default
    10), `min_light` (0..1, default 0.2: darker than this, nobody is seen)."""

    READINGS = frozenset({"detections", "brightness", "fov", "resolution", "max_range", "min_light"})

    def __init__(self, device: Device, robot_id: str, sim: Simulation) -> None:
        super().__init__(device, robot_id, sim)
        self.fov = math.radians(self.option("fov", 60.0, lambda x: 0 < x < 360))
        self.resolution = int(self.option("resolution", 640, lambda x: x >= 1 and x == int(x)))
        self.max_range = self.option("max_range", 10.0)
        self.min_light = self.option("min_light", 0.2, lambda x: 0 <= x <= 1)

    def detections(self) -> list[DetectionLike]:
        """People seen now; bearing in radians (left positive, to the pixel), distance in metres."""
        pixel = self.fov / self.resolution
        with self.sim_errors():
            seen = self.sim.camera(self.robot_id, self.fov, self.max_range, self.min_light)
        return [dataclasses.replace(d, bearing=round(d.bearing / pixel) * pixel) for d in seen]

    def brightness(self, n_regions: int) -> list[float]:
        """Mean light of `n_regions` strips (at most `resolution`), right to left."""
        if not 1 <= n_regions <= self.resolution:
            raise ValueError(f"{self.device.id}: n_regions must be in [1, {self.resolution}], got {n_regions}")
        with self.sim_errors():
            return self.sim.brightness(self.robot_id, self.fov, n_regions, self.max_range)
