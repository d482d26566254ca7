"""The controller role: the Resource Controller Manager and the Mission Executive, fed by the cluster view.

`Membership` is the pure rule for hot-plug: a host's resources enter the manager when it comes up
and leave it one lease after it went down (if it has not come back meanwhile), which frees its
grants. `Controller` is the thin shell around `drd.executive.Executive` that applies it and answers
`drd/<cluster>/rcm/resources`. Everything that touches the executive runs under the daemon's lock:
the executive is single-threaded, and bus handlers run on zenoh's threads (`SerializedBus`).
"""

from __future__ import annotations

import threading
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

from drd.bus import Bus, BusWrapper, Handler, Message, Query, Queryable, Reply
from drd.bus.keys import is_concrete
from drd.bus.messages import encode
from drd.cluster.keys import ClusterKeys
from drd.daemon.messages import (
    BlockerInfo,
    ResourcesReply,
    ResourcesRequest,
    RobotInfo,
    UnitInfo,
    ViewRequest,
    WaiterInfo,
)
from drd.hosts import Cluster
from drd.paging import by_position
from drd.rcm import Aggregate, Request, Unit
from drd.runtime.clock import Clock, WallClock
from dsl.catalog import Catalog


@dataclass(frozen=True, slots=True)
class Action:
    """What the shell must do to the manager: `add` or `remove` the resources of `host`, or take them `offline` (seen
    down: kept for a lease, grants and all, but granted to no one new) and back `online`."""

    kind: str
    host: str


class Membership:
    """Which hosts' resources the manager holds. Pure: time is passed in."""

    def __init__(self, lease: float, present: set[str] | None = None) -> None:
        self.lease = lease
        self.present: set[str] = set(present or ())
        self.removal: dict[str, float] = {}
        self.suspected: set[str] = set()  # hosts whose resources a timed-out call took offline (`silent`)

    def up(self, host: str, now: float) -> list[Action]:
        """A host came up: cancel a pending removal (its resources are back online), or add its resources."""
        suspected = host in self.suspected
        self.suspected.discard(host)
        if self.removal.pop(host, None) is not None:
            return [Action("online", host)]
        if host in self.present:
            return [Action("online", host)] if suspected else []
        self.present.add(host)
        return [Action("add", host)]

    def down(self, host: str, now: float) -> list[Action]:
        """A host went down: its resources go offline now and leave one lease from now (unless it comes back)."""
        self.suspected.discard(host)  # offline already: for good now, unless it comes back
        if host in self.present and host not in self.removal:
            self.removal[host] = now + self.lease
            return [Action("offline", host)]
        return []

    def silent(self, host: str) -> list[Action]:
        """A call to `host` timed out while the view still has it up: its resources go offline now, provisionally.
        A frozen host stops answering at once but is judged down only when its load reports have been missing for a
        lease; its holder's call failed in between, and a waiter granted its robot failed in the same instant
        (CI, the SIGSTOP variant of cluster audit 19, #1). Back online at its next report (`heard`), or down for
        good (`down`)."""
        if host not in self.present or host in self.removal or host in self.suspected:
            return []
        self.suspected.add(host)
        return [Action("offline", host)]

    def heard(self, host: str) -> list[Action]:
        """A load report from `host`: a host suspected by `silent` answers again, its resources are back online."""
        if host not in self.suspected:
            return []
        self.suspected.discard(host)
        return [] if host in self.removal else [Action("online", host)]

    def due(self, now: float) -> list[Action]:
        """Removals whose lease ran out, in time order."""
        out = []
        for host, at in sorted(self.removal.items(), key=lambda item: (item[1], item[0])):
            if at <= now:
                del self.removal[host]
                self.present.discard(host)
                out.append(Action("remove", host))
        return out

    def pending(self, now: float) -> dict[str, float]:
        """Host -> seconds left before its resources are removed."""
        return {h: max(0.0, at - now) for h, at in sorted(self.removal.items())}


