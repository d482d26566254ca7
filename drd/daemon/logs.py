"""Rate-limited logging: a peer that floods us with bad messages costs a few log lines, not a full disk.

`RateLimit` is a `logging.Filter`: per message template, at most `burst` records per `window`
seconds pass; when the window turns over, the next record that passes says how many were dropped.
The daemon installs it on the loggers that report what peers send (`drd.bus`, `drd.daemon.rejects`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable


class RateLimit(logging.Filter):
    """At most `burst` records per message template per `window` seconds."""

    def __init__(self, burst: int = 10, window: float = 10.0, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self.burst, self.window, self.clock = burst, window, clock
        self._lock = threading.Lock()
        self._windows: dict[str, tuple[float, int, int]] = {}  # template -> (window start, passed, dropped)

    def filter(self, record: logging.LogRecord) -> bool:
        template = str(record.msg)
        now = self.clock()
        with self._lock:
            start, passed, dropped = self._windows.get(template, (now, 0, 0))
            if now - start >= self.window:
                start, passed = now, 0
            if passed >= self.burst:
                self._windows[template] = (start, passed, dropped + 1)
                return False
            self._windows[template] = (start, passed + 1, 0)
            if len(self._windows) > 1024:  # templates are few; never let this grow without bound
                self._windows.clear()
        if dropped:
            record.msg = f"{record.getMessage()} [{dropped} similar messages suppressed]"
            record.args = ()
        return True


def install(*names: str, burst: int = 10, window: float = 10.0) -> None:
    """Put one `RateLimit` on each named logger (once: installing again changes nothing)."""
    for name in names:
        logger = logging.getLogger(name)
        if not any(isinstance(f, RateLimit) for f in logger.filters):
            logger.addFilter(RateLimit(burst, window))
