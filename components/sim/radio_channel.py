"""The `sim` RadioChannel: whether a Scout and its Ranger are within radio reach (each wall shortens it)."""

from __future__ import annotations

from components.sim import SimDriver
from drd.hosts import Device
from drd.sim import Simulation


class SimRadioChannel(SimDriver):
    """A simulated radio. Options: `range` (m in the open, default 30). `peer`: the robot at the other end
    by default (a Scout's carrier); if not given, a Scout's Ranger is the one whose magazine it starts in."""

    READINGS = frozenset({"link_ok", "range", "peer"})

    def __init__(self, device: Device, robot_id: str, sim: Simulation, peer: str | None = None) -> None:
        super().__init__(device, robot_id, sim)
        self.range = self.option("range", 30.0)
        self.peer = peer if peer is not None else next(
            (r.id for r in sim.world.rangers if robot_id in r.magazine), None)
        self._rangers = frozenset(r.id for r in sim.world.rangers)

    def link_ok(self, peer: str | None = None) -> bool:
        """Whether this robot and `peer` (default: its Ranger) can talk now."""
        other = peer if peer is not None else self.peer
        if other is None:
            raise ValueError(f"{self.device.id}: {self.robot_id} has no default peer; name one")
        scout, ranger = (self.robot_id, other) if other in self._rangers else (other, self.robot_id)
        with self.sim_errors():
            return self.sim.radio_ok(scout, ranger, self.range)
