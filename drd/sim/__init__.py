"""The dry-run simulator: worlds loaded from `worlds/*.yaml` (`drd.sim.world`) and a seeded pymunk
simulation of them (`drd.sim.physics`), pure and free of I/O beyond reading a world file."""

from __future__ import annotations

from drd.sim.model import DoorState, World, WorldError, WorldProblem
from drd.sim.physics import Simulation
from drd.sim.robots import Flight, Pose, RobotState, SimError
from drd.sim.sensors import NOISELESS, Detection, Noise
from drd.sim.world import check_hosts, load_world, parse_world

__all__ = [
    "NOISELESS", "Detection", "DoorState", "Flight", "Noise", "Pose", "RobotState", "SimError", "Simulation",
    "World", "WorldError", "WorldProblem", "check_hosts", "load_world", "parse_world",
]
