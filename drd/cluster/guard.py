"""Constraints on a cluster: the guard at each device's host, told by the controller what is in force.

In a dry-run the gates and the constraints live in one process (`drd.runtime.constraints.ConstraintGuard`). On a
cluster a device's gate is on its host, next to its driver, so the guard must be there too: a command is judged
where it is executed, in the cycle it is issued, whatever the network to the controller does afterwards.

- The controller's `SharedGuard` is the executive's guard: when a behavior's constraint comes into force it also
  sends, with the gate operations of every host that has a device of a robot the constraint names, a `guard`
  operation: the holder, the constraint's name, its condition as the printer writes it (`dsl.printer`), the
  robots it names, the declaring behavior's scope for the names the condition reads (resources by id, plain
  values, points) and the world's rooms. Its end sends `unguard`.
- The host's `HostGuard` parses the condition again, builds the names over its own pool of the cluster's
  resources, and guards its gates with a `ConstraintGuard`: it reads its own robots from their drivers and the
  others (a Ranger a Scout must stay near) from the poses the controller ships each cycle (`seen`, one control
  cycle old). A refused command goes back with the reply as a `breach` record, which the controller hands to
  the declaring behavior (`Executive.record`): the same `violation` event as in a dry-run.

What a host cannot read as the controller does: `count(...)` counts the hosts file's resources, and a static
dependency changed at run time (a launched Scout's `carrier`) reads as in the hosts file. A name whose value
cannot be sent (a list of records...) is left out: the condition then cannot be evaluated on the host, the gate
lets the command through, and the controller's monitor stops the robot at the next cycle.
"""

from __future__ import annotations

import functools
import logging
import threading
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from drd.hosts import Cluster
from drd.rcm import ResourceManager
from drd.rcm.constraints import Measure, measure
from drd.runtime.constraints import Active, ConstraintGuard, walk
from drd.runtime.interpreter import describe_devices
from drd.runtime.ownership import LocalGates
from drd.runtime.pool import ResourcePool, ResourceView
from drd.runtime.telemetry import DriverTelemetry
from dsl import ast
from dsl.evaluate import Point
from dsl.parser import parse_expression

log = logging.getLogger("drd.guard")

Place = tuple[float, float, float, float]
#: One queued gate operation (`drd.cluster.gates.GateUpdate`).
Op = list[Any]
#: Seconds `BackgroundRead.close` waits for a read under way (a driver's) before it lets the thread finish alone.
CLOSE_WAIT = 1.0


def read_names(condition: ast.Expr) -> list[str]:
    """The names a condition reads, in order of first appearance."""
    return list(dict.fromkeys(node.id for node in walk(condition) if isinstance(node, ast.Name)))


def encode_scope(condition: ast.Expr, names: Mapping[str, object]) -> dict[str, list[Any]]:
    """What a host needs of the scope to evaluate `condition`: `["resource", id]`, `["point", x, y]` or
    `["value", v]` per name it reads (names with other values are left out, see the module)."""
    scope: dict[str, list[Any]] = {}
    for name in read_names(condition):
        value = names.get(name)
        if isinstance(value, ResourceView):
            scope[name] = ["resource", value.id]
        elif isinstance(value, Point):
            scope[name] = ["point", value.x, value.y]
        elif isinstance(value, bool | int | float | str):
            scope[name] = ["value", value]
    return scope


def decode_scope(scope: Mapping[str, Any], pool: ResourcePool) -> dict[str, object]:
    """The names `encode_scope` sent, over the host's pool (unknown resources and malformed entries left out)."""
    names: dict[str, object] = {}
    for name, entry in scope.items():
        match entry:
            case ["resource", str(rid)] if pool.view(rid) is not None:
                names[name] = pool.view(rid)
            case ["point", int() | float() as x, int() | float() as y]:
                names[name] = Point(float(x), float(y))
            case ["value", bool() | int() | float() | str() as v]:
                names[name] = v
    return names


