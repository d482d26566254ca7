"""The Load Reporter's measurements: the host's CPU, memory, load average and instance count (psutil)."""

from __future__ import annotations

import os

import psutil

from drd.bus import LoadReport


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
