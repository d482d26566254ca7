"""The `sim` RangeSensor: ray-cast laser scans with the device's `beams`, `max_range` and `fov`."""

from __future__ import annotations

import math

from components.sim import SimDriver
from drd.hosts import Device
from drd.hw.interfaces import Scan
from drd.sim import Simulation


class SimRangeSensor(SimDriver):
    """A simulated laser. Options: `beams` (default 181), `max_range` (m, default 8), `fov` (degrees, default 180).

    Like a real laser's driver, `scan()` returns the latest scan: one per sim instant. Every behavior that reads
    this laser in one control cycle (FollowCorridor, AvoidObstacles and DetectDoor together) gets the same `Scan`
    object, and the rays are cast once; a new scan is taken when the simulation has changed (`Simulation.version`).
    """

    READINGS = frozenset({"scan", "beams", "max_range", "fov"})

    def __init__(self, device: Device, robot_id: str, sim: Simulation) -> None:
        super().__init__(device, robot_id, sim)
        self.beams = int(self.option("beams", 181, lambda x: x >= 1 and x == int(x)))
        self.max_range = self.option("max_range", 8.0)
        self.fov = math.radians(self.option("fov", 180.0, lambda x: 0 < x <= 360))
        self._latest: tuple[int, Scan] | None = None

    def scan(self) -> Scan:
        """The scan at the current sim instant, right to left, angles relative to the heading."""
        version = self.sim.version
        if self._latest is not None and self._latest[0] == version:
            return self._latest[1]
        with self.sim_errors():
            ranges = self.sim.ranges(self.robot_id, self.beams, self.max_range, self.fov)
        if self.beams == 1:
            scan = Scan(tuple(ranges), 0.0, 0.0, self.max_range)
        else:
            scan = Scan(tuple(ranges), -self.fov / 2, self.fov / (self.beams - 1), self.max_range)
        self._latest = (version, scan)
        return scan