class SharedGuard(ConstraintGuard):
    """The controller's guard: the executive's `ConstraintGuard`, which also tells the hosts of the robots each
    constraint names (see the module). `send(host, op)` queues a gate operation for a host."""

    def __init__(self, pool: ResourcePool, device_hosts: Mapping[str, str], send: Callable[[str, Op], None],
                 now: Callable[[], float]) -> None:
        super().__init__(pool)
        self.device_hosts = dict(device_hosts)
        self.send = send
        self.now = now
        self._told: dict[str, set[str]] = {}  # holder -> the hosts told of its constraints

    def hosts_of(self, robots: Iterable[str]) -> list[str]:
        """The hosts with a device of one of these robots."""
        return sorted({h for r in robots for u in self.pool.units(r) if (h := self.device_hosts.get(u))})

    def add(self, constraint: Active) -> None:
        super().add(constraint)
        scope = encode_scope(constraint.condition, constraint.names())
        op = ["guard", constraint.holder, constraint.path, constraint.name, constraint.text,
              list(constraint.robots), scope, {k: list(v) for k, v in self.pool.places.items()}, self.now()]
        for host in self.hosts_of(constraint.robots):
            self._told.setdefault(constraint.holder, set()).add(host)
            self.send(host, op)

    def remove(self, holder: str) -> None:
        super().remove(holder)
        for host in sorted(self._told.pop(holder, ())):
            self.send(host, ["unguard", holder, self.now()])

    def share(self, latest: Callable[[str], Mapping[str, float] | None]) -> None:
        """Ship to each guarding host the live values of the robots its constraints name on other hosts."""
        wanted: dict[str, dict[str, dict[str, float]]] = {}
        for a in self.active:
            for host in self._told.get(a.holder, ()):
                for robot in a.robots:
                    data = latest(robot)
                    if data is not None and host not in self.hosts_of([robot]):
                        wanted.setdefault(host, {})[robot] = dict(data)
        for host, robots in sorted(wanted.items()):
            self.send(host, ["seen", robots, self.now()])


class HostGuard:
    """A device host's guard over its gates (see the module): applies `guard`, `unguard`, `seen` and `watch`
    operations, and reports breaches and the watched robots' live values as records (`report`)."""

    KINDS = frozenset({"guard", "unguard", "seen", "watch"})

    def __init__(self, cluster: Cluster, host: str, drivers: Any, gates: LocalGates, clock: Callable[[], float],
                 report: Callable[[dict[str, Any]], None]) -> None:
        self.host = host
        self.clock = clock
        self.report = report
        self.pool = ResourcePool(ResourceManager())
        self.pool.add(cluster.resources(), 0.0)
        self.mine = {r.id for r in cluster.host(host).robots}
        self.local = DriverTelemetry(drivers, self.pool, clock)
        self.shipped: dict[str, dict[str, float]] = {}
        self.pool.telemetry = self._telemetry
        self.guard = ConstraintGuard(self.pool)
        self.watched: list[str] = []
        self.checked: set[str] = set()  # this host's robots its gates' checks asked for: read with the watched
        self._reads = BackgroundRead(self._read_watched)
        gates.describe(*describe_devices(self.pool), self.guard)

    def _telemetry(self, robot: str) -> Mapping[str, float] | None:
        """A robot's live values for a gate's check: shipped by the controller, or read from this host's drivers
        off the request's thread (`BackgroundRead`), as `telemetry` does: a driver waiting for its first message
        (a ROS 2 robot's first battery state, up to 2 s) held the Creator's lock, so the world it serves did not
        step, and the behavior's readings went stale. A robot not read yet is unknown, and the gate does not guess."""
        if robot not in self.mine:
            return self.shipped.get(robot)
        self.checked.add(robot)  # from now on read with the watched ones
        read: dict[str, dict[str, float]] = self._reads.get(TELEMETRY_WAIT) or {}
        return read.get(robot)

    def apply(self, op: Op) -> None:
        """One operation from the controller (malformed ones are logged and ignored)."""
        match op:
            case ["guard", str(holder), str(path), str(name), str(text), list(robots), dict(scope), dict(places),
                  int() | float()]:
                self._guard(holder, path, name, text, [str(r) for r in robots], scope, places)
            case ["unguard", str(holder), int() | float()]:
                self.guard.remove(holder)
            case ["seen", dict(robots), int() | float()]:
                for robot, data in robots.items():
                    if isinstance(data, dict):
                        self.shipped[str(robot)] = {str(k): float(v) for k, v in data.items()
                                                    if isinstance(v, int | float) and not isinstance(v, bool)}
            case ["watch", list(robots), int() | float()]:
                self.watched = sorted({str(r) for r in robots} & self.mine)
            case _:
                log.warning("guard on %s: a malformed operation was ignored: %.200r", self.host, op)

    def _guard(self, holder: str, path: str, name: str, text: str, robots: list[str], scope: Mapping[str, Any],
               places: Mapping[str, Any]) -> None:
        condition = parse_expression(text)
        if condition is None:
            log.warning("guard on %s: constraint %s of %s does not parse: %.200r", self.host, name, holder, text)
            return
        for room, rect in places.items():
            if isinstance(rect, list) and len(rect) == 4 and all(isinstance(v, int | float) for v in rect):
                self.pool.places[str(room)] = (float(rect[0]), float(rect[1]), float(rect[2]), float(rect[3]))
        names = decode_scope(scope, self.pool)
        active = Active(holder, path, name, condition, tuple(robots),
                        functools.partial(measure, condition, names, self.pool.count, self.pool.place))
        active.refused = functools.partial(self._refused, active)
        self.guard.add(active)

    def _refused(self, active: Active, m: Measure) -> None:
        self.report({"kind": "breach", "mission": active.holder.partition("/")[0], "holder": active.holder,
                     "name": active.name, "holds": m.holds, "margin": m.margin, "value": m.value, "limit": m.limit,
                     "measured": m.kind})

    def telemetry(self) -> dict[str, Any] | None:
        """The watched robots' live values, as a record (None when none is watched). Read off the request's
        thread (`BackgroundRead`): a driver that waits for its first message (a ROS 2 robot before the world's
        first step) must not hold the Creator's reply, which the controller waits 1 s for at most."""
        if not self.watched:
            return None
        read = self._reads.get(TELEMETRY_WAIT) or {}
        robots = {r: data for r, data in read.items() if r in self.watched}
        return {"kind": "telemetry", "mission": "", "host": self.host, "robots": robots}

    def close(self, wait: float = CLOSE_WAIT) -> None:
        """End the telemetry thread (waiting `wait` s at most): when the guard's world is replaced and when the
        daemon stops. Nothing of the guard stays after; a read hanging in a driver keeps it until it returns."""
        if not self._reads.close(wait):
            log.info("guard on %s: a telemetry read still waits on its driver; its thread ends when it returns",
                     self.host)

    def _read_watched(self) -> dict[str, dict[str, float]]:
        robots = sorted(set(self.watched) | self.checked)  # each a copy made at once, under the GIL
        return {r: dict(data) for r in robots if (data := self.local(r)) is not None}


