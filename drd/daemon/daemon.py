"""The Distributed Robotics Daemon: one per host, a thin shell around the cluster view.

Services of every daemon (keys in `drd.cluster.keys`, docs/daemon.md):

- **presence**: a liveliness token `drd/<cluster>/host/<host>`;
- **Load Reporter**: a `LoadReport` every `load_period` seconds;
- **Component Database**: the full `ClusterView`, fed by every host's token, load reports and
  announcements; answers `hosts`, `components`, `query` (the trader) and `lookup` (the name
  service) under `host/<host>/db/`, and `status` about the daemon itself;
- **peer check**: `zenoh.open()` succeeds even when every peer refused us, so after a grace period
  the daemon names each configured peer it cannot see, and why (`drd.daemon.peers`);
- on the `controller` host, the **Resource Controller Manager** and the **Mission Executive**
  (`drd.daemon.controller`): a host's resources join the manager when it comes up and leave it a
  lease after it went down.

Threading: bus callbacks run on zenoh's threads and the periodic work on the thread calling
`run()`; they go through one lock around the view. The controller's executive has its own, which the mission
loop holds through each control cycle; the view never waits for it (membership changes are queued for the
executive), so a host slow to answer the loop never holds up the view, load reports or queries. Callbacks only
update state; publishing happens in `step()`. Input from peers is never trusted: anything of the
wrong type, from an unknown host or under the wrong key is refused, counted and logged (on
`drd.bus` and `drd.daemon.rejects`: `drd start` rate-limits them, with the other `drd.daemon.logs.PEER_LOGGERS`).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drd.bus import DEFAULT_TIMEOUT, Bus, BusError, LoadReport, Message, Ping, Pong, Query, Reply, Sample
from drd.bus.base import RECONNECT_EACH_SECOND, BusWrapper, Declaration, Handler, Queryable
from drd.bus.messages import encode
from drd.cluster.instances import InstanceInfo
from drd.cluster.keys import ClusterKeys, cluster_of
from drd.daemon.controller import Controller
from drd.daemon.load import LoadSampler, live_robots
from drd.daemon.messages import (
    Announcement,
    ClusterEvent,
    ComponentsReply,
    DaemonStatus,
    HostInfo,
    HostsReply,
    Leaving,
    LiveReport,
    Lookup,
    TraderReply,
    TraderRequest,
    ViewRequest,
)
from drd.daemon.peers import REFUSED, diagnose
from drd.daemon.security import Transport, describe, transport
from drd.daemon.view import Change, ClusterView, HostState, runnable_components
from drd.errors import ConfigurationError
from drd.hosts import Cluster, Role
from drd.paging import by_position
from drd.runtime.clock import Clock
from drd.trader import TraderError, compile_query
from dsl.catalog import Catalog

if TYPE_CHECKING:  # only a controller with `ros2` robots imports it
    from drd.hw.safestop import StandbyLinks

#: Times a claim to this host is checked, a lease apart, before it is refused (`Daemon._check_claim`).
CLAIM_TRIES = 3
#: Kinds of rejected messages counted apart in `status`; the rest count as "other".
MAX_REJECTED_KINDS = 64

log = logging.getLogger("drd.daemon")
rejects = logging.getLogger("drd.daemon.rejects")


class RefusalsCounted(BusWrapper):
    """The bus a daemon's Creator and simulator serve on: a request their handler refuses (an error reply: an
    unknown op or component, a method off the simulator's allow-list, a world outside its folders) is counted in
    `rejected` and logged on `drd.daemon.rejects`, as the daemon's own refusals are (docs/security.md: "refused,
    counted and logged"; wire audit 10, D3: they were answered, and neither)."""

    def __init__(self, inner: Bus, reject: Callable[[str, str], None]) -> None:
        super().__init__(inner)
        self.reject = reject

    def serve(self, key_expr: str, handler: Handler) -> Queryable:
        def counted(query: Query) -> Message | Reply | None:
            answer = handler(query)
            if isinstance(answer, Reply) and answer.error is not None:
                self.reject(query.key, answer.error)
            return answer

        return self.inner.serve(key_expr, counted)

    def call(self, key: str, payload: Message | None = None, timeout: float = DEFAULT_TIMEOUT) -> Message:
        """The inner bus's own call (zenoh's has a faster path than `Bus.call` over `request_raw`): a Creator's
        `sim` drivers call a simulator on another host for every reading."""
        return self.inner.call(key, payload, timeout)

MAX_EVENTS = 1000
#: Seconds a view query waits for the daemon's lock before it reads without it.
BUSY_WAIT = 0.25
#: How long a daemon's start waits for the zero Twists it sends its `ros2` robots (`stop_robots`): a robot router
#: that does not answer holds the start up no longer (the thread goes on, logged).
START_STOP_WAIT = 2.0


@dataclass(frozen=True, slots=True)
class DaemonConfig:
    """Everything a daemon needs; `transport` defaults to the one `hosts.yaml` security asks for."""

    cluster: Cluster
    host: str
    catalog: Catalog
    transport: Transport | None = None
    load_period: float = 1.0
    steps_per_period: int = 4
    peer_grace: float = 3.0
    peer_recheck: float = 5.0
    journal: Path | None = None  # the controller's missions on disk (`drd.journal`); None: not kept
    #: component types this host does not run, with why (`drd.preflight.StartCheck`): not announced, so not placed
    unavailable: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.cluster.host(self.host)  # KeyError naming the known hosts
        if not (self.load_period > 0 and self.steps_per_period >= 1):
            raise ValueError("load_period must be positive and steps_per_period at least 1")

    @property
    def period(self) -> float:
        """The load period actually used: at most a third of the lease, or live hosts would look silent."""
        return min(self.load_period, self.cluster.lease / 3)

    @property
    def tick(self) -> float:
        """Seconds between two steps (0.25 s by default): a load report is at most this late, a silent host is seen
        down at most this long after its lease, and an idle daemon wakes this often (each wake-up costs the process
        about as much CPU as the step itself, so 20 a second were half of an idle daemon's CPU)."""
        return self.period / self.steps_per_period


