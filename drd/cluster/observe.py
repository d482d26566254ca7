"""What a host's real drivers read, for a recording client: the real robots' counterpart of the simulator host's
tap (`drd.sim.observe`), so that `missionctl run --record` on a cluster with no simulator host has the robots'
poses (`/drd/tf`) and laser scans (`/drd/scan/<robot>`) too (docs/recording.md, docs/design.md).

`DriverTap.attach(drivers)` wraps, on each driver instance of a host with no simulator (`drd.hw.HostDrivers`), the
laser's `scan`, so that every scan it gives a behavior also goes, once, into an `Observations` buffer (each new scan,
at most one a control cycle, as the simulator's); `observe(request)` answers the same `WorldObserve` with the same
`WorldObservation` as the simulator host: each robot's pose as its Drive reads it now (`odometry()`: a `ros2`
Drive's is odometry in the mission's map, through its `origin` option), and a page of readings. Times are this
host's monotonic clock: the client measures its offset from the mission's time once, per host.
"""

from __future__ import annotations

import functools
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

from drd.hw.interfaces import HardwareError
from drd.sim.observe import SCAN_EVERY, Observations
from drd.sim.service import OBSERVE_PAGE, WorldObservation, WorldObserve

log = logging.getLogger("drd.cluster.observe")


class DriverTap:
    """One host's real drivers, tapped (see the module). Thread-safe: the Creator builds drivers for each world while
    the bus asks for observations."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self.observations = Observations()  # kept across worlds: a reader's cursor stays valid
        self.drives: dict[str, Any] = {}  # robot -> the driver whose `odometry()` says where it is
        self.lock = threading.Lock()

    def attach(self, drivers: Any) -> None:
        """Tap `drivers` (a `HostDrivers` built with no simulation: real ones); those of a previous world are
        forgotten."""
        drives: dict[str, Any] = {}
        tapped: set[int] = set()
        for robot, parts in getattr(drivers, "robots", {}).items():
            for driver in parts.values():
                if callable(getattr(driver, "odometry", None)) and callable(getattr(driver, "set_velocity", None)):
                    drives.setdefault(robot, driver)
                if callable(getattr(driver, "scan", None)) and id(driver) not in tapped:
                    tapped.add(id(driver))
                    self._tap_scan(robot, driver)
        with self.lock:
            self.drives = drives

    def _tap_scan(self, robot: str, driver: Any) -> None:
        read = driver.scan
        last: dict[str, Any] = {"scan": None, "at": -math.inf}

        def scan() -> Any:
            out = read()
            at = self.clock()
            # a new scan (the driver gives the same one until the robot sends another), at most one a control cycle:
            # half a period apart, as reads in real time are not exactly a period apart
            if out is not last["scan"] and at - last["at"] >= SCAN_EVERY / 2:
                last["scan"], last["at"] = out, at
                ranges = list(out.ranges)
                fov = out.angle_step * (len(ranges) - 1) if len(ranges) > 1 else 0.0
                self.observations.scan(robot, at, ranges, float(out.max_range), fov)
            return out
        driver.scan = functools.update_wrapper(scan, read)

    def observe(self, req: WorldObserve) -> WorldObservation:
        """Every tapped robot's pose now (one whose Drive cannot say, stale or not yet heard from, is left out) and
        a page of readings numbered `req.after` or later."""
        with self.lock:
            drives = dict(self.drives)
        poses: dict[str, list[float]] = {}
        for robot, drive in drives.items():
            try:
                x, y, heading = drive.odometry()
            except (HardwareError, RuntimeError, ValueError) as e:  # no odometry now: no pose this time
                log.debug("%s: no pose to observe: %s", robot, e)
                continue
            poses[robot] = [float(x), float(y), float(heading)]
        now = self.clock()
        readings, nxt, missed = self.observations.after(max(0, min(req.after, self.observations.next)), OBSERVE_PAGE)
        return WorldObservation(now, "", poses, {}, {}, readings, nxt, more=nxt < self.observations.next,
                                missed=missed)
