"""The Component Creator's worker processes: pre-started containers, dedicated processes, the pipe protocol.

Component code is not ours to trust: a component that crashes the interpreter (`os._exit`, a segfault in an
extension, the OOM killer) must take down its process, never the daemon. So the Creator
(`drd.cluster.creator`) runs every component instance in a worker process and keeps the trusted side to
itself: the catalog check, the drivers, their fencing (`drd.runtime.fence.Fenced`), the per-cycle
arbitration of actuator commands and the simulator.

- `WorkerPool` keeps `size` idle workers started ahead of time (default 2, `DRD_WORKERS`) and refills in a
  background thread, so placing an instance costs a pipe round trip, not a process start, but only while the
  host has work: the pool is **warm** from a `take` or a `warm()` (the Creator's, when a world starts) until
  `keep_warm` seconds after the last of them, then its idle workers are stopped, and with them the fork server
  (started again by the next spawn). An idle daemon has no worker and no fork server, and one that never runs a
  component (the controller, on its own host) never starts it. Workers come from
  a `multiprocessing` **forkserver**: the daemon holds zenoh threads and must never fork; the fork server is a
  fresh single-threaded interpreter that imports the behavior modules once (`preload`), so a refill is a
  fork of a warm process (a few ms) and a first placement finds its module already imported.
- A worker taken by the Creator becomes a **container** (hosting every instance whose manifest says
  `process: container` with the same `scheduling`) or a **dedicated** process (one instance, never shared).
- The protocol is duplex, over one `multiprocessing` pipe per worker; its messages are the typed records of
  `drd.cluster.pipe` (one `encode`, one `decode`). A new worker says `Ready`. The Creator sends `Run` (one or
  several `Call`s, see `run_calls`); the worker may send any number of driver requests, `DeviceCall` /
  `AttrRead`, each answered `Ok` or `Raise`, and setpoints, `Command` (not answered), and ends with `Done`
  (a `CallReply` per call run). `Drop` forgets instances (no answer). What comes from a worker is decoded as plain
  data only (`pipe.PlainUnpickler`: no class is ever looked up), so a component cannot make the Creator build
  an object, and a malformed message (`pipe.ProtocolError`) gets its worker killed. The worker reads the
  Creator's messages with the normal unpickler (`decode(..., trusted=True)`): a `Raise` carries the driver's
  exception.
- Readings ahead: a step call may carry the readings its instance made in its previous step, read again by
  the Creator just before (the `READINGS` of the `sim` drivers, a function of the world's instant); the
  proxy serves those without a round trip (`pipe.reading_key` names them). An answer whose `changed` is set
  says the world changed since (a launch): the rest of the run asks for every reading.
- A worker that dies, or does not answer within `call_timeout` (it is then killed), raises `WorkerDied`
  with its exit code; the Creator fails the calls of its instances and takes another worker.

- Snapshots: a `start` may carry the state to restore (`Component.restore` before `start`); a reply carries the
  instance's snapshot after its start and every `SNAPSHOT_EVERY` steps when it changed, and always after a
  `terminate` whose status is `moved` (the instance goes on on another host).

`Tune`/`Tuned` are the Creator's run-time scheduling request and answer (`missionctl tune`).
"""

from __future__ import annotations

import collections
import contextlib
import functools
import json
import logging
import multiprocessing
import os
import pickle
import select
import signal
import sys
import threading
import time
import types
from collections.abc import Iterable, Iterator, Sequence
from multiprocessing.connection import Connection
from multiprocessing.connection import wait as wait_for
from multiprocessing.process import BaseProcess
from typing import Any

import psutil

from drd import entrypoints
from drd.bus import Message, message
from drd.cluster.pipe import (
    AttrRead,
    Call,
    CallReply,
    Command,
    DeviceCall,
    Done,
    Drop,
    Ok,
    ProtocolError,
    Raise,
    Ready,
    Run,
    Setup,
    decode,
    encode,
    reading_key,
)
from drd.cluster.pipe import Message as PipeMessage
from drd.errors import COMPONENT_RAISES, ComponentFailure, debug_traceback, raised
from drd.hw.commands import spec_of
from drd.stuck import STUCK_AFTER, WORKER_STUCK_AFTER, stuck_calls_end

log = logging.getLogger("drd.cluster.workers")

