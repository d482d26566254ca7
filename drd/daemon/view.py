"""The Component Database's cluster view: every host's presence, load and announcement. Pure.

Each daemon holds the full view, fed by what the bus delivers: host liveliness tokens, load
reports and announcements. The view reads no clock: every call takes `now`, monotonic seconds,
and returns the `Change`s it caused, which the daemon logs, records and acts on (the controller
adds and removes resources). The rules:

- A host is **up** while its liveliness token is present and it keeps reporting its load: a
  report at most `lease` seconds old, or a token younger than `lease` (its first report is on its
  way).
- It goes **down** at once when its token vanishes (a clean stop, a crash, a closed socket; in a cluster with
  routers, a lease later if it did not say goodbye and its token is still gone: a router's loss takes every token
  behind it, and they come back through the other router), and
  when its reports stop for longer than `lease` while the token stays (a frozen or SIGSTOPped
  process, a host whose link is silent but not yet expired). A host that went down that way is
  shown **unresponsive** (`shown_state`), not down, until it reports again: its token may vanish
  later, when zenoh's link lease runs out, but a frozen, partitioned or overloaded host never
  closed its link; a killed or stopped one did, at once.
- A down host comes back **up** when its token is present and a report arrives.
- The view's own host is always up: it is the process answering.
- **Silence is evidence only while this view was listening.** When the daemon's own ticks stop for longer than
  the lease (its process was frozen, suspended or starved), it heard nothing over that gap: on waking it reports
  once that it was frozen (`Change("frozen")`, on its own host) and gives every other host a fresh lease from the
  wake-up before judging it, silence and a vanished token alike (zenoh may drop the link of a silent peer: ours).
  A host still silent, or still without its token, after that grace goes down as above; one that said goodbye
  (`leaving`) goes at once.

Hosts are those of `hosts.yaml`; anything about another host is refused (`Change("rejected")`).

A robot's offer carries hosts.yaml's properties with the live ones over them (`live_report`): those the acting
controller's last `LiveReport` gave (a launched Scout's `carrier`, the robot's pose and battery), while that
controller is up and its report is at most a lease old, each with its age (`Offer.live`).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum

from drd.bus import LoadReport
from drd.cluster.instances import InstanceInfo
from drd.daemon.load import TELEMETRY, live_value
from drd.daemon.messages import Announcement, LiveReport, Location
from drd.hosts import Cluster, Host, Role
from drd.placement import HostView, required_devices, view_of
from drd.trader import Offer
from dsl.catalog import Catalog


class HostState(StrEnum):
    UP = "up"
    """Its token is present and its load reports are fresh."""
    DOWN = "down"
    """Never seen, gone (token vanished) or silent for longer than the lease."""


#: How a down host that went silent (rather than closing its link) is shown: frozen, partitioned or overloaded.
UNRESPONSIVE = "unresponsive"
#: A gap in a view's own ticks longer than this many tick periods is one nobody listened through (`_wake`); what
#: it lasted beyond one period does not count in the others' silence. A tick a little late is no gap: with a lease
#: of 1 s, four periods, excusing every late tick would never let a silent host go down.
GAP_TICKS = 2
#: How many such gaps a view remembers (a host's silence is judged against those since it was last heard).
GAPS_KEPT = 32


@dataclass(frozen=True, slots=True)
class Change:
    """What one input changed: `kind` is `up`, `down`, `config-mismatch`, `rejected` or `frozen` (this view's own
    host did not tick for longer than the lease, `ClusterView.tick`); `at` is monotonic."""

    at: float
    kind: str
    host: str
    detail: str


@dataclass(slots=True)
class HostRecord:
    """What the view knows of one configured host (mutable, owned by the view)."""

    config: Host
    state: HostState = HostState.DOWN
    since: float | None = None
    reason: str = "never seen"
    token: bool = False
    silent: bool = False  # down because its reports stopped while its link stayed open (shown unresponsive)
    token_since: float | None = None
    heard: float | None = None
    report: LoadReport | None = None
    announcement: Announcement | None = None
    leaving: str = ""
    mismatch: str = ""
    grace: float = -math.inf  # until then it is not judged: this view was not listening before (it was frozen)

    @property
    def name(self) -> str:
        return self.config.name

    @property
    def instances(self) -> list[InstanceInfo]:
        return list(self.announcement.instances) if self.announcement else []


class ClusterView:
    """The full view of one cluster, as seen from host `me` (see the module docstring)."""

    def __init__(self, cluster: Cluster, me: str, *, lease: float | None = None, digest: str = "",
                 now: float = 0.0, tick: float = 0.25) -> None:
        self.cluster = cluster
        self.me = cluster.host(me).name
        self.lease = cluster.lease if lease is None else lease
        if not self.lease > 0:
            raise ValueError(f"lease must be positive, not {self.lease!r}")
        self.digest = digest
        self.records: dict[str, HostRecord] = {h.name: HostRecord(h) for h in cluster.hosts}
        self.live: dict[str, dict[str, object]] = {}  # robot id -> its live properties (the controller's last report)
        self.live_from: str | None = None  # the controller that sent them
        self.live_at: float | None = None  # when they arrived (monotonic)
        self.ticked: float | None = None  # the last tick (or wake-up): a longer gap than the lease is a freeze
        self.woke: tuple[float, float] | None = None  # the last freeze of its own: (wake-up, seconds frozen)
        self.deaf: deque[tuple[float, float]] = deque(maxlen=GAPS_KEPT)  # gaps in its own ticks: (from, to)
        self.tick_period = tick  # how often it is ticked (`DaemonConfig.tick`)
        mine = self.records[self.me]
        mine.state, mine.since, mine.reason = HostState.UP, now, "this host"
        #: Through routers, a vanished token is not evidence at once: a router's loss takes every token behind it,
        #: and they come back through the other router a moment later (`token`).
        self.routed = any(Role.ROUTER in h.roles for h in cluster.hosts)

    # -- inputs ----------------------------------------------------------------------------------

    def token(self, host: str, alive: bool, now: float) -> list[Change]:
        """A host's liveliness token appeared (`alive`) or vanished."""
        rec = self.records.get(host)
        if rec is None:
            return [Change(now, "rejected", host, "a host token from a host not in the hosts file")]
        if host == self.me:
            rec.token = alive
            return []
        if alive:
            if not rec.token:
                rec.token, rec.token_since, rec.leaving = True, now, ""
            if rec.state is HostState.DOWN and self._fresh(rec, now):
                return [self._set(rec, HostState.UP, now, "joined")]
            return []
        rec.token, rec.token_since = False, None
        woke = self._wake(now)
        if rec.state is HostState.UP and not rec.leaving and now <= rec.grace:
            return woke  # perhaps our own link, dropped while we were frozen: judged when the grace ends (`tick`)
        if rec.state is HostState.UP and not rec.leaving and self.routed:
            rec.grace = now + self.lease  # perhaps a router lost, the host not: judged when the grace ends (`tick`)
            return woke
        if rec.state is HostState.UP:
            return [*woke, self._set(rec, HostState.DOWN, now, rec.leaving or "lost: its liveliness token vanished")]
        if rec.silent and rec.leaving:  # a silent host said goodbye after all: it is down, not unresponsive
            rec.silent, rec.reason = False, rec.leaving
        return woke

    def _unknown_sender(self, host: str, key_host: str | None, what: str, now: float) -> list[Change]:
        """The rejection of a report from a host not in the hosts file, or published under another host's key
        (none when it may be read)."""
        if host not in self.records:
            return [Change(now, "rejected", host, f"{what} from a host not in the hosts file")]
        if key_host is not None and key_host != host:
            return [Change(now, "rejected", key_host, f"{what} for {host} published under {key_host}")]
        return []

    def load(self, report: LoadReport, now: float, key_host: str | None = None) -> list[Change]:
        """A load report; `key_host` is the host named by the key it came on (must match the report)."""
        host = report.host
        rec = self.records.get(host)
        refused = self._unknown_sender(host, key_host, "a load report", now)
        if refused or rec is None:
            return refused
        if not _sane(report):
            return [Change(now, "rejected", host, "a load report with out-of-range values")]
        rec.heard, rec.report = now, report
        if host != self.me and rec.state is HostState.DOWN and rec.token:
            return [self._set(rec, HostState.UP, now, "reporting again" if rec.since is not None else "joined")]
        return []

    def live_report(self, report: LiveReport, now: float, key_host: str | None = None) -> list[Change]:
        """The acting controller's live properties of the robots: they replace the last ones. Only a controller
        host's (a standby never sends any), only hosts.yaml's robots and their own keys, only scalar values."""
        host = report.host
        rec = self.records.get(host)
        refused = self._unknown_sender(host, key_host, "live properties", now)
        if refused or rec is None:
            return refused
        if Role.CONTROLLER not in rec.config.roles:
            return [Change(now, "rejected", host, "live properties from a host that is not a controller")]
        robots = {r.id: r for r in self.cluster.robots}
        self.live = {rid: {k: v for k, v in values.items()
                           if (k in TELEMETRY or k in robots[rid].properties) and live_value(v)}
                     for rid, values in report.robots.items() if rid in robots and isinstance(values, dict)}
        self.live_from, self.live_at = host, now
        return []

    def live_of(self, robot: str, now: float) -> tuple[dict[str, object], float]:
        """A robot's live properties and their age (seconds): none when the controller that sent them is not up or
        its report is more than a lease old (it stopped, or no longer acts)."""
        if self.live_at is None or self.live_from is None or now - self.live_at > self.lease:
            return {}, 0.0
        if self.records[self.live_from].state is not HostState.UP:
            return {}, 0.0
        return self.live.get(robot, {}), max(0.0, now - self.live_at)

    def announce(self, ann: Announcement, now: float, key_host: str | None = None) -> list[Change]:
        """A daemon's announcement: its runnable components, instances and services."""
        rec = self.records.get(ann.host)
        if rec is None:
            return [Change(now, "rejected", ann.host, "an announcement from a host not in the hosts file")]
        if key_host is not None and key_host != ann.host:
            return [Change(now, "rejected", key_host, f"an announcement for {ann.host} published under {key_host}")]
        if ann.cluster != self.cluster.name:
            return [Change(now, "rejected", ann.host, f"an announcement for cluster {ann.cluster!r}")]
        rec.announcement = ann
        if self.digest and ann.config and ann.config != self.digest and rec.mismatch != ann.config:
            rec.mismatch = ann.config
            return [Change(now, "config-mismatch", ann.host,
                           f"runs with a different hosts file (digest {ann.config[:12]}, ours {self.digest[:12]})")]
        return []

    def leaving(self, host: str, reason: str, now: float) -> list[Change]:
        """A daemon said it is stopping: its token is about to go; remember why."""
        rec = self.records.get(host)
        if rec is None:
            return [Change(now, "rejected", host, "a goodbye from a host not in the hosts file")]
        if host != self.me:
            rec.leaving = f"stopped: {reason}" if reason else "stopped"
        return []

    def tick(self, now: float) -> list[Change]:
        """Hosts whose reports stopped for longer than the lease go down, or whose token vanished during the grace
        after a freeze of this view's own (then the freeze is reported first: `_wake`)."""
        out = self._wake(now)
        for rec in self.records.values():
            if rec.name == self.me or rec.state is not HostState.UP or self._fresh(rec, now):
                continue
            if not rec.token:
                out.append(self._set(rec, HostState.DOWN, now, rec.leaving or "lost: its liveliness token vanished"))
                continue
            last = max(t for t in (rec.heard, rec.token_since) if t is not None)
            out.append(self._set(rec, HostState.DOWN, now,
                                 f"silent: no load report for {now - last:.2f} s (lease {self.lease:g} s)"))
            rec.silent = True
        return out

    def _wake(self, now: float) -> list[Change]:
        """A gap in this view's own ticks (over `GAP_TICKS` periods): the others' silence over it, beyond a period,
        is not evidence (nobody listened, and what they sent meanwhile is still being delivered), so it does not
        count in their silence (`deaf`): a worker
        frozen for 2.85 s of a 3 s lease woke and took its controller, last heard 0.85 s before the freeze, for dead
        (faults audit 23, #1). A gap over the lease is a freeze: reported once, and each host gets a lease from now
        before it is judged."""
        last, self.ticked = self.ticked, now
        if last is None:
            return []
        if now - last > GAP_TICKS * self.tick_period:
            self.deaf.append((last + self.tick_period, now))
        if now - last <= self.lease:
            return []
        self.woke = (now, now - last)
        for rec in self.records.values():
            if rec.name != self.me:
                rec.grace = now + self.lease
        return [Change(now, "frozen", self.me,
                       f"this daemon did not run for {now - last:.2f} s, longer than the lease ({self.lease:g} s):"
                       " frozen, suspended or starved; the other hosts get a lease from now before their silence"
                       " counts")]

    # -- queries ---------------------------------------------------------------------------------

    def frozen_since(self, t: float, now: float) -> float:
        """Seconds this view's own host was frozen (its ticks stopped for longer than the lease) at some time after
        `t`, or during the lease after it woke, 0.0 if it was not: whoever timed a call out across that gap (the
        mission loop) blames this host, not the callee. Already true before the first tick after the wake-up
        (another thread may wake first); and for a lease after it, while the links the others dropped meanwhile
        are made again (a call then gets no answer at once)."""
        if self.ticked is not None and now - self.ticked > self.lease:
            return now - self.ticked
        if self.woke is not None and (self.woke[0] >= t or now - self.woke[0] <= self.lease):
            return self.woke[1]
        return 0.0

    def state(self, host: str) -> HostState:
        return self.records[host].state

    def shown_state(self, host: str) -> str:
        """The state the operator sees: `up`, `down`, or `unresponsive` (down because it went silent while its
        link stayed open: frozen, partitioned or overloaded, not stopped or killed)."""
        rec = self.records[host]
        return UNRESPONSIVE if rec.state is HostState.DOWN and rec.silent else rec.state.value

    def not_up(self) -> dict[str, str]:
        """The configured hosts that are not up, each with its shown state (`down` or `unresponsive`)."""
        return {name: self.shown_state(name) for name, rec in self.records.items() if rec.state is not HostState.UP}

    def up(self) -> list[str]:
        """The hosts that are up, in hosts-file order."""
        return [r.name for r in self.records.values() if r.state is HostState.UP]

    def instances(self) -> list[InstanceInfo]:
        """Component instances of the hosts that are up (those of a host that went down are gone)."""
        return [i for r in self._up_records() for i in r.instances]

    def services(self) -> list[InstanceInfo]:
        """Daemon services (`rcm`, `executive`, `<host>.db`...) of the hosts that are up."""
        return [InstanceInfo(name, "drd." + name.rsplit(".", 1)[-1], r.name, "running", key)
                for r in self._up_records() if r.announcement for name, key in r.announcement.services.items()]

    def runnable(self, catalog: Catalog | None = None) -> dict[str, list[str]]:
        """Component type -> the hosts that are up and can run it (their announcements, else the catalog)."""
        out: dict[str, list[str]] = {}
        for r in self._up_records():
            names: Iterable[str] = (r.announcement.components if r.announcement
                                    else runnable_components(r.config, catalog) if catalog else ())
            for name in names:
                out.setdefault(name, []).append(r.name)
        return dict(sorted(out.items()))

    def lookup(self, name: str) -> Location | None:
        """The name service: an instance first, then a daemon service."""
        for inst in self.instances():
            if inst.name == name:
                return Location(name, "instance", inst.host, inst.key)
        for svc in self.services():
            if svc.name == name:
                return Location(name, "service", svc.host, svc.key)
        return None

    def host_facts(self, host: str) -> dict[str, object]:
        """What a trader expression sees as `host`: name, load (cpu / 100), cpu, memory, up."""
        rec = self.records[host]
        cpu = rec.report.cpu if rec.report else math.nan
        memory = rec.report.memory if rec.report else math.nan
        return {"name": host, "load": cpu / 100.0, "cpu": cpu, "memory": memory,
                "up": rec.state is HostState.UP}

    def offers(self, now: float | None = None) -> list[Offer]:
        """Trader offers: the devices, robots and instances of the hosts that are up, in hosts-file order; at `now`,
        a robot's live properties over hosts.yaml's (`live_of`)."""
        out: list[Offer] = []
        for r in self._up_records():
            facts = self.host_facts(r.name)
            out += [Offer(d.id, d.type, {**d.options, "driver": d.driver}, facts) for d in r.config.devices]
            for b in r.config.robots:
                live, age = self.live_of(b.id, now) if now is not None else ({}, 0.0)
                out.append(Offer(b.id, b.type, {**b.properties, **b.parts, **live}, facts, dict.fromkeys(live, age)))
            out += [Offer(i.name, i.component, {"state": i.state}, facts) for i in r.instances]
        return out

    def host_views(self) -> list[HostView]:
        """What the Load Balancer needs of every configured host (down ones included, refused as `down`); the types
        each offers are those its daemon announced (it refuses to start any other)."""
        out = []
        for r in self.records.values():
            running: dict[str, int] = {}
            for inst in r.instances:
                running[inst.component] = running.get(inst.component, 0) + 1
            cpu, memory = (r.report.cpu, r.report.memory) if r.report else (0.0, 0.0)
            out.append(view_of(r.config, cpu=cpu, memory=memory, up=r.state is HostState.UP, running=running,
                               offers=r.announcement.components if r.announcement else None))
        return out

    # -- internals -------------------------------------------------------------------------------

    def _up_records(self) -> list[HostRecord]:
        return [r for r in self.records.values() if r.state is HostState.UP]

    def _fresh(self, rec: HostRecord, now: float) -> bool:
        """Token present and a report (or the token's arrival) within the lease; or within the grace after a freeze
        of this view's own (`_wake`)."""
        if now <= rec.grace:
            return True
        if not rec.token:
            return False
        last = max((t for t in (rec.heard, rec.token_since) if t is not None), default=None)
        return last is not None and now - last - self._deaf_since(last) <= self.lease

    def _deaf_since(self, t: float) -> float:
        """Seconds after `t` this view did not tick (its own gaps, `_wake`): nobody listened then."""
        return sum(end - max(start, t) for start, end in self.deaf if end > t)

    @staticmethod
    def _set(rec: HostRecord, state: HostState, now: float, reason: str) -> Change:
        rec.state, rec.since, rec.reason = state, now, reason
        rec.silent = False
        return Change(now, state.value, rec.name, reason)


def runnable_components(host: Host, catalog: Catalog) -> list[str]:
    """The component types whose device needs this host's devices cover (behaviors and data need none); never an
    abstract type (`Robot`, `Sensor`): nothing runs one (placement audit 24, #8: `Robot`, an arc without parts, was
    listed on every host, the controller too)."""
    types = {d.type for d in host.devices}
    return sorted(t.name for t in catalog.components.values() if not t.abstract and required_devices(t) <= types)


#: At most this many instances on one host (a 64-bit count: the wire's JSON decoder takes any integer, and a 400-digit
#: count was stored and shown by `missionctl hosts`; wire audit 10, D4).
MAX_INSTANCES_REPORTED = 2**63 - 1


def _sane(report: LoadReport) -> bool:
    numbers = (report.cpu, report.memory, report.load1)
    return all(math.isfinite(v) and v >= 0 for v in numbers) and 0 <= report.instances <= MAX_INSTANCES_REPORTED