def aligned_wait(wall: float, period: float, at_least: float = 0.0) -> float:
    """Seconds from `wall` to the next multiple of `period` on the wall clock, at least `at_least`.

    Every daemon steps and reports its load on the same wall-clock instants, so a router receives a fleet's reports
    together and passes them on in a few batches: each daemon then wakes a few times a period rather than once per
    host (docs/design.md "Load reports in step")."""
    wait = period - wall % period
    while wait < at_least:
        wait += period
    return wait


def config_digest(cluster: Cluster) -> str:
    """A digest of what the hosts file says (not of its text), to spot a host started with another file."""
    data = {"name": cluster.name, "lease": cluster.lease, "security": cluster.security.mode.value,
            "hosts": [asdict(h) for h in cluster.hosts]}
    return hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()


#: zenoh settings of a cluster's own links. No QoS: drd sets no priority, and a link with QoS keeps a queue per
#: priority that the router's tx thread goes over for each batch (idle router at 50 daemons: 0.96-0.99 % of a core
#: with it, 0.70 % without; docs/design.md "Load reports in step"). A ROS 2 session (`drd.bus.ros2`) keeps zenoh's.
#: One dialer per pair (`Transport.dials`): no link made on gossip (it would dial back), and a dialer tries again
#: each second (`RECONNECT_EACH_SECOND`).
CLUSTER_LINKS: dict[str, object] = {
    "transport/unicast/qos/enabled": False,
    "scouting/gossip/autoconnect": [],
    "connect/retry": RECONNECT_EACH_SECOND,
}


def open_bus(config: DaemonConfig, tr: Transport, stop: threading.Event | None = None) -> Bus:
    """This host's zenoh session: a peer listening on its endpoint and meshed with every other one (dialing those
    listed before it: `Transport.dials`), or, when the hosts file names routers, a router (listening, meshed with the
    other routers the same way) or a client of the routers. A client waits for a router (zenoh opens a client only
    once connected): started before its routers, it tries again each second, saying so once, each time with another
    router first, until one answers or `stop` is set."""
    from drd.bus.zenoh_bus import ZenohBus  # zenoh only when a real cluster is joined

    lease_ms = max(1000, int(config.cluster.lease * 2000))  # zenoh drops a silent link after twice our lease
    me = config.host
    mode = tr.zenoh_mode(me)
    listen = [tr.endpoints[me]] if tr.listens(me) else []
    options = {**CLUSTER_LINKS, **tr.options, "mode": mode,
               **({"connect/timeout_ms": ROUTER_WAIT_MS} if mode == "client" else {})}
    connect = list(tr.dials(me).values())
    said = False
    while True:
        try:
            return ZenohBus(listen=listen, connect=connect, lease_ms=lease_ms, options=options, name=me)
        except BusError:
            if mode != "client" or (stop is not None and stop.is_set()):
                raise
            if not said:
                log.info("waiting for a router to answer at %s", ", ".join(connect))
                said = True
            # zenoh spends the attempt's whole wait redialing the first endpoint: a client whose first router was
            # down never tried the second one (measured: 0 of 3 attempts opened). Another router first next time.
            connect = connect[1:] + connect[:1]


#: Milliseconds a client of the routers waits for one at each attempt to open its session.
ROUTER_WAIT_MS = 1000


def token_on_bus(config: DaemonConfig, tr: Transport, key: str, timeout: float = 1.0) -> bool:
    """Whether a host token `key` is on the cluster's bus, asked before this host's own session opens (which dials
    only some hosts: `Transport.dials`, so another daemon running as this host may be one nobody it dials is linked
    to yet). Asked as a zenoh client of the first host that answers: a peer or a router answers its client for
    every host it is linked to, which in a mesh is every host. Closed at once; it listens nowhere."""
    from drd.bus.zenoh_bus import ZenohBus

    me = config.host
    others = list(tr.others(me).values())
    if not others:
        return False
    options = {**{k: v for k, v in tr.options.items() if k != "access_control"}, "mode": "client",
               "connect/timeout_ms": ROUTER_WAIT_MS}
    try:
        probe = ZenohBus(connect=others, options=options, name=f"{me} (start)")
    except BusError:  # no host answers yet: nobody runs as this one among them
        return False
    try:
        return bool(probe.alive(key, timeout=timeout))
    finally:
        probe.close_within(PROBE_CLOSE)


#: Seconds a daemon's start waits for its probe session to close (a frozen peer holds zenoh's close for 10 s).
PROBE_CLOSE = 0.5


class HostTaken(ConfigurationError):
    """Another daemon already runs as this host in this cluster (seen on the bus): this one must not start."""


