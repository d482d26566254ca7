"""The Mission Executive: runs missions against one Resource Controller Manager, over a bus.

The same executor serves the embedded dry-run (a `LocalBus`, a simulated clock, one
process) and the controller daemon (a `ZenohBus`, real time). It owns the manager (behind
a broker, so missions share it by priority) and the resource pool built from
`hosts.yaml`; it publishes every record of every mission on
`drd/<cluster>/mission/<id>/record` and answers operator commands on
`drd/<cluster>/executive` (status, stop, emit). Components come from a registry: the
default one imports a component's entry point, from its manifest, the first time it runs.
"""

from __future__ import annotations

import collections
import functools
import itertools
import logging
from collections.abc import Callable, Collection, Iterable, Iterator, Mapping
from contextlib import contextmanager
from typing import Any

import orjson

from drd import entrypoints
from drd.bus import Bus, Message, Query, Reply
from drd.bus.messages import MalformedMessage, encode
from drd.entrypoints import EntryPointError
from drd.errors import host_down_reason
from drd.executive_messages import MissionCommand, MissionRecord, MissionRecords, MissionStatus
from drd.paging import PAGE_BYTES, fill
from drd.rcm import ReleaseReason, ResourceManager, Unit
from drd.runtime import records as rec
from drd.runtime.broker import ResourceBroker
from drd.runtime.clock import Clock
from drd.runtime.component import Component
from drd.runtime.constraints import Breach, ConstraintGuard
from drd.runtime.interpreter import Interpreter, describe_devices, stop_together
from drd.runtime.ownership import Gates, LocalGates, NoGates
from drd.runtime.pool import ResourcePool
from drd.runtime.records import plain
from drd.runtime.snapshot import NodeImage
from drd.runtime.telemetry import DriverTelemetry
from dsl.catalog import Catalog
from dsl.statechart import Statechart

log = logging.getLogger("drd.executive")

#: Records kept per mission for a client that missed some (`records` command): its latest ones, while it runs and
#: for the `KEPT_FINISHED` missions that ended last.
KEPT_RECORDS = 2000
KEPT_FINISHED = 5


class EntryPoints(Mapping[str, Callable[[], Component]]):
    """A registry that imports `module:Class` from each manifest on first use."""

    def __init__(self, catalog: Catalog, overrides: Mapping[str, Callable[[], Component]] | None = None):
        self.catalog = catalog
        self.overrides = dict(overrides or {})
        self._cache: dict[str, Callable[[], Component]] = {}

    def __getitem__(self, name: str) -> Callable[[], Component]:
        if name in self.overrides:
            return self.overrides[name]
        if name not in self._cache:
            ct = self.catalog.get(name)
            if ct is None or not ct.entry_point:
                raise KeyError(name)
            try:
                self._cache[name] = entrypoints.load(ct.entry_point)
            except EntryPointError as e:
                raise KeyError(name) from e
        return self._cache[name]

    def get(self, name: str, default: Any = None) -> Any:
        try:
            return self[name]
        except KeyError:
            return default

    def __iter__(self) -> Any:
        return iter(self.catalog.names())

    def __len__(self) -> int:
        return len(self.catalog.components)