def coalesced(pending: list[Action], action: Action) -> list[Action]:
    """`pending` with `action` queued after it, but a host's return cancels its departure if that is still queued: a
    mission loop held up applied a removal due before the host was back after it had rejoined, then added the
    resources again, and a waiter for its robot failed in between (cluster audit 20, #2). `add` after a queued
    `remove` becomes `online` (its units are still in the manager, offline); `online` after a queued `offline`
    cancels both. Pure."""
    undone = {"add": "remove", "online": "offline"}.get(action.kind)
    last = next((i for i in range(len(pending) - 1, -1, -1) if pending[i].host == action.host), None)
    if undone is None or last is None or pending[last].kind != undone:
        return [*pending, action]
    rest = pending[:last] + pending[last + 1:]
    return [*rest, Action("online", action.host)] if action.kind == "add" else rest


def host_resources(cluster: Cluster, host: str) -> list[Unit | Aggregate]:
    """The units and aggregates of one host, as `ResourcePool.add` takes them."""
    return [c for c in cluster.resources() if c.host == host]


#: One waiter as the manager tells it (`ResourceManager.waiters`): its request, the units it claims, who is in its way.
WaiterView = tuple[Request, frozenset[str], tuple[str, ...]]


def resources_reply(snapshot: Mapping[str, Any], cluster: str, answered_by: str,
                    removing: Mapping[str, float], hosts: Mapping[str, str] | None = None,
                    waiters: Sequence[WaiterView] | None = None,
                    shelved: Mapping[str, Sequence[str]] | None = None) -> ResourcesReply:
    """`ResourceManager.snapshot()` as the wire's view: each unit with holders, queue and epoch.

    A unit's queue lists the waiters that claim it (`waiters`, from `ResourceManager.waiters`: a need's `where`
    narrows what it may take), in service order; without `waiters`, those that need its type or the type of a robot
    using it (a coarser guess: a waiter for ranger2 would stand in ranger1's queue too). A waiter's `offline` hosts
    are those of the offline units it claims and those down whose resources would serve it (`shelved`, from
    `ResourceManager.shelf_waiters`)."""
    aggregates: Mapping[str, Mapping[str, Any]] = snapshot.get("aggregates", {})
    holds: Mapping[str, Mapping[str, Any]] = snapshot.get("holds", {})
    views = {request.holder: (claims, blockers) for request, claims, blockers in waiters or ()}
    requests = {request.holder: request for request, _, _ in waiters or ()}
    offline = {str(uid): str(u["host"] or "") for uid, u in dict(snapshot.get("units", {})).items()
               if u.get("offline")}
    queue = [WaiterInfo(str(w["holder"]), int(w["priority"]), str(w.get("mission") or ""),
                        {str(k): str(v) for k, v in dict(w.get("needs", {})).items()},
                        int(w.get("mission_priority") or 1), _wheres(requests.get(str(w["holder"]))),
                        _blockers(views.get(str(w["holder"])), holds, aggregates, {str(q["holder"]) for q in
                                                                                   snapshot.get("queue", [])}),
                        sorted({offline[u] for u in views.get(str(w["holder"]), (frozenset(), ()))[0] if u in offline}
                               | set((shelved or {}).get(str(w["holder"]), ()))))
             for w in snapshot.get("queue", [])]
    robot_of: dict[str, set[str]] = {}
    for agg in aggregates.values():
        for unit in dict(agg.get("parts", {})).values():
            robot_of.setdefault(str(unit), set()).add(str(agg["type"]))
    units = []
    for uid, u in dict(snapshot.get("units", {})).items():
        types = {str(u["type"])} | robot_of.get(uid, set())
        waiting = [w.holder for w in queue if (uid in views[w.holder][0] if w.holder in views
                                               else bool(types & set(w.needs.values())))]
        units.append(UnitInfo(uid, str(u["type"]), str(u["host"] or ""), bool(u["sharable"]), float(u["capacity"]),
                              float(u["load"]), int(u["epoch"]), sorted(map(str, dict(u["holders"]))), waiting,
                              {str(k): v for k, v in dict(u.get("properties", {})).items()}, uid in offline))
    robots = [RobotInfo(aid, str(a["type"]), str(a["host"] or ""),
                        {str(k): str(v) for k, v in dict(a["parts"]).items()},
                        sorted(h for h, hold in holds.items() if aid in dict(hold.get("assignment", {})).values()))
              for aid, a in aggregates.items()]
    units.sort(key=lambda u: u.id)
    robots.sort(key=lambda r: r.id)
    return ResourcesReply(cluster, answered_by, units, robots, queue, dict(removing), dict(hosts or {}))