class Daemon:
    """One host's daemon. `run(stop)` serves until `stop` is set; `start`/`step`/`close` for tests."""

    def __init__(self, config: DaemonConfig, bus: Bus | None = None, *,
                 clock: Callable[[], float] = time.monotonic, wall: Callable[[], float] = time.time,
                 controller_clock: Clock | None = None) -> None:
        self.config = config
        self.cluster = config.cluster
        self.host = config.host
        self.keys = ClusterKeys(config.cluster.name)
        self.transport = config.transport or transport(config.cluster, daemon=True, host=config.host)
        self.clock, self.wall = clock, wall
        self.digest = config_digest(config.cluster)
        self.started = wall()
        self.view = ClusterView(config.cluster, config.host, digest=self.digest, now=clock(), tick=config.tick)
        self.events: deque[ClusterEvent] = deque(maxlen=MAX_EVENTS)
        self.rejected: Counter[str] = Counter()
        self.unreachable: dict[str, str] = {}
        self._suspects: dict[str, str] = {}  # host -> a "refused credentials" diagnosis seen once, not yet confirmed
        self.controller: Controller | None = None
        self.runner: Any = None  # drd.daemon.missions.MissionRunner, on the controller
        self.creator: Any = None  # drd.cluster.creator.Creator
        self.sim_service: Any = None  # drd.sim.service.SimulationService, on the simulator host
        self._bus = bus
        self._lock = threading.RLock()  # the view, the events, the announcements
        self._exec_lock = threading.RLock()  # the controller's executive (the mission loop holds it per cycle)
        self._declared: list[Declaration] = []
        self._token: Declaration | None = None
        self._sampler = LoadSampler(config.host)
        self._announce_due = True
        self._watching = False  # a thread is asking the robots' hosts to watch them (`_publish_live`)
        self._next_load = 0.0
        self._reannounce_until = 0.0  # after its controller was lost: announce with every load report until then
        self._losses_seen = 0  # the Creator's `losses` when last looked at
        self._next_peer_check = 0.0
        self._checking = False
        self._claim_next: tuple[int, float, bool] | None = None  # the latest claim to this host not checked yet
        self._claim_checking = False  # a thread checks claims
        self._standby: StandbyLinks | None = None  # of a controller with `ros2` robots
        self._all_reachable = False  # the last peer check found every peer (and said so)
        self._closed = False
        self._controller_clock = controller_clock
        self.stop_reason = "stopped"
        self._stop: threading.Event | None = None  # the event `run` serves until (set by a conflict too)
        self.election: Any = None  # drd.cluster.election.Election, on a controller host of a replicated store
        self._stepping_down = False

    @property
    def bus(self) -> Bus:
        if self._bus is None:
            raise RuntimeError("the daemon is not started")
        return self._bus

    @property
    def roles(self) -> list[str]:
        return [str(r) for r in self.cluster.host(self.host).roles]

    # -- lifetime --------------------------------------------------------------------------------

    def start(self) -> None:
        """Open the bus (unless given one) and declare every service; the token comes last."""
        keys, me = self.keys, self.host
        # before anything is declared: the first one stays in charge. A peer's or a router's own session dials only
        # some hosts (`Transport.dials`), so it asks first; a client of the routers sees every token through them
        if self._bus is None and self.transport.listens(me):
            taken = token_on_bus(self.config, self.transport, keys.host(me))
            self._bus = open_bus(self.config, self.transport, self._stop)
        else:
            if self._bus is None:
                self._bus = open_bus(self.config, self.transport, self._stop)
            taken = bool(self._bus.alive(keys.host(me), timeout=1.0))
        bus = self.bus
        if taken:
            raise HostTaken(f"another drd already runs as host {me} in cluster {self.cluster.name} (its token is on "
                            "the bus): host names are unique in a cluster, and one controller acts",
                            hint=f"stop that one first (drd stop --host {me} where it runs), or start this one as"
                                 " another host")
        stop_robots(self.cluster, me, f"host {me} starting", wait=START_STOP_WAIT)  # before it serves missions
        self._declared += [bus.subscribe(keys.loads, self._on_load), bus.subscribe(keys.announces, self._on_announce),
                           bus.subscribe(keys.lives, self._on_live)]
        self._serve(keys.ping(me), self._ping, Ping)
        self._serve(keys.status(me), self._status, ViewRequest, type(None))
        self._serve(keys.db(me, "hosts"), self._hosts, ViewRequest, type(None))
        self._serve(keys.db(me, "components"), self._components, ViewRequest, type(None))
        self._serve(keys.db(me, "lookup"), self._lookup, Lookup)
        self._serve(keys.db(me, "query"), self._query, TraderRequest)
        roles = self.cluster.host(me).roles
        refusing = RefusalsCounted(bus, self._reject)  # what the Creator and the simulator refuse is counted too
        if Role.SIMULATOR in roles:
            self.sim_service = self._simulator(refusing)
        from drd.cluster.creator import Creator

        self.creator = Creator(refusing, self.cluster, me, self.config.catalog,
                               sim_service=self.sim_service,
                               on_change=self._instances_changed, acting=self._acts_here)
        if Role.CONTROLLER in roles and self.cluster.store.replicated:
            self._campaign()  # a standby until etcd elects it (`_elected`)
        elif Role.CONTROLLER in roles:
            from drd.journal import SqliteJournal

            journal = SqliteJournal(self.config.journal, keep=self.cluster.history) if self.config.journal else None
            self._become_controller(bus, journal, self.started)  # its term: the start time it announces
        self._declared.append(bus.watch_tokens(keys.hosts, self._on_token, history=True))
        takes = Role.WORKER in roles or not any(Role.WORKER in h.roles for h in self.cluster.hosts)
        if takes and not self.creator.pool.wait_ready():  # up once a component can be placed here in milliseconds
            log.warning("the Creator's worker processes are not all ready yet: the first starts here may be slow")
        self.creator.watch_from_now()  # a slow start is no freeze
        self._token = bus.declare_token(keys.host(me))
        now = self.clock()
        self._next_peer_check = now + self.config.peer_grace
        log.info("drd %s started in cluster %s (roles %s, pid %d); load every %g s, lease %g s",
                 me, self.cluster.name, ", ".join(self.roles), os.getpid(), self.config.period, self.cluster.lease)
        log.info("bus: %s", describe(self.transport.mode, [self.transport.endpoints[me]]))
        self.step()

    def _acts_here(self) -> bool:
        """Whether this daemon runs the controller that acts now (an elected one asks its election, by its own clock:
        after a freeze past its etcd lease it no longer acts, and a standby took its missions)."""
        if self.controller is None:
            return False
        return self.election is None or self.election.acting()

    def _become_controller(self, bus: Bus, journal: Any, term: float | None) -> None:
        """Take the controller's services: the manager and the executive (`Controller`), the missions' runner with
        `journal` (which resumes the missions it holds), under `term` (None: its start time)."""
        from drd.daemon.missions import MissionRunner

        me = self.host
        if any(d.driver == "ros2" and d.type == "Drive" for d in self.cluster.devices) and self._standby is None:
            from drd.hw.safestop import StandbyLinks  # now, not when a host is lost (0.17 s: the robot moves meanwhile)

            self._standby = StandbyLinks()  # and its sessions to the robots' routers (ROS 2 audit 17, D4)
            self._standby.warm(self.cluster)
        with self._exec_lock:
            controller = Controller(bus, self.cluster, self.config.catalog, me, self._exec_lock,
                                    on_reject=self._reject, on_change=self._controller_change,
                                    clock=self._controller_clock, host_states=self.view.not_up)
            self.controller = controller
            self.runner = MissionRunner(bus, self.cluster, self.config.catalog, me, self._exec_lock,
                                        controller, controller.mission_clock, sim_service=self.sim_service,
                                        host_down=lambda h: self.view.state(h) is HostState.DOWN,
                                        host_views=self.view.host_views, journal=journal, term=term,
                                        frozen=self.frozen_since)

    # -- several controllers: an election through etcd (drd.cluster.election) --------------------------------------

    def _campaign(self) -> None:
        """Campaign for the controller's role through the cluster's etcd (`cluster.store`): a standby meanwhile."""
        from drd.cluster.election import Election, election_ttl
        from drd.etcd import Etcd

        ttl = election_ttl(self.cluster.lease)  # whole seconds, at least etcd's own minimum (the dry-run's too)
        self.election = Election(Etcd(self.cluster.store.etcd), self.cluster.name, self.host, ttl,
                                 on_elected=self._elected, on_fenced=self._fenced)
        self.election.start()
        log.info("standby controller: campaigning through etcd at %s (lease %d s)",
                 ", ".join(self.cluster.store.etcd), ttl)

    def _elected(self, term: int) -> None:
        """etcd elected this host (its thread): take the controller's services behind a fence that closes when the
        election says it no longer acts, and resume the missions of the replicated journal."""
        from drd.cluster.election import FencedBus
        from drd.journal import DeferredJournal, EtcdJournal, JournalError

        election = self.election
        assert election is not None
        started = self.clock()
        bus = FencedBus(self.bus, lambda: election.acting(term), f"controller {self.host} (term {term})")
        try:
            journal = DeferredJournal(EtcdJournal(election.etcd, self.cluster.name, term, leader=election.key,
                                                  keep=self.cluster.history, on_fenced=self._fenced,
                                                  acting=lambda: election.acting(term)))  # off the mission loop
            self._become_controller(bus, journal, float(term))
        except (JournalError, ValueError) as e:
            log.error("cannot act as the controller: %s", e)
            self.stop_reason = f"cannot act as the controller: {e}"
            if self._stop is not None:
                self._stop.set()
            return
        with self._lock:  # the hosts already up join the manager (later changes reach it through `_handle`)
            controller = self.controller
            if controller is not None:
                for rec in self.view.records.values():
                    if rec.name != self.host and rec.state is HostState.UP:
                        controller.host_up(rec.name)
            for rec in self.view.records.values():  # a host lost with the old controller: nobody stopped its robots
                if rec.name != self.host and rec.state is HostState.DOWN and rec.since is not None:
                    self._stop_robots_of(rec.name, f"down when controller {self.host} took over: {rec.reason}")
            self._announce_due = True  # the others learn that this host serves the executive now
            self._record("elected", self.host, f"the acting controller (term {term}), services up in"
                         f" {self.clock() - started:.2f} s")

    def _fenced(self, reason: str) -> None:
        """This controller lost the election (any thread): it already sends nothing (its fence); step down on a
        thread of our own (closing the mission loop joins it) and campaign again as a standby."""
        with self._lock:
            if self._stepping_down or self.controller is None or self._closed:
                return
            self._stepping_down = True
        threading.Thread(target=self._step_down, args=(reason,), name="drd-step-down", daemon=True).start()

    def _step_down(self, reason: str) -> None:
        runner, controller = self.runner, self.controller
        with self._lock:
            self.runner, self.controller = None, None
            self._announce_due = True
        try:
            if runner is not None:
                runner.close()
            with self._exec_lock:
                if controller is not None:
                    controller.close()
        except Exception:  # stepping down must finish: the fence already holds
            log.exception("stepping down")
        kept = getattr(runner, "bus", None)  # the FencedBus of its term
        self._record("fenced", self.host, f"stepped down, a standby again: {reason} (its fence kept"
                     f" {getattr(kept, 'dropped', 0)} messages from going out)")
        with self._lock:
            self._stepping_down = False
        if self.election is not None and not self._closed:
            self.election.standby()

    def run(self, stop: threading.Event, ready: Callable[[], object] | None = None) -> None:
        """Start, call `ready()`, then serve until `stop` is set; always closes."""
        self._stop = stop
        try:
            self.start()
            if ready is not None:
                ready()
            while not stop.wait(aligned_wait(self.wall(), self.config.tick)):
                self.step()
        finally:
            self.close()

    def step(self) -> None:
        """The periodic work: load reports (first: never behind the lock a mission loop may hold while a host is
        slow to answer, or the others would take this host for dead), silent hosts, the controller,
        announcements, peer checks."""
        now = self.clock()
        if now >= self._next_load - self.config.tick / 2:  # a wake-up a little early is on time
            self._next_load = now + aligned_wait(self.wall(), self.config.period, at_least=self.config.period / 2)
            self.bus.put(self.keys.load(self.host), self._sampler.sample(len(self._instances()), self.wall()))
            self._publish_live()
            if now < self._reannounce_until:
                self._announce_due = True
        if self.creator is not None:  # before anything it serves: a freeze of its own ends its grants
            self.creator.check_freeze()
            if self.creator.losses != self._losses_seen:  # its controller lost (a freeze noticed by any thread, a
                # token gone): its instances were retired, and the announcement saying so may have gone out before
                # its session was back, the list never to change again (cluster audit 14, D2: a dead instance
                # listed `running`): it is said again with each load report for two leases
                self._losses_seen = self.creator.losses
                self._reannounce_until = now + 2 * self.cluster.lease
        with self._lock:
            self._handle(self.view.tick(now))
            if self.controller is not None:
                self.controller.step()
            announce, self._announce_due = self._announce_due, False
        if announce:
            self.bus.put(self.keys.announce(self.host), self.announcement())
        if now >= self._next_peer_check and not self._checking:
            self._next_peer_check = now + self.config.peer_recheck
            self._check_peers()

    def frozen_since(self, t: float) -> float:
        """Seconds this daemon was frozen (SIGSTOP, a suspended machine, starved: its ticks stopped for longer than
        the lease) at some time after `t` (its monotonic clock), 0.0 if not. Read without the lock, from any thread:
        a mission loop whose call timed out across the freeze learns that the silence was its own, not the
        callee's (`ClusterView.frozen_since`)."""
        return self.view.frozen_since(t, self.clock())

    def close(self, reason: str | None = None) -> None:
        """Say goodbye, drop the token (peers see us leave at once), undeclare everything, close the bus."""
        if self._closed or self._bus is None:
            return
        self._closed = True
        runner = self.runner
        if runner is not None and runner.journal is not None:  # journaled as running, for the next start or the
            runner.suspend()  # standby: before the goodbye (no host lost meanwhile), its world's loop ends without
            # stopping them (an elected one's loop stopped them in words: "ended stopped", "the world is gone", while
            # the standby resumed them: cluster audit 17, D5)
        try:
            self.bus.put(self.keys.announce(self.host), Leaving(self.host, reason or self.stop_reason))
        except Exception:  # the bus may already be gone; leaving must go on
            log.debug("could not say goodbye", exc_info=True)
        if self._token is not None:
            self._token.close()
        if self.election is not None:  # its missions go to a standby as they are, not stopped by the loop's end
            runner = self.runner
            if runner is not None and runner.journal is not None:  # the last states queued, written while it acts
                runner.journal.flush(timeout=2.0)
            self.election.resign()
        if self.runner is not None:
            self.runner.close()  # joins the mission loop, which takes the lock
        if self._standby is not None:
            self._standby.close()
        with self._exec_lock:
            if self.controller is not None:
                self.controller.close()
        if self.election is not None:  # after the executive stopped: a standby takes over now, not at lease expiry
            self.election.close(revoke=True)
        for service in (self.creator, self.sim_service):
            if service is not None:
                service.close()
        for declaration in reversed(self._declared):
            declaration.close()
        self.bus.close()
        log.info("drd %s stopped", self.host)

    # -- what the daemon says about itself --------------------------------------------------------

    def _simulator(self, bus: Bus) -> Any:
        """The simulator host's `SimulationService`: the world served as ROS 2 robots too when hosts.yaml says so
        (docs/ros2.md); its robots start charged as hosts.yaml says."""
        serving = self.cluster.host(self.host).serving
        if serving.ros2:
            from drd.sim.ros2 import ServedSimulationService

            return ServedSimulationService(bus, self.cluster, listen=serving.listen, domain_id=serving.domain_id)
        from drd.sim.service import SimulationService, world_dirs
        from drd.sim.world import hosts_charges

        return SimulationService(bus, self.cluster.name, beside=world_dirs(self.cluster),
                                 charges=hosts_charges(self.cluster))

    def announcement(self) -> Announcement:
        me, keys = self.host, self.keys
        services = {f"{me}.db": f"{keys.host(me)}/db", f"{me}.status": keys.status(me)}
        if self.controller is not None:
            services |= {"rcm": f"{keys.root}/rcm", "executive": keys.executive,
                         "missions": f"{keys.root}/missions/run"}
        if self.sim_service is not None:
            services |= {"simulator": f"{keys.root}/sim"}
        services |= {f"{me}.creator": f"{keys.host(me)}/creator"}
        runnable = [name for name in runnable_components(self.cluster.host(me), self.config.catalog)
                    if name not in self.config.unavailable]
        return Announcement(me, self.cluster.name, os.getpid(), self.started, self.roles, runnable,
                            self._instances(), services, self.digest)

    def status(self) -> DaemonStatus:
        return DaemonStatus(self.host, self.cluster.name, os.getpid(), self.started, self.wall() - self.started,
                            self.roles, self._sampler.rss(), self.config.period, self.cluster.lease,
                            self.bus.stats.as_dict(), dict(self.rejected), dict(self.unreachable))

    @contextmanager
    def _briefly(self) -> Iterator[None]:
        """The lock for a read of the view, if it comes within `BUSY_WAIT` seconds; else the read goes on without
        it (it may see a host's record mid-update, never a broken reply): a view query answers at once even while
        the mission loop holds the lock waiting on a frozen host."""
        got = self._lock.acquire(timeout=BUSY_WAIT)
        try:
            yield
        finally:
            if got:
                self._lock.release()

    def hosts(self, events: int = 50) -> HostsReply:
        now = self.clock()
        infos = []
        with self._briefly():
            for rec in self.view.records.values():
                state, ann = self.view.shown_state(rec.name), rec.announcement
                # a host down runs nothing: its last load report is not its load (cluster audit 26, D2: `instances`
                # 1 on a killed host whose instance ran elsewhere); an unresponsive one keeps it, with its age
                report = rec.report if state != "down" else None
                infos.append(HostInfo(
                    rec.name, state, None if rec.since is None else self._to_wall(rec.since),
                    rec.reason,
                    self.transport.endpoints.get(rec.name, rec.config.endpoint), [str(r) for r in rec.config.roles],
                    report.cpu if report else None, report.memory if report else None,
                    report.load1 if report else None, report.instances if report else 0,
                    None if rec.heard is None else now - rec.heard,
                    [d.id for d in rec.config.devices], [r.id for r in rec.config.robots],
                    ann.pid if ann else None))
            recent = list(self.events)[-events:] if events > 0 else []
        return HostsReply(self.cluster.name, self.host, self.wall(), infos, recent)

    def components(self, after: int = 0, count: int = 0) -> ComponentsReply:
        """A page of the Component Database (`drd.paging`): the instances, then the services, after `after`."""
        with self._briefly():
            whole = ComponentsReply(self.cluster.name, self.host, self.view.runnable(self.config.catalog),
                                    self.view.instances(), self.view.services())
        return components_page(whole, after, count)

    # -- bus callbacks (zenoh threads) -----------------------------------------------------------

    def _on_token(self, key: str, alive: bool) -> None:
        found = cluster_of(key)
        if found is None or found[0] != self.cluster.name:
            self._reject(key, "not a host token of this cluster")
            return
        self._apply(lambda now: self.view.token(found[1], alive, now))

    def _on_load(self, sample: Sample) -> None:
        report = sample.payload
        if not isinstance(report, LoadReport):
            self._reject(sample.key, f"expected a drd.load, got a {type(report).TYPE}")
            return
        changes = self._apply(lambda now: self.view.load(report, now, _host_of(sample.key)))
        controller = self.controller  # (None once it resigns, on another thread)
        if controller is not None and not any(c.kind == "rejected" for c in changes):
            controller.heard(report.host)  # a host a timed-out call suspected answers again

    def _on_live(self, sample: Sample) -> None:
        report = sample.payload
        if not isinstance(report, LiveReport):
            self._reject(sample.key, f"expected a drd.daemon.live, got a {type(report).TYPE}")
            return
        self._apply(lambda now: self.view.live_report(report, now, _host_of(sample.key)))

    def _publish_live(self) -> None:
        """On the acting controller, with the load report: the robots' live properties (`live_robots`), and while a
        world runs every robot watched, so its host sends its pose and battery with its replies (once per world)."""
        controller, runner = self.controller, self.runner
        if controller is None or runner is None:
            return
        telemetry = runner.telemetry
        unwatched = [r.id for r in self.cluster.robots
                     if r.host and r.id not in telemetry.wanted.get(r.host, ()) and runner.world is not None]
        if unwatched and not self._watching:
            self._watching = True
            threading.Thread(target=self._watch, args=(telemetry, unwatched), name="drd-live-watch",
                             daemon=True).start()
        try:
            latest = dict(telemetry.latest)
        except RuntimeError:  # a reply is being delivered right now: the next report has it
            latest = {}
        robots = live_robots(self.cluster.robots, controller.executive.pool.properties, latest)
        self.bus.put(self.keys.live(self.host), LiveReport(self.host, self.wall(), robots))

    def _watch(self, telemetry: Any, robots: list[str]) -> None:
        """Read each robot once as an expression would (its first read asks its host to watch it), under the
        executive's lock as the mission loop reads it; off the daemon's thread (each first read is a round trip)."""
        try:
            with self._exec_lock:
                for robot in robots:
                    telemetry(robot)
        except Exception:  # a host that does not answer now is asked again at the next report
            log.debug("watching the robots for their live properties", exc_info=True)
        finally:
            self._watching = False

    def _on_announce(self, sample: Sample) -> None:
        msg, host = sample.payload, _host_of(sample.key)
        if isinstance(msg, Announcement):
            # another daemon as this host announces under this host's key: one that names this host under its own
            # key is a peer faking it (security audit D1: a worker's own credentials stopped the controller)
            if msg.host == self.host and host == self.host and (msg.pid, msg.started) != (os.getpid(), self.started):
                later = (self.started, os.getpid()) > (msg.started, msg.pid)  # the later one gives way, if it is one
                if not later:  # the later one may not have heard us (we announce to newcomers only): tell it
                    with self._lock:
                        self._announce_due = True
                self._check_claim(msg.pid, msg.started, stops=later)
                return
            self._apply(lambda now: self.view.announce(msg, now, host))
        elif isinstance(msg, Leaving) and msg.host == host:
            self._apply(lambda now: self.view.leaving(msg.host, msg.reason, now))
        else:
            self._reject(sample.key, f"expected a drd.daemon.announce or a matching goodbye, got a {type(msg).TYPE}")

    def _check_claim(self, pid: int, started: float, stops: bool) -> None:
        """Another drd announced itself as this host (two daemons met after both started): once it answers a status
        query on this host's key as that daemon, a conflict is recorded, and the one started later (`stops`) stops.
        An announcement alone, forged or replayed (one from a daemon gone since), changes nothing: refused and logged
        (wire audit 17, D1). One thread checks the latest claim at a time, asking up to `CLAIM_TRIES` times a lease
        apart (a daemon slow to answer is still found; a flood of claims costs one query at a time, not a thread
        each: review); a subscriber's callback must not wait on a query."""
        with self._lock:
            self._claim_next = (pid, started, stops)
            if self._claim_checking:
                return
            self._claim_checking = True
        threading.Thread(target=self._check_claims, name="drd-claim-check", daemon=True).start()

    def _check_claims(self) -> None:
        while True:
            with self._lock:
                claim, self._claim_next = self._claim_next, None
                if claim is None or self._closed:
                    self._claim_checking = False
                    return
            try:
                self._check_one_claim(*claim)
            except Exception:  # never leave the checking flag set: the next claim would go unchecked
                log.exception("checking a claim to host %s", self.host)

    def _check_one_claim(self, pid: int, started: float, stops: bool) -> None:
        for attempt in range(CLAIM_TRIES):
            if attempt:
                time.sleep(self.cluster.lease)
            if self._closed:
                return
            try:
                replies = self.bus.request(self.keys.status(self.host), timeout=min(2.0, self.cluster.lease))
            except BusError:  # closing meanwhile
                return
            if any(isinstance(r.payload, DaemonStatus) and r.payload.host == self.host
                   and (r.payload.pid, r.payload.started) == (pid, started) for r in replies):
                break
        else:
            self._reject(self.keys.announce(self.host), f"an announcement of another drd as host {self.host} that no"
                         f" daemon answers for: ignored (pid {pid})")
            return
        with self._lock:
            self._record("conflict", self.host, f"another drd (pid {pid}) runs as host {self.host}; host names must "
                         "be unique in the cluster; " + ("this one, started later, stops" if stops else
                                                         "the other, started later, stops"))
        if stops and self._stop is not None:
            self.stop_reason = f"conflict: another drd (pid {pid}) runs as host {self.host}"
            self._stop.set()

    def _apply(self, update: Callable[[float], list[Change]]) -> list[Change]:
        with self._lock:
            changes = update(self.clock())
            self._handle(changes)
        return changes

    def _handle(self, changes: list[Change]) -> None:
        """Record, log and act on what the view reports (called with the lock held)."""
        for change in changes:
            if change.kind == "rejected":
                self._reject(change.host, change.detail)
                continue
            self._record(change.kind, change.host, change.detail, change.at)
            if change.kind == HostState.UP:
                self.unreachable.pop(change.host, None)
                self._suspects.pop(change.host, None)
                self._announce_due = True  # a newcomer learns about us (and whoever came back)
                if self.controller is not None:
                    self.controller.host_up(change.host)
                if self.runner is not None:
                    self.runner.host_back(change.host)
            elif change.kind == HostState.DOWN and self.controller is not None:
                self.controller.host_down(change.host)
                self._stop_robots_of(change.host, change.detail)
            elif change.kind == HostState.DOWN and self.creator is not None and self._acting_controller(change.host):
                self.creator.controller_lost(f"controller {change.host} lost ({change.detail})")

    def _stop_robots_of(self, host: str, detail: str) -> None:
        """The controller saw `host` go down: its daemon's watchdogs may have died with it, so a zero Twist goes to
        its `ros2` robots from here, on a thread (never the loop's time), unless it comes back meanwhile, and its
        simulated robots stop in the running world (`MissionRunner.halt_host`)."""
        stop_robots(self.cluster, host, f"host {host} down ({detail}), stopped by controller {self.host}",
                    still=lambda: self.view.state(host) is HostState.DOWN, standby=self._standby)
        if self.runner is not None:  # its simulated robots: in the running world
            self.runner.halt_host(host)

    def _acting_controller(self, host: str) -> bool:
        """Whether `host` is the controller that acts: the one of hosts.yaml, or with several (a replicated store)
        the one whose last announcement offered the executive (a standby's loss stops no robot)."""
        if not self.cluster.store.replicated:
            return host == self.cluster.controller.name
        rec = self.view.records.get(host)
        return rec is not None and rec.announcement is not None and "executive" in rec.announcement.services

    def _controller_change(self, kind: str, host: str, detail: str) -> None:
        """The controller's news: recorded. A host whose resources left the manager keeps its robots in the running
        world, stopped where `halt_host` stopped them when it went down (records audit 18, #1: they left it, and a
        Ranger drove through where one stood); they are its resources again when it comes back."""
        self._record(kind, host, detail)

    def _record(self, kind: str, host: str, detail: str, at: float | None = None) -> None:
        wall = self.wall() if at is None else self._to_wall(at)
        self.events.append(ClusterEvent(wall, kind, host, detail))
        level = logging.WARNING if kind in ("down", "config-mismatch", "conflict", "frozen") else logging.INFO
        log.log(level, "host %s %s: %s", host, kind, detail)

    def _reject(self, where: str, reason: str) -> None:
        kind = reason.split(":", 1)[0][:80]
        with self._lock:  # bounded, whatever a peer varies in what it sends (review: 14,000 kinds outgrew `status`)
            if kind not in self.rejected and len(self.rejected) >= MAX_REJECTED_KINDS - 1:  # and "other"
                kind = "other"
            self.rejected[kind] += 1
        rejects.warning("rejected a message on %s: %s", where, reason)

    # -- queryables ------------------------------------------------------------------------------

    def _serve(self, key: str, handler: Callable[[Query], Message | Reply], *accepts: type) -> None:
        """Serve `key`; a payload that is not one of `accepts` is refused, counted and logged."""
        names = " or ".join("no payload" if t is type(None) else getattr(t, "TYPE", t.__name__) for t in accepts)

        def guarded(query: Query) -> Message | Reply:
            if not isinstance(query.payload, accepts):
                got = "no payload" if query.payload is None else type(query.payload).TYPE
                reason = f"expected {names}, got {got}"
                self._reject(query.key, reason)
                return query.error(reason)
            return handler(query)

        self._declared.append(self.bus.serve(key, guarded))

    def _ping(self, query: Query) -> Message:
        assert isinstance(query.payload, Ping)
        return Pong(query.payload.nonce, self.host)

    def _status(self, query: Query) -> Message:
        return self.status()

    def _hosts(self, query: Query) -> Message:
        events = query.payload.events if isinstance(query.payload, ViewRequest) else 50
        return self.hosts(max(0, min(events, MAX_EVENTS)))

    def _components(self, query: Query) -> Message:
        asked = query.payload if isinstance(query.payload, ViewRequest) else ViewRequest()
        return self.components(asked.after, asked.count)

    def _lookup(self, query: Query) -> Message | Reply:
        assert isinstance(query.payload, Lookup)
        name = query.payload.name
        with self._lock:
            found = self.view.lookup(name)
            known = sorted({i.name for i in self.view.instances() + self.view.services()})
        if found is None:
            return query.error(f"no instance or service called {name!r} (known: {', '.join(known) or 'none'})")
        return found

    def _query(self, query: Query) -> Message | Reply:
        assert isinstance(query.payload, TraderRequest)
        text = query.payload.query
        try:
            compiled = compile_query(text, self.config.catalog)
        except TraderError as e:
            return query.error(e.render(text))
        with self._lock:
            offers = self.view.offers(self.clock())
        found = compiled.run(offers, query.payload.seed)
        page, nxt = by_position(found, query.payload.after, query.payload.count,
                                lambda o: len(json.dumps(_offer_dict(o.id, o.type, o.host, o.properties, o.live),
                                                         default=str)))
        return TraderReply(text, [_offer_dict(o.id, o.type, o.host, o.properties, o.live) for o in page], nxt,
                           self.host)

    # -- helpers ---------------------------------------------------------------------------------

    def _instances(self) -> list[InstanceInfo]:
        """The Creator's instances of the current mission (not terminated), as the Component Database lists them."""
        return self.creator.instance_infos() if self.creator is not None else []

    def _instances_changed(self) -> None:
        """The Creator's hook (its thread, its lock held): announce at the next tick. No daemon lock here: the
        mission loop holds it while it waits for this very Creator over the bus."""
        self._announce_due = True

    def _to_wall(self, at: float) -> float:
        return self.wall() - (self.clock() - at)

    def _check_peers(self) -> None:
        """In a thread of its own (a probe may take a while): name the peers we cannot see, and why."""
        with self._lock:
            down = {h.name: h.endpoint for h in self.cluster.hosts
                    if h.name != self.host and self.view.state(h.name) is HostState.DOWN
                    and self.transport.listens(h.name)}  # a client of the routers has no endpoint to probe
            silent = {h for h in down if self.view.records[h].silent}  # frozen or cut off: not a credentials issue
        if not down:
            if not self.unreachable and not self._all_reachable:  # said once, not at every check
                self._all_reachable = True
                log.info("all %d peers reachable", len(self.cluster.hosts) - 1)
            return
        self._all_reachable = False
        down = {h: self.transport.endpoints.get(h, e) for h, e in down.items()}
        self._checking = True

        def check() -> None:
            try:
                found = diagnose(down, silent=silent)
                with self._lock:
                    for host, why in found.items():
                        if self.view.state(host) is not HostState.DOWN or self.unreachable.get(host) == why:
                            continue
                        if why.endswith(REFUSED) and self._suspects.get(host) != why:
                            # a peer still starting accepts connections before its session: confirm next check
                            self._suspects[host] = why
                            continue
                        self._suspects.pop(host, None)
                        self.unreachable[host] = why
                        log.warning("peer %s unreachable: %s", host, why)
            finally:
                self._checking = False

        threading.Thread(target=check, name="drd-peer-check", daemon=True).start()


