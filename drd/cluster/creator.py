"""The Component Creator of one host: runs the components whose devices this host owns.

It serves `drd/<cluster>/host/<host>/creator` with `drd.cluster.remote.ComponentCall`s from the controller's
executive (through `RemoteComponent` proxies) and answers each with a `ComponentReply`. It is closed:

- it instantiates only elementary behaviors declared by a manifest of its own catalog, from that manifest's
  entry point (never a module or class named on the wire);
- parameters must be declared by the manifest and of its declared type (`float`, `duration`, `int`...);
- a need's resource must be a device of this host; its driver is this host's (`drd.hw.drivers`), behind the
  device's gate (`drd.runtime.ownership`): the controller tells the gates every grant and end of one
  (`drd.cluster.gates`, carried by each call or sent alone), so only the holder's subtree, at its grant's
  epoch, moves a device, and a device whose holder lost it is stopped here, next to it.

Component code runs in worker processes (`drd.cluster.workers`): a pre-started container shared by the
instances whose manifest says `process: container` (and the same `scheduling`), or a process of its own for
`process: dedicated`. What stays here, on the trusted side: the checks above, the drivers and their fencing,
the arbitration below and the simulator. Inside the worker a component's devices are proxies: each method
call comes back over the pipe and runs here on the gated driver, so one call costs one pipe round trip plus
one per driver call, and a batch one round trip per run of consecutive steps in the same process. A worker
that dies fails the calls of its instances (`component process of X died (exit code -9)`) and nothing else;
the pool replaces it. Several missions may run at once: instances are kept per mission (`<mission>/<path>`),
each mission has processes of its own, retired when the controller says the mission ended (`retire`). `Tune`
(on the Creator's key) changes the CPU affinity and nice of the process running an instance at run time.

Actuator commands of one control cycle are fenced by the gate first, then arbitrated per device as the
dry-run's `Arbiter` does (highest priority, then the behavior declared last): the best of one message's calls
is executed when they are done, so only it reaches the driver; a lower-ranked command in a later message of the
same round is dropped. What the gates record (each command, each halt) goes back to the controller with the
reply.

`sim` drivers reach the simulator through a `drd.sim.service.RemoteSimulation`, built per mission for the
world the call names; on the simulator host itself they call the simulation directly
(`drd.sim.service.LocalSimulation`, under the service's lock), as in the dry-run.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import os
import pickle
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import psutil

from drd.bus import Bus, BusError, MalformedMessage, Message, Query, Reply, encode, typed_handler
from drd.bus.keys import is_concrete
from drd.bus.messages import MAX_SIZE
from drd.cluster.freeze import FreezeWatch
from drd.cluster.gates import GateUpdate, GateUpdateReply, wire_record
from drd.cluster.guard import CLOSE_WAIT, HostGuard
from drd.cluster.instances import InstanceInfo
from drd.cluster.keys import ClusterKeys
from drd.cluster.pipe import (
    AttrRead,
    Call,
    CallReply,
    Command,
    DeviceCall,
    DeviceRequest,
    Done,
    Drop,
    Ok,
    Raise,
    ReadingKey,
    Run,
    Setup,
    reading_key,
    reading_request,
)
from drd.cluster.remote import ComponentBatch, ComponentBatchReply, ComponentCall, ComponentReply
from drd.cluster.terms import TermFence, Witness
from drd.cluster.workers import (
    CANNOT_MOVE,
    DEFAULT_SIZE,
    MOVED,
    Tune,
    Tuned,
    Worker,
    WorkerDied,
    WorkerPool,
    apply_scheduling,
    device_methods,
    scheduling_of,
)
from drd.errors import ComponentFailure, HardwareFailure, raised
from drd.hosts import Cluster, Role
from drd.hw.commands import spec_of
from drd.profiling import Sampler
from drd.runtime import records as rec
from drd.runtime.ownership import Arbiter, Binding, BoundDevice, LocalGates, Proposal
from dsl.catalog import Catalog, ComponentType, Kind, Process

log = logging.getLogger("drd.cluster.creator")

OPS = ("start", "step", "suspend", "resume", "terminate", "retire")


class CycleArbiter(Arbiter):
    """`Arbiter` over the calls of one message (see the module docstring): fenced by the gate when proposed, the
    best per device executed when the message's calls are done (`flush_round`), unless a higher-ranked behavior
    commanded the device in an earlier message of the same round; `round` changes per cycle and phase. A driver
    that raises is reported through `on_error(owner, exception)`."""

    def __init__(self, clock: Callable[[], float], on_error: Callable[[Any, Exception], None]) -> None:
        super().__init__(clock)
        self.on_error = on_error
        self.round: tuple[float, bool] = (-1.0, False)
        self._done: dict[str, tuple[tuple[float, bool], tuple[int, int]]] = {}  # device -> (round, rank) executed

    def propose(self, p: Proposal) -> None:
        done = self._done.get(p.gate.device)
        if done is not None and done[0] == self.round and p.rank < done[1]:
            return  # a higher-ranked behavior already commanded this device in this round: it never reaches it
        super().propose(p)

    def flush_round(self) -> None:
        """Execute the best setpoint proposed per device since the last flush: only the winner reaches the driver
        (and the robot: a ROS 2 robot got the loser's Twist, then the winner's, every cycle; safety audit 8)."""
        for p in self.best.values():
            self._done[p.gate.device] = (self.round, p.rank)
        self.flush(self.on_error)


#: Seconds a new world waits for the last world's telemetry read under way (the Creator's lock is held, and the
#: controller waits 1 s for a reply): a read that hangs longer ends its thread when it returns, keeping nothing.
REPLACE_WAIT = 0.1

#: Instance states, as announced to the Component Database.
RUNNING, SUSPENDED, TERMINATED, FAILED = "running", "suspended", "terminated", "failed"
_STATE_AFTER = {"start": RUNNING, "resume": RUNNING, "suspend": SUSPENDED, "terminate": TERMINATED}
#: The calls after which an instance may no longer command its devices (a `resume` binds it again, at its epochs).
_UNBINDS = frozenset({"suspend", "terminate"})


@dataclass
class Instance:
    """A component instance as the Creator keeps it: the process running its code, and its gated devices."""

    name: str
    mission: str
    path: str
    bindings: dict[str, list[str]]
    worker: Worker
    devices: dict[str, BoundDevice] = field(default_factory=dict)
    bound: dict[str, Binding] = field(default_factory=dict)  # need -> its binding (epoch from each call)
    setup: Setup | None = None  # sent with its first call (entry point, resources, device methods)
    state: str = "starting"
    dead: str = ""  # how its process went, once it has
    notes: list[str] = field(default_factory=list)  # scheduling not applied: told in the start reply's logs
    readings: dict[str, frozenset[str]] = field(default_factory=dict)  # need -> its driver's `READINGS`
    reads: list[ReadingKey] = field(default_factory=list)  # readings of its last step: read ahead of the next
    asked: list[ReadingKey] = field(default_factory=list)  # readings it asked over the pipe in this step


def token_slots(running: dict[str, str], held: dict[str, tuple[str, int]]) -> dict[str, tuple[str, int]]:
    """(path, slot) of each running instance's token (`running`: key -> path; `held`: the tokens declared now).
    Held ones keep theirs; each new one takes the lowest slot no running instance of the same path holds, so the
    slot is 0 unless runs of one mission overlap on this host. Why not the mission id in the key: zenoh keeps about
    2 kB of state for every token key it ever saw, in the declarer and in every peer, for good (worker daemons grew
    ~40 kB per corridor mission); the keys must come from a bounded set. Why not the path alone: two overlapping
    runs would declare one key twice, and zenoh then undeclares it once."""
    out = {k: held[k] for k in running if k in held}
    taken = set(out.values())
    for key in sorted(running.keys() - out.keys()):
        path = running[key]
        slot = next(n for n in range(len(running) + 1) if (path, n) not in taken)
        out[key] = (path, slot)
        taken.add((path, slot))
    return out


class CreatorError(ComponentFailure, ValueError):
    """A call refused outright (unknown component, bad parameter, a device of another host)."""


class NoInstance(CreatorError):
    """A call for an instance this host does not run (never started here, or retired): its reply says `lost`, so
    the controller places a movable one again (`drd.cluster.remote.InstanceLost`)."""


class Creator:
    def __init__(self, bus: Bus | None, cluster: Cluster, host: str, catalog: Catalog, *,
                 sim_service: Any = None, pool: WorkerPool | None = None,
                 workers: int | None = None, on_change: Callable[[], None] | None = None,
                 drivers: Callable[[str], Any] | None = None, acting: Callable[[], bool] | None = None) -> None:
        """`pool`: the worker processes to use (default: a pool of `workers` idle ones, else `$DRD_WORKERS`, else
        2, owned and closed by this Creator); `on_change` is called when the announced instances change;
        `drivers(world)`: this host's drivers (`drd.hw.HostDrivers`) for a world, instead of those hosts.yaml names
        (a test's fakes); `acting()`: whether this process runs the controller that acts now, whose grants a freeze
        of its own took nothing from (`check_freeze`; default: whether the host has the controller role)."""
        self.cluster, self.host, self.catalog = cluster, host, catalog
        self.instances: dict[str, Instance] = {}  # by `<mission>/<path>`
        self.calls = 0
        # the live controller's term, once a call of it was accepted: older ones are refused (drd.cluster.terms)
        self.terms = TermFence(host, Witness(bus, cluster).live if bus is not None else None)
        self._now = 0.0  # the controller's time of the call being served (the gates' records carry it)
        self.losses = 0  # how many times it lost its controller (`controller_lost`): its daemon re-announces then
        self.arbiter = CycleArbiter(lambda: self._now, self._setpoint_failed)
        self._sim_service = sim_service  # this host's own SimulationService (drd.sim.service), if it has one
        self._bus = bus
        self._drivers: Any = None
        self._make_drivers = drivers
        self._generation: tuple[str, int] | None = None  # (world, reset generation) the drivers were built for
        self._gates = LocalGates(self._gate_record)
        self._guard: HostGuard | None = None  # the constraints in force on this host's gates
        self._records: list[dict[str, Any]] = []  # what the gates recorded since the last reply
        self._sim: Any = None  # a RemoteSimulation, when the drivers reach the simulator through requests
        self._world: Any = None  # the simulation the drivers use (local or remote), for its `version`
        self._ahead_version: int | None = None  # the world's version when the current run's readings were read
        mine = cluster.host(host)
        self._devices = {d.id for d in mine.devices} | {r.id for r in cluster.robots}  # what a need may be bound to
        self._sharable = {d.id for d in mine.devices if d.sharable}
        self._command_errors: list[tuple[str, str]] = []  # (instance key, error) of setpoints that raised
        self._lock = threading.Lock()
        self._still = FreezeWatch(cluster.lease)  # this process not running for longer than the lease
        self._acting = acting if acting is not None else lambda: Role.CONTROLLER in cluster.host(host).roles
        self._own_pool = pool is None
        # cold until a world starts or a component is placed here: an idle daemon runs no worker processes
        self.pool = pool if pool is not None else WorkerPool(pool_size(workers), preload=behavior_modules(catalog),
                                                             warm=False)
        self._workers: dict[int, Worker] = {}  # the processes taken from the pool for the missions, by pid
        self._on_change = on_change
        self._dirty = False
        self._infos: list[InstanceInfo] = []
        self.key = f"drd/{cluster.name}/host/{host}/creator"
        self._keys = ClusterKeys(cluster.name)
        self._tokens: dict[str, tuple[str, int, Any]] = {}  # instance key -> (its path, slot, liveliness token)
        self._sampler = Sampler(host, every=200)  # DRD_PROFILE: the step batches, in <DRD_PROFILE>.<host>
        self._observed: Any = None  # the tap's queryable (below)
        self._queryable = bus.serve(self.key, self._serve) if bus else None
        # an operator's `Tune`, on its own key (the Creator's own is the controller's)
        self._tune = bus.serve(self._keys.tune(host), typed_handler(Tune, self.tune, (CreatorError,))) if bus else None
        # real robots (no simulator host): what this host's drivers read, for a recording client (docs/recording.md)
        self.tap: Any = None  # drd.cluster.observe.DriverTap
        if bus is not None and mine.robots and not any(Role.SIMULATOR in h.roles for h in cluster.hosts):
            from drd.cluster.observe import DriverTap
            from drd.sim.service import WorldObserve

            self.tap = DriverTap()
            self._observed = bus.serve(self._keys.robots(host), typed_handler(WorldObserve, self.tap.observe))

    def close(self) -> None:
        """Stop serving and kill every worker process (the pool's too, if this Creator owns it)."""
        for served in (self._queryable, self._tune, self._observed):
            if served is not None:
                served.close()
        with self._lock:
            self._retire_all(wait=True)  # nothing of it outlives its close
            self._close_guard()
            self._close_drivers()
            self.instances.clear()
            self._dirty = False
            self._infos = []
            self._sync_tokens({})
        if self._own_pool:
            self.pool.close()

    def watch_from_now(self) -> None:
        """Its daemon serves from now: the time it took to start is no freeze (`check_freeze`)."""
        self._still.restart()

    def check_freeze(self) -> str:
        """Whether this process stood still for longer than the lease since it last looked (called by the daemon's
        every tick and before every call, whichever runs first after a SIGCONT): then the controller has taken this
        host for lost and ended its grants, so its devices stop and its instances go, as on a controller's loss,
        before a call sent meanwhile can move anything (recovery audit D0: a step delivered during the freeze ran
        on waking and drove the Ranger on after its mission had failed). Not when this process runs the controller
        that still acts: its grants froze with it and nothing was taken meanwhile (a suspended one-host laptop); a
        standby's, or a fenced one's, came from a controller elsewhere. The reason, or "" when it ran on."""
        gap = self._still.gap()
        if not gap or self._acting():
            return ""
        reason = (f"this host was frozen for {gap:.1f} s, longer than the lease ({self.cluster.lease:g} s): the"
                  " controller took it for lost")
        self.controller_lost(reason)
        return reason

    def controller_lost(self, reason: str) -> None:
        """The controller is gone (its liveliness token vanished, or its lease ran out): nobody may grant this
        host's devices any more, so every actuator stops now and refuses commands until a controller grants it
        again, and every instance here is retired (it would run for a mission nobody executes)."""
        with self._lock:
            self.losses += 1
            self._gates.orphan_all(self._now, reason)
            self.instances.clear()
            self._retire_all()
            self._dirty = True
            self._publish()  # announced now: they were listed `running`, with dead pids (recovery audit D2)
        log.warning("creator %s: %s: every device stopped, every instance retired", self.host, reason)

    @property
    def missions(self) -> list[str]:
        """The missions with instances here."""
        return sorted({inst.mission for inst in self.instances.values()})

    def names(self) -> list[tuple[str, str]]:
        """(instance path, component) of the instances here, of every mission."""
        return [(inst.path, inst.name) for inst in self.instances.values()]

    def instance_infos(self) -> list[InstanceInfo]:
        """The instances to announce: those of the current mission not terminated (`failed` if their process died)."""
        return list(self._infos)

    # -- the seam: one call in, one reply out ---------------------------------------------------------

    def handle(self, call: ComponentCall) -> ComponentReply:
        unvouched = self.terms.admit(call.term)  # may ask the witness: not under the lock
        if unvouched:
            return ComponentReply(error=unvouched)
        with self._lock:
            stale = self.terms.stale(call.term)
            if stale:
                return ComponentReply(error=stale)
            if call.op not in OPS:  # before anything of the call is applied (or its term adopted)
                raise CreatorError(f"unknown op {call.op!r}: use {', '.join(OPS)}")
            if not call.mission or "/" in call.mission:
                raise CreatorError(f"a call names a mission (without '/'), not {call.mission!r}")
            if call.op != "retire":  # a retire says no time (and may come late, owed): the halts' time stays
                self._now = call.now  # the last the controller said (cluster audit 14, D1: they were at 0)
            if call.op == "retire":
                self._apply_gates(call.gates, call.world, call.generation)
                self._retire(call.mission)
                self.terms.adopt(call.term)
                self._publish()
                return ComponentReply(records=self._take_records())
            self._apply_gates(call.gates, call.world, call.generation)
            if self._sim is not None:
                self._sim.owner = _key(call)
            try:
                inst = self._prepare(call)
                self.terms.adopt(call.term)  # accepted: op, mission and component checked
                reply = self._run(inst.worker, [(call, inst)], {})[0]
            except NoInstance as e:
                reply = ComponentReply(error=self._refusal(call, e), lost=True)
            finally:
                refused = self._flush_sim()
                self._publish()
            if refused and not reply.error:
                reply = dataclasses.replace(reply, error=refused[0][1])
            return dataclasses.replace(reply, records=self._take_records())

    def update_gates(self, update: GateUpdate) -> GateUpdateReply:
        """Apply gate operations from the controller (grants, ends of grants, unbindings); the halts they caused."""
        if self.terms.admit(update.term):
            return GateUpdateReply([])
        with self._lock:
            if self.terms.stale(update.term):
                return GateUpdateReply([])
            self._apply_gates(update.ops, update.world, update.generation)
            self.terms.adopt(update.term)
            self._flush_sim()
            return GateUpdateReply(self._take_records() or [])

    def handle_batch(self, batch: ComponentBatch) -> ComponentBatchReply:
        """The steps of one cycle in order, up to the first the controller must see first (`ComponentBatch`)."""
        unvouched = self.terms.admit(batch.calls[0].term)  # may ask the witness: not under the lock
        if unvouched:
            return ComponentBatchReply([ComponentReply(error=unvouched)])
        with self._sampler.run():
            return self._handle_batch(batch)

    def _handle_batch(self, batch: ComponentBatch) -> ComponentBatchReply:
        """Consecutive steps whose instances share a process go to it in one round trip (a run); the worker
        stops a run where this loop would have stopped, and `latest` chains shared dicts across runs."""
        replies: list[ComponentReply] = []
        latest: dict[str, Any] = {}  # shared dict id on the controller -> its value after the last step
        with self._lock:
            first = batch.calls[0]
            stale = self.terms.stale(first.term)
            if stale:
                return ComponentBatchReply([ComponentReply(error=stale)])
            self._now = first.now
            self._apply_gates(batch.gates, first.world, first.generation)
            owners: dict[str, int] = {}
            stepped = self._step_world(batch.sim_step) if batch.sim_step else None
            try:
                calls, i = batch.calls, 0
                while i < len(calls):
                    run: list[tuple[ComponentCall, Instance]] = []
                    refused: ComponentReply | None = None
                    while i < len(calls):
                        call = calls[i]
                        if call.op != "step":
                            raise CreatorError(f"a batch holds steps only, not {call.op!r}")
                        try:
                            inst = self._prepare(call)
                            self.terms.adopt(first.term)
                        except CreatorError as e:
                            refused = ComponentReply(error=self._refusal(call, e), lost=isinstance(e, NoInstance))
                            break
                        if run and inst.worker is not run[0][1].worker:
                            break
                        run.append((call, inst))
                        i += 1
                    if run:
                        for k, (call, _) in enumerate(run):
                            owners[_key(call)] = len(replies) + k
                        got = self._run(run[0][1].worker, run, latest)
                        replies += got
                        last = got[-1]
                        if len(got) < len(run) or last.events or last.dependencies or last.error:
                            break  # the controller reacts to this before the next step
                    if refused is not None:
                        replies.append(refused)
                        break
            except Exception as e:  # the world stepped: the reply must still say so, or the controller is behind
                if stepped is None:
                    raise
                log.warning("creator %s: a step batch failed after its simulation step: %s", self.host, e)
                replies.append(ComponentReply(error=f"{type(e).__name__}: {e}"))
            finally:
                for key, error in self._flush_sim():
                    at = owners.get(key)
                    if at is not None and at < len(replies) and not replies[at].error:
                        replies[at] = dataclasses.replace(replies[at], error=error)
                self._publish()
            records = self._take_records()
        if stepped is None:
            return ComponentBatchReply(replies, records=records)
        return ComponentBatchReply(replies, stepped.time, stepped.version, records=records)

    def _refusal(self, call: ComponentCall, e: CreatorError) -> str:
        """A call refused here, worded as the controller words a refused call (`ComponentRouter._request`)."""
        return f"{self.host}'s Creator refused {call.op} of {call.path}: {e}"

    def _step_world(self, dt: float) -> Any:
        """The cycle's simulation step, carried by the batch (`ComponentBatch.sim_step`): this host must serve the
        simulation. A RemoteSimulation of this process learns the new time and version from it."""
        if self._sim_service is None:
            raise CreatorError(f"{self.host} serves no simulation: a batch cannot step it")
        from drd.sim.service import SimRequest

        reply = self._sim_service.handle(SimRequest("step", dt=dt))
        if self._sim is not None:
            self._sim.sync(reply.time, reply.version)
        return reply

    def _flush_sim(self) -> list[tuple[str, str]]:
        """Send the actuator commands the drivers queued (one request): [(instance key, error)] of refusals, with
        the setpoint commands that raised here (sent by workers without waiting, see `_exchange`)."""
        self.arbiter.flush_round()  # the winners of the calls just made, at once (their errors join the refusals)
        refused, self._command_errors = self._command_errors, []
        sim = self._sim
        if sim is None or not hasattr(sim, "flush"):
            return refused
        sim.owner = ""
        refused += [(key, f"component raised HardwareError: {error}") for key, error in sim.flush()]
        return refused

    # -- the gates ------------------------------------------------------------------------------------

    def _apply_gates(self, ops: list[list[Any]] | None, world: str, generation: int) -> None:
        """The controller's gate operations, in order, before anything else of the message (malformed ones are
        logged and skipped: the gates keep what they had)."""
        if not ops:
            return
        try:
            self._drivers_for(world, generation)
        except HardwareFailure as e:  # a world no longer run (the simulator's host restarted): its gates are moot
            log.warning("creator %s: %d gate operations of world %s (generation %d) not applied: %s", self.host,
                        len(ops), world, generation, e)  # one line, not a handler's traceback (faults audit 21, #5)
            return
        gates = self._gates
        for op in ops:
            try:
                match op:
                    case ["grant", str(device), str(holder), int(epoch), float() | int() as at]:
                        gates.grant(device, holder, epoch, float(at))
                    case ["clear", str(device), str(holder), float() | int() as at, str(reason)]:
                        gates.clear(device, holder, float(at), reason)
                    case ["unbind", str(device), str(issuer), float() | int() as at, str(reason)]:
                        gates.unbind(device, issuer, float(at), reason)
                    case [str(kind), *_] if kind in HostGuard.KINDS and self._guard is not None:
                        self._guard.apply(op)
                    case _:
                        log.warning("creator %s: a malformed gate operation was ignored: %.200r", self.host, op)
            except Exception as e:  # a driver that cannot stop is reported in the halt's record, never raised
                log.warning("creator %s: gate operation %.200r failed: %s", self.host, op, e)

    def _gate_record(self, mission: str, record: rec.Record) -> None:
        self._records.append(wire_record(mission, record))

    def _report(self, data: dict[str, Any]) -> None:
        self._records.append(data)

    def _take_records(self) -> list[dict[str, Any]] | None:
        """What goes back with a reply: the gates' records, then the watched robots' live values."""
        telemetry = self._guard.telemetry() if self._guard is not None else None
        if telemetry is not None:
            self._records.append(telemetry)
        records, self._records = self._records, []
        return records or None

    def _setpoint_failed(self, owner: Any, e: Exception) -> None:
        """A setpoint the driver refused (sent by a worker without waiting): fails that instance's step."""
        if isinstance(owner, str):
            self._command_errors.append((owner, raised(e)))

    # -- calls ----------------------------------------------------------------------------------------

    def _prepare(self, call: ComponentCall) -> Instance:
        """Everything before the call goes to the worker: checks, sim clock, placement, epochs."""
        if call.op not in OPS:
            raise CreatorError(f"unknown op {call.op!r}: use {', '.join(OPS)}")
        if not call.mission or "/" in call.mission:
            raise CreatorError(f"a call names a mission (without '/'), not {call.mission!r}")
        if self._sim is not None and call.sim_version > self._sim.version:  # a batch that stepped knows better
            self._sim.sync(call.sim_time, call.sim_version)
        inst = self.instances.get(_key(call))
        if call.op == "start":
            inst = self._start_instance(call, inst)
        elif inst is None:
            raise NoInstance(f"no instance {call.path} of mission {call.mission} on {self.host}")
        elif call.op == "resume" and call.bindings is not None and call.bindings != inst.bindings:
            self._rebind(inst, dict(call.bindings), _rank(call))
        for need, epoch in (call.epochs or {}).items():
            binding = inst.bound.get(need)
            if binding is not None:
                binding.epoch = epoch
        self.arbiter.round = (call.now, call.op == "step")
        return inst

    def _run(self, worker: Worker, run: list[tuple[ComponentCall, Instance]],
             latest: dict[str, Any]) -> list[ComponentReply]:
        """Calls of instances of one worker, in one round trip (plus one per driver request); a prefix of replies."""
        first, inst0 = run[0]
        if inst0.dead:
            return [ComponentReply(error=f"component process of {first.path} {inst0.dead}")]
        calls: list[Call] = []
        aheads: list[dict[ReadingKey, Any] | None] = []
        self._ahead_version = getattr(self._world, "version", None)
        for call, inst in run:
            self.calls += 1
            ahead = self._read_ahead(inst) if call.op == "step" else None
            aheads.append(ahead)
            calls.append(Call(call.path, call.op, call.now - call.origin, call.status, call.shared, call.shared_ids,
                              call.inputs,
                              call.params if call.op == "start" else None, inst.setup, ahead,
                              call.restore if call.op == "start" else None))
            inst.setup = None
        try:
            got = self._exchange(worker, Run(tuple(calls), latest))
        except WorkerDied as e:  # which of the run's calls it died in is not known: each is named
            self._worker_died(worker, str(e))
            return [ComponentReply(error=f"component process of {', '.join(c.path for c, _ in run)} {e}")]
        replies = []
        for (call, inst), ahead, reply in zip(run, aheads, got, strict=False):
            answer = self._replied(call, inst, ahead, reply)
            replies.append(answer if worker.received <= MEASURE_OVER else _fitting(call, answer))
            if reply.setup_failed:
                continue
            shared = reply.shared
            if shared is not None and call.shared_ids:
                for name, ref in call.shared_ids.items():
                    if name in shared:
                        latest[ref] = shared[name]
        return replies

    def _replied(self, call: ComponentCall, inst: Instance, ahead: dict[ReadingKey, Any] | None,
                 reply: CallReply) -> ComponentReply:
        """What the worker's reply to `call` means here: the instance's state, what to read ahead of its next step;
        the reply for the controller."""
        if ahead is not None or inst.asked:
            inst.reads = _reads_next(ahead, reply.unused, inst.asked)
        if reply.setup_failed:  # setup raised: the start fails and the instance is forgotten
            self._forget(_key(call))
            return ComponentReply(error=reply.error)
        logs = reply.logs
        if inst.notes:
            logs, inst.notes = [*inst.notes, *logs], []
        if call.op == "terminate" and call.status == MOVED and reply.error.startswith(CANNOT_MOVE):  # its state
            return ComponentReply(reply.status, reply.outputs, reply.events, logs, reply.shared,  # cannot go along:
                                  reply.dependencies, reply.error)  # it was not stopped, and runs on here, bound
        state = _STATE_AFTER.get(call.op)
        if state is not None and state != inst.state:
            inst.state = state
            self._dirty = True
        if call.op in _UNBINDS:  # its last words (a stop in `terminate`) go now, then a thread of its own that goes
            self.arbiter.flush_from(f"{inst.mission}/{inst.path}", self._setpoint_failed)  # on commanding is
            for binding in inst.bound.values():  # refused (not bound to a grant), as in process (safety audit 8 D1)
                binding.epoch = None
        if call.op == "terminate" and call.status == MOVED:  # it goes on elsewhere: nothing of it stays here
            self._forget(_key(call))
        return ComponentReply(reply.status, reply.outputs, reply.events, logs, reply.shared, reply.dependencies,
                              reply.error, snapshot=reply.snapshot, raised=reply.raised)

    def _exchange(self, worker: Worker, run: Run) -> tuple[CallReply, ...]:
        """Send `run`, serve the worker's driver requests until its final `Done`; WorkerDied if it goes."""
        worker.send(run)
        while True:
            match worker.recv(self.pool.call_timeout):
                case Done(replies):
                    return replies
                case DeviceCall() | AttrRead() as req:
                    self._device_request(worker, req)
                case Command() as req:  # a setpoint: no answer awaited, a refusal fails the step after
                    error = self._device_request(worker, req, answer=False)
                    if error is not None:
                        self._command_errors.append((f"{worker.mission}/{req.path}", raised(error)))
                case other:
                    worker.kill()
                    raise WorkerDied(f"sent an unexpected message ({type(other).__name__}): killed")

    def _device_request(self, worker: Worker, req: DeviceRequest, answer: bool = True) -> Exception | None:
        """Run one driver call (or attribute read) of a component in `worker` on its gated device; answer it
        (or, for a setpoint `Command`, return what it raised). An answer tells the worker when the world changed
        since its readings were read ahead (a launch): it then asks for the rest of the run's readings."""
        value: Any = None
        error: Exception | None = None
        try:
            inst = self.instances.get(f"{worker.mission}/{req.path}")
            if inst is None or inst.worker is not worker:
                raise LookupError(f"no instance {req.path!r} in this process")
            if not isinstance(req, Command) and req.name in inst.readings.get(req.need, ()):
                key = reading_key(req)
                if key is not None and key not in inst.asked:
                    inst.asked.append(key)
            value = self._device_value(inst, req)
        except Exception as e:  # the component sees the driver's exception, as it would in process
            if not answer:
                return e
            error = e
        if not answer:
            return None
        changed = False
        if self._ahead_version is not None and getattr(self._world, "version", None) != self._ahead_version:
            changed, self._ahead_version = True, None
        try:
            worker.send(Ok(value, changed) if error is None else Raise(error, changed))
        except (pickle.PicklingError, TypeError, AttributeError) as e:
            what = f"{type(error).__name__}: {error}" if error is not None else "its result"
            worker.send(Raise(RuntimeError(f"{req.need}.{req.name}: {what} cannot be sent to the component process"
                                           f" ({e})"), changed))
        return None

    def _device_value(self, inst: Instance, req: DeviceRequest) -> Any:
        """A driver call (`DeviceCall`, `Command`) or attribute read (`AttrRead`) of an instance on its gated
        device."""
        need, name = req.need, req.name
        device = inst.devices.get(need)
        if device is None:
            raise LookupError(f"{inst.path}: no device for need {need!r} (have: {', '.join(inst.devices) or 'none'})")
        if name.startswith("_"):
            raise AttributeError(f"{need}: no public attribute {name!r}")
        if self._sim is not None:
            self._sim.owner = f"{inst.mission}/{inst.path}"
        target = getattr(device, name)
        if not isinstance(req, AttrRead):
            return target(*req.args, **req.kwargs)
        if callable(target):
            raise TypeError(f"{need}.{name} is a method: call it")
        return target

    def _read_ahead(self, inst: Instance) -> dict[ReadingKey, Any] | None:
        """The readings `inst` made in its last step, read now for this one (`READINGS` of the `sim` drivers: a
        function of the world's instant, so reading ahead changes nothing); each saves a pipe round trip. One
        that raises is left out: asked over the pipe, it raises there as it would have."""
        inst.asked = []
        if not inst.reads or self._ahead_version is None:
            return None
        ahead: dict[ReadingKey, Any] = {}
        for key in inst.reads:
            try:
                ahead[key] = self._device_value(inst, reading_request(inst.path, key))
            except Exception:
                continue
        return ahead or None

    # -- processes ----------------------------------------------------------------------------------------

    def _place(self, ct: ComponentType, mission: str) -> tuple[Worker, list[str]]:
        """The process for a new instance of `ct`: the mission's container with the same scheduling (not tuned
        since), else a pre-started worker from the pool (always, for `process: dedicated`)."""
        sched = ct.scheduling
        key = (tuple(sched.cores) if sched.cores is not None else None, sched.nice)
        if ct.process is not Process.DEDICATED:
            for w in self._workers.values():
                if w.kind == "container" and w.mission == mission and w.key == key and not w.tuned and w.alive:
                    return w, []
        w = self.pool.take()
        w.kind = "dedicated" if ct.process is Process.DEDICATED else "container"
        w.key = key
        w.mission = mission
        self._workers[w.pid] = w
        return w, self._apply_manifest(w, ct)

    def _apply_manifest(self, w: Worker, ct: ComponentType) -> list[str]:
        """The manifest's `scheduling` on a process just taken for it; nice 0 means "as the daemon". A setting
        the OS refuses (raising priority needs privileges) is logged and told, never fatal."""
        cores, nice = ct.scheduling.cores, ct.scheduling.nice
        try:
            want_nice = nice if nice != 0 and nice != psutil.Process(w.pid).nice() else None
            if cores is None and want_nice is None:
                return []
            apply_scheduling(w.pid, cores, want_nice)
        except (psutil.Error, OSError, ValueError) as e:
            note = (f"scheduling of {ct.name} (cores {list(cores) if cores is not None else 'any'}, nice {nice})"
                    f" not applied to its process {w.pid}: {_os_reason(e)}")
            log.warning("creator %s: %s", self.host, note)
            return [note]
        return []

    def _worker_died(self, worker: Worker, reason: str) -> None:
        worker.died = worker.died or reason
        names = sorted(worker.instances)
        for path in names:
            inst = self.instances.get(f"{worker.mission}/{path}")
            if inst is not None and inst.worker is worker:
                inst.dead, inst.state = reason, FAILED
        log.warning("creator %s: component process %d (%s) %s", self.host, worker.pid, ", ".join(names) or "idle",
                    reason)
        self._workers.pop(worker.pid, None)
        self.pool.release(worker)
        self._dirty = True

    def _forget(self, key: str) -> None:
        """Drop an instance: from its container (which goes on), or with its dedicated process."""
        inst = self.instances.pop(key, None)
        if inst is None:
            return
        self._dirty = True
        w = inst.worker
        w.instances.discard(inst.path)
        if w.died:
            return
        if w.kind == "dedicated" or not w.alive:  # its process goes with it, after its `shutdown` (bounded)
            self._workers.pop(w.pid, None)
            self.pool.retire(w, [inst.path])
            return
        try:
            w.send(Drop((inst.path,)))
        except WorkerDied:
            self._worker_died(w, w.died)

    def _retire(self, mission: str) -> None:
        """A mission ended: its instances are dropped (each gets its `shutdown`, bounded: `WorkerPool.retire`) and
        its processes retired (they exit, or are killed; the pool has fresh ones)."""
        for key in [k for k, inst in self.instances.items() if inst.mission == mission]:
            del self.instances[key]
        for pid in [pid for pid, w in self._workers.items() if w.mission == mission]:
            w = self._workers.pop(pid)
            self.pool.retire(w, sorted(w.instances))
        self._dirty = True

    def _retire_all(self, wait: bool = False) -> None:
        """Every process retired, its instances' `shutdown` first (bounded, `WorkerPool.retire`); `wait`: return
        once every one is gone (at most `SHUTDOWN_GRACE` and a little, all in parallel)."""
        reapers = [self.pool.retire(w, sorted(w.instances)) for w in self._workers.values()]
        self._workers.clear()
        for reaper in reapers:
            if wait and reaper is not None:
                reaper.join()

    def _publish(self) -> None:
        """Refresh what `instance_infos` says, and tell the daemon (to announce it) when it changed."""
        if not self._dirty:
            return
        self._dirty = False
        infos = [InstanceInfo(inst.path, inst.name, self.host, inst.state, self.key, inst.worker.pid, inst.mission)
                 for inst in self.instances.values() if inst.state not in (TERMINATED, "starting")]
        if infos != self._infos:
            self._infos = infos
            self._sync_tokens({f"{i.mission}/{i.name}": i.name for i in infos})
            if self._on_change is not None:
                self._on_change()

    def _sync_tokens(self, running: dict[str, str]) -> None:
        """A liveliness token per running instance (`running`: its key, mission/path -> its path), keyed
        `drd/<c>/instance/<host>/<slot>/<path>` (`token_slots`): it vanishes when the instance ends or its daemon
        dies, so a peer sees either without asking."""
        if self._bus is None:
            return
        for key in [k for k in self._tokens if k not in running]:
            self._tokens.pop(key)[2].close()
        held = {k: (path, slot) for k, (path, slot, _) in self._tokens.items()}
        for key, (path, slot) in token_slots(running, held).items():
            if key in self._tokens:
                continue
            try:
                token = self._bus.declare_token(self._keys.instance(self.host, f"{slot}/{path}"))
            except (ValueError, BusError) as e:  # a path that is no key (never for compiled missions): say so once
                log.warning("creator %s: no liveliness token for %s: %s", self.host, key, e)
                continue
            self._tokens[key] = (path, slot, token)

    # -- run-time scheduling ------------------------------------------------------------------------------

    def _find(self, name: str) -> Instance | None:
        """An instance by `<mission>/<path>`, or by its path when only one mission runs it."""
        inst = self.instances.get(name)
        if inst is not None:
            return inst
        found = [i for i in self.instances.values() if i.path == name]
        return found[0] if len(found) == 1 else None

    def tune(self, req: Tune) -> Tuned:
        """Set cores and/or nice of the process running `req.instance`; what it runs with now and who shares it.

        Raises CreatorError: unknown instance, cores or nice out of range, or the OS refused (privileges)."""
        with self._lock:
            inst = self._find(req.instance)
            if inst is None or inst.state in (TERMINATED, "starting"):
                running = sorted(i.path for i in self.instances.values() if i.state not in (TERMINATED, "starting"))
                raise CreatorError(f"no instance {req.instance!r} runs on {self.host}"
                                   f" (running: {', '.join(running) or 'none'})")
            if inst.dead:
                raise CreatorError(f"{req.instance}: its component process {inst.dead}")
            count = psutil.cpu_count() or 1
            cores = sorted(set(req.cores)) if req.cores is not None else None
            if cores is not None:
                if not cores:
                    raise CreatorError("cores: give at least one core")
                bad = [c for c in cores if not 0 <= c < count]
                if bad:
                    raise CreatorError(f"core {bad[0]} does not exist: {self.host} has {count} cores (0-{count - 1})")
            if req.nice is not None and not -20 <= req.nice <= 19:
                raise CreatorError(f"nice must be in -20..19, not {req.nice}")
            w = inst.worker
            try:
                apply_scheduling(w.pid, cores, req.nice)
            except (psutil.Error, OSError, ValueError) as e:
                what = " and ".join(x for x, v in (("nice", req.nice), ("cores", cores)) if v is not None)
                raise CreatorError(f"cannot set {what} of process {w.pid} running {req.instance}:"
                                   f" {_os_reason(e)}") from None
            if cores is not None or req.nice is not None:
                w.tuned = True  # a state no manifest asked for: new instances go elsewhere
            try:
                now_cores, now_nice = scheduling_of(w.pid)
            except (psutil.Error, OSError) as e:
                raise CreatorError(f"process {w.pid} running {req.instance}: {_os_reason(e)}") from None
            # who else runs in that process now (the worker's own list keeps a terminated instance until its
            # mission ends)
            sharing = {i.path for i in self.instances.values()
                       if i.worker is w and i is not inst and i.state not in (TERMINATED, "starting")}
            return Tuned(inst.path, self.host, w.pid, w.kind, now_cores, now_nice, sorted(sharing))

    # -- helpers ----------------------------------------------------------------------------------------

    def _drivers_for(self, world: str, generation: int) -> Any:
        """This host's drivers and their gates for the world the controller runs (built again when the world is
        reset: a new world, or the same one restarted for a mission that runs alone). A new world warms the worker
        pool: the mission's components are placed in the next moments."""
        if self._drivers is None or self._generation != (world, generation):
            self.pool.warm()
            self._close_guard(REPLACE_WAIT)  # before its drivers close: no read of them is under way after
            self._close_drivers()
            if self._make_drivers is not None:
                self._drivers = self._make_drivers(world)
                self._guard_gates()
                self._generation = (world, generation)
                return self._drivers
            from drd.hw.drivers import drivers_for
            from drd.sim.service import RemoteSimulation, world_dirs

            service = self._sim_service
            local = service.local(world) if service is not None else None
            if local is not None:  # the simulator is in this process: direct calls, as in the dry-run
                sim: Any = local
                self._sim = None
            elif service is not None:
                sim = self._sim = RemoteSimulation(service.handle, world, beside=service.beside)
            elif self._bus is not None and any(Role.SIMULATOR in h.roles for h in self.cluster.hosts):
                sim = self._sim = RemoteSimulation.over(self._bus, self.cluster.name, world,
                                                        beside=world_dirs(self.cluster))
            else:  # no simulator host: real robots, their drivers need no world
                sim = self._sim = None
            self._drivers = drivers_for(self.cluster, self.host, sim, catalog=self.catalog)
            if self.tap is not None:
                self.tap.attach(self._drivers)
            self._guard_gates()
            self._world = sim
            self._generation = (world, generation)
        return self._drivers

    def _close_guard(self, wait: float = CLOSE_WAIT) -> None:
        """End the last world's guard (its telemetry thread), waiting `wait` s at most for a read under way."""
        if self._guard is not None:
            self._guard.close(wait)
            self._guard = None

    def _close_drivers(self) -> None:
        """Close the drivers of the last world (what they hold: a ROS 2 driver's subscriptions), if any."""
        close = getattr(self._drivers, "close", None)
        if callable(close):
            close()

    def _guard_gates(self) -> None:
        """Gates over the drivers just built, guarded by the constraints the controller says are in force (the
        last world's guard is closed: its telemetry thread would keep that world's drivers alive)."""
        self._close_guard(REPLACE_WAIT)
        self._gates = LocalGates.of(self._drivers.devices, self._drivers.robots, self._sharable, self._gate_record)
        self._guard = HostGuard(self.cluster, self.host, self._drivers, self._gates, lambda: self._now,
                                self._report)

    def _check(self, call: ComponentCall) -> ComponentType:
        ct = self.catalog.get(call.component)
        if ct is None or not ct.entry_point or ct.kind is not Kind.BEHAVIOR:
            raise CreatorError(f"{call.component!r} is not an elementary behavior declared by a manifest")
        specs = {p.name: p for p in ct.params}
        for name, value in (call.params or {}).items():
            spec = specs.get(name)
            if spec is None:
                declared = ", ".join(specs) or "none"
                raise CreatorError(f"{call.component} has no parameter {name!r} (declared: {declared})")
            if not _type_ok(spec.type, value):
                raise CreatorError(f"{call.component}.{name} must be a {spec.type}, got {value!r}")
        self._check_bindings(call.path, call.bindings or {})
        return ct

    def _check_bindings(self, path: str, bindings: dict[str, list[str]]) -> None:
        """A need is bound to a device of this host, or to a robot of the cluster held as a whole (a Scout a launch
        moves, `MOVES`: no device here to call, wherever its parts are)."""
        for need, binding in bindings.items():
            if len(binding) != 3 or binding[0] not in self._devices:
                raise CreatorError(f"{path}: need {need} is bound to {binding[0] if binding else '?'},"
                                   f" neither a device of {self.host} nor a robot of the cluster")

    def _start_instance(self, call: ComponentCall, inst: Instance | None) -> Instance:
        ct = self._check(call)
        bindings = dict(call.bindings or {})
        key = _key(call)
        if inst is not None and not inst.dead and inst.name == call.component and inst.bindings == bindings:
            return inst  # the worker resets its params and outputs on start
        if inst is not None:
            self._forget(key)
        self._drivers_for(call.world, call.generation)
        worker, notes = self._place(ct, call.mission)
        assert ct.entry_point is not None
        new = Instance(call.component, call.mission, call.path, {}, worker, notes=notes)
        methods, commands = self._rebind(new, bindings, _rank(call))
        new.setup = Setup(ct.entry_point, {n: b[0] for n, b in bindings.items()}, methods, commands)
        self.instances[key] = new
        worker.instances.add(call.path)
        return new

    def _rebind(self, inst: Instance, bindings: dict[str, list[str]], rank: tuple[int, int]
                ) -> tuple[dict[str, list[str]], dict[str, list[str]]]:
        """The instance's gated devices for these bindings (a resumed grant may name other units); the methods
        and the setpoints (sent by the worker without waiting) of each need's driver."""
        self._check_bindings(inst.path, bindings)
        issuer = f"{inst.mission}/{inst.path}"
        inst.bindings, inst.devices, inst.bound, inst.readings = bindings, {}, {}, {}
        methods: dict[str, list[str]] = {}
        commands: dict[str, list[str]] = {}
        for need, (unit, robot, part) in bindings.items():
            found = self._gates.bound(unit, robot, part)
            if found is None:
                continue
            gate, driver = found
            binding = Binding(need, unit, "", None, gate, driver, robot, part)
            inst.bound[need] = binding
            inst.devices[need] = BoundDevice(binding, issuer, self.arbiter, rank, f"{inst.mission}/{inst.path}",
                                             lambda: self._now, functools.partial(_holds, inst))
            methods[need] = device_methods(driver)
            inst.readings[need] = spec_of(driver).readings
            commands[need] = sorted(spec_of(driver).setpoints)
        return methods, commands

    def _serve(self, query: Query) -> Message | Reply:
        if not is_concrete(query.key):  # only the controller calls, by this exact key (drd.daemon.acl)
            return query.error(f"ask {self.key} by its exact key")
        frozen = self.check_freeze()
        if frozen:  # a call sent while this host stood still: its controller has given up on it
            return query.error(f"{frozen}: its devices are stopped until a controller grants them again")
        if isinstance(query.payload, ComponentBatch):
            if not query.payload.calls:
                return query.error("an empty batch")
            try:
                return self.handle_batch(query.payload)
            except Exception as e:
                log.warning("creator %s: a step batch failed: %s", self.host, e)
                return ComponentBatchReply([ComponentReply(error=f"{type(e).__name__}: {e}")],
                                           records=self._take_records())
        if isinstance(query.payload, GateUpdate):
            return self.update_gates(query.payload)
        if not isinstance(query.payload, ComponentCall):
            return query.error("expected a drd.component.call")
        try:
            return self.handle(query.payload)
        except CreatorError as e:
            return query.error(str(e))
        except Exception as e:  # a driver could not be built, no worker could start: this call fails, we go on
            log.warning("creator %s: %s of %s failed: %s", self.host, query.payload.op, query.payload.path, e)
            return ComponentReply(error=f"{type(e).__name__}: {e}", records=self._take_records())


#: A worker's message past this many bytes (pickled) may hold a reply too large for a bus message once it is JSON:
#: each of its replies is then measured (`_fitting`). Smaller ones are not encoded twice.
MEASURE_OVER = MAX_SIZE // 8
#: What a batch reply adds around one instance's reply, at most, in bytes (its records, the envelope).
REPLY_ROOM = 64 << 10


def _fitting(call: ComponentCall, reply: ComponentReply) -> ComponentReply:
    """`reply`, or the error of one too large for a bus message (wedge audit D5: a 2 MB output made the whole step
    batch unsendable, failing every instance of the host with "handler returned a malformed reply")."""
    try:
        size = len(encode(reply))
    except MalformedMessage as e:
        why = e.reason
    else:
        if size <= MAX_SIZE - REPLY_ROOM:
            return reply
        why = f"{size} bytes"
    return ComponentReply(error=f"the reply to {call.op} of {call.path} is too large for the bus ({why}; at most"
                                f" {MAX_SIZE - REPLY_ROOM} bytes): a call's outputs, events and logs travel in one"
                                " message (docs/components.md)")


def _holds(inst: Instance, robot: str) -> bool:
    """Whether the instance is bound to `robot` (a launch moves only a Scout its behavior holds): its bindings as
    the controller last sent them, at its holders' current grants."""
    return any(robot in (unit, bot) for unit, bot, _ in inst.bindings.values())


def _key(call: ComponentCall) -> str:
    """An instance's key here: `<mission>/<path>` (several missions may run the same mission file)."""
    return f"{call.mission}/{call.path}"


def _rank(call: ComponentCall) -> tuple[int, int]:
    rank = call.rank or [0, 0]
    return int(rank[0]), int(rank[1])


#: At most this many readings of one instance are read ahead of its step.
MAX_AHEAD = 32


def _reads_next(ahead: dict[ReadingKey, Any] | None, unused: Any, asked: list[ReadingKey]) -> list[ReadingKey]:
    """What to read ahead of an instance's next step: what it read in this one, from ahead (all but `unused`)
    or over the pipe (`asked`)."""
    left = {tuple(k) for k in unused} if isinstance(unused, list) else set()
    reads = [k for k in ahead or () if k not in left]
    return (reads + [k for k in asked if k not in (ahead or {})])[:MAX_AHEAD]


def behavior_modules(catalog: Catalog) -> list[str]:
    """The modules of the catalog's elementary behaviors: the fork server imports them once for every worker."""
    return sorted({ct.entry_point.partition(":")[0] for ct in catalog.components.values()
                   if ct.kind is Kind.BEHAVIOR and ct.entry_point})


#: The most idle workers `$DRD_WORKERS` may ask for: each holds about 7 MB and takes a fork (about 20 ms) to
#: start, and only idle ones are pre-started (a placement beyond them starts its own), so more buys nothing a
#: host's missions use at once and costs memory for as long as the host has work (docs/design.md).
MAX_WORKERS = 64


def pool_size(workers: int | None) -> int:
    """`workers`, else `$DRD_WORKERS` if it is a whole number from 0 to MAX_WORKERS, else (with a warning, as the
    daemon's start should not fail on a tuning knob) the default."""
    if workers is not None:
        return workers
    text = os.environ.get("DRD_WORKERS", "").strip()
    if not text:
        return DEFAULT_SIZE
    try:
        size = int(text)
    except ValueError:
        log.warning("DRD_WORKERS=%r is not a number: using %d idle workers", text, DEFAULT_SIZE)
        return DEFAULT_SIZE
    if not 0 <= size <= MAX_WORKERS:
        log.warning("DRD_WORKERS=%s is out of range (0 to %d idle workers): using %d", text, MAX_WORKERS,
                    DEFAULT_SIZE)
        return DEFAULT_SIZE
    return size


def _os_reason(e: BaseException) -> str:
    if isinstance(e, psutil.AccessDenied | PermissionError):
        return ("permission denied (raising a process's priority, a lower nice, needs root or CAP_SYS_NICE;"
                " some cores may be outside this daemon's cgroup)")
    if isinstance(e, psutil.NoSuchProcess):
        return "the process is gone"
    return f"{type(e).__name__}: {e}"


def _type_ok(kind: str, value: Any) -> bool:
    if kind in ("float", "duration", "number"):
        return isinstance(value, int | float) and not isinstance(value, bool)
    if kind == "int":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind in ("bool", "boolean"):
        return isinstance(value, bool)
    if kind in ("string", "str"):
        return isinstance(value, str)
    return isinstance(value, str | int | float | bool | dict | list) or value is None
