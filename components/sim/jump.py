"""The `sim` Jump: a Scout's spring-foot hop on the simulator."""

from __future__ import annotations

from components.sim import SimDriver
from drd.hosts import Device
from drd.sim import Simulation


class SimJump(SimDriver):
    """A simulated foot. Options: `max_height` (m, informative: the simulator's obstacle height limit applies),
    `max_distance` (m, default and cap: the simulator's longest hop)."""

    READINGS = frozenset({"max_height", "max_distance"})
    ACTIONS = ("jump",)

    def __init__(self, device: Device, robot_id: str, sim: Simulation) -> None:
        super().__init__(device, robot_id, sim)
        self.max_height = self.option("max_height", sim.jump_height)
        self.max_distance = min(sim.max_jump, self.option("max_distance", sim.max_jump))

    def jump(self, dx: float, epoch: int | None = None) -> None:
        """Hop `dx` metres ahead, 0 < dx <= max_distance."""
        self.fence.check(epoch)
        if not 0 < dx <= self.max_distance:
            raise ValueError(f"{self.device.id}: jump distance must be in (0, {self.max_distance:g}] m, got {dx}")
        with self.sim_errors():
            self.sim.jump(self.robot_id, dx)