#: Idle workers kept ready while the host has work (`DRD_WORKERS` overrides it for a daemon).
DEFAULT_SIZE = 2
#: Seconds idle workers are kept after the last `take` or `warm()`: a mission's components start and stop within
#: it; a daemon with no mission frees them (about 7 MB each) after it.
KEEP_WARM = 60.0
#: Seconds a worker may take to send its next message during a call before it is killed. Below the
#: executive's 1 s per call (`drd.daemon.missions.CALL_TIMEOUT`): a component stuck in a loop fails its
#: state with a clear error instead of making its whole host look lost.
CALL_TIMEOUT = 0.8
#: Seconds a new worker may take to say hello.
START_TIMEOUT = 20.0
#: Consecutive failed starts after which the pool says its workers cannot start (`WorkerPool.fault`, one log line).
FAULT_AFTER = 3
#: Longest pause between two tries of the background refill while workers cannot start: with the fork server's
#: traceback in the log at each try, at most one a minute (and none once the pool is cold, `keep_warm`).
RETRY_MAX = 60.0

#: Seconds a dropped instance's `shutdown` may take, all of a process's dropped instances together: the worker
#: gives up waiting for the rest after it (each runs in a thread of its own), and a retired process still running
#: then is killed (`WorkerPool.retire`, a little later). A component that hangs in `shutdown` never holds up a
#: mission's end, a move or a retire, and its process never outlives this bound by much.
SHUTDOWN_GRACE = 1.0
#: Seconds after `SHUTDOWN_GRACE` a retired worker is given to exit (its interpreter's own ending) before it is
#: killed.
REAP_MARGIN = 0.5

#: Modules every worker needs, imported once by the fork server.
BASE_PRELOAD = ("drd.cluster.workers", "drd.runtime.component", "drd.runtime.records", "drd.hw.interfaces")


@message("drd.creator.tune", 1)
class Tune(Message):
    """Set the CPU affinity (`cores`) and/or nice level of the process running `instance`; None leaves it.
    With neither, it only reports the current settings."""

    instance: str
    cores: list[int] | None = None
    nice: int | None = None


@message("drd.creator.tuned", 1)
class Tuned(Message):
    """What the process of `instance` runs with now, and which other instances share it (a container)."""

    instance: str
    host: str
    pid: int
    process: str
    cores: list[int]
    nice: int
    shared_with: list[str]


class WorkerDied(ComponentFailure):
    """The worker process is gone (crashed, killed, or stuck and killed by us); the message says how."""


# -- the Creator's side ---------------------------------------------------------------------------------


class Worker:
    """One worker process and the Creator's end of its pipe (used under the Creator's lock)."""

    def __init__(self, proc: BaseProcess, conn: Connection, pid: int, lock: threading.Lock | None = None) -> None:
        self.proc = proc
        # multiprocessing reads a forkserver child's exit code from a pipe once: two threads polling at once
        # (ours, and Process.start's clean-up of finished children) could lose it, so polls share the pool's lock
        self._lock = lock or threading.Lock()
        self.conn = conn
        self.pid = pid
        self.kind = "idle"  # idle, container or dedicated
        self.key: tuple[tuple[int, ...] | None, int] | None = None  # the manifest scheduling it was placed with
        self.mission = ""  # the mission whose instances it hosts (a process never serves two)
        self.tuned = False  # changed at run time: no new instance joins it
        self.instances: set[str] = set()
        self.died = ""  # why it is gone, once it is
        self.received = 0  # bytes of its last message (a large one's replies may not fit a bus message)
        # one poll object for the pipe and the exit sentinel: `multiprocessing.connection.wait` builds a selector
        # per call, which is most of a round trip's cost on the Creator's side
        self._poll = select.poll()
        self._poll.register(conn.fileno(), select.POLLIN)
        self._poll.register(proc.sentinel, select.POLLIN)

    def __repr__(self) -> str:
        return f"Worker(pid={self.pid}, {self.kind}, {sorted(self.instances)})"

    def send(self, msg: PipeMessage) -> None:
        try:
            self.conn.send_bytes(encode(msg))
        except (BrokenPipeError, ConnectionResetError, EOFError) as e:
            raise self._gone() from e

    def recv(self, timeout: float) -> PipeMessage:
        """The worker's next message (plain data only); WorkerDied if it dies, stays silent for `timeout` seconds
        or sends something malformed (killed)."""
        try:
            events = _spin(self._poll) or self._poll.poll(max(0, int(timeout * 1000)))
        except (OSError, ValueError):  # the pipe is closed
            events = [(self.proc.sentinel, select.POLLHUP)]
        fds = {fd for fd, _ in events}
        if not self.conn.closed and self.conn.fileno() in fds:
            try:
                data = self.conn.recv_bytes()
                self.received = len(data)
                return decode(data)
            except (EOFError, OSError):
                pass
            except pickle.UnpicklingError as e:
                self.kill()
                raise WorkerDied(f"sent something that is not plain data ({e}): killed") from None
            except ProtocolError as e:
                self.kill()
                raise WorkerDied(f"sent an unexpected message ({e}): killed") from None
        elif not events:
            self.kill()
            self.died = f"did not answer within {timeout:g} s (killed)"
            raise WorkerDied(self.died)
        raise self._gone()

    def _gone(self) -> WorkerDied:
        with self._lock:
            self.proc.join(1.0)
            code = self.proc.exitcode
        self.died = self.died or f"died (exit code {code if code is not None else 'unknown'})"
        return WorkerDied(self.died)

    def kill(self) -> None:
        """SIGKILL and reap (bounded): a worker never outlives this call."""
        with self._lock:
            if self.proc.exitcode is None:
                try:
                    self.proc.kill()
                except (OSError, ValueError, AttributeError):
                    pass
                self.proc.join(5.0)
        self.died = self.died or "stopped"
        self.conn.close()

    @property
    def alive(self) -> bool:
        if self.died:
            return False
        with self._lock:
            return self.proc.exitcode is None


