"""The `ros2` Jump: hops as requests on `foot/jump` answered on `foot/result` (JSON in `std_msgs/msg/String`,
docs/ros2.md)."""

from __future__ import annotations

from components.ros2 import Actions, Ros2Driver
from drd.hosts import Device


class Ros2Jump(Ros2Driver):
    """A ROS 2 Scout's foot. Options: `max_height` (m, informative). `driver_options`: `action_timeout`, topics."""

    READINGS = frozenset({"max_height"})
    ACTIONS = ("jump",)

    def __init__(self, device: Device, robot_id: str, backend: object = None) -> None:
        super().__init__(device, robot_id, backend)
        self.max_height = self.option("max_height", 0.3)
        self._jump = Actions(self, "jump", "jump_result")

    def jump(self, dx: float, epoch: int | None = None) -> None:
        """Hop `dx` metres ahead (the robot refuses what it cannot do: HardwareError)."""
        self.fence.check(epoch)
        if not dx > 0:
            raise ValueError(f"{self.device.id}: jump distance must be positive, got {dx}")
        self._jump.call(dx=dx)
