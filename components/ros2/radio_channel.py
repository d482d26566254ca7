"""The `ros2` RadioChannel: `radio/link/<peer>` (`std_msgs/msg/Bool`) says whether this robot can talk to `peer`
(docs/ros2.md)."""

from __future__ import annotations

import threading

from components.ros2 import Latest, Ros2Driver
from drd.hosts import Device


class Ros2RadioChannel(Ros2Driver):
    """A ROS 2 robot's radio link. Options: `range` (m, informative). `driver_options`: `peer` (the default peer:
    a Scout's Ranger), `status_max_age`, `topics: {link: ...}`."""

    READINGS = frozenset({"link_ok", "range", "peer"})

    def __init__(self, device: Device, robot_id: str, backend: object = None) -> None:
        super().__init__(device, robot_id, backend)
        self.range = self.option("range", 30.0)
        self.peer = self.opts.peer
        self._links: dict[str, Latest | None] = {}
        self._lock = threading.Lock()
        if self.peer is not None and self.peer != robot_id:  # subscribed now: the first reading finds it there
            self._link(self.peer)

    def _link(self, peer: str) -> Latest | None:
        with self._lock:
            if peer not in self._links:
                self._links[peer] = self.subscribe("link", self.opts.status_max_age, suffix=f"/{peer}")
            return self._links[peer]

    def link_ok(self, peer: str | None = None) -> bool:
        """Whether this robot and `peer` (default: the `peer` option) can talk now."""
        other = peer if peer is not None else self.peer
        if other is None:
            raise ValueError(f"{self.device.id}: {self.robot_id} has no default peer (driver_options: peer); name one")
        latest = self._link(other)
        return bool(latest.get().data) if latest is not None else False