_open_pools = 0
_open_lock = threading.Lock()


class WorkerPool:
    """`size` idle workers started ahead of time (a background thread refills); `take` hands one out.

    `preload` modules are imported once by the fork server (the behavior modules of the catalog), so neither a
    refill nor a first placement imports them. The pool owns every worker it started: `close` kills them all
    (by pid, reaped), and the last pool of the process also stops the fork server.
    """

    def __init__(self, size: int = DEFAULT_SIZE, *, preload: Iterable[str] = (), call_timeout: float = CALL_TIMEOUT,
                 method: str = "forkserver", keep_warm: float = KEEP_WARM, warm: bool = True) -> None:
        global _open_pools
        if size < 0:
            raise ValueError(f"pool size must be >= 0, not {size}")
        self.size = size
        self.call_timeout = call_timeout
        self.keep_warm = keep_warm
        self.cooled = 0  # times the fork server was stopped because the pool went cold (`_cool_down`)
        self._warm_until = time.monotonic() + keep_warm if warm else 0.0  # idle workers are kept until then
        self._ctx: Any = multiprocessing.get_context(method)
        if method == "forkserver":
            self._ctx.set_forkserver_preload(list(dict.fromkeys([*BASE_PRELOAD, *preload])))
        self._idle: collections.deque[Worker] = collections.deque()
        self._workers: dict[int, Worker] = {}  # every live worker of ours, idle or taken
        self._cond = threading.Condition()
        self._spawn_lock = threading.Lock()  # Process.start is not thread-safe (multiprocessing's child list)
        self._closed = False
        self.started = 0
        self.failures = 0  # starts failed in a row (any success resets it)
        self.fault = ""  # why workers cannot start, once `FAULT_AFTER` starts in a row failed; "" while they do
        with _open_lock:
            _open_pools += 1
        self._thread = threading.Thread(target=self._refill, name="drd-workers", daemon=True)
        self._thread.start()

    def warm(self) -> None:
        """Keep `size` idle workers from now until `keep_warm` seconds after the last call (starting them now)."""
        with self._cond:
            self._warm_until = time.monotonic() + self.keep_warm
            self._cond.notify_all()

    def take(self, timeout: float = START_TIMEOUT) -> Worker:
        """An idle worker (started now if none is ready); the pool starts another in the background."""
        with self._cond:
            if self._closed:
                raise RuntimeError("the worker pool is closed")
            self._warm_until = time.monotonic() + self.keep_warm
            while self._idle:
                w = self._idle.popleft()
                if w.alive:
                    self._cond.notify_all()
                    return w
                self._forget(w)
            self._cond.notify_all()
        try:
            w = self._spawn(timeout)
        except Exception as e:
            raise self._start_failed(e) from None
        self._start_ok()
        with self._cond:
            if self._closed:
                w.kill()
                raise RuntimeError("the worker pool is closed")
        return w

    def release(self, worker: Worker) -> None:
        """Kill a worker taken from the pool (its instances are gone) and forget it."""
        worker.kill()
        with self._cond:
            self._forget(worker)

    def retire(self, worker: Worker, paths: Iterable[str], grace: float = SHUTDOWN_GRACE) -> threading.Thread | None:
        """Stop a worker whose instances (`paths`) are dropped: they get their `shutdown` first (`Drop`), then the
        worker exits by itself (its pipe is closed); one still running `grace` seconds (and a little) later is
        killed. Returns at once: the reaper thread that waits (None: the worker was killed now), so a retire
        never waits for component code; join it to know the process is gone."""
        paths = tuple(paths)
        if not paths or not worker.alive:
            self.release(worker)
            return None
        try:
            worker.send(Drop(paths))
        except WorkerDied:
            self.release(worker)
            return None
        with contextlib.suppress(OSError):
            worker.conn.close()  # the worker reads the Drop, then the end of its pipe: it exits
        reaper = threading.Thread(target=self._reap, args=(worker, grace + REAP_MARGIN), name="drd-reap", daemon=True)
        reaper.start()
        return reaper

    def _reap(self, worker: Worker, wait: float) -> None:
        """A retired worker exits by itself within `wait` seconds, or is killed then; either way reaped."""
        wait_for([worker.proc.sentinel], wait)
        self.release(worker)

    def idle(self) -> int:
        with self._cond:
            return sum(1 for w in self._idle if w.alive)

    def pids(self) -> list[int]:
        """Every live worker process of this pool, idle or taken."""
        with self._cond:
            return [pid for pid, w in self._workers.items() if w.alive]

    def wait_ready(self, timeout: float = START_TIMEOUT) -> bool:
        """Warm the pool and block until `size` workers are idle (bounded): for benches and tests."""
        self.warm()
        deadline = time.monotonic() + timeout
        with self._cond:
            while sum(1 for w in self._idle if w.alive) < self.size:
                left = deadline - time.monotonic()
                if left <= 0 or self._closed:
                    return False
                self._cond.wait(min(left, 0.05))
        return True

    def close(self) -> None:
        """Kill every worker (SIGKILL by pid, reaped); the last pool of the process also stops the fork server."""
        global _open_pools
        with self._cond:
            if self._closed:
                return
            self._closed = True
            workers = list(self._workers.values())
            self._workers.clear()
            self._idle.clear()
            self._cond.notify_all()
        self._thread.join(START_TIMEOUT)  # a worker being started when we closed is killed by its starter
        for w in workers:
            w.kill()
        with _open_lock:
            _open_pools -= 1
            last = _open_pools == 0
        if last:
            _stop_forkserver()

    def _forget(self, worker: Worker) -> None:
        self._workers.pop(worker.pid, None)

    def _cool_down(self) -> None:
        """The pool went cold: with no worker left anywhere in this process, the fork server (and its resource
        tracker, about 40 MB with the behaviors' modules) goes too; the next spawn starts it again
        (multiprocessing's `ensure_running`), preloading the same modules. Under the spawn lock, so no spawn of
        this pool races it; only when this is the process's one pool, so no other pool's spawn does."""
        with self._spawn_lock:
            with self._cond:
                busy = bool(self._workers) or self._closed or self._warm_until > time.monotonic()
            with _open_lock:
                alone = _open_pools == 1
            if not busy and alone and self._ctx.get_start_method() == "forkserver":
                _stop_forkserver()
                self.cooled += 1

    def _spawn(self, timeout: float = START_TIMEOUT) -> Worker:
        with self._spawn_lock:
            parent, child = self._ctx.Pipe(duplex=True)
            proc = self._ctx.Process(target=worker_main, args=(child,), name="drd-worker", daemon=True)
            with _main_hidden():
                proc.start()
            child.close()
            assert proc.pid is not None
            w = Worker(proc, parent, proc.pid, self._spawn_lock)
            self.started += 1
        with self._cond:  # never while holding the spawn lock: `take` polls workers (that lock) under this one
            self._workers[w.pid] = w
        try:
            hello = w.recv(timeout)
        except WorkerDied:
            with self._cond:
                self._forget(w)
            raise
        if not isinstance(hello, Ready):
            self.release(w)
            raise WorkerDied(f"a new worker said {hello!r} instead of hello")
        return w

    def _start_failed(self, e: Exception) -> WorkerDied:
        """Count a failed start; the error for whoever wanted the worker. The `FAULT_AFTER`-th in a row is a host
        fault (`fault`), logged once as an error; the others are a warning until then, a debug line after."""
        with self._cond:
            self.failures += 1
            faulty, newly = bool(self.fault), not self.fault and self.failures >= FAULT_AFTER
            if newly:
                self.fault = f"worker processes cannot start ({e})"
        if newly:
            log.error("%s, %d times in a row: every component placed on this host fails until one starts (the "
                      "worker's own error, if any, is above; files changed under the daemon or a broken "
                      "installation: restart it)", self.fault, self.failures)
        elif faulty:
            log.debug("a worker process still cannot start (%s)", e)
        else:
            log.warning("could not start a worker process (%s); retrying", e)
        return WorkerDied(f"this host's worker processes cannot start ({e})" if self.fault
                          else f"a worker process could not start ({e})")

    def _start_ok(self) -> None:
        """A worker started: the host fault, if any, is over (said once)."""
        with self._cond:
            was, self.fault, self.failures = self.fault, "", 0
        if was:
            log.warning("worker processes start again (they could not: %s)", was)

    def _refill(self) -> None:
        while True:
            idle: list[Worker] = []
            with self._cond:
                while not self._closed:
                    left = self._warm_until - time.monotonic()
                    if left <= 0 and self._idle:  # nothing taken for `keep_warm` s: the idle workers go
                        idle = [self._idle.popleft() for _ in range(len(self._idle))]
                        for w in idle:
                            self._forget(w)
                        break
                    if left > 0 and sum(1 for w in self._idle if w.alive) < self.size:
                        break
                    self._cond.wait(left if left > 0 else None)
                if self._closed:
                    return
            if idle:
                for w in idle:  # outside the condition: a kill reaps, which may take a moment
                    w.kill()
                self._cool_down()
                continue
            try:
                w = self._spawn()
            except Exception as e:  # keep the daemon serving; try again a little later (sooner if closed)
                self._start_failed(e)
                with self._cond:
                    self._cond.wait_for(lambda: self._closed, min(RETRY_MAX, 0.2 * 2 ** min(self.failures, 9)))
                continue
            self._start_ok()
            with self._cond:
                if self._closed:
                    w.kill()
                    return
                self._idle.append(w)
                self._cond.notify_all()


