"""Hardware abstraction (ERSP): the interfaces behaviors use (`drd.hw.interfaces`) and driver loading
(`drd.hw.drivers`); drivers live in `components/<driver>/`, chosen by hosts.yaml and imported lazily."""

from __future__ import annotations

from drd.hw.drivers import DriverError, HostDrivers, driver_entry_point, drivers_for, load_driver
from drd.hw.interfaces import (
    INTERFACES,
    Camera,
    DetectionLike,
    Drive,
    HardwareError,
    Jump,
    Landing,
    Launcher,
    RadioChannel,
    RangeSensor,
    Scan,
    StaleCommand,
)

__all__ = [
    "INTERFACES", "Camera", "DetectionLike", "Drive", "DriverError", "HardwareError", "HostDrivers", "Jump",
    "Landing", "Launcher", "RadioChannel", "RangeSensor", "Scan", "StaleCommand", "driver_entry_point",
    "drivers_for", "load_driver",
]
