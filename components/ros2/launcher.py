"""The `ros2` Launcher: the magazine from `launcher/magazine`, launches as requests on `launcher/launch` answered
on `launcher/result` (JSON in `std_msgs/msg/String`, docs/ros2.md)."""

from __future__ import annotations

import json

from components.ros2 import Actions, Ros2Driver
from drd.hosts import Device
from drd.hw.interfaces import HardwareError, Landing
from drd.hw.ros2 import compose


class Ros2Launcher(Ros2Driver):
    """A ROS 2 Scout launcher. Options: `max_range` (m, default 30). `driver_options`: `origin` (the Ranger's
    odometry frame in the map, as its Drive's), `status_max_age`, `action_timeout`, topics."""

    READINGS = frozenset({"loaded", "max_range"})
    ACTIONS = ("launch",)
    MOVES = {"launch": "scout_id"}  # the Scout it throws: only a behavior holding that Scout may (drd.hw.commands)

    def __init__(self, device: Device, robot_id: str, backend: object = None) -> None:
        super().__init__(device, robot_id, backend)
        self.max_range = self.option("max_range", 30.0)
        self._magazine = self.subscribe("magazine", self.opts.status_max_age)
        self._launch = Actions(self, "launch", "launch_result")

    def loaded(self) -> tuple[str, ...]:
        """The Scouts still in the magazine, in launch order."""
        assert self._magazine is not None
        try:
            scouts = json.loads(self._magazine.get().data)
        except ValueError:
            scouts = None
        if not isinstance(scouts, list) or not all(isinstance(s, str) for s in scouts):
            raise HardwareError(f"{self.describe()}: the magazine is not a JSON list of Scout ids")
        return tuple(scouts)

    def launch(self, scout_id: str, heading: float, distance: float, epoch: int | None = None) -> Landing:
        """Launch `scout_id` `heading` rad off the Ranger's heading, `distance` m capped at `max_range`."""
        self.fence.check(epoch)
        if distance <= 0:
            raise ValueError(f"{self.device.id}: launch distance must be positive, got {distance}")
        loaded = self.loaded()
        if scout_id not in loaded:
            raise HardwareError(f"{self.device.id}: {scout_id} is not in {self.robot_id}'s magazine"
                                f" ({', '.join(loaded) or 'empty'})")
        answer = self._launch.call(scout=scout_id, heading=heading, distance=min(distance, self.max_range))
        try:
            x, y, a = compose(self.opts.origin, (float(answer["x"]), float(answer["y"]), float(answer["heading"])))
            return Landing(x, y, a, float(answer["duration"]))
        except (KeyError, TypeError, ValueError):
            raise HardwareError(f"{self.describe()}: a launch result without x, y, heading and duration") from None