_main_lock = threading.Lock()  # one start at a time hides the main module, so each restores what it saw


@contextlib.contextmanager
def _main_hidden() -> Iterator[None]:
    """Start workers without the daemon's main module: multiprocessing would make each worker run it again,
    from disk (`spawn.prepare`), so files changed under a running daemon (an upgrade) would kill every new worker
    at import. Instead, for the moment of a start, `sys.modules['__main__']` is a module with no `__spec__` and
    no `__file__` (what `python -c` has): multiprocessing then sends neither `init_main_from_name` nor
    `init_main_from_path`, and the worker keeps the fork server's `__main__`. A worker's target and arguments
    (`worker_main`, a pipe) need nothing from `__main__`. One lock for every pool: each restores what it saw."""
    with _main_lock:
        real = sys.modules.get("__main__")
        sys.modules["__main__"] = types.ModuleType("__main__")  # no spec, no file: the main of `python -c`
        try:
            yield
        finally:
            if real is not None:
                sys.modules["__main__"] = real
            else:
                sys.modules.pop("__main__", None)


def _stop_forkserver() -> None:
    """Stop multiprocessing's fork server (and its resource tracker): no process of ours is left behind.
    Private API (`_stop`, used by CPython's own tests); if it changes, they still exit with this process."""
    try:
        from multiprocessing import forkserver, resource_tracker

        forkserver._forkserver._stop()  # type: ignore[attr-defined]
        resource_tracker._resource_tracker._stop()  # type: ignore[attr-defined]
    except Exception:  # pragma: no cover - best effort
        log.debug("could not stop the fork server", exc_info=True)


