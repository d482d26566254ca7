"""What `missionctl` uses to look at a running cluster: a bus session and the daemons' queryables.

`ClusterClient.connect(endpoints)` opens a zenoh session that connects to the given endpoints
(every host of `hosts.yaml`, or one `--connect ENDPOINT`) and waits, bounded by `timeout`, until
it sees a daemon's token; otherwise `NoDaemon` names the endpoints tried. A peer session by default,
linked to every endpoint; with `options={"mode": "client"}` (a hosts file with routers:
`Transport.client_mode`) a zenoh client linked to one of them at a time, so that a request does not
reach a daemon once through each router. Requests go to one
daemon at a time, preferred ones first (the controller), so a frozen daemon costs one short
timeout instead of stalling every answer.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, replace
from typing import Any, Self, TypeVar

from drd.bus import Bus, BusError, BusTimeout, Message, Ping, Pong
from drd.cluster.keys import ClusterKeys, cluster_of
from drd.daemon.messages import (
    ComponentsReply,
    DaemonStatus,
    HostsReply,
    Location,
    Lookup,
    ResourcesReply,
    ResourcesRequest,
    TraderReply,
    TraderRequest,
    ViewRequest,
)
from drd.errors import BusFailure

M = TypeVar("M", bound=Message)
PREFER_WAIT = 0.5  # seconds (at most a quarter of the timeout) to wait for the preferred daemon once another answered
#: Seconds a request gets at least, even past the command's deadline (a connect that took the whole budget).
FLOOR = 0.1
#: Seconds the client's close waits for its session, at least and at most: a clean close takes a few milliseconds
#: (measured 0-10 ms on loopback); a frozen peer would hold it 10 s, and the process exits right after anyway.
CLOSE_FLOOR = 0.05
CLOSE_MOST = 0.2
#: The part of `timeout` a client of the routers gives one router to finish zenoh's handshake before it tries the next
#: (zenoh's own default is 10 s: a frozen first router, which accepts the TCP link and never answers, held the open
#: 10.04 s; with 0.5 s, the session opened through the second router in 0.55 s).
HANDSHAKE_SHARE = 0.25


class ClientError(BusFailure):
    """The cluster cannot answer (no daemon, no controller, several clusters): one line for the user."""


class NoDaemon(ClientError):
    """No daemon answered at the endpoints tried."""

    def __init__(self, endpoints: Sequence[str], timeout: float, detail: str = "") -> None:
        where = ", ".join(endpoints) or "no endpoint"
        super().__init__(f"no drd daemon answered at {where} within {timeout:g} s" + (f" ({detail})" if detail else ""))
        self.endpoints = list(endpoints)


class ClusterClient:
    """Requests to the daemons of one cluster over a bus session this client owns."""

    def __init__(self, bus: Bus, cluster: str, *, timeout: float = 2.0, prefer: Sequence[str] = (),
                 endpoints: Sequence[str] = (), began: float | None = None) -> None:
        """`began`: when the command began (monotonic; default now): `budget` is `timeout` after it, the deadline
        of a one-shot command (`missionctl status --timeout 1` answers within about 1 s, then exits)."""
        self.began = time.monotonic() if began is None else began
        self.bus = bus
        self.cluster = cluster
        self.keys = ClusterKeys(cluster)
        self.timeout = timeout
        self.prefer = list(prefer)
        self.endpoints = list(endpoints)

    @classmethod
    def connect(cls, endpoints: Sequence[str], *, cluster: str | None = None, options: Mapping[str, Any] | None = None,
                timeout: float = 2.0, prefer: Sequence[str] = ()) -> Self:
        """Join the cluster's bus (listening nowhere) and wait for a daemon's token.

        Raises:
            NoDaemon: nobody answered within `timeout`.
            ClientError: the daemons seen belong to several clusters (pass `cluster`).
        """
        from drd.bus.base import RECONNECT_EACH_SECOND
        from drd.bus.zenoh_bus import ZenohBus

        began = time.monotonic()
        if timeout <= 0:
            raise ValueError(f"timeout must be positive, not {timeout!r}")
        opts = {"scouting/delay": 0, "connect/retry": RECONNECT_EACH_SECOND, **dict(options or {})}
        if opts.get("mode") == "client":  # zenoh opens a client once a router answered, trying them in turn
            opts.setdefault("transport/unicast/open_timeout", max(50, int(timeout * HANDSHAKE_SHARE * 1000)))
        try:
            bus = ZenohBus(connect=list(endpoints), options=opts, name="missionctl")
        except BusError as e:
            raise NoDaemon(endpoints, timeout, str(e)) from e
        try:
            deadline = time.monotonic() + timeout
            found = _wait_for_tokens(bus, f"drd/{cluster or '*'}/host/*", deadline)
            if not found:
                raise NoDaemon(endpoints, timeout)
            if prefer and prefer[0] not in {h for _, h in found}:  # links come up one by one: give the
                found = _wait_for_tokens(bus, f"drd/{cluster or '*'}/host/{prefer[0]}",  # preferred one a moment
                                         min(deadline, time.monotonic() + min(PREFER_WAIT, timeout / 4))) or found
            clusters = sorted({c for c, _ in found})
            if len(clusters) > 1:
                raise ClientError(f"daemons of several clusters answer ({', '.join(clusters)}): pass --config"
                                  " with the cluster's hosts file")
        except BaseException:
            bus.close()
            raise
        return cls(bus, clusters[0], timeout=timeout, prefer=prefer, endpoints=endpoints, began=began)

    @property
    def budget(self) -> float:
        """The deadline of a one-shot command (monotonic): `timeout` after it began."""
        return self.began + self.timeout

    def close(self) -> None:
        """Close the session, waiting for it at most what is left of the command's budget (a frozen peer holds a
        zenoh close for 10 s; the process exits right after, and the OS closes its links)."""
        close_within = getattr(self.bus, "close_within", None)
        if close_within is None:
            self.bus.close()
            return
        close_within(min(CLOSE_MOST, max(CLOSE_FLOOR, self.budget - time.monotonic())))

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    # -- what the daemons answer ---------------------------------------------------------------------

    def daemons(self) -> list[str]:
        """The hosts whose daemon token is alive now, preferred ones first."""
        hosts = [h for c, h in _tokens(self.bus, f"{self.keys.root}/host/*", 0.5) if c == self.cluster]
        rank = {h: i for i, h in enumerate(self.prefer)}
        return sorted(hosts, key=lambda h: (rank.get(h, len(rank)), h))

    def hosts(self, events: int = 50, *, deadline: float | None = None, slow: set[str] | None = None) -> HostsReply:
        """Any daemon's view of the hosts (`deadline`: answer by then, monotonic; `slow`: daemons not to ask, and
        where those that did not answer in time are added)."""
        return self._ask(lambda h: self.keys.db(h, "hosts"), ViewRequest(events), HostsReply, deadline, slow)

    def components(self, *, deadline: float | None = None, slow: set[str] | None = None,
                   count: int = 0) -> ComponentsReply:
        """Any daemon's Component Database, page after page from the daemon that answered first (`drd.paging`),
        assembled; an instance that moved between two pages is listed once."""
        first = self._ask(lambda h: self.keys.db(h, "components"), ViewRequest(count=count), ComponentsReply,
                          deadline, slow)
        pages = self._following(first, self.keys.db(first.answered_by, "components"),
                                lambda after: ViewRequest(after=after, count=count), ComponentsReply, deadline)
        instances = {(i.host, i.mission, i.name): i for p in pages for i in p.instances}
        services = {(i.host, i.name): i for p in pages for i in p.services}
        return replace(first, instances=list(instances.values()), services=list(services.values()), next=0)

    def lookup(self, name: str) -> Location:
        return self._ask(lambda h: self.keys.db(h, "lookup"), Lookup(name), Location)

    def query(self, text: str, seed: int = 0, *, deadline: float | None = None, count: int = 0) -> TraderReply:
        """The trader's offers for `text`, best first, page after page from the daemon that answered first."""
        first = self._ask(lambda h: self.keys.db(h, "query"), TraderRequest(text, seed, count=count), TraderReply,
                          deadline)
        if not first.answered_by:
            return first
        pages = self._following(first, self.keys.db(first.answered_by, "query"),
                                lambda after: TraderRequest(text, seed, after, count), TraderReply, deadline)
        return replace(first, offers=[o for p in pages for o in p.offers], next=0)

    def _following(self, first: M, key: str, ask: Callable[[int], Message], want: type[M],
                   deadline: float | None) -> list[M]:
        """`first` and the pages after it (`drd.paging`), asked of the daemon that answered it (the cursors are its
        own) by `deadline`. Raises ClientError when a page does not come in time."""
        pages, after = [first], 0
        end = time.monotonic() + self._left(deadline)
        while (nxt := int(getattr(pages[-1], "next", 0))) > after:
            after, wait = nxt, end - time.monotonic()
            try:
                if wait <= 0:
                    raise BusTimeout("no time left")
                pages.append(_expect(self.bus.call(key, ask(after), timeout=wait), want))
            except BusTimeout:
                raise ClientError(f"{key} did not answer the page after {after} in time") from None
        return pages

    def daemon_status(self, host: str, *, deadline: float | None = None) -> DaemonStatus:
        return _expect(self.bus.call(self.keys.status(host), ViewRequest(), timeout=self._left(deadline)),
                       DaemonStatus)

    def ping(self, host: str) -> Pong:
        return _expect(self.bus.call(self.keys.ping(host), Ping(1, time.time()), timeout=self.timeout), Pong)

    def resources(self, *, deadline: float | None = None, count: int = 0) -> ResourcesReply:
        """The controller's manager, asked page by page (`drd.paging`, `count` items a page) by `deadline`, and
        assembled; asked again from the start (three tries) when a host came or went between two pages. Raises
        ClientError when the controller does not answer in time."""
        end = time.monotonic() + self._left(deadline)
        for _attempt in range(3):
            first = page = self._resources_page(0, count, end)
            pages = [first]
            while page.next and page.layout == first.layout:
                after = page.next
                page = self._resources_page(after, count, end)
                pages.append(page)
                if page.next and page.next <= after:  # a server that does not move on: never loop
                    break
            if page.layout == first.layout:
                return replace(first, units=[u for p in pages for u in p.units],
                               robots=[r for p in pages for r in p.robots], queue=[w for p in pages for w in p.queue],
                               next=0)
        raise ClientError(f"the controller's resources kept changing while {self.keys.resources} was read page by "
                          "page; try again")

    def _resources_page(self, after: int, count: int, end: float) -> ResourcesReply:
        """One page of the manager, asked within what is left until `end`."""
        wait = end - time.monotonic()
        try:
            if wait <= 0:
                raise BusTimeout("no time left")
            return _expect(self.bus.call(self.keys.resources, ResourcesRequest(after, count), timeout=wait),
                           ResourcesReply)
        except BusTimeout:
            raise ClientError(f"the controller does not answer on {self.keys.resources} in time"
                              " (is its drd up, or frozen?)") from None

    def missions(self, mission: str = "", *, count: int = 0, timeout: float | None = None) -> list[dict[str, Any]]:
        """The controller's missions (`MissionStatus.missions`; only `mission`, if given: none when it is not
        known), asked page by page (`drd.paging`, `count` a page) within `timeout` (the client's) in all. Raises
        ClientError when the executive does not answer."""
        from drd.executive_messages import MissionCommand, MissionStatus  # registers the executive's messages

        out: list[dict[str, Any]] = []
        for page in self._pages(lambda a: MissionCommand("status", mission, after=a, count=count), MissionStatus,
                                "the executive", timeout):
            out += page.missions
        return out

    def records(self, mission: str, after: int = 0, *, count: int = 0,
                timeout: float | None = None) -> list[Any]:
        """The records of `mission` the executive kept, numbered after `after` (`MissionRecord`s in order), asked
        page by page within `timeout` in all."""
        from drd.executive_messages import MissionCommand, MissionRecords

        out: list[Any] = []
        for page in self._pages(lambda a: MissionCommand("records", mission, after=a, count=count), MissionRecords,
                                "the executive", timeout, start=after):
            out += page.records
        return out

    def _pages(self, ask: Callable[[int], Message], want: type[M], who: str, timeout: float | None,
               start: int = 0) -> Iterator[M]:
        """The pages of a paginated reply (each says the cursor of the next, 0 for none), asked of the executive's
        read-only key one after the other, all within `timeout`."""
        limit = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + limit
        after = start
        while True:
            remaining = deadline - time.monotonic()
            try:
                if remaining <= 0:
                    raise BusTimeout(f"no time left for the page after {after}")
                page = _expect(self.bus.call(self.keys.executive_status, ask(after), timeout=remaining), want)
            except BusTimeout:
                raise ClientError(f"{who} does not answer on {self.keys.executive_status} within {round(limit, 1):g} s"
                                  " (is the controller's drd up?)") from None
            yield page
            nxt = int(getattr(page, "next", 0))
            if nxt <= after:  # the last page (0), or a server that does not move on: never loop
                return
            after = nxt

    def status(self, events: int = 50, *, deadline: float | None = None) -> dict[str, Any]:
        """One view of the cluster: hosts, instances, resources, missions and recent events (plain JSON), all asked
        by `deadline` (default: the client's timeout from now): a daemon that did not answer one part is not asked
        the next, and a part with no time left is an error of its own, never a wait."""
        deadline = time.monotonic() + self.timeout if deadline is None else deadline
        slow: set[str] = set()
        hosts = self.hosts(events, deadline=deadline, slow=slow)
        components = self.components(deadline=deadline, slow=slow)
        out: dict[str, Any] = {
            "cluster": self.cluster, "answered_by": hosts.answered_by, "at": hosts.at,
            "hosts": [asdict(h) for h in hosts.hosts],
            "instances": [asdict(i) for i in components.instances],
            "services": [asdict(s) for s in components.services],
            "resources": None, "missions": None, "daemon": None, "errors": {},
            "events": [asdict(e) for e in hosts.events],
        }
        try:
            out["daemon"] = asdict(self.daemon_status(hosts.answered_by, deadline=deadline))
        except BusError as e:
            out["errors"]["daemon"] = f"{hosts.answered_by} did not say how it is: {e}"
        controller = self.prefer[0] if self.prefer else ""
        if controller in slow:  # it did not answer the view in time: the manager and the missions would not either
            why = f"the controller {controller} did not answer within {self.timeout:g} s (frozen, or cut off?)"
            out["errors"] |= {"resources": why, "missions": why}
            return out
        missions: dict[str, Any] = {}

        def ask_missions() -> None:  # beside the resources: a controller that does not answer costs one wait, not two
            try:
                missions["missions"] = self.missions(timeout=self._left(deadline))
            except ClientError as e:
                missions["error"] = str(e)

        asking = threading.Thread(target=ask_missions, name="missionctl-missions", daemon=True)
        asking.start()
        try:
            res = self.resources(deadline=deadline)
            out["resources"] = {"units": [asdict(u) for u in res.units], "robots": [asdict(r) for r in res.robots],
                                "queue": [asdict(w) for w in res.queue], "removing": res.removing,
                                "hosts": res.hosts}
        except ClientError as e:
            out["errors"]["resources"] = str(e)
        asking.join(self._left(deadline) + 1.0)  # its own requests are bounded by the deadline
        if "missions" in missions:
            out["missions"] = missions["missions"]
        else:
            out["errors"]["missions"] = missions.get("error", "the executive did not answer in time")
        return out

    def _left(self, deadline: float | None) -> float:
        """Seconds a request may wait: the client's timeout, or what is left until `deadline` (at least `FLOOR`)."""
        return self.timeout if deadline is None else max(FLOOR, deadline - time.monotonic())

    def _ask(self, key_of: Callable[[str], str], payload: Message, want: type[M], deadline: float | None = None,
             slow: set[str] | None = None) -> M:
        """Ask the daemons one at a time, preferred first (but not those in `slow`), until one answers by `deadline`
        (default: the timeout from now); those that did not answer in time go into `slow`."""
        deadline = time.monotonic() + self.timeout if deadline is None else max(deadline, time.monotonic() + FLOOR)
        per_try = max(0.5, self.timeout / 2)
        tried: list[str] = []
        skip = slow if slow is not None else set()
        for host in self.daemons():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            if host in skip:
                continue
            try:
                return _expect(self.bus.call(key_of(host), payload, timeout=min(remaining, per_try)), want)
            except BusTimeout:
                tried.append(host)
                skip.add(host)
        detail = f"daemons {', '.join(tried)} did not answer" if tried else "no daemon token is alive any more"
        raise NoDaemon(self.endpoints, self.timeout, detail)


def _expect(msg: Message, want: type[M]) -> M:
    if not isinstance(msg, want):
        raise ClientError(f"expected a {want.TYPE} reply, got a {type(msg).TYPE}")
    return msg


def _tokens(bus: Bus, key_expr: str, timeout: float) -> list[tuple[str, str]]:
    return [found for key in bus.alive(key_expr, timeout=timeout) if (found := cluster_of(key)) is not None]


def _wait_for_tokens(bus: Bus, key_expr: str, deadline: float) -> list[tuple[str, str]]:
    while True:
        found = _tokens(bus, key_expr, max(0.05, min(0.25, deadline - time.monotonic())))
        if found or time.monotonic() >= deadline:
            return found
        time.sleep(0.02)
