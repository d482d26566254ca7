"""Noticing, from inside, that this process did not run for a while (SIGSTOP, a suspended machine, starvation).

A host's Creator asks before every call and at every tick of its daemon (`Creator.check_freeze`): whichever runs
first after the process resumes sees the gap, so a call that waited in the socket through the freeze is never
served as if nothing had happened. Pure apart from the clock it is given.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable


class FreezeWatch:
    """The time between two looks; a gap longer than `limit` seconds is reported once, by the look that sees it."""

    def __init__(self, limit: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.limit, self.clock = limit, clock
        self._last = clock()
        self._lock = threading.Lock()

    def restart(self) -> None:
        """Count from now (a process that was busy starting up was not frozen)."""
        with self._lock:
            self._last = self.clock()

    def gap(self) -> float:
        """The seconds this process stood still before this look, when longer than `limit`, else 0.0."""
        with self._lock:
            now = self.clock()
            gap, self._last = now - self._last, now
        return gap if gap > self.limit else 0.0