def _wheres(request: Request | None) -> dict[str, str]:
    """Need -> its `where` as written (the runtime's `Where` keeps the expression; a pinned need of a resumed
    mission says which resource it must be)."""
    from dsl.printer import expr

    found: dict[str, str] = {}
    for need in request.needs if request is not None else ():
        source = getattr(need.where, "expr", None)
        if source is not None:
            found[need.name] = expr(source)
        elif need.where is not None:
            found[need.name] = "(a condition set by drd)"
    return found


def _blockers(view: tuple[frozenset[str], tuple[str, ...]] | None, holds: Mapping[str, Mapping[str, Any]],
              aggregates: Mapping[str, Mapping[str, Any]], queued: set[str]) -> list[BlockerInfo]:
    """Who is in a waiter's way, each holder with what it holds of the units the waiter claims (need -> id)."""
    if view is None:
        return []
    claims, blockers = view
    found = []
    for holder in blockers:
        assignment = {str(need): str(cid) for need, cid in dict(holds.get(holder, {}).get("assignment", {})).items()}
        held = {need: cid for need, cid in assignment.items() if not claims.isdisjoint(_units(cid, aggregates))}
        found.append(BlockerInfo(holder, held, holder in queued and holder not in holds))
    return found


def _units(candidate: str, aggregates: Mapping[str, Mapping[str, Any]]) -> set[str]:
    """The unit ids a granted candidate occupies: a robot's parts, or the unit itself."""
    parts = aggregates.get(candidate, {}).get("parts")
    return {str(u) for u in dict(parts).values()} if parts else {candidate}


def resources_page(whole: ResourcesReply, after: int = 0, count: int = 0) -> ResourcesReply:
    """A page of `whole` (`drd.paging`): one cursor over its units, then its robots, then its queue (1-based
    positions); the page's `layout` is a checksum of the unit and robot ids, so a client that sees it change
    between pages knows positions moved (a host came or went) and starts again. Pure."""
    items: list[Message] = [*whole.units, *whole.robots, *whole.queue]
    page, nxt = by_position(items, after, count, lambda item: len(encode(item)))
    layout = zlib.crc32("\n".join([u.id for u in whole.units] + ["|"] + [r.id for r in whole.robots]).encode())
    return replace(
        whole, units=[i for i in page if isinstance(i, UnitInfo)], robots=[i for i in page if isinstance(i, RobotInfo)],
        queue=[i for i in page if isinstance(i, WaiterInfo)], next=nxt, layout=layout)


#: Seconds a query waits for the executive's lock; then a read gets the last answer given, a command a refusal.
BUSY_WAIT = 0.5
#: Executive commands answered without its lock: `records` copies the deque of a mission's latest records, which
#: the mission loop only appends to (a client catching up must not depend on the loop's pauses).
LOCK_FREE = frozenset({"records"})