#: Seconds a side of the pipe polls before it sleeps in the kernel: most answers come within it, and a
#: wake-up from sleep costs more than the answer on a busy machine (measured in docs/design.md).
SPIN = 0.0002


def _spin(poll: Any) -> list[tuple[int, int]]:
    """Poll without sleeping for up to `SPIN` seconds: the events, or [] (then sleep in `poll` as usual)."""
    deadline = time.perf_counter() + SPIN
    while True:
        events: list[tuple[int, int]] = poll.poll(0)
        if events or time.perf_counter() >= deadline:
            return events


def apply_scheduling(pid: int, cores: Sequence[int] | None, nice: int | None) -> list[int]:
    """Set the nice level and CPU affinity of every thread of process `pid`; the threads it changed.

    Raises psutil.Error/OSError/ValueError (AccessDenied: raising priority needs privileges)."""
    proc = psutil.Process(pid)
    tids = [t.id for t in proc.threads()] or [pid]
    for tid in tids:
        if nice is not None:
            os.setpriority(os.PRIO_PROCESS, tid, nice)
        if cores is not None:
            os.sched_setaffinity(tid, list(cores))
    return tids


def scheduling_of(pid: int) -> tuple[list[int], int]:
    """(CPU affinity, nice) of process `pid`, as psutil reports them."""
    proc = psutil.Process(pid)
    return sorted(proc.cpu_affinity() or []), int(proc.nice())


def device_methods(driver: object) -> list[str]:
    """The declared names of a driver that are methods (`drd.hw.commands`): the calls a worker's proxy forwards
    (its other declared names are attributes; the Creator's device handle refuses anything undeclared)."""
    cls = type(driver)
    return sorted(n for n in spec_of(driver).names if callable(getattr(cls, n, None)))


# -- the worker's side ----------------------------------------------------------------------------------


