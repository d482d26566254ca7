"""The `sim` Drive: velocity commands and odometry on the simulator, clamped to the device's `max_speed`."""

from __future__ import annotations

import math

from components.sim import SimDriver
from drd.hosts import Device
from drd.sim import Simulation


class SimDrive(SimDriver):
    """A simulated wheeled base. Options: `max_speed` (m/s; without it, only the simulator's wheels limit)."""

    READINGS = frozenset({"odometry", "origin", "battery", "max_speed"})
    SETPOINTS = ("set_velocity", "stop")
    STOP = "stop"

    def __init__(self, device: Device, robot_id: str, sim: Simulation) -> None:
        super().__init__(device, robot_id, sim)
        self.max_speed = math.inf
        if "max_speed" in device.options:
            self.max_speed = self.option("max_speed", math.inf)
            with self.sim_errors():
                sim.set_max_speed(robot_id, self.max_speed)

    def set_velocity(self, v: float, omega: float, epoch: int | None = None) -> None:
        """`v` m/s (clamped to +-max_speed) and `omega` rad/s counter-clockwise."""
        self.fence.check(epoch)
        v = max(-self.max_speed, min(self.max_speed, v))
        with self.sim_errors():
            self.sim.set_velocity(self.robot_id, v, omega)

    def stop(self, epoch: int | None = None) -> None:
        """Zero both wheels."""
        self.fence.check(epoch)
        with self.sim_errors():
            self.sim.stop(self.robot_id)

    def odometry(self) -> tuple[float, float, float]:
        """x, y (m) and heading (rad) from wheel odometry."""
        with self.sim_errors():
            p = self.sim.odometry(self.robot_id)
        return p.x, p.y, p.heading

    def origin(self) -> tuple[float, float, float]:
        """Where the odometry began: x, y (m) and heading (rad) of the robot's start pose."""
        with self.sim_errors():
            p = self.sim.origin(self.robot_id)
        return p.x, p.y, p.heading

    def battery(self) -> float:
        """The charge left, 0 (empty: the wheels stop) .. 1 (full); the world's battery model drains it."""
        with self.sim_errors():
            return self.sim.battery(self.robot_id)