class SerializedBus(BusWrapper):
    """A bus whose handlers run under a lock: hands a single-threaded object (the executive) a bus.

    Everything else is delegated to `inner`; closing it does not close `inner` (the daemon owns it).
    `expect` maps served keys to the payload types their handler takes (`type(None)`: no payload):
    anything else is refused before the handler runs, and reported through `on_reject(key, reason)`.
    """

    def __init__(self, inner: Bus, lock: threading.RLock | threading.Lock, *,
                 expect: Mapping[str, tuple[type, ...]] | None = None,
                 on_reject: Callable[[str, str], None] | None = None) -> None:
        super().__init__(inner)
        self._lock = lock
        self._expect = dict(expect or {})
        self._on_reject = on_reject
        self.busy_wait = BUSY_WAIT
        # (key, what was asked) -> the last answer to that read-only query; (key, DEFAULT): the kept answer to the
        # plain one (the first page of a status, a view), refreshed by `refresh`
        self._last: dict[tuple[str, tuple[Any, ...]], Message] = {}
        self._readers: dict[str, Callable[[], Message]] = {}  # key -> how to answer it anew (`keep`)

    def serve(self, key_expr: str, handler: Handler) -> Queryable:
        wanted = self._expect.get(key_expr)

        def locked(query: Query) -> Reply | Message | None:
            if wanted is not None and not isinstance(query.payload, wanted):
                reason = f"expected {_expected(wanted)}, got {_type_name(query.payload)}"
                if self._on_reject is not None:
                    self._on_reject(query.key, reason)
                return query.error(reason)
            if not is_concrete(query.key):  # the executive answers only what is addressed to it (drd.daemon.acl)
                return query.error(f"ask {key_expr} by its exact key, not with {query.key}")
            if getattr(query.payload, "op", "") in LOCK_FREE:  # reads only what the loop appends: no lock needed
                return handler(query)
            if not self._lock.acquire(timeout=self.busy_wait):
                return self._busy(key_expr, query)
            try:
                reply = handler(query)
            finally:
                self._lock.release()
            if isinstance(reply, Reply) and reply.error is not None and self._on_reject is not None:
                self._on_reject(query.key, reply.error)  # an unknown op or mission: counted and logged too
            if self._read_only(query) and isinstance(reply, Message):
                if len(self._last) > MAX_KEPT:  # pages asked once: forget them, keep the refreshed ones
                    self._last = {k: v for k, v in self._last.items() if k[1] == DEFAULT}
                self._last[(key_expr, _asked(query.payload))] = reply
            return reply

        return self.inner.serve(key_expr, locked)

    @staticmethod
    def _read_only(query: Query) -> bool:
        """A query that changes nothing (a status, a view): its last answer may stand in while the lock is busy."""
        op = getattr(query.payload, "op", "status")
        return op == "status"

    def _busy(self, key: str, query: Query) -> Reply | Message:
        """The lock stayed taken (the mission loop waits on a slow host): a read gets the last answer given, a
        command a clear refusal to retry (never a hang)."""
        asked = _asked(query.payload)
        last = self._last.get((key, asked)) or (self._last.get((key, DEFAULT)) if asked[0] == "plain" else None)
        if last is not None and self._read_only(query):
            return last
        return query.error(f"the controller is busy (its mission loop has held it over {self.busy_wait:g} s: a large"
                           " mission starting, or a host slow to answer: see `missionctl hosts`); try again")

    def keep(self, key: str, read: Callable[[], Message]) -> None:
        """Keep an answer to read-only queries on `key` ready (`refresh`), for when the lock is busy."""
        self._readers[key] = read

    def refresh(self) -> None:
        """Compute again the answers kept for a busy lock (called with the lock held)."""
        for key, read in self._readers.items():
            self._last[(key, DEFAULT)] = read()



#: What the kept answer of a key answers (`SerializedBus.keep`): the plain query (a view, a status's first page).
DEFAULT: tuple[Any, ...] = ("kept",)
#: Answers to other read-only queries kept for a busy lock (pages, one mission's status), at most.
MAX_KEPT = 256


def _asked(payload: Message | None) -> tuple[Any, ...]:
    """What a query asks, as a key of the answers kept for a busy lock: `("plain",)` for a view or a status's first
    page of every mission (the kept answer stands in for it), else its page and mission."""
    op, mission, after = getattr(payload, "op", "status"), getattr(payload, "mission", ""), getattr(payload, "after", 0)
    if op == "status" and not mission and not after:
        return ("plain",)
    return (op, mission, after, getattr(payload, "count", 0))


