"""The `sim` RangeSensor: ray-cast laser scans with the device's `beams`, `max_range` and `fov`."""

from __future__ import annotations

import math

from components.sim import SimDriver
from drd.hosts import Device
from drd.hw.interfaces import Scan
from drd.sim import Simulation


class SimRangeSensor(SimDriver):
    """A simulated laser. Options: `beams` (default 181), `max_range` (m, default 8), `fov` (degrees, default 180)."""

    def __init__(self, device: Device, robot_id: str, sim: Simulation) -> None:
        super().__init__(device, robot_id, sim)
        self.beams = int(self.option("beams", 181, lambda x: x >= 1 and x == int(x)))
        self.max_range = self.option("max_range", 8.0)
        self.fov = math.radians(self.option("fov", 180.0, lambda x: 0 < x <= 360))

    def scan(self) -> Scan:
        """One scan, right to left, angles relative to the heading."""
        with self.sim_errors():
            ranges = self.sim.ranges(self.robot_id, self.beams, self.max_range, self.fov)
        if self.beams == 1:
            return Scan(tuple(ranges), 0.0, 0.0, self.max_range)
        return Scan(tuple(ranges), -self.fov / 2, self.fov / (self.beams - 1), self.max_range)