#: Seconds a reply waits for the watched robots' reading of this cycle before it takes the last one.
TELEMETRY_WAIT = 0.05


class BackgroundRead:
    """`read()` on a thread of its own, one at a time: `get(wait)` starts a read if none is running and returns
    its result if it comes within `wait` seconds, else the last result (None before the first). A read that raises
    leaves the last result standing. `close()` ends the thread: a guard is made per world, and a thread that
    outlived its world would keep the world's drivers alive, one more per mission (soak audit, defect 1)."""

    def __init__(self, read: Callable[[], Any]) -> None:
        self._read: Callable[[], Any] | None = read
        self._cond = threading.Condition()
        self._asked = self._done = 0  # reads asked for, reads finished
        self._last: Any = None
        self._thread: threading.Thread | None = None
        self._closed = False

    def get(self, wait: float) -> Any:
        with self._cond:
            if self._closed:
                return self._last
            if self._done == self._asked:
                self._asked += 1
                self._cond.notify_all()
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="drd-telemetry", daemon=True)
                self._thread.start()
            self._cond.wait_for(lambda: self._done == self._asked, wait)
            return self._last

    def close(self, wait: float = CLOSE_WAIT) -> bool:
        """End the thread (waiting up to `wait` s for a read under way to return); True if it ended. A read that
        hangs in its driver keeps what it reads until it returns; then the thread ends, and nothing else does."""
        with self._cond:
            self._closed = True
            self._read = None
            self._cond.notify_all()
            thread = self._thread
        if thread is None:
            return True
        if thread is not threading.current_thread():
            thread.join(wait)
        return not thread.is_alive()

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._closed or self._asked > self._done)
                read = self._read
                if self._closed or read is None:
                    self._read = None  # what it reads (a guard, its world's drivers) is let go with the thread
                    return
            try:
                value = read()
            except Exception:  # a driver that cannot tell now: the last values stand
                log.debug("a telemetry read failed", exc_info=True)
                value = None
            del read
            with self._cond:
                if value is not None:
                    self._last = value
                self._done = self._asked
                self._cond.notify_all()