class _Link:
    """The worker's end of the pipe, for driver requests made from inside a call, and the readings the Creator
    read ahead of the call (`ahead`, see `drd.cluster.creator.Creator._read_ahead`)."""

    def __init__(self, conn: Connection) -> None:
        self.conn = conn
        self._poll = select.poll()
        self._poll.register(conn.fileno(), select.POLLIN)
        self.ahead: dict[tuple[Any, ...], Any] = {}
        self.used: set[tuple[Any, ...]] = set()
        self.changed = False  # the world changed during this run: what was read ahead of it is stale

    def begin(self, ahead: dict[tuple[Any, ...], Any] | None) -> None:
        """A call starts, with the readings read ahead of it (none once the world changed in this run)."""
        self.ahead = {} if self.changed or ahead is None else ahead
        self.used = set()

    def unused(self) -> list[tuple[Any, ...]]:
        """The call is over: the readings read ahead that it did not use."""
        left = [k for k in self.ahead if k not in self.used]
        self.ahead = {}
        return left

    def _ahead(self, key: tuple[Any, ...] | None, once: bool) -> tuple[bool, Any]:
        if key is None or key not in self.ahead:
            return False, None
        self.used.add(key)
        return True, self.ahead.pop(key) if once else self.ahead[key]

    def send(self, msg: PipeMessage) -> None:
        self.conn.send_bytes(encode(msg))

    def request(self, req: DeviceCall | AttrRead) -> Any:
        try:
            self.send(req)
        except (pickle.PicklingError, TypeError, AttributeError) as e:
            raise TypeError(f"a driver call takes plain data only: {e}") from None
        _spin(self._poll)  # the Creator answers a reading in ~0.1 ms: do not fall asleep for it
        answer = decode(self.conn.recv_bytes(), trusted=True)  # from the Creator: a Raise carries an exception
        if not isinstance(answer, Ok | Raise):
            raise ProtocolError(f"a driver request answered by {type(answer).__name__}, not Ok or Raise")
        if answer.changed:
            self.changed, self.ahead = True, {}
        if isinstance(answer, Raise):
            raise answer.error
        return answer.value

    def call(self, path: str, need: str, method: str, *args: Any, **kwargs: Any) -> Any:
        req = DeviceCall(path, need, method, args, kwargs)
        if self.ahead:  # a method's result is used once (the component may change it); the next call asks
            found, value = self._ahead(reading_key(req), once=True)
            if found:
                return value
        return self.request(req)

    def attr(self, path: str, need: str, name: str) -> Any:
        req = AttrRead(path, need, name)
        if self.ahead:
            found, value = self._ahead(reading_key(req), once=False)
            if found:
                return value
        return self.request(req)

    def command(self, path: str, need: str, method: str, *args: Any, **kwargs: Any) -> None:
        """A setpoint: sent without waiting (it returns nothing; a refusal fails the step when it ends)."""
        try:
            self.send(Command(path, need, method, args, kwargs))
        except (pickle.PicklingError, TypeError, AttributeError) as e:
            raise TypeError(f"a driver call takes plain data only: {e}") from None


class DeviceProxy:
    """A device as a component in a worker sees it: each method call and attribute read goes to the Creator,
    which runs it on the fenced driver (`drd.runtime.fence.Fenced`)."""

    __slots__ = ("_link", "_path", "_need", "_methods", "_commands")

    def __init__(self, link: _Link, path: str, need: str, methods: Iterable[str], commands: Iterable[str] = ()) -> None:
        self._link = link
        self._path = path
        self._need = need
        self._methods = frozenset(methods)
        self._commands = frozenset(commands)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        if name in self._commands:
            return functools.partial(self._link.command, self._path, self._need, name)
        if name in self._methods:
            return functools.partial(self._link.call, self._path, self._need, name)
        return self._link.attr(self._path, self._need, name)

    def __repr__(self) -> str:
        return f"DeviceProxy({self._path}:{self._need})"


class _Hosted:
    """One component instance in a worker, and what it emitted since the last reply."""

    __slots__ = ("comp", "ctx", "events", "logs", "deps", "now", "sent", "steps")

    def __init__(self) -> None:
        self.comp: Any = None
        self.ctx: Any = None
        self.events: list[list[Any]] = []
        self.logs: list[str] = []
        self.deps: list[list[Any]] = []
        self.now = 0.0
        self.sent: str | None = None  # its last snapshot sent, as JSON (None: none sent yet)
        self.steps = 0  # steps since the last snapshot taken


