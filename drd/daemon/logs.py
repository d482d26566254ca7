"""Rate-limited logging: a peer that floods us with bad messages costs a few log lines, not a full disk.

`RateLimit` is a `logging.Filter`: per message template, at most `burst` records per `window`
seconds pass; when the window turns over, the next record that passes says how many were dropped.
`drd start` and `drd sim` install it on the loggers that report what peers send (`PEER_LOGGERS`).

`RotatingLog` is a daemon's log file: bounded (it rolls over at `MAX_BYTES`, keeping `BACKUPS` old files), and
reopened when an external logrotate moved or removed it (docs/daemon.md, docs/design.md).
"""

from __future__ import annotations

import logging
import logging.handlers
import os
import threading
import time
from collections.abc import Callable

from drd.inert import escapes

#: What a log line's message shows of a control character: a newline or carriage return, which would start a line of
#: a peer's own making, and the rest of C0, DEL and C1, which a terminal tailing the log would act on.
_ONE_LINE = escapes()


class OneLine(logging.Formatter):
    """A daemon's log format, one line per message: a message's control characters are shown as escapes, so text a
    peer sent (a mission id with a newline, as `_reject` logs it) cannot forge a line of the log (wire audit 25, D5).
    A traceback still follows on its own lines: it is ours."""

    def formatMessage(self, record: logging.LogRecord) -> str:
        record.message = record.message.translate(_ONE_LINE)
        return super().formatMessage(record)


class RateLimit(logging.Filter):
    """At most `burst` records per message template and subject per `window` seconds, and `burst * SUBJECTS` per
    template: the subject is the record's `subject` (`extra={"subject": key}`: the bus's lines, whose first argument
    is the bus's own name), else its first argument (the key a rejected message came on, the host it named).
    Keyed by template alone, a trickle of one junk message used every rejection's budget, and a forged host token
    or load report was counted but never named (wire audit 10, D2); keyed by subject alone, a peer varying its keys
    would make the limit nothing; keyed by the bus's name, junk on one key hid a malformed load report on another
    (wire audit 17, D2)."""

    SUBJECTS = 5  # subjects a template may name in full per window, at the most

    def __init__(self, burst: int = 10, window: float = 10.0, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self.burst, self.window, self.clock = burst, window, clock
        self._lock = threading.Lock()
        # template -> (window start, passed, dropped, passed per subject)
        self._windows: dict[str, tuple[float, int, int, dict[str, int]]] = {}

    def filter(self, record: logging.LogRecord) -> bool:
        template = str(record.msg)
        args = record.args
        subject = getattr(record, "subject", None)
        if subject is None:
            subject = args[0] if isinstance(args, tuple) and args else ""
        subject = str(subject)[:200]
        now = self.clock()
        with self._lock:
            start, passed, dropped, subjects = self._windows.get(template, (now, 0, 0, {}))
            if now - start >= self.window:
                start, passed, subjects = now, 0, {}
            if passed >= self.burst * self.SUBJECTS or subjects.get(subject, 0) >= self.burst:
                self._windows[template] = (start, passed, dropped + 1, subjects)
                return False
            subjects[subject] = subjects.get(subject, 0) + 1
            self._windows[template] = (start, passed + 1, 0, subjects)
            if len(self._windows) > 1024:  # templates are few; never let this grow without bound
                self._windows.clear()
        if dropped:
            record.msg = f"{record.getMessage()} [{dropped} messages of this kind suppressed]"
            record.args = ()
        return True


#: The loggers that report what peers send: drd's bus, its rejections, ROS 2 messages to the drivers and to a served
#: simulator. Each by its own name: a logger's filter sees only the records logged on that logger, not those its
#: children pass up (a `drd.bus.ros2` flood went through the limit put on `drd.bus`).
PEER_LOGGERS = ("drd.bus", "drd.bus.ros2", "drd.daemon.rejects", "drd.hw.ros2", "drd.ros2", "drd.sim.ros2")
#: The controller's placement decisions: one line each, which a mission restarting a component many times an
#: instant turned into 1,200 lines a second (reverify audit 7, D-c). Limited more loosely than what peers send: a
#: mission placing 50 components at once logs them all. `missionctl status` explains every placement anyway.
PLACEMENT_LOGGER, PLACEMENT_BURST = "drd.daemon.placement", 100


def install_daemon_limits() -> None:
    """`drd start`'s limits: what peers send, and the controller's placement lines."""
    install(*PEER_LOGGERS)
    install(PLACEMENT_LOGGER, burst=PLACEMENT_BURST)


def install(*names: str, burst: int = 10, window: float = 10.0) -> None:
    """Put one `RateLimit` on each named logger (once: installing again changes nothing)."""
    for name in names:
        logger = logging.getLogger(name)
        if not any(isinstance(f, RateLimit) for f in logger.filters):
            logger.addFilter(RateLimit(burst, window))


#: A daemon's log rolls over at this size (about 13,000 missions of a controller's log, measured 0.75 KB each)...
MAX_BYTES = 10 * 1024 * 1024
#: ...keeping this many old files (`HOST.log.1` the newest): at most 40 MB of logs per daemon.
BACKUPS = 3


class RotatingLog(logging.handlers.RotatingFileHandler):
    """A daemon's log file, bounded: it rolls over past `max_bytes`, keeping `backups` old files. It also
    reopens its file when something else moved or removed it (an external logrotate without `copytruncate`),
    where a plain file handler would go on writing to the moved file, or to a deleted one, forever."""

    def __init__(self, path: str | os.PathLike[str], max_bytes: int = MAX_BYTES, backups: int = BACKUPS) -> None:
        super().__init__(path, maxBytes=max_bytes, backupCount=backups, encoding="utf-8")

    def emit(self, record: logging.LogRecord) -> None:
        stream = self.stream
        if stream is not None and self._moved(stream.fileno()):
            stream.close()
            self.stream = None  # reopened by the emit below, as after close()
        super().emit(record)

    def _moved(self, fd: int) -> bool:
        """The path no longer names the open file (one stat per record: a daemon logs a few lines a minute)."""
        try:
            now = os.stat(self.baseFilename)
        except FileNotFoundError:
            return True
        opened = os.fstat(fd)
        return (now.st_dev, now.st_ino) != (opened.st_dev, opened.st_ino)
