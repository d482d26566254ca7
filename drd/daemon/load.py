"""The Load Reporter's measurements: the host's CPU, memory, load average and instance count (psutil), and on the
acting controller the robots' live properties (`live_robots`, pure) that every daemon's trader merges over hosts.yaml.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Mapping

import psutil

from drd.bus import LoadReport
from drd.hosts import Robot

#: What a robot's drivers report (`drd.runtime.pool.LIVE`): its odometry's pose and its charge left.
TELEMETRY = ("x", "y", "heading", "battery")
#: A live string value longer than this is left out: a report stays small whatever a component writes.
MAX_TEXT = 200


class LoadSampler:
    """Samples the host's load; CPU is the average since the previous sample (psutil, non-blocking)."""

    def __init__(self, host: str) -> None:
        self.host = host
        self._process = psutil.Process(os.getpid())
        psutil.cpu_percent(interval=None)  # the first reading only starts the measurement

    def sample(self, instances: int, at: float) -> LoadReport:
        """A `LoadReport` stamped `at` (wall-clock seconds)."""
        cpu = psutil.cpu_percent(interval=None)
        memory = psutil.virtual_memory().percent
        load1 = psutil.getloadavg()[0]
        return LoadReport(self.host, float(cpu), float(memory), float(load1), instances, at)

    def rss(self) -> int:
        """This process's resident memory, in bytes."""
        return int(self._process.memory_info().rss)


def live_robots(robots: Iterable[Robot], properties: Callable[[str], Mapping[str, object]],
                telemetry: Mapping[str, Mapping[str, object]]) -> dict[str, dict[str, object]]:
    """What the controller's `LiveReport` carries for the configured `robots`: the properties its Static Dependency
    Database (`properties(id)`) holds with another value than hosts.yaml (a launched Scout's `carrier` is ""), then the
    drivers' latest `telemetry` (finite numbers). Only hosts.yaml's robots, their own keys and scalar values: the
    report's size is bounded by the hosts file, and a robot with nothing live is left out."""
    out: dict[str, dict[str, object]] = {}
    for r in robots:
        values: dict[str, object] = {}
        try:
            known = dict(properties(r.id))
        except Exception:  # the manager is changing it right now (another thread): the next report has it
            known = {}
        for key, value in known.items():
            if key in r.properties and value != r.properties[key] and live_value(value):
                values[key] = value
        for key, value in (telemetry.get(r.id) or {}).items():
            if key in TELEMETRY and live_value(value) and not isinstance(value, str | bool):
                values[key] = float(value)  # type: ignore[arg-type]
        if values:
            out[r.id] = values
    return out


#: The integers a live property may hold: those the bus can send again (64 bits). A larger one, which the decoder takes,
#: made every daemon's trader reply unsendable, so `missionctl query` failed on every host (wire audit 25, D3).
LIVE_INTS = range(-(2**63), 2**63)


def live_value(value: object) -> bool:
    """A value a live property may take: a string of at most `MAX_TEXT` characters, a bool, a finite float, an
    integer of 64 bits."""
    if isinstance(value, str):
        return len(value) <= MAX_TEXT
    if isinstance(value, int):
        return isinstance(value, bool) or value in LIVE_INTS
    return isinstance(value, float) and math.isfinite(value)