def worker_main(conn: Connection) -> None:
    """A worker's life: say hello, then serve the Creator's messages until its end of the pipe closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C of the daemon's terminal is for the daemon
    _die_with_parent()
    link = _Link(conn)
    hosted: dict[str, _Hosted] = {}
    link.send(Ready(os.getpid()))
    # a call stuck in a component's Python code is interrupted before the Creator would kill this process with
    # every instance in it (`CALL_TIMEOUT`): its state fails, the others go on, as in a dry-run
    with stuck_calls_end(WORKER_STUCK_AFTER, poll=0.05, rule=f"a cluster's worker stops a component's call after"
                         f" that; the dry-run after {STUCK_AFTER:g} s", gated=True) as watch:
        try:
            while True:
                match decode(conn.recv_bytes(), trusted=True):  # the Creator is trusted (see drd.cluster.pipe)
                    case Run(calls, latest):
                        with watch.calls() if watch is not None else contextlib.nullcontext():
                            done = tuple(run_calls(calls, latest, link, hosted))
                        link.send(Done(done))
                    case Drop(paths):
                        _shutdown_all([hosted.pop(path, None) for path in paths], SHUTDOWN_GRACE)
                    case _:  # nothing else comes unasked
                        pass
        except (EOFError, OSError):  # the Creator retired this worker (or died): its end of the pipe is closed
            pass
    os._exit(0)


def _shutdown_all(dropped: Sequence[_Hosted | None], grace: float) -> None:
    """Dropped instances' `shutdown`, in order, each in a thread of its own, all within `grace` seconds: one that
    hangs keeps its thread (the worker goes on, or exits with its pipe), never the worker's loop; those not
    reached by then are not called."""
    deadline = time.monotonic() + grace
    for h in dropped:
        left = deadline - time.monotonic()
        if h is None or h.comp is None or left <= 0:
            continue
        t = threading.Thread(target=_shutdown, args=(h,), name="drd-shutdown", daemon=True)
        t.start()
        t.join(left)


def _shutdown(h: _Hosted | None) -> None:
    """An instance forgotten for good: its `shutdown` (what it raises only ends it; nobody waits for an answer)."""
    if h is not None and h.comp is not None:
        try:
            h.comp.shutdown()
        except COMPONENT_RAISES:  # component code is not ours to trust, and this instance is gone anyway
            pass


def _die_with_parent() -> None:
    """Linux: SIGKILL this worker when the fork server exits (it does when the daemon dies, even by kill -9)."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except Exception:  # pragma: no cover - best effort
            pass


def run_calls(calls: Sequence[Call], latest: dict[str, Any], link: _Link,
              hosted: dict[str, _Hosted]) -> list[CallReply]:
    """Run calls in order, as `Creator.handle_batch` did in process: stop after one that emitted events,
    changed dependencies or failed; chain shared dicts (`shared_ids`) through `latest`.

    A call's `setup` builds a new instance, its `ahead` holds the readings read ahead of it (`{reading_key:
    value}`, or None); a reply's `unused` are the keys of `ahead` the call did not use."""
    replies: list[CallReply] = []
    link.changed = False
    for call in calls:
        _chain_in(call, latest)
        h = hosted.get(call.path)
        if call.setup is not None:
            try:
                h = _setup(call.path, call.setup, call.params, link)
            except COMPONENT_RAISES as e:  # a failed start (sys.exit too): the Creator forgets the instance
                replies.append(CallReply(error=f"{type(e).__name__}: {e}", setup_failed=True))
                break
            hosted[call.path] = h
        elif call.op == "start" and h is not None:
            h.ctx.params, h.ctx.outputs = dict(call.params or {}), {}
        if h is not None and call.op == "start" and call.restore is not None:
            try:  # before start: the state it had elsewhere (or None: it was lost)
                h.comp.restore(call.restore[0] if call.restore else None)
            except COMPONENT_RAISES as e:  # component code is not ours to trust: its start fails
                replies.append(CallReply(error=f"component raised {type(e).__name__} in restore: {e}", raised=True))
                break
        if h is None:
            replies.append(CallReply(error=f"no instance {call.path} in worker {os.getpid()}"))
            break
        reply = _run_call(h, call, link)
        replies.append(reply)
        if call.shared_ids:
            for name, ref in call.shared_ids.items():
                if reply.shared is not None and name in reply.shared:
                    latest[ref] = reply.shared[name]
        if reply.events or reply.dependencies or reply.error:
            break  # the controller reacts to this before the next step
    return replies


def _chain_in(call: Call, latest: dict[str, Any]) -> None:
    """The shared dicts of `call` that an earlier call of the batch changed: their latest values (copies)."""
    from drd.runtime.records import plain

    shared, ids = call.shared, call.shared_ids
    if shared is not None and ids:
        for name, ref in ids.items():
            if ref in latest and name in shared:
                shared[name] = plain(latest[ref])  # a copy: the earlier reply keeps its own


