"""The `ros2` RangeSensor: the latest `sensor_msgs/msg/LaserScan` on `scan` (docs/ros2.md)."""

from __future__ import annotations

import math
from typing import Any

from components.ros2 import Ros2Driver
from drd.hosts import Device
from drd.hw.interfaces import HardwareError, Scan
from drd.hw.ros2 import scan_ranges

#: The most beams a scan may have: the densest 2D lasers give a few thousand (0.0625 degrees over 360: 5,760).
MAX_BEAMS = 20_000


class Ros2RangeSensor(Ros2Driver):
    """A ROS 2 laser. Options: `beams`, `max_range` (manifest properties: what the device is said to have; the
    scan itself says what it has). `driver_options`: `max_age`, `scan_frame`, `topics: {scan: ...}`."""

    READINGS = frozenset({"scan", "beams", "max_range"})

    def __init__(self, device: Device, robot_id: str, backend: object = None) -> None:
        super().__init__(device, robot_id, backend)
        self.beams = int(self.option("beams", 181))
        self.max_range = self.option("max_range", 8.0)
        self._scan = self.subscribe("scan", self.opts.max_age, self.opts.frames.get("scan_frame"))
        self._latest: tuple[Any, Scan] | None = None

    def scan(self) -> Scan:
        """The latest scan, right to left, angles relative to the heading: the same object until a new one comes."""
        assert self._scan is not None
        msg = self._scan.get()
        if self._latest is not None and self._latest[0] is msg:
            return self._latest[1]
        top, low, first, step = float(msg.range_max), float(msg.range_min), float(msg.angle_min), \
            float(msg.angle_increment)
        if not all(math.isfinite(v) for v in (top, low, first, step)) or top <= 0:
            raise HardwareError(f"{self.describe()}: the laser's scan geometry is not usable (angle_min {first}, "
                                f"angle_increment {step}, range_min {low}, range_max {top}): a faulted laser")
        count, said = len(msg.ranges), _beams_said(first, float(msg.angle_max), step)
        if count > MAX_BEAMS:  # converted and shipped every cycle, a 4 MB scan stalled the host (ros2 audit 18, #3)
            raise HardwareError(f"{self.describe()}: the laser gives {count:,} beams, more than {MAX_BEAMS:,}: "
                                "not a scan drd reads (a 2D laser has a few thousand)")
        if count == 0 or 2 * count < said:  # a laser that lost its data but still heartbeats: never free space
            raise HardwareError(f"{self.describe()}: the laser gives {count} beams where its scan's angles say "
                                f"{said}: a faulted laser (an empty scan is never read as free space)")
        try:
            ranges = scan_ranges(msg.ranges, low, top)
        except HardwareError as e:  # which laser, as every other fault of it says (ros2 audit 22, #3)
            raise HardwareError(f"{self.describe()}: {e}") from None
        scan = Scan(ranges, first, step, top)
        self._latest = (msg, scan)
        return scan


def _beams_said(angle_min: float, angle_max: float, increment: float) -> int:
    """How many beams a LaserScan's angles say it has (0 when they do not say: a zero or non-finite step)."""
    if increment == 0 or not math.isfinite(angle_max):
        return 0
    beams = round((angle_max - angle_min) / increment) + 1
    return beams if 0 < beams <= 1_000_000 else 0
