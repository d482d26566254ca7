"""A component call that never returns, in a process that runs components (the dry-run's, a cluster's worker): found
and ended, so the process and the other components in it go on.

The dry-run runs every component in its own process, so a step in a busy loop, a `start` blocked on a lock or a
`sleep(1e9)` held the whole run, with no report, and `--until` (sim time) never came (wedge audit D4). A cluster's
worker (a container shared by a mission's instances on a host) was killed when a call did not answer within 0.8 s,
failing every instance in it with the stuck one (users audit 22, #1). Here a thread looks at the main thread's
stack every `poll` seconds: the outermost frame of a component's own code (not
drd's, not the standard library's: `drd.errors.components_own`) is the call drd made into it. When one such frame
is still there after `limit` seconds, the main thread is interrupted (a signal, whose handler raises
`ComponentStuck` there, if that call is still running): the exception leaves the component like any it raises,
and its state fails, naming the line it was stuck at. `ComponentStuck` is not an `Exception`: a component's
`except Exception` lets it through (its `finally` blocks run). A call that catches it anyway (`except
BaseException`) and goes on is interrupted again each `limit`; the run goes on as soon as it returns. A call
stuck inside one C function (a huge `sum(range(...))`, a regular expression that backtracks for ever) cannot be
interrupted: Python runs the handler only between two bytecodes.

Only in the main thread (signals); a component that ends the process itself (`os._exit`) cannot be helped here.
"""

from __future__ import annotations

import functools
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

from drd import runtime
from drd.errors import ComponentStuck, components_own

#: Wall seconds a component call may run in the dry-run before it is interrupted.
STUCK_AFTER = 5.0
#: The same in a cluster's worker: below the 0.8 s after which the Creator kills a worker that does not answer
#: (`drd.cluster.workers.CALL_TIMEOUT`), which is left for a call stuck in one C function.
WORKER_STUCK_AFTER = 0.6


#: Where drd calls component code from (the interpreter, the component host, the device proxies; a worker's loop).
_RUNTIME = os.path.join(os.path.dirname(os.path.realpath(runtime.__file__)), "")
_DRD = os.path.join(os.path.dirname(os.path.dirname(_RUNTIME)), "")  # drd's own code, never cut in the middle
_WORKER = os.path.join(_DRD, "cluster", "workers.py")


@functools.lru_cache(maxsize=4096)
def _own(filename: str) -> bool:
    return components_own(filename)


@functools.lru_cache(maxsize=4096)
def _in_drd(filename: str) -> bool:
    return os.path.realpath(filename).startswith(_DRD)


@functools.lru_cache(maxsize=4096)
def _in_runtime(filename: str) -> bool:
    path = os.path.realpath(filename)
    return path.startswith(_RUNTIME) or path == _WORKER


def boundary(frame: FrameType | None) -> FrameType | None:
    """The outermost frame of component code called by drd's runtime in the stack ending at `frame`: the call drd
    made into a component (or a driver); None when the stack is in none."""
    found = None
    while frame is not None:
        caller = frame.f_back
        if caller is not None and _own(frame.f_code.co_filename) and _in_runtime(caller.f_code.co_filename):
            found = frame
        frame = caller
    return found


def _within(frame: FrameType | None, call: FrameType) -> bool:
    while frame is not None:
        if frame is call:
            return True
        frame = frame.f_back
    return False


class StuckWatch:
    """The thread that watches the main thread's component calls (see the module)."""

    def __init__(self, limit: float = STUCK_AFTER, poll: float = 0.25, rule: str = "the dry-run stops a component's"
                 f" call after that; a cluster's worker after {WORKER_STUCK_AFTER:g} s") -> None:
        self.limit, self.poll, self.rule = limit, poll, rule
        self.main = threading.main_thread()
        self.stopped = threading.Event()
        self.stuck: FrameType | None = None  # the call being interrupted (read by the handler)
        self.deferred = False  # the handler found drd's own code running: interrupt again at the next look
        self.calling = threading.Event()  # set while the main thread makes calls (`calls`); always, by default
        self.calling.set()
        self.thread = threading.Thread(target=self._watch, name="drd-stuck-watch", daemon=True)

    @contextmanager
    def calls(self) -> Iterator[None]:
        """The main thread makes component calls in this block: looked at only then (`gated`), so a process that
        waits for work (a cluster's idle worker) is not woken `1 / poll` times a second for nothing."""
        self.calling.set()
        try:
            yield
        finally:
            self.calling.clear()

    def _watch(self) -> None:
        seen: FrameType | None = None
        since = 0.0
        while True:
            if not self.calling.is_set():
                seen = None  # a call after the wait is a new one
                self.calling.wait()
            if self.stopped.wait(self.poll):
                return
            now = time.monotonic()  # not a count of polls: on a loaded machine a poll takes longer than `poll`
            call = boundary(sys._current_frames().get(self.main.ident or 0))
            if call is not seen:
                seen, since = call, now
                continue
            if call is not None and (now - since >= self.limit or self.deferred):
                self.stuck, since, self.deferred = call, now, False  # again after another `limit`
                signal.pthread_kill(self.main.ident or 0, signal.SIGUSR1)
            del call

    def interrupt(self, signum: int, frame: FrameType | None) -> None:
        """The signal's handler, in the main thread: raise in the stuck call if it is still running."""
        stuck, self.stuck = self.stuck, None
        if stuck is None or not _within(frame, stuck):
            return  # it returned meanwhile
        if frame is not None and _in_drd(frame.f_code.co_filename):  # drd's own code runs (a device proxy the
            self.deferred = True  # component called): never cut it in the middle; the next look tries again
            return
        raise ComponentStuck(f"{stuck.f_code.co_name} did not return within {self.limit:g} s of wall time"
                             f" ({self.rule})")


@contextmanager
def stuck_calls_end(limit: float = STUCK_AFTER, poll: float = 0.25, rule: str | None = None,
                    gated: bool = False) -> Iterator[StuckWatch | None]:
    """While the body runs in the main thread, a component call stuck for `limit` seconds is interrupted; `rule`
    (how the error explains the limit) defaults to the dry-run's; `gated`: only within the watch's `calls()`."""
    if threading.current_thread() is not threading.main_thread():
        yield None
        return
    watch = StuckWatch(limit, poll) if rule is None else StuckWatch(limit, poll, rule)
    if gated:
        watch.calling.clear()
    previous = signal.signal(signal.SIGUSR1, watch.interrupt)
    watch.thread.start()
    try:
        yield watch
    finally:
        watch.stopped.set()
        watch.calling.set()  # out of its wait, to see it is stopped
        watch.thread.join(timeout=2 * watch.poll + 1)
        signal.signal(signal.SIGUSR1, previous)