def _run_call(h: _Hosted, call: Call, link: _Link) -> CallReply:
    """One lifecycle call of a hosted instance; what it did, and what it emitted since the last reply."""
    from drd.runtime.component import Status

    h.now = call.now
    services = h.ctx.services
    services.shared = call.shared if call.shared is not None else {}
    h.ctx.inputs = {**(call.inputs or {}), **services.shared}  # shared data: the objects sent back
    result = ""
    error = ""
    raised_here = False  # the error is the component's own code raising
    snapshot: list[Any] | None = None
    link.begin(call.ahead)
    try:
        op = call.op
        if op == "step":
            result = str(h.comp.step(call.now))
        elif op == "start":
            h.comp.start()
        elif op == "suspend":
            h.comp.suspend()
        elif op == "resume":
            h.comp.resume()
        elif op == "terminate":
            status = call.status
            if status == MOVED:  # stopped to go on elsewhere: its state as it leaves, then stopped while running
                said = len(h.logs)
                snapshot = take_snapshot(h, force=True)
                if snapshot is None:  # its snapshot raised or is too large: it stays, running (placement audit 24)
                    why = h.logs.pop(said) if len(h.logs) > said else "its snapshot was not taken"
                    return _reply(h, services, f"{CANNOT_MOVE} ({why}): it goes on where it is",
                                  unused=link.unused())
            h.comp.terminate(Status(status) if status in Status.__members__.values() else Status.RUNNING)
        else:
            error = f"unknown op {op!r}"
    except COMPONENT_RAISES as e:  # component code is not ours to trust (a `sys.exit` too): the state fails,
        # the worker goes on
        error, raised_here = raised(e), True
        if (tb := debug_traceback(e)) is not None:  # DRD_DEBUG=1 on this daemon: the traceback in the mission's log
            h.logs.append(tb)
    if not error and (call.op == "start" or call.op == "step" and _due(h)):
        snapshot = take_snapshot(h, force=call.op == "start")  # a new entry: the controller forgot the last
    return _reply(h, services, error, result, snapshot, raised_here, link.unused())


def _reply(h: _Hosted, services: Any, error: str, result: str = "", snapshot: list[Any] | None = None,
           raised_here: bool = False, unused: list[Any] | None = None) -> CallReply:
    """The reply to a call of `h`, with what it emitted, logged and shared since the last one (then forgotten)."""
    from drd.runtime.records import plain

    reply = CallReply(result, plain(h.ctx.outputs), h.events, h.logs, plain(services.shared), h.deps, error, False,
                      unused or [], snapshot, raised=raised_here)
    h.events, h.logs, h.deps = [], [], []
    return reply


#: A running instance's snapshot is taken after its start and every this many steps (and when it is moved); it
#: travels with the reply only when it changed.
SNAPSHOT_EVERY = 10
#: The status of a `terminate` that moves an instance elsewhere: its snapshot comes back with the reply.
MOVED = "moved"
#: How a worker's refusal of such a `terminate` begins (its snapshot could not be taken): the instance was not
#: stopped, and the Creator keeps it running and bound (any other error of the call is the instance's end).
CANNOT_MOVE = "it cannot move with its state"


def _due(h: _Hosted) -> bool:
    h.steps += 1
    return h.steps >= SNAPSHOT_EVERY


def take_snapshot(h: _Hosted, force: bool = False) -> list[Any] | None:
    """`[state]` if the instance's snapshot changed since the last sent (or `force`), else None. A snapshot that
    raises, is not plain data or is larger than `MAX_SNAPSHOT` is not sent, and said so in its logs."""
    from drd.runtime.component import MAX_SNAPSHOT
    from drd.runtime.records import plain

    h.steps = 0
    try:
        state = h.comp.snapshot()
        state = None if state is None else plain(dict(state))
        text = json.dumps(state, sort_keys=True, allow_nan=False)
    except COMPONENT_RAISES as e:  # component code is not ours to trust
        h.logs.append(f"its snapshot was not taken: {type(e).__name__}: {e}")
        return None
    if len(text) > MAX_SNAPSHOT:
        h.logs.append(f"its snapshot ({len(text)} bytes) is over {MAX_SNAPSHOT} bytes: not kept")
        return None
    if text == h.sent and not force:
        return None
    h.sent = text
    return [state]


def _setup(path: str, setup: Setup, params: dict[str, Any] | None, link: _Link) -> _Hosted:
    from drd.errors import own_caller
    from drd.runtime.component import Context, Services
    from drd.runtime.records import plain

    factory = entrypoints.load(setup.entry_point)  # the one loader: says which of module, import or name failed
    h = _Hosted()
    devices = {need: DeviceProxy(link, path, need, names, setup.commands.get(need, ()))
               for need, names in setup.methods.items()}
    ctx = Context(path, dict(params or {}), dict(setup.resources),
                  lambda ev, **f: h.events.append([ev, plain(f), own_caller()]),
                  lambda text: h.logs.append(str(text)),
                  lambda: h.now, devices=devices,
                  services=Services(dependencies=lambda rid, k, v: h.deps.append([rid, k, plain(v)])))
    h.ctx = ctx
    h.comp = factory()
    h.comp.setup(ctx)
    return h