def _type_name(payload: Message | None) -> str:
    return "no payload" if payload is None else f"a {type(payload).TYPE}"


def _expected(types: tuple[type, ...]) -> str:
    return " or ".join("no payload" if t is type(None) else f"a {getattr(t, 'TYPE', t.__name__)}" for t in types)


class Controller:
    """The controller host's services: the manager and the executive, kept in step with the view.

    `lock` is the executive's (the mission loop holds it through a control cycle): membership changes are queued
    and applied when it is free (`flush`); the executive's own queryable and `rcm/resources` take it themselves
    and answer from their last reply when a slow host holds the loop up (`SerializedBus`).
    """

    def __init__(self, bus: Bus, cluster: Cluster, catalog: Catalog, me: str, lock: threading.RLock, *,
                 on_reject: Callable[[str, str], None] | None = None,
                 on_change: Callable[[str, str, str], None] | None = None, clock: Clock | None = None,
                 host_states: Callable[[], Mapping[str, str]] | None = None) -> None:
        """`host_states`: the configured hosts that are not up, each `down` or `unresponsive` (the daemon's view),
        for the resources reply: a frozen host's resources leave the manager, its name must not."""
        from drd.executive import EntryPoints, Executive  # the runtime: only on the controller
        from drd.executive_messages import MissionCommand

        self.cluster = cluster
        self.me = me
        self.keys = ClusterKeys(cluster.name)
        self.clock: Clock = clock or WallClock()
        self._lock = lock
        self._on_change = on_change
        self._host_states = host_states
        expect = {self.keys.executive: (MissionCommand,), self.keys.executive_status: (MissionCommand,),
                  self.keys.resources: (ResourcesRequest, ViewRequest, type(None))}
        serialized = SerializedBus(bus, lock, expect=expect, on_reject=on_reject)
        # The executive runs on the simulator's time (`drd.daemon.missions`); membership on this clock.
        from drd.daemon.missions import SimTimeClock

        self.mission_clock = SimTimeClock()
        self.executive = Executive(serialized, clock or self.mission_clock, EntryPoints(catalog), cluster=cluster.name,
                                   resources=host_resources(cluster, me), lease=cluster.lease,
                                   history=cluster.history,
                                   origin=(lambda: 0.0) if clock is not None else lambda: self.mission_clock.origin)
        self.executive.absent(c for c in cluster.resources() if c.host != me)  # until each host is seen up
        self.membership = Membership(cluster.lease, {me})
        self._pending: list[Action] = []  # membership actions the executive has not applied yet
        self._pending_lock = threading.Lock()
        self._queryable = serialized.serve(self.keys.resources, self._resources)
        self.serialized = serialized
        serialized.keep(self.keys.resources, lambda: resources_page(self.resources()))
        serialized.keep(self.keys.executive, self.executive.status)
        serialized.keep(self.keys.executive_status, self.executive.status)

    def host_up(self, host: str) -> None:
        with self._pending_lock:  # the mission loop suspects hosts too (`apply_offline`)
            actions = self.membership.up(host, self.clock.now())
        self._queue(actions)

    def host_down(self, host: str) -> None:
        now = self.clock.now()
        with self._pending_lock:
            actions = self.membership.down(host, now)
        self._queue(actions)
        if host in self.membership.removal and self._on_change is not None:
            self._on_change("resources-pending", host,
                            f"its resources leave the manager in {self.membership.removal[host] - now:.2f} s"
                            " unless it comes back, and are granted to no one new meanwhile")

    def apply_offline(self, host: str) -> None:
        """Take `host`'s resources offline now: a call found the host down, or it did not answer, mid-cycle (on the
        mission loop, which holds the executive's lock), and the failure it ends its holder with must not hand that
        host's robots to a waiter before the next cycle's `flush` (cluster audit 19, #1: granted, it failed in the
        same instant). A queued `offline` is applied if it is the first action of that host queued (they keep their
        order); with none queued, a host the view still has up is suspected (`Membership.silent`) until it reports
        again (`heard`). Only when the lock is free or this thread's."""
        if not self._lock.acquire(blocking=False):
            return
        try:
            with self._pending_lock:
                first = next((a for a in self._pending if a.host == host), None)
                if first is None:
                    actions = self.membership.silent(host)
                elif first.kind == "offline":
                    self._pending.remove(first)
                    actions = [first]
                else:
                    return
            self._apply(actions)
            if first is None and actions and self._on_change is not None:
                self._on_change("resources-offline", host, "a call to it did not answer: its resources are granted"
                                " to no one new until it reports again")
        finally:
            self._lock.release()

    def heard(self, host: str) -> None:
        """A load report from `host` (accepted by the view): a host suspected by `apply_offline` is back online."""
        if host not in self.membership.suspected:  # the usual case, at every report: no lock
            return
        with self._pending_lock:
            actions = self.membership.heard(host)
        self._queue(actions)
        if actions and self._on_change is not None:
            self._on_change("resources-online", host, "it reports again: its resources may be granted")

    def holds(self, host: str) -> bool:
        """Whether the manager holds `host`'s resources now (added, and no action of it still queued): a journal's
        missions resume on them (`drd.daemon.resume.wait_for_hosts`), not merely on the host being seen up."""
        self.flush(blocking=False)
        with self._pending_lock:
            queued = any(a.host == host for a in self._pending)
        return host in self.membership.present and not queued

    def step(self) -> None:
        """Apply removals that fell due. Missions are stepped in lockstep with the simulator by their own
        loop (`drd.daemon.missions.WorldRun`), not here."""
        with self._pending_lock:
            actions = self.membership.due(self.clock.now())
        self._queue(actions)

    def _queue(self, actions: list[Action]) -> None:
        """Membership actions for the executive: applied now if its lock is free, else by the mission loop at its
        next cycle (`flush`): the daemon's view never waits for a mission loop held up by a slow host. A return
        cancels a departure still queued (`coalesced`)."""
        with self._pending_lock:
            for action in actions:
                self._pending = coalesced(self._pending, action)
        self.flush(blocking=False)

    def flush(self, blocking: bool = True) -> None:
        """Apply the membership actions queued (with the executive's lock; `blocking=False`: only if it is free)."""
        if not self._pending or not self._lock.acquire(blocking=blocking):
            return
        try:
            with self._pending_lock:
                actions, self._pending = self._pending, []
            self._apply(actions)
        finally:
            self._lock.release()

    def resources(self) -> ResourcesReply:
        rcm = self.executive.broker.rcm
        hosts = self._host_states() if self._host_states is not None else {}
        return resources_reply(rcm.snapshot(), self.cluster.name, self.me, self.membership.pending(self.clock.now()),
                               hosts, rcm.waiters(), rcm.shelf_waiters())

    def close(self) -> None:
        self._queryable.close()
        self.executive.close()

    def _resources(self, query: Query) -> Message:
        asked = query.payload
        if isinstance(asked, ResourcesRequest):
            return resources_page(self.resources(), asked.after, asked.count)
        return resources_page(self.resources())  # a plain view: its first page

    def _apply(self, actions: list[Action]) -> None:
        pool, now = self.executive.pool, self.executive.clock.now()
        for action in actions:
            if action.kind == "add":
                found = host_resources(self.cluster, action.host)  # its robots stood in the world meanwhile
                self.executive.add_resources(found)  # hot-plug: running multiplicities may grow
                detail = f"{len(found)} resources added to the manager"
            elif action.kind in ("offline", "online"):  # told by the `down` event's resources-pending, and `up`
                self.executive.set_host_offline(action.host, action.kind == "offline")
                continue
            else:
                if any(not m.finished for m in self.executive.missions.values()):
                    self.executive.remove_host(action.host)  # every mission settles the consequences now
                pool.remove_host(action.host, now)  # (again: a no-op when a mission did it)
                detail = "its resources left the manager; their grants are freed"
            if self._on_change is not None:
                self._on_change(f"resources-{'added' if action.kind == 'add' else 'removed'}", action.host, detail)