def stop_robots(cluster: Cluster, host: str, why: str, *, still: Callable[[], bool] = lambda: True,
                wait: float = 0.0, standby: Any = None) -> None:
    """A zero Twist to each `ros2` Drive of `host`'s robots (`drd.hw.safestop`), best effort, on a thread; waits up
    to `wait` s for it. Nothing at all (not even an import) for a host with none."""
    if not any(d.driver == "ros2" and d.type == "Drive" for d in cluster.host(host).devices):
        return

    def send() -> None:
        from drd.hw.safestop import stop_host_robots

        try:
            stop_host_robots(cluster, host, why, still=still, wait=wait, standby=standby)
        except Exception:  # best effort: a stop that cannot be sent must not take the daemon down
            log.exception("zero Twists to host %s's robots", host)

    thread = threading.Thread(target=send, name=f"drd stop {host}'s robots", daemon=True)
    thread.start()
    thread.join(wait)
    if wait > 0 and thread.is_alive():
        log.warning("the zero Twists to host %s's robots are not all sent after %g s: still trying", host, wait)


def _host_of(key: str) -> str | None:
    parts = key.split("/")
    return parts[3] if len(parts) > 3 else None


def components_page(whole: ComponentsReply, after: int = 0, count: int = 0) -> ComponentsReply:
    """A page of `whole` (`drd.paging.by_position`): one cursor over its instances, then its services. Pure."""
    cut = max(0, len(whole.instances) - after)  # how many of the page's first items are instances
    page, nxt = by_position([*whole.instances, *whole.services], after, count, lambda i: len(encode(i)))
    return ComponentsReply(whole.cluster, whole.answered_by, whole.types, page[:cut], page[cut:], nxt)


def _offer_dict(oid: str, type_: str, host: Any, properties: Any, live: Any) -> dict[str, Any]:
    facts = dict(host)
    load = facts.get("load")
    return {"id": oid, "type": type_, "host": facts.get("name"),
            "load": load if isinstance(load, float) and load == load else None,
            "properties": dict(properties), "live": {k: round(v, 3) for k, v in live.items()}}