class Executive:
    """Missions, one manager, one bus. Call `step()` whenever the clock moves."""

    def __init__(self, bus: Bus, clock: Clock, registry: Mapping[str, Callable[[], Component]], *,
                 cluster: str = "local", resources: Iterable[Any] = (), lease: float = 3.0,
                 default_slice: float = 5.0, services: Mapping[str, Any] | None = None, preallocate: bool = False,
                 gates: Gates | None = None, history: int = 100, origin: Callable[[], float] = lambda: 0.0):
        """`gates`: the devices' gates; by default, gates over the in-process drivers of `services["drivers"]`
        (the dry-run), shared by every mission so that ownership holds across missions."""
        self.bus = bus
        self.clock = clock
        self.origin = origin  # when the current world began on `clock` (`Interpreter`'s `origin`)
        self.registry = registry
        self.cluster = cluster
        self.services = dict(services or {})
        if isinstance(registry, EntryPoints):  # its components' emits are checked against their manifests
            self.services.setdefault("catalog", registry.catalog)
        self.preallocate = preallocate
        self.broker = ResourceBroker(ResourceManager(lease=lease, default_slice=default_slice))
        self.pool = ResourcePool(self.broker)
        self.pool.add(resources, clock.now())
        self.missions: dict[str, Interpreter] = {}
        self.history = history  # finished missions kept (the oldest finished go first)
        #: Missions that ended before this executive started (its controller's journal): id -> status as listed
        #: then, in the order they ended; they count in `history` and go first.
        self.past: dict[str, dict[str, Any]] = {}
        self.guard = ConstraintGuard(self.pool)  # the constraints in force, of every mission
        self.gates: Gates = self._gates(gates)
        self.pool.places = dict(self.services.get("places", {}))  # the world's rooms: `inside(ranger, "n1")`
        catalog = self.services.get("catalog")
        if isinstance(catalog, Catalog):
            self.pool.references = catalog.references()
        self._ids = itertools.count(1)
        self.order: dict[str, int] = {}  # mission -> its start ordinal: the cursor of status pages
        self._ordinals = itertools.count(1)
        self.sent = 0  # records sent, of every mission: each is numbered in the order they happened
        self.kept: dict[str, collections.deque[MissionRecord]] = {}  # each mission's latest records, for catch-up
        #: More of a mission's status from its host (the cluster controller's placement decisions), if any.
        self.status_extras: Callable[[str], Mapping[str, Any]] | None = None
        #: Its host's missions not entered yet, for `stop` to refuse and `unknown` to name (a controller resuming its
        #: journal's once their hosts are back), with what to say of them.
        self.pending: Callable[[], tuple[list[str], str]] = lambda: ([], "")
        self._queryable = bus.serve(f"drd/{cluster}/executive", self._command)
        self._reads = bus.serve(f"drd/{cluster}/executive/status", self._read)  # what an observer may ask

    def _gates(self, gates: Gates | None) -> Gates:
        if gates is not None:
            return gates
        drivers = self.services.get("drivers")
        if drivers is None:
            return NoGates()
        sharable = [c.id for c in self.pool.candidates.values() if isinstance(c, Unit) and c.sharable]
        local = LocalGates.of(getattr(drivers, "devices", {}), getattr(drivers, "robots", {}), sharable, self.record)
        local.describe(*describe_devices(self.pool), self.guard)
        self.pool.telemetry = DriverTelemetry(drivers, self.pool, self.clock.now)
        return local

    def record(self, mission: str, record: rec.Record | Breach) -> None:
        """A record about `mission` from outside its interpreter (a device's gate): to its listeners; a command a
        gate refused for a constraint: to the behavior that declared it."""
        if isinstance(record, Breach):
            self.guard.breached(record)
            return
        interp = self.missions.get(mission)
        if interp is not None and interp.finished:  # a mission's trace ends with `finished` (docs/trace.md)
            log.warning("a %s record of %s came after the mission finished: not recorded", record.kind, record.path)
        elif interp is not None:
            interp.record(record)

    def submit(self, chart: Statechart, mission_id: str | None = None,
               listeners: Iterable[Callable[[rec.Record], None]] = (),
               registry: Mapping[str, Callable[[], Component]] | None = None, priority: int = 1,
               resume: NodeImage | None = None, since: float = 0.0, paused: float = 0.0,
               earlier: Iterable[rec.Record] = ()) -> str:
        """Start a compiled mission; returns its id (`<name>-<n>`).

        `registry` replaces the executive's own for this mission (a cluster mission's `RemoteRegistry`);
        `priority` ranks the mission against the others sharing the team (1 first); `resume`: enter it again as
        it was saved at `since` (`drd.runtime.snapshot`), after its controller was lost `paused` seconds ago;
        `earlier`: what its hosts recorded meanwhile (the halts when they lost the controller), recorded first."""
        mid = mission_id or f"{chart.name}-{next(self._ids)}"
        self.forget_finished()
        if mid in self.missions:
            raise ValueError(f"a mission {mid} is already running")
        if self.past.pop(mid, None) is not None:  # an id an ended mission of before the restart had: this one now
            self.order.pop(mid, None)
        if "/" in mid:
            raise ValueError(f"a mission id has no '/': {mid!r}")
        interp = Interpreter(chart, registry if registry is not None else self.registry, self.broker, self.clock,
                             pool=self.pool, mission=mid, services=self.services, preallocate=self.preallocate,
                             gates=self.gates, priority=priority, guard=self.guard, origin=self.origin)
        key = f"drd/{self.cluster}/mission/{mid}/record"
        interp.attach(functools.partial(self._send, key, mid))
        for listener in listeners:
            interp.attach(listener)
        self.missions[mid] = interp
        self.order[mid] = next(self._ordinals)
        for record in earlier:  # they happened before the restore: they come before its records
            interp.record(record)
        if resume is not None:
            interp.resume(resume, since, paused)
        else:
            interp.start()
        return mid

    @contextmanager
    def together(self) -> Iterator[None]:
        """Missions submitted in this block ask for resources as one: by priority, not by which was submitted first
        (`drd.runtime.broker.ResourceBroker.together`: a controller resuming its missions, a dry-run starting).
        What their grants then entered is run to completion at once, as a mission started alone is: a component
        that fails as it starts ends its state at that instant (users audit 21, #2: a cycle later in a dry-run)."""
        with self.broker.together():
            yield
        for interp in list(self.missions.values()):
            interp.settle()

    def restore_history(self, ended: Iterable[tuple[str, Mapping[str, Any]]]) -> None:
        """Missions that ended before a restart (id, status as listed then), in the order they ended: `status`
        lists them again, before every mission of this executive, and `history` bounds them with the rest."""
        for mid, status in ended:
            if mid in self.missions or mid in self.past:
                continue
            self.past[mid] = {**status, "id": mid}
            self.order[mid] = next(self._ordinals)
        self.forget_finished()

    def continue_records(self, after: int) -> None:
        """Number the next records after `after` (a controller resuming goes on with its journal's numbering), and
        grant the next epochs above it: each grant is a record, so no unit's epoch exceeds the number of records
        its executive sent, and a resumed one gives no epoch a dead one gave (safety audit 25, D1)."""
        self.sent = max(self.sent, after)
        self.broker.rcm.epochs_above(after)

    def highest_number(self) -> int:
        """What a controller taking over from this one continues after (`continue_records`): the number of the last
        record sent, or the highest epoch granted if that is more."""
        return max(self.sent, self.broker.rcm.highest_epoch())

    def _send(self, key: str, mission: str, record: rec.Record) -> None:
        self.sent += 1
        msg = _to_message(mission, record, self.sent)
        kept = self.kept.get(mission)
        if kept is None:
            kept = self.kept[mission] = collections.deque(maxlen=KEPT_RECORDS)
        kept.append(msg)
        self.bus.put(key, msg)

    def step(self) -> None:
        for interp in list(self.missions.values()):
            interp.step()
        if len(self.missions) + len(self.past) > self.history or len(self.kept) > 2 * KEPT_FINISHED:
            self.forget_finished()

    def forget_finished(self) -> list[str]:
        """Drop the oldest finished missions beyond `history` (running ones are never dropped); their ids. Called
        as missions end too (not only from `step`: a mission stopped between steps, the last one of a world, must
        not leave `history` + 1)."""
        finished = [mid for mid, interp in self.missions.items() if interp.finished]
        over = max(0, len(self.past) + len(finished) - self.history)
        gone = list(self.past)[:over]  # those that ended before a restart go first
        for mid in gone:
            del self.past[mid]
            self.order.pop(mid, None)
        dropped = finished[:over - len(gone)]
        for mid in dropped:
            del self.missions[mid]
            self.order.pop(mid, None)
        for mid in [m for m in self.kept if m not in self.missions or m in finished[:-KEPT_FINISHED]]:
            del self.kept[mid]  # a client catching up is after a mission that ran lately
        return gone + dropped

    def run(self, advance: Callable[[], None], until: float, *, done: Callable[[], bool] | None = None) -> None:
        """Step until every mission finished (or `done()`), calling `advance` to move time."""
        while self.clock.now() < until and not (done() if done else self.finished):
            advance()
            self.step()

    def add_resources(self, resources: Iterable[Any]) -> None:
        """Hot-plug: new units and aggregates join the shared pool once; every running mission may grow into them."""
        self.pool.add(resources, self.clock.now())
        for m in list(self.missions.values()):
            if not m.finished:
                m.grow()

    def remove_host(self, host: str) -> None:
        """A host is gone: its resources leave the shared manager; every mission settles the consequences."""
        for m in self.missions.values():
            m.remove_host(host)

    def set_host_offline(self, host: str, offline: bool) -> None:
        """A host seen down keeps its resources in the shared manager, but no one new gets them until it is back;
        back online, every running mission may be granted or grow into them. Taken offline, nothing is settled: it
        may be applied mid-cycle (`Controller.apply_offline`)."""
        self.pool.set_host_offline(host, offline, self.clock.now())
        for m in list(self.missions.values()) if not offline else ():
            if not m.finished:
                m.grow()

    def absent(self, resources: Iterable[Any]) -> None:
        """Resources of the team the manager does not have now, by host (hosts down or not joined yet): a need only
        they would meet fails saying that their host is down, until it joins (`ResourceManager.shelve`)."""
        by_host: dict[str, list[Any]] = {}
        for r in resources:
            by_host.setdefault(r.host, []).append(r)
        for host, found in sorted(by_host.items()):
            self.broker.rcm.shelve(host, found)

    def host_died(self, host: str, units: Collection[str]) -> None:
        """A host's daemon died (a dry-run's `kill`): as on a cluster, its resources go offline (they leave at its
        lease's end, `remove_host`) and the components bound to its `units` fail, as calls to a dead host do."""
        self.set_host_offline(host, True)
        for m in list(self.missions.values()):
            if not m.finished:
                m.components_lost(units, host_down_reason(host))

    def host_restarted(self, units: Collection[str]) -> None:
        """A host's daemon started again (a dry-run's `restart`): components bound to its `units` may run again."""
        for m in self.missions.values():
            m.components_back(units)

    def remove_resources(self, resource_ids: Iterable[str], reason: ReleaseReason = "resource lost") -> None:
        """Resources are gone (a lost robot): the same as a lost host, for just these."""
        ids = tuple(resource_ids)
        for m in self.missions.values():
            m.remove_resources(ids, reason)

    @property
    def finished(self) -> bool:
        return all(m.finished for m in self.missions.values())

    def stop(self, mission_id: str = "", reason: str = "stopped by operator") -> list[str]:
        """Stop one mission, or all at once (`stop_together`: no mission being stopped is granted what another's
        stop gives back); the ids asked of."""
        targets = [mission_id] if mission_id else list(self.missions)
        stop_together([self.missions[mid] for mid in targets], reason)
        return targets

    def status(self, after: int = 0, count: int = 0, only: Iterable[str] | None = None) -> MissionStatus:
        """A page of the missions (`drd.paging`): those started after the cursor `after` (`only` these, if given),
        in the order they started; a mission whose active tree alone is over a page shows without it."""
        wanted = None if only is None else set(only)

        def items() -> Iterable[tuple[int, tuple[dict[str, Any], int]]]:
            for mid, status in list(self.past.items()):
                n = self.order.get(mid, 0)
                if n > after and (wanted is None or mid in wanted):
                    yield n, _sized(dict(status))
            for mid, interp in list(self.missions.items()):
                n = self.order.get(mid, 0)
                if n > after and (wanted is None or mid in wanted):
                    extras = self.status_extras(mid) if self.status_extras is not None else {}
                    yield n, _sized({"id": mid, **plain(interp.snapshot()), **extras})

        page, nxt = fill(items(), lambda item: item[1], count)
        return MissionStatus(self.clock.now(), [item for item, _size in page], nxt)

    def close(self) -> None:
        self.stop()
        self._queryable.close()
        self._reads.close()

    def abandon_missions(self) -> None:
        """Its controller stops for maintenance (`MissionRunner.suspend`): its missions are left as they are and
        say nothing more (no stop, no record: what the journal holds of them is resumed by the next start); the
        services stay until `close`, which then has nothing to stop."""
        for interp in self.missions.values():
            interp.listeners.clear()
        self.missions = {mid: interp for mid, interp in self.missions.items() if interp.finished}

    def abandon(self) -> None:
        """Its process died (a dry-run's `kill controller`): nothing more is said or done, missions are left as
        they were (no stop, no release: what a crash leaves)."""
        for interp in self.missions.values():
            interp.listeners.clear()
        self._queryable.close()
        self._reads.close()

    def _read(self, query: Query) -> Message | Reply:
        """`status` and `records` only: the executive's read-only side."""
        cmd = query.payload
        if not isinstance(cmd, MissionCommand) or cmd.op not in ("status", "records"):
            return query.error("expected a drd.mission.command status or records (others go to the executive)")
        return self._command(query)

    def _command(self, query: Query) -> Message | Reply:
        cmd = query.payload
        if not isinstance(cmd, MissionCommand):
            return query.error("expected a drd.mission.command")
        if cmd.op == "status":  # of one mission (none: it is not, or no more, known) or a page of them all
            return self.status(cmd.after, cmd.count, [cmd.mission] if cmd.mission else None)
        if cmd.mission and cmd.mission in self.past and cmd.op == "stop":  # it ended before the restart
            return MissionStatus(self.clock.now(), [{**self.past[cmd.mission], "already_ended": True}])
        pending, why = self.pending()
        if cmd.op == "stop" and pending and (not cmd.mission or cmd.mission in pending):  # cluster audit 26, D1:
            return query.error(f"cannot stop {', '.join(pending)} yet: the controller is resuming them {why}; stop"
                               " them once `missionctl status` lists them")  # it said "nothing to stop", then ran
        if cmd.mission and cmd.mission not in self.missions:
            return query.error(self.unknown(cmd.mission))
        match cmd.op:
            case "stop":
                return self._stop_reply(cmd.mission, cmd.count)
            case "records" if cmd.mission:
                kept = list(self.kept.get(cmd.mission, ()))  # one copy: the loop may append meanwhile
                page, nxt = fill(((r.seq, r) for r in kept if r.seq > cmd.after), _size, cmd.count)
                return MissionRecords(page, nxt)
            case "emit" if cmd.event:
                targets = [cmd.mission] if cmd.mission else list(self.missions)
                try:  # what its record could not carry is refused before any mission hears it (wire audit 25, D4)
                    encode(_to_message("", rec.Event(0.0, "operator", cmd.event, dict(cmd.fields or {}))))
                except MalformedMessage as e:
                    return query.error(f"emit {cmd.event}: its fields cannot be recorded: {e.reason}")
                for mid in targets:
                    self.missions[mid].emit(cmd.event, "operator", **(cmd.fields or {}))
                return self.status(0, cmd.count, targets)
        return query.error(f"unknown command {cmd.op!r}: use status, stop, emit EVENT or records")

    def unknown(self, mission: str) -> str:
        """The error for a mission id it does not know: with those still running (an ended one cannot be stopped,
        nor sent an event that changes anything), and how many ended ones it still knows."""
        running = [mid for mid, interp in self.missions.items() if not interp.finished]
        ended = len(self.missions) + len(self.past) - len(running)
        pending = self.pending()[0]
        return (f"no mission {mission}; running: {', '.join(running[-20:]) or 'none'}"
                + (f" (and {len(running) - 20} more)" if len(running) > 20 else "")
                + (f"; resuming from the journal: {', '.join(pending[:20])}" if pending else "")
                + (f"; {ended} ended mission{'s' if ended != 1 else ''} known (missionctl status lists them)"
                   if ended else ""))

    def _stop_reply(self, mission: str, count: int) -> MissionStatus:
        """`stop`'s answer: the status of each mission it was asked to stop; one that had already ended is marked
        `already_ended` (its outcome is its own, not the operator's stop), so nobody is told it was stopped now."""
        ended = {mid for mid in ([mission] if mission else self.missions) if self.missions[mid].finished}
        reply = self.status(0, count, self.stop(mission))
        for m in reply.missions:
            if m.get("id") in ended:
                m["already_ended"] = True
        self.forget_finished()  # after the reply: it lists every mission it stopped
        return reply


def _size(msg: Message) -> int:
    """Its bytes on the wire (as a message of its own: a few bytes more than inside a page)."""
    return len(encode(msg))


def _sized(item: dict[str, Any]) -> tuple[dict[str, Any], int]:
    """A mission's status and its size in JSON; over a page, without its active tree (it says how big it was)."""
    size = len(orjson.dumps(item, default=str))
    if size > PAGE_BYTES:
        item = {**item, "tree": None, "cut": f"its active tree is {size} bytes, over a reply page ({PAGE_BYTES})"}
        size = len(orjson.dumps(item, default=str))
    return item, size


def _to_message(mission: str, r: rec.Record, seq: int = 0) -> MissionRecord:
    data = r.to_dict()
    kind, at, path = data.pop("kind"), data.pop("at"), data.pop("path")
    return MissionRecord(mission, kind, at, path, plain(data), seq)


