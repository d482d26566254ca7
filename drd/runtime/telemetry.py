"""Where each robot is and the charge it has left, read from its own drivers (the dry-run's, in process).

A robot's pose is what its Drive's odometry says (the robot's own belief, as on real hardware), its battery what
its Drive reports (`Drive.battery()`), else the static `battery` of hosts.yaml. A reading the driver cannot give
(it raises, or says NaN) is not known: a constraint on it cannot be measured, so after 2 s it counts as broken (a
NaN pose passed a geofence, a stale battery read as the static 1.0: ROS 2 audit 12). Read at most once per instant
of the clock, and only when an expression asks (`ranger.x` in a guard, a constraint).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

from drd.rcm import Aggregate
from drd.runtime.pool import ResourcePool


class DriverTelemetry:
    """`ResourcePool.telemetry` from drivers by robot and part (`drd.hw.HostDrivers`)."""

    def __init__(self, drivers: Any, pool: ResourcePool, clock: Callable[[], float]) -> None:
        self.drivers = drivers
        self.pool = pool
        self.clock = clock
        self._cache: dict[str, tuple[float, Mapping[str, float] | None]] = {}

    def __call__(self, robot: str) -> Mapping[str, float] | None:
        now = self.clock()
        cached = self._cache.get(robot)
        if cached is not None and cached[0] == now:
            return cached[1]
        data = self._read(robot)
        self._cache[robot] = (now, data)
        return data

    def _read(self, robot: str) -> Mapping[str, float] | None:
        agg = self.pool.candidates.get(robot)
        if not isinstance(agg, Aggregate):
            return None
        drive = None
        for part, unit in agg.parts.items():
            cand = self.pool.candidates.get(unit)
            if cand is not None and cand.type == "Drive":
                parts = getattr(self.drivers, "robots", {}).get(robot, {})
                drive = parts.get(part) or getattr(self.drivers, "devices", {}).get(unit)
                break
        if drive is None:
            return None
        out: dict[str, float] = {}
        try:  # the live `heading` in [-pi, pi], as a ROS yaw: odometry keeps counting turns (7.37 after one)
            x, y, heading = (float(v) for v in drive.odometry())
            if math.isfinite(x) and math.isfinite(y) and math.isfinite(heading):  # NaN: where it is is not known
                out["x"], out["y"], out["heading"] = x, y, math.remainder(heading, math.tau)
        except Exception:  # a lost robot cannot say where it is
            pass
        reading = getattr(drive, "battery", None)
        if callable(reading):
            try:
                out["battery"] = float(reading())
            except Exception:  # the driver cannot tell now (NaN, stale): not known, never the static value
                out["battery"] = math.nan
        return out
