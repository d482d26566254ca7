"""The `sim` Launcher: ballistic launches of the Scouts in the Ranger's magazine, capped at `max_range`."""

from __future__ import annotations

import math

from components.sim import SimDriver
from drd.hosts import Device
from drd.hw.interfaces import HardwareError, Landing
from drd.sim import Simulation
from drd.sim.physics import MAX_LAUNCH


class SimLauncher(SimDriver):
    """A simulated launcher on a Ranger. Options: `max_range` (m, at most the simulator's 30 m)."""

    READINGS = frozenset({"loaded", "max_range"})
    ACTIONS = ("launch",)
    MOVES = {"launch": "scout_id"}  # the Scout it throws: only a behavior holding that Scout may (drd.hw.commands)

    def __init__(self, device: Device, robot_id: str, sim: Simulation) -> None:
        super().__init__(device, robot_id, sim)
        self.max_range = min(MAX_LAUNCH, self.option("max_range", MAX_LAUNCH))

    def loaded(self) -> tuple[str, ...]:
        """The Scouts still in this Ranger's magazine."""
        with self.sim_errors():
            return self.sim.magazine(self.robot_id)

    def launch(self, scout_id: str, heading: float, distance: float, epoch: int | None = None) -> Landing:
        """Launch `scout_id` `heading` rad off the Ranger's heading, `distance` m capped at `max_range`."""
        self.fence.check(epoch)
        if distance <= 0:
            raise ValueError(f"{self.device.id}: launch distance must be positive, got {distance}")
        if scout_id not in self.loaded():
            raise HardwareError(f"{self.device.id}: {scout_id} is not in {self.robot_id}'s magazine"
                                f" ({', '.join(self.loaded()) or 'empty'})")
        distance = min(distance, self.max_range)
        with self.sim_errors():
            pose = self.sim.odometry(self.robot_id)
            flight = self.sim.launch(scout_id, heading, distance)
        x, y, a = pose.x, pose.y, pose.heading
        return Landing(x + distance * math.cos(a + heading), y + distance * math.sin(a + heading), a + heading,
                       flight.t1 - flight.t0)
