"""Components that run on another host: `RemoteComponent`, the executive's proxy, and its wire messages.

The executive steps a `RemoteComponent` exactly like a local one. It works out, at each `start`, which host
owns the devices its needs are bound to (`ranger1.drive` -> `ranger1`, from its context's bindings) and sends
each lifecycle call (`start`, `step`, `suspend`, `resume`, `terminate`) to that host's Creator
(`drd.cluster.creator`) as a `ComponentCall`. A call carries what the component may read of the mission: its
parameters, the unit bound to each need with the epoch it is bound at (None once unbound: the gate on the
device's host then refuses its commands), the inputs the mission bound (shared data such as a DoorLog,
siblings' outputs). Every message to a host first carries the gate operations queued for it
(`drd.cluster.gates.RemoteGates`). The `ComponentReply` brings back its status, outputs, the events it
emitted, its log lines, the shared data as it left it, its changes to the Static Dependency Database and what
the gates there recorded; the proxy applies them to the local context, so the interpreter sees what a local
component would have done.

A component with no device needs is *movable*. With a placer (`ComponentRouter.place`, the Load Balancer's
policy over the hosts that are up, `drd.placement`), its `start` goes to the host the policy picks; a host that
does not register it within `START_TIMEOUT` (every `start` may take that long: a first start on a host may
load the component's module), or whose start fails, is excluded with its reason and the next best is tried,
until one starts it or the policy says why none can (a host that does not offer the type is never picked).
When its host is lost later, the instance is started again on another host before its next call, restored
from the last snapshot its host sent (`Component.snapshot`, which comes back with the replies when it
changed): the mission sees the same component go on (it gets its parameters and inputs again with every
call). `migrate` moves a running one on purpose (`missionctl migrate`, `drd.daemon.migrate`). Without a
placer (the router of a test), a movable component runs right here, in the controller (`local`).

A component bound to devices runs on the host that owns them, and only there: when that host does not answer
within `timeout` (or the daemon already saw it go down), the call raises at once and the interpreter fails just
that state.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from drd.bus import Bus, BusError, Message, RemoteError, message
from drd.cluster.gates import GateUpdate, RemoteGates, deliver, take_pending
from drd.errors import ComponentFailure, host_down_reason
from drd.runtime.component import Component, Context, Status, step_status
from drd.runtime.constraints import Breach
from drd.runtime.emits import EmitError
from drd.runtime.records import Record, plain


@message("drd.component.call", 6)
class ComponentCall(Message):
    """One lifecycle call for the instance `path` of mission `mission` (see the module docstring).

    `bindings`: need -> [unit id, robot, part] (robot and part "" unless bound through a robot's part);
    `epochs`: need -> the epoch it is bound at (None: unbound); `rank`: [-priority, declaration order], for the
    host's per-cycle arbitration of actuator commands; `sim_time`/`sim_version`: the simulation's clock;
    `gates`: the gate operations for this host, applied before the call (`drd.cluster.gates.GateUpdate`);
    `retire` (no path) ends mission `mission` on that host: its instances and processes go; `restore`, on a
    start: `[state]`, the instance's state to go on from (`Component.restore`; state None: it was lost); a
    `terminate` whose status is `moved` brings back the instance's snapshot and drops it there. `now` is on the
    executive's clock (records, halts), `origin` when the world began on it: the component sees `now - origin`."""

    op: str
    mission: str
    path: str
    component: str = ""
    world: str = ""
    params: dict[str, Any] | None = None
    bindings: dict[str, list[str]] | None = None
    epochs: dict[str, int | None] | None = None
    rank: list[int] | None = None
    now: float = 0.0
    sim_time: float = -1.0
    sim_version: int = -1
    shared: dict[str, Any] | None = None
    inputs: dict[str, Any] | None = None  # the component's inputs that are not shared data (siblings' outputs)
    status: str = ""
    shared_ids: dict[str, str] | None = None
    gates: list[list[Any]] | None = None
    generation: int = 0  # the world's reset count: a new one means new drivers on the device's host
    term: float = 0.0  # when the calling controller started: a host refuses calls of a controller older than one
    #                    it has heard (one revived after another took over must not act)
    restore: list[Any] | None = None
    origin: float = 0.0


@message("drd.component.reply", 5)
class ComponentReply(Message):
    """What the call did: `status` (after a step), outputs, events `[name, fields, where]` (`where`: the line of the
    component's emit, for a refusal), log lines, shared data,
    dependency changes `[resource, key, value]`, and `error` if the component raised (the state fails);
    `records`: what the host's gates recorded meanwhile (`drd.cluster.gates.wire_record`); `snapshot`:
    `[state]` when the instance's snapshot changed (after its start, every few steps, when it is moved); `lost`:
    the host runs no such instance (it retired it, e.g. when it lost its controller): a movable one is placed again;
    `raised`: the error is the component's own code raising in the call, which another host would run alike (a
    start that raised is not tried elsewhere)."""

    status: str = ""
    outputs: dict[str, Any] | None = None
    events: list[list[Any]] | None = None
    logs: list[str] | None = None
    shared: dict[str, Any] | None = None
    dependencies: list[list[Any]] | None = None
    error: str = ""
    records: list[dict[str, Any]] | None = None
    snapshot: list[Any] | None = None
    lost: bool = False
    raised: bool = False


@message("drd.component.batch", 3)
class ComponentBatch(Message):
    """The `step` calls of one control cycle for one host, in the interpreter's order (see `ComponentRouter.step`).

    The Creator runs them in turn and stops after a step that emitted an event, changed the Static
    Dependency Database or failed to run: the controller must react to that before the next step (an event
    may exit the components that come later), so those are stepped again by a later call. `shared_ids` of
    each call name the shared dicts that are one object on the controller, so a later step of the batch
    sees what an earlier one left in them, as it would over single calls.

    `sim_step` (seconds), on a batch to the simulator host: step the simulation by that much before the calls
    (the cycle's step, carried by its first batch: one round trip less per cycle)."""

    calls: list[ComponentCall]
    sim_step: float = 0.0
    gates: list[list[Any]] | None = None


@message("drd.component.batch-reply", 3)
class ComponentBatchReply(Message):
    """One reply per call that ran, in order (a prefix of the batch's calls); the simulation's time and version
    after the step, when the batch carried one; what the host's gates recorded meanwhile."""

    replies: list[ComponentReply]
    sim_time: float = -1.0
    sim_version: int = -1
    records: list[dict[str, Any]] | None = None


class ComponentError(ComponentFailure):
    """The remote component raised, or its host did not answer: the state fails with this message."""

    said = True


class HostDown(ComponentError):
    """The host of the call is down or did not answer: a movable component is placed again elsewhere."""


class ComponentRaised(ComponentError):
    """The component's own code raised in the call: its state fails, as in process; a start is not tried on
    another host, which would run the same code again (users audit 22, #3)."""


class InstanceLost(ComponentError):
    """The host answered that it runs no such instance (it retired it, e.g. after it lost its controller for a
    while): a movable component is placed again from its last snapshot, as after a host loss."""


class ControllerFrozen(ComponentError):
    """The call timed out because this controller itself was frozen (SIGSTOP, a suspended machine) for longer than
    the lease: the callee did nothing wrong (its host stopped its robots and retired the instances when its
    controller went silent), so it is neither marked gone nor placed around."""


def frozen_reason(away: float) -> str:
    """Why a mission cannot go on after its controller was frozen `away` seconds, past the lease: one text whether a
    call timed out across the freeze (`ControllerFrozen`, said as it is) or the mission loop stops the missions
    first (CI saw the call's text without the `ControllerFrozen:` the docs give)."""
    return (f"ControllerFrozen: this controller was frozen for {away:.1f} s, longer than the lease: its hosts stopped"
            " the robots and retired the mission's instances meanwhile")


#: Seconds a Creator may take to register a started instance (its first start on a host may load its module).
START_TIMEOUT = 5.0


@dataclass
class RouterStats:
    calls: int = 0
    seconds: float = 0.0
    by_host: dict[str, int] = field(default_factory=dict)
    slowest: float = 0.0

    def add(self, host: str, seconds: float) -> None:
        self.calls += 1
        self.seconds += seconds
        self.slowest = max(self.slowest, seconds)
        self.by_host[host] = self.by_host.get(host, 0) + 1

    def as_dict(self) -> dict[str, Any]:
        mean = self.seconds / self.calls if self.calls else 0.0
        return {"calls": self.calls, "mean_ms": round(mean * 1000, 3), "slowest_ms": round(self.slowest * 1000, 3),
                "by_host": dict(self.by_host)}


class SimCycle:
    """The lockstep of one world, shared by the routers of every mission running in it: the simulation's time and
    version, and the cycle's step, made once before the cycle's first call to another host (carried by a batch
    to the simulator host `simulator`, else made alone by `step_sim(dt)`); `sim_error` when the simulator did not
    answer a step (the missions must stop)."""

    def __init__(self) -> None:
        self.sim_time = -1.0
        self.sim_version = -1
        self.simulator = ""
        self.step_sim: Callable[[float], Any] | None = None
        self.pending_step = 0.0
        self.sim_error: Exception | None = None
        self.steps_alone = RouterStats()
        self.origin = 0.0  # when the world began on the executive's clock (`drd.daemon.missions.SimTimeClock`)


class ComponentRouter:
    """What every `RemoteComponent` of one mission shares: where resources live, the bus, the sim clock.

    `active()` gives the mission's components in the order the interpreter steps them in this cycle (as
    `drd.runtime.hosting.ComponentHost.active` does: (node, component) pairs), for batching;
    `local` builds components that run in this process (those with no device needs);
    `gates` queues the gate operations for each host, `records` takes (mission, record) of what gates send back."""

    def __init__(self, bus: Bus, cluster: str, resource_hosts: Mapping[str, str], me: str, *,
                 local: Mapping[str, Callable[[], Component]], mission: str, world: str,
                 active: Callable[[], Iterable[tuple[Any, Component]]] = lambda: (),
                 timeout: float = 1.0, dead: Callable[[str], bool] = lambda h: False, catalog: Any = None,
                 place: Callable[[str, Mapping[str, Any], Mapping[str, str]], str] | None = None,
                 gates: RemoteGates | None = None,
                 records: Callable[[str, Record | Breach], None] = lambda mission, record: None,
                 cycle: SimCycle | None = None, generation: int = 0, term: float = 0.0,
                 frozen: Callable[[float], float] = lambda since: 0.0,
                 on_down: Callable[[str], None] = lambda host: None, clock: Callable[[], float] | None = None,
                 ended: Callable[[str, str], None] = lambda host, component: None):
        """`frozen(since)`: seconds this controller's daemon was frozen after `since` (`time.monotonic()`), 0.0 if
        not (`Daemon.frozen_since`); `on_down(host)`: told when a call fails because `host` is down or did not
        answer, before the failure is raised (the manager takes its resources offline first); `clock`: the
        executive's, which a call's `now` is on (components see the world's time: `now - origin`, the cycle's);
        `ended(host, component)`: a placed instance on `host` ended or moved away (it no longer counts there)."""
        self.ended = ended
        self.bus = bus
        self.cluster = cluster
        self.frozen = frozen
        self.on_down = on_down
        self.clock = clock
        self.resource_hosts = dict(resource_hosts)
        self.me = me
        self.active = active
        self.gates = gates
        self.records = records
        self.local = local
        self.mission = mission
        self.world = world
        self.timeout = timeout
        self.dead = dead
        self.catalog = catalog
        self.place = place  # (component, params, hosts to avoid -> why) -> host, or ComponentError saying why none
        self.placed: deque[tuple[str, str, str]] = deque(maxlen=200)  # (path, host, "placed" or "re-placed")
        self.gone: set[str] = set()
        self.cycle = cycle if cycle is not None else SimCycle()
        self.generation = generation
        self.term = term
        self.stats = RouterStats()
        self.batches = RouterStats()  # one per host per cycle when nothing interrupts the cycle
        self._ready: dict[int, tuple[float, ComponentReply]] = {}  # id(component) -> (now, its step's reply)

    # The world's clock and the cycle's pending step live in the `SimCycle` every mission in the world shares.
    @property
    def sim_time(self) -> float:
        return self.cycle.sim_time

    @sim_time.setter
    def sim_time(self, value: float) -> None:
        self.cycle.sim_time = value

    @property
    def sim_version(self) -> int:
        return self.cycle.sim_version

    @sim_version.setter
    def sim_version(self, value: int) -> None:
        self.cycle.sim_version = value

    @property
    def simulator(self) -> str:
        return self.cycle.simulator

    @simulator.setter
    def simulator(self, value: str) -> None:
        self.cycle.simulator = value

    @property
    def step_sim(self) -> Callable[[float], Any] | None:
        return self.cycle.step_sim

    @step_sim.setter
    def step_sim(self, value: Callable[[float], Any] | None) -> None:
        self.cycle.step_sim = value

    @property
    def pending_step(self) -> float:
        return self.cycle.pending_step

    @pending_step.setter
    def pending_step(self, value: float) -> None:
        self.cycle.pending_step = value

    @property
    def sim_error(self) -> Exception | None:
        return self.cycle.sim_error

    @sim_error.setter
    def sim_error(self, value: Exception | None) -> None:
        self.cycle.sim_error = value

    @property
    def steps_alone(self) -> RouterStats:
        return self.cycle.steps_alone

    def is_down(self, host: str) -> bool:
        return host in self.gone or self.dead(host)

    def back(self, host: str) -> None:
        """`host` is up again (the daemon saw it report after it was down): it is no longer taken for gone in this
        mission, so its instances can be retired and moved (recovery audit D1: a host frozen past its lease stayed
        gone for the mission's life, its instances and processes left running)."""
        self.gone.discard(host)

    def step_first(self, host: str | None) -> float:
        """Make the cycle's pending simulation step before a call to `host`: returns the seconds a batch to the
        simulator host carries (it steps the world first), else 0.0 once the step is made. ComponentError if
        the simulator did not answer (`sim_error` says so to the mission loop)."""
        dt, self.pending_step = self.pending_step, 0.0
        if not dt:
            return 0.0
        if host and host == self.simulator and not self.is_down(host):
            return dt
        assert self.step_sim is not None, "a pending step needs step_sim"
        t0 = time.perf_counter()
        try:
            reply = self.step_sim(dt)
        except Exception as e:
            self.sim_error = e
            sim = self.simulator
            raise ComponentError(self.world_gone() or  # the first words a leaf fails with name the host
                                 f"the simulator{f' on host {sim}' if sim else ''} did not step: {e}") from None
        self.steps_alone.add("simulator", time.perf_counter() - t0)
        self.sim_time, self.sim_version = reply.time, reply.version
        return 0.0

    def world_gone(self) -> str | None:
        """Why every component of this world fails, in the dry-run's words, when the simulator's host is seen down
        (or taken for gone by this mission); None otherwise."""
        sim = self.simulator
        return host_down_reason(sim, simulator=True) if sim and self.is_down(sim) else None

    def implements(self, component: str) -> bool:
        """Whether an instance of `component` can be started: with a placer and a catalog, its manifest names an
        entry point (the hosts import it; one that cannot does not offer it, `drd.preflight.StartCheck`), without
        them its class imports here, where it would run."""
        if self.place is not None and self.catalog is not None:
            ct = self.catalog.get(component)
            return ct is not None and bool(ct.entry_point)
        return component in self.local

    def param_names(self, component: str) -> set[str] | None:
        """The parameters the manifest declares (what a call may carry), or None if unknown."""
        ct = self.catalog.get(component) if self.catalog is not None else None
        return None if ct is None else {p.name for p in ct.params}

    def portable(self, component: str) -> bool:
        """Whether the manifest says `movable: true`: the component's state may be given back on another host (a
        component it does not know: yes, as before manifests said it)."""
        ct = self.catalog.get(component) if self.catalog is not None else None
        return ct is None or bool(ct.movable)

    def creator_key(self, host: str) -> str:
        return f"drd/{self.cluster}/host/{host}/creator"

    def _request(self, host: str, msg: ComponentCall | ComponentBatch, op: str, path: str) -> tuple[Any, float]:
        """One round trip to `host`'s Creator: the reply and its duration, or ComponentError. A host that does not
        answer is marked gone, so later calls fail at once (the daemon removes it at lease expiry), until the daemon
        sees it up again (`back`)."""
        if self.is_down(host):
            if self.dead(host):  # seen down: its queued `offline` now; one only this mission took for gone (a call
                self.on_down(host)  # timed out) was told then, and telling again would undo what its reports did
            raise HostDown(host_down_reason(host, simulator=bool(host) and host == self.simulator))
        ops = self.gates.take(host) if self.gates is not None else None
        if ops:  # the gate operations queued for that host go first
            msg = dataclasses.replace(msg, gates=ops)
        t0 = time.perf_counter()
        moving = op == "start" or isinstance(msg, ComponentCall) and msg.status == "moved"  # a migration's two calls
        timeout = max(self.timeout, START_TIMEOUT) if moving else self.timeout
        sent = time.monotonic()
        try:
            reply = self.bus.call_reaching(self.creator_key(host), msg, timeout, lambda: self.dead(host))
        except RemoteError as e:
            raise ComponentError(f"{host}'s Creator refused {op} of {path}: {e.reason}") from None
        except BusError as e:
            away = self.frozen(sent)
            if away:  # our own silence, not the host's: its robots were stopped and its instances retired meanwhile
                self.take_halts()  # the halts they made then come before the failure this ends the mission with
                raise ControllerFrozen(frozen_reason(away)) from None
            if op == "start":  # a slow start excludes the host from this placement only; the instance it may
                self._forget_late_start(host, msg)  # still register there is terminated (best effort)
            else:
                self.gone.add(host)
            self.on_down(host)
            if self.dead(host):  # the view has it down now (its token vanished: the call ended at once): the words
                raise HostDown(host_down_reason(host, simulator=host == self.simulator)) from None  # of the dry-run
            raise HostDown(f"host {host} did not answer {op} within {timeout:g} s ({e})") from None
        deliver(getattr(reply, "records", None), self.records, self.gates.seen if self.gates is not None else None)
        return reply, time.perf_counter() - t0

    def take_halts(self) -> None:
        """Take now what the devices' hosts recorded while this controller was away (they stopped the robots when
        they lost it) and hand it to the missions, before this controller does anything more with them."""
        update = GateUpdate([], self.world, self.generation, self.term)
        hosts = sorted(set(self.resource_hosts.values()))
        deliver(take_pending(self.bus, self.cluster, hosts, update, self.timeout, self.is_down), self.records,
                self.gates.seen if self.gates is not None else None)

    def _forget_late_start(self, host: str, msg: ComponentCall | ComponentBatch) -> None:
        """Terminate, in the background, an instance whose start timed out: if the host was only slow, it would
        otherwise run there unseen (the Creator handles calls in turn, so this comes after the start)."""
        if not isinstance(msg, ComponentCall):
            return
        stop = ComponentCall("terminate", msg.mission, msg.path, msg.component, msg.world, status="failure",
                             generation=msg.generation, term=msg.term)  # the start's term: a Creator refuses term 0
        key = self.creator_key(host)

        def send() -> None:
            try:
                self.bus.call(key, stop, timeout=START_TIMEOUT)
            except Exception:  # the host is really gone: nothing runs there
                pass
        threading.Thread(target=send, name=f"drd-forget-{host}", daemon=True).start()

    def call(self, host: str, msg: ComponentCall) -> ComponentReply:
        reply, seconds = self._request(host, msg, msg.op, msg.path)
        self.stats.add(host, seconds)
        if not isinstance(reply, ComponentReply):
            raise ComponentError(f"{host} answered {msg.op} with a {type(reply).TYPE}")
        return reply

    def step(self, comp: RemoteComponent, now: float) -> ComponentReply:
        """`comp`'s step reply: received with an earlier batch of this cycle, or by a batch starting at it.

        A batch holds `comp` and the components the interpreter steps right after it in this cycle on the same
        host (active, remote, in `_running` order), up to the first one that runs elsewhere or here: nothing
        the controller does between those steps can change them (the Creator stops at the first step whose
        reply the controller must react to first, see `ComponentBatch`)."""
        ready = self._ready.pop(id(comp), None)
        if ready is not None and ready[0] == now:
            return ready[1]
        assert comp.host is not None
        dt = self.step_first(comp.host)
        group = comp.followers()
        msg = ComponentBatch([c.message("step", now=now) for c in group], dt)
        try:
            replies = self.call_batch(comp.host, msg)
        except Exception as e:
            if dt:  # the simulator's host did not answer, or not with the step: the cycle cannot go on
                self.sim_error = e
            raise
        for c, reply in zip(group[1:], replies[1:], strict=False):
            self._ready[id(c)] = (now, reply)
        return replies[0]

    def forget_reply(self, comp: RemoteComponent) -> None:
        """Drop `comp`'s step reply received with an earlier batch of this cycle (its host was lost)."""
        self._ready.pop(id(comp), None)

    def call_batch(self, host: str, msg: ComponentBatch) -> list[ComponentReply]:
        reply, seconds = self._request(host, msg, "step", msg.calls[0].path)
        self.batches.add(host, seconds)
        if not isinstance(reply, ComponentBatchReply) or not reply.replies:
            raise ComponentError(f"{host} answered a step batch with a {type(reply).TYPE}")
        if msg.sim_step:
            if reply.sim_version < 0:
                raise ComponentError(f"{host} did not step the simulation: {reply.replies[0].error or 'no reason'}")
            self.sim_time, self.sim_version = reply.sim_time, reply.sim_version
        for _ in reply.replies:
            self.stats.calls += 1  # component steps, for the figures (one round trip carried them all)
            self.stats.by_host[host] = self.stats.by_host.get(host, 0) + 1
        return list(reply.replies)

    def registry(self, names: Iterator[str] | None = None) -> RemoteRegistry:
        return RemoteRegistry(self)


class RemoteRegistry(Mapping[str, Callable[[], Component]]):
    """The executive's registry for a cluster mission: every component type becomes a `RemoteComponent`."""

    def __init__(self, router: ComponentRouter):
        self.router = router

    def __getitem__(self, name: str) -> Callable[[], Component]:
        if not self.router.implements(name):  # the Creator checks again on its side
            raise KeyError(name)
        return lambda: RemoteComponent(name, self.router)

    def get(self, name: str, default: Any = None) -> Any:
        try:
            return self[name]
        except KeyError:
            return default

    def __iter__(self) -> Iterator[str]:
        return iter(self.router.local)

    def __len__(self) -> int:
        return len(self.router.local)


class RemoteComponent(Component):
    """A component whose code runs in the Creator of the host owning its devices (see the module docstring)."""

    def __init__(self, name: str, router: ComponentRouter) -> None:
        super().__init__()
        self.name = name
        self.router = router
        self.host: str | None = None
        self.local: Component | None = None
        self.movable = False  # no device needs and a placer: the policy picks its host (module docstring)
        self._params: dict[str, Any] = {}
        self._bindings: dict[str, list[str]] = {}
        self._rank: list[int] = [0, 0]
        self.state: list[Any] | None = None  # [its last snapshot] as its host sent it (None: none yet)
        self._restore: list[Any] | None = None  # [state] to restore at its next start (`restore`)
        self._failed = ""  # the error its last step failed with (its `terminate` does not say it again)
        self._started = False  # its host accepted its last start (else a terminate finds no instance there)
        self._raised = ""  # its own code raised as a migration started it elsewhere: its next step fails with that

    # -- lifecycle ------------------------------------------------------------------------------------

    def setup(self, ctx: Context) -> None:
        super().setup(ctx)  # the remote instance is set up at its first start, once its host is known

    def snapshot(self) -> Mapping[str, Any] | None:
        """Its last snapshot as its host sent it (a local one's own)."""
        if self.local is not None and self.host is None:
            return self.local.snapshot()
        return self.state[0] if self.state else None

    def restore(self, state: Mapping[str, Any] | None) -> None:
        """Given to the instance with its next start (wherever it is started)."""
        self._restore = [dict(state) if state is not None else None]

    def start(self) -> None:
        self._resolve()
        restore, self._restore, self.state, self._failed, self._raised = self._restore, None, None, "", ""
        if self.host is None and not self.movable:
            if self.local is None:
                self.local = self.router.local[self.name]()
                self.local.setup(self._ctx)
            if restore is not None:
                self.local.restore(restore[0])
            self.local.start()
            return
        names = self.router.param_names(self.name)
        self._params = {k: plain(v) for k, v in self._ctx.params.items() if names is None or k in names}
        self._started = False
        if self.movable:
            self._place("placed", set(), restore)
        else:
            self._call("start", params=self._params, bindings=self._bindings, rank=self._rank, restore=restore)
        self._started = True

    def step(self, now: float) -> Status:
        if self.local is not None and self.host is None:
            return self.local.step(now)
        if self._raised:  # started by a migration, its own code raised: the state fails with that
            raise ComponentRaised(self._raised)
        reply = self._step_placed(now)
        self._apply(reply)
        if reply.error:
            self._failed = reply.error
            raise ComponentError(self.router.world_gone() or reply.error)  # a reading that found the world gone
            # (a BusTimeout on the simulator's key) says the dry-run's words (faults audit 21, #1)
        return step_status(reply.status, self.name) if reply.status else Status.RUNNING  # one rule in both modes

    def _step_placed(self, now: float) -> ComponentReply:
        """The step's reply; a movable instance whose host was lost, or no longer runs it, is placed again first."""
        try:
            if self.movable and self.host is not None and self.router.is_down(self.host):
                raise HostDown(f"host {self.host} is down")
            reply = self.router.step(self, now)
            if not (reply.lost and self.movable):
                return reply
            self._replace(host_lost=False)
        except HostDown:
            if not self.movable:
                raise
            self._replace(host_lost=True)
        return self.router.step(self, now)

    def suspend(self) -> None:
        self._lifecycle("suspend")

    def resume(self) -> None:
        if self.host is not None and not self.movable:  # a resumed grant may name other units of the same types
            old = self.host
            self._resolve()
            if self.host != old:
                raise ComponentError(f"{self._ctx.path}: resumed with devices on {self.host}, not {old}")
            self._call("resume", bindings=self._bindings)
            return
        self._lifecycle("resume")

    def terminate(self, status: Status) -> None:
        if self.local is not None and self.host is None:
            self.local.terminate(status)
            return
        if self.host is not None and not (self.movable and self.router.is_down(self.host)):
            try:
                self._call("terminate", status=str(status))  # a movable one on a lost host went with it
            except InstanceLost:
                if not self.movable and self._started:
                    raise  # a movable one its host no longer runs is already gone; one whose start failed (its
                    # module did not import there) never ran (users audit 21, #6: a second, spurious fault logged)
            except ComponentError as e:
                if str(e) != self._failed:  # a dead process answers each call as its step's failure said
                    raise  # (users audit 12, D6: logged twice)
            if self.movable:  # placed by the policy, and gone: it no longer counts on its host
                self.router.ended(self.host, self.name)

    # -- helpers --------------------------------------------------------------------------------------

    @property
    def _ctx(self) -> Context:
        return self.ctx

    def _lifecycle(self, op: str) -> None:
        if self.local is not None and self.host is None:
            getattr(self.local, op)()
        elif self.host is not None:
            try:
                if self.movable and self.router.is_down(self.host):
                    raise HostDown(f"host {self.host} is down")
                self._call(op)
            except (HostDown, InstanceLost) as e:
                if not self.movable:
                    raise
                self._replace(host_lost=isinstance(e, HostDown))
                if op == "suspend":  # started afresh: a resume needs nothing more, a suspend is sent
                    self._call(op)

    def _place(self, how: str, avoid: set[str], restore: list[Any] | None = None) -> None:
        """Start on the host the policy picks, with `restore` (`[state]`) if given. A host whose start fails or
        times out is excluded, with why, and the policy asked again, until a host starts it or the policy says why
        none can: each try excludes one more host, so there are at most as many tries as hosts."""
        place = self.router.place
        assert place is not None
        path, refused = self._ctx.path, dict.fromkeys(avoid, "")
        while True:
            self.host = None
            # hosts that timed out in this mission are left out (down ones the policy refuses itself)
            excluded = {**dict.fromkeys(self.router.gone, "it did not answer in this mission"), **refused}
            try:
                host = place(self.name, self._params, excluded)
            except ComponentError as e:
                if len(refused) > len(avoid):
                    raise ComponentError(f"{path}: {self.name} could not be started: {e}") from None
                raise
            if host in excluded:  # a policy that ignores its exclusions must not loop
                raise ComponentError(f"{path}: {self.name}: the placer chose {host} again, where its start failed")
            self.host = host
            try:
                self._call("start", params=self._params, bindings={}, rank=self._rank, restore=restore)
            except ComponentRaised:  # its own code: it is started, and failed, as in process
                self.router.placed.append((path, host, how))
                raise
            except ComponentError as e:  # it did not answer, or the start failed there: the next host by policy
                refused[host] = str(e)
                continue
            self.router.placed.append((path, host, how))
            return

    def _replace(self, host_lost: bool) -> None:
        """Its host is lost (`host_lost`: left out of this placement), or answered that it no longer runs it (it
        may be chosen again): start the instance again where the policy says, from its last snapshot (None if it
        sent none: its state is gone, and it is told so)."""
        old = self.host or ""
        why = f"its host {old} " + ("was lost" if host_lost else "no longer ran it")
        self.router.forget_reply(self)  # a step reply batched from the old host is no longer ours
        portable = self.router.portable(self.name)  # its manifest says its state may go elsewhere (`movable`)
        restore = self.state if self.state is not None and portable else [None]
        self._place("re-placed", {old} if host_lost else set(), restore)
        said = "from its last snapshot" if restore[0] is not None else "afresh (no snapshot)" if portable else \
            "afresh (its manifest does not say movable: true, so its state stays behind)"
        self._ctx.log(f"{self.name} placed again on {self.host} {said}: {why}")

    def migrate(self, host: str) -> list[Any]:
        """Move the running instance to `host`: stopped where it runs as `moved` (its fresh snapshot comes back,
        nothing of it stays there; from its last snapshot if that host is lost), then set up, restored and
        started on `host`. The state in the mission does not change. `[state]` moved; ComponentError if `host`
        refused it (the instance is then started again where it was, from that state, when that host is up)."""
        old = self.host
        if old is None or not self.movable:
            raise ComponentError(f"{self._ctx.path}: {self.name} runs where its devices are: it cannot move")
        self.router.forget_reply(self)
        moved = self.state if self.state is not None else [None]
        if not self.router.is_down(old):
            try:
                reply = self._call("terminate", status="moved")  # ComponentError: it stays where it is
                moved = reply.snapshot if reply.snapshot is not None else moved
            except InstanceLost:  # its host no longer runs it: from its last snapshot
                pass
        self.state = moved
        try:
            self.host = host
            self._call("start", params=self._params, bindings={}, rank=self._rank, restore=moved)
        except ComponentRaised as e:  # its own `restore` or `start` raised: any host would run the same code, so
            # its state fails with that, at its next step, as a start that raises does (placement audit 24, #1)
            self._raised = self._failed = str(e)
            self.router.placed.append((self._ctx.path, host, "migrated"))
            self.router.ended(old, self.name)
            raise ComponentError(f"{self._ctx.path}: {self.name} raised as it was started on {host} ({e}): its state"
                                 " fails with that") from None
        except ComponentError as e:
            self.host = None if self.router.is_down(old) else old
            if self.host is None:
                self._place("re-placed", {host, old}, moved)
            else:
                self._call("start", params=self._params, bindings={}, rank=self._rank, restore=moved)
            raise ComponentError(f"{host} did not start {self._ctx.path}: {e}; it goes on on {self.host}") from None
        self.router.placed.append((self._ctx.path, host, "migrated"))
        self.router.ended(old, self.name)
        self._ctx.log(f"{self.name} moved from {old} to {host}")
        return moved

    def _resolve(self) -> None:
        """Which unit (and robot part) each need is bound to, from the context's bindings, and so the host."""
        ctx = self._ctx
        self._rank = list(ctx.rank)
        self._bindings = {need: [b.unit, b.robot or "", b.part or ""] for need, b in ctx.bindings.items()}
        hosts = {h for h in (self.router.resource_hosts.get(b.unit) for b in ctx.bindings.values()) if h}
        gates = self.router.gates
        if len(hosts) > 1 and gates is not None:  # a robot held as a whole (a Scout it launches) has no device to
            devices = {gates.device_hosts.get(b.unit) for b in ctx.bindings.values()}  # call: where the devices
            hosts = {h for h in devices if h} or hosts  # are decides (new-user audit 8, D2)
        if len(hosts) > 1:
            raise ComponentError(f"{ctx.path}: its devices are on several hosts ({', '.join(sorted(hosts))})")
        self.host = next(iter(hosts)) if hosts else None
        self.movable = not hosts and not self._bindings and self.router.place is not None

    def _epochs(self) -> dict[str, int | None]:
        return {need: b.epoch for need, b in self._ctx.bindings.items()}

    def followers(self) -> list[RemoteComponent]:
        """This component, then those the interpreter steps after it in this cycle on the same host, up to the
        first active component that runs anywhere else."""
        group: list[RemoteComponent] = [self]
        seen = False
        for _node, comp in self.router.active():
            if not seen:
                seen = comp is self
                continue
            if not isinstance(comp, RemoteComponent) or comp.router is not self.router or comp.host != self.host \
                    or comp.local is not None and comp.host is None:
                break
            group.append(comp)
        return group

    def message(self, op: str, **fields: Any) -> ComponentCall:
        ctx, router = self._ctx, self.router
        shared = ctx.services.shared  # the inputs bound to shared data, by input name
        inputs = {k: v for k, v in ctx.inputs.items() if k not in shared}
        ids = {k: str(id(v)) for k, v in shared.items() if isinstance(v, dict)}
        seen = fields.pop("now", None)  # the world's time the interpreter stepped it at
        if router.clock is not None:  # a call carries the executive's time: the host's records and halts are on it
            now = router.clock()
        else:  # a router of a test: its components' time is the only one
            now = ctx.now() if seen is None else seen
        return ComponentCall(op, router.mission, ctx.path, self.name, router.world, generation=router.generation,
                             term=router.term,
                             epochs=self._epochs(), sim_time=router.sim_time, sim_version=router.sim_version,
                             shared=plain(shared) if shared else None,
                             inputs=plain(inputs) if inputs else None,
                             now=now, shared_ids=ids or None, origin=router.cycle.origin, **fields)

    def _call(self, op: str, **fields: Any) -> ComponentReply:
        assert self.host is not None
        self.router.step_first(None)
        msg = self.message(op, **fields)
        reply = self.router.call(self.host, msg)
        self._apply(reply)
        if reply.error:
            raise (InstanceLost if reply.lost else ComponentRaised if reply.raised else ComponentError)(reply.error)
        return reply

    def _apply(self, reply: ComponentReply) -> None:
        ctx = self._ctx
        if reply.snapshot is not None:
            self.state = list(reply.snapshot)
        if reply.outputs is not None:
            ctx.outputs.clear()
            ctx.outputs.update(reply.outputs)
        shared = ctx.services.shared
        if reply.shared is not None:
            for name, value in reply.shared.items():
                old = shared.get(name)
                if isinstance(old, dict) and isinstance(value, dict):
                    old.clear()
                    old.update(value)  # the ancestor's own dict: every component sharing it sees the change
                else:
                    shared[name] = value
        for line in reply.logs or ():
            ctx.log(str(line))
        update = ctx.services.dependencies
        for dep in reply.dependencies or ():
            if update is not None and len(dep) == 3:
                update(str(dep[0]), str(dep[1]), dep[2])
        for event in reply.events or ():
            if len(event) in (2, 3) and isinstance(event[1], dict):
                try:
                    ctx.emit(str(event[0]), **event[1])
                except EmitError as e:  # refused here: it says the line of the component's emit, as in process
                    e.where = e.where or (str(event[2]) if len(event) == 3 and event[2] else None)
                    raise
