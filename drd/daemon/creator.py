"""The Component Creator of one host: runs the components whose devices this host owns.

It serves `drd/<cluster>/host/<host>/creator` with `drd.runtime.remote.ComponentCall`s from the controller's
executive (through `RemoteComponent` proxies) and answers each with a `ComponentReply`. It is closed:

- it instantiates only elementary behaviors declared by a manifest of its own catalog, from that manifest's
  entry point (never a module or class named on the wire);
- parameters must be declared by the manifest and of its declared type (`float`, `duration`, `int`...);
- a need's resource must be a device of this host; its driver is this host's (`drd.hw.drivers`), fenced by
  the grant's epoch as in the dry-run (`drd.runtime.fence.Fenced`).

Component code runs in the daemon process for now, in the thread answering the call (one call at a time:
the executive makes them in turn). The seam for the worker-process pool is `Creator.handle`: it takes a call
and returns a reply, so a pool can run it in a container process instead. Actuator commands of one control
cycle are arbitrated per driver as the dry-run's `Arbiter` does (highest priority, then the behavior
declared last), but executed at once: a lower-ranked command that comes after a higher-ranked one in the
same round is dropped, and one that comes before is overwritten, so the last setpoint is the same.

`sim` drivers reach the simulator through a `drd.sim.service.RemoteSimulation`, built per mission for the
world the call names (on the simulator host itself it calls the service in-process).
"""

from __future__ import annotations

import cProfile
import logging
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from drd.bus import Bus, Message, Query, Reply
from drd.hosts import Cluster
from drd.runtime.component import Component, Context, Status
from drd.runtime.fence import Arbiter, Fenced, Proposal
from drd.runtime.records import plain
from drd.runtime.remote import ComponentBatch, ComponentBatchReply, ComponentCall, ComponentReply
from dsl.catalog import Catalog, Kind

log = logging.getLogger("drd.daemon.creator")

OPS = ("start", "step", "suspend", "resume", "terminate")


class CycleArbiter(Arbiter):
    """`Arbiter` with immediate execution (see the module docstring); `round` changes per cycle and phase."""

    def __init__(self) -> None:
        super().__init__()
        self.round: tuple[float, bool] = (-1.0, False)
        self._best: dict[int, tuple[tuple[float, bool], tuple[int, int]]] = {}

    def propose(self, driver: Any, proposal: Proposal) -> None:
        best = self._best.get(id(driver))
        if best is not None and best[0] == self.round and proposal.rank < best[1]:
            return  # a higher-ranked behavior already commanded this driver in this round
        self._best[id(driver)] = (self.round, proposal.rank)
        proposal.call()


@dataclass
class Instance:
    name: str
    component: Component
    ctx: Context
    bindings: dict[str, list[str]]
    epochs: dict[str, int | None] = field(default_factory=dict)
    events: list[list[Any]] = field(default_factory=list)
    logs: list[str] = field(default_factory=list)
    dependencies: list[list[Any]] = field(default_factory=list)
    now: float = 0.0


class CreatorError(ValueError):
    """A call refused outright (unknown component, bad parameter, a device of another host)."""


class Creator:
    def __init__(self, bus: Bus | None, cluster: Cluster, host: str, catalog: Catalog, *,
                 sim_call: Callable[[Any], Any] | None = None) -> None:
        from drd.executive import EntryPoints

        self.cluster = cluster
        self.host = host
        self.catalog = catalog
        self.entry_points = EntryPoints(catalog)
        self.instances: dict[str, Instance] = {}
        self.mission = ""
        self.calls = 0
        self.arbiter = CycleArbiter()
        self._sim_call = sim_call  # in-process calls to this host's own SimulationService
        self._bus = bus
        self._drivers: Any = None
        self._sim: Any = None
        mine = cluster.host(host)
        self._devices = {d.id for d in mine.devices} | {r.id for r in mine.robots}  # what a need may be bound to
        self._lock = threading.Lock()
        # DRD_PROFILE=path: profile the step batches (cProfile), dumped to path.<host> every 200 batches
        self._profile_path = os.environ.get("DRD_PROFILE", "")
        self._profile = cProfile.Profile() if self._profile_path else None
        self._profiled = 0
        self._queryable = bus.serve(f"drd/{cluster.name}/host/{host}/creator", self._serve) if bus else None

    def close(self) -> None:
        if self._queryable is not None:
            self._queryable.close()

    def names(self) -> list[tuple[str, str]]:
        """(instance path, component) of the instances of the current mission."""
        return [(path, inst.name) for path, inst in self.instances.items()]

    # -- the seam: one call in, one reply out ---------------------------------------------------------

    def handle(self, call: ComponentCall) -> ComponentReply:
        with self._lock:
            if self._sim is not None:
                self._sim.owner = call.path
            try:
                reply = self._handle(call, call.shared)
            finally:
                refused = self._flush_sim()
            if refused and not reply.error:
                reply = ComponentReply(reply.status, reply.outputs, reply.events, reply.logs, reply.shared,
                                       reply.dependencies, f"component raised HardwareError: {refused[0][1]}")
            return reply

    def handle_batch(self, batch: ComponentBatch) -> ComponentBatchReply:
        """The steps of one cycle in order, up to the first the controller must see first (`ComponentBatch`)."""
        prof = self._profile
        if prof is None:
            return self._handle_batch(batch)
        prof.enable()
        try:
            return self._handle_batch(batch)
        finally:
            prof.disable()
            self._profiled += 1
            if self._profiled % 200 == 0:
                prof.dump_stats(f"{self._profile_path}.{self.host}")

    def _handle_batch(self, batch: ComponentBatch) -> ComponentBatchReply:
        replies: list[ComponentReply] = []
        latest: dict[str, Any] = {}  # shared dict id on the controller -> its value after the last step
        with self._lock:
            owners: dict[str, int] = {}
            try:
                for call in batch.calls:
                    if call.op != "step":
                        raise CreatorError(f"a batch holds steps only, not {call.op!r}")
                    shared = dict(call.shared) if call.shared is not None else None
                    ids = call.shared_ids or {}
                    if shared is not None:
                        for name, ref in ids.items():
                            if ref in latest and name in shared:
                                shared[name] = plain(latest[ref])  # a copy: the earlier reply keeps its own
                    if self._sim is not None:
                        self._sim.owner = call.path
                    owners[call.path] = len(replies)
                    try:
                        reply = self._handle(call, shared)
                    except CreatorError as e:
                        replies.append(ComponentReply(error=f"{self.host}'s Creator refused step of {call.path}: {e}"))
                        break
                    replies.append(reply)
                    if reply.shared is not None:
                        for name, ref in ids.items():
                            if name in reply.shared:
                                latest[ref] = reply.shared[name]
                    if reply.events or reply.dependencies or reply.error:
                        break  # the controller reacts to this before the next step
            finally:
                for path, error in self._flush_sim():
                    i = owners.get(path)
                    if i is not None and not replies[i].error:
                        r = replies[i]
                        replies[i] = ComponentReply(r.status, r.outputs, r.events, r.logs, r.shared, r.dependencies,
                                                    f"component raised HardwareError: {error}")
        return ComponentBatchReply(replies)

    def _flush_sim(self) -> list[tuple[str, str]]:
        """Send the actuator commands the drivers queued (one request): [(instance path, error)] of refusals."""
        sim = self._sim
        if sim is None or not hasattr(sim, "flush"):
            return []
        sim.owner = ""
        refused: list[tuple[str, str]] = sim.flush()
        return refused

    def _handle(self, call: ComponentCall, shared: dict[str, Any] | None) -> ComponentReply:
        self.calls += 1
        if call.op not in OPS:
            raise CreatorError(f"unknown op {call.op!r}: use {', '.join(OPS)}")
        if call.mission != self.mission:
            self._new_mission(call.mission)
        if self._sim is not None and call.sim_version >= 0:
            self._sim.sync(call.sim_time, call.sim_version)
        inst = self.instances.get(call.path)
        if call.op == "start":
            inst = self._start_instance(call, inst)
        elif inst is None:
            raise CreatorError(f"no instance {call.path} of mission {call.mission} on {self.host}")
        inst.now = call.now
        if call.epochs is not None:
            inst.epochs.update(call.epochs)
        services = inst.ctx.services
        assert isinstance(services, dict)
        services["shared"] = shared if shared is not None else {}
        services["siblings"] = call.siblings if call.siblings is not None else {}
        self.arbiter.round = (call.now, call.op == "step")
        status = ""
        error = ""
        try:
            match call.op:
                case "start":
                    inst.component.start()
                case "step":
                    status = str(inst.component.step(call.now))
                case "suspend":
                    inst.component.suspend()
                case "resume":
                    inst.component.resume()
                case "terminate":
                    inst.component.terminate(Status(call.status) if call.status in Status.__members__.values()
                                             else Status.RUNNING)
        except Exception as e:  # component code is not ours to trust: the state fails, the daemon goes on
            error = f"component raised {type(e).__name__}: {e}"
        reply = ComponentReply(status, plain(inst.ctx.outputs), inst.events, inst.logs,
                               plain(services["shared"]), inst.dependencies, error)
        inst.events, inst.logs, inst.dependencies = [], [], []
        return reply

    # -- helpers ----------------------------------------------------------------------------------------

    def _new_mission(self, mission: str) -> None:
        self.instances.clear()
        self.mission = mission
        self._drivers = self._sim = None

    def _drivers_for(self, world: str) -> Any:
        if self._drivers is None:
            from drd.hw.drivers import drivers_for
            from drd.sim.service import RemoteSimulation

            if self._sim_call is not None:
                self._sim = RemoteSimulation(self._sim_call, world)
            elif self._bus is not None:
                self._sim = RemoteSimulation.over(self._bus, self.cluster.name, world)
            self._drivers = drivers_for(self.cluster, self.host, self._sim, catalog=self.catalog)
        return self._drivers

    def _check(self, call: ComponentCall) -> None:
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
        for need, binding in (call.bindings or {}).items():
            if len(binding) != 3 or binding[0] not in self._devices:
                raise CreatorError(f"{call.path}: need {need} is bound to {binding[0] if binding else '?'},"
                                   f" not a device of {self.host}")

    def _start_instance(self, call: ComponentCall, inst: Instance | None) -> Instance:
        self._check(call)
        bindings = dict(call.bindings or {})
        if inst is not None and inst.name == call.component and inst.bindings == bindings:
            inst.ctx.params, inst.ctx.outputs = dict(call.params or {}), {}
            return inst
        drivers = self._drivers_for(call.world)
        devices: dict[str, Any] = {}
        rank = (int((call.rank or [0, 0])[0]), int((call.rank or [0, 0])[1]))
        holder: dict[str, Instance] = {}
        for need, (rid, robot, part) in bindings.items():
            by_robot = drivers.robots.get(robot, {}) if robot and part else {}
            driver = by_robot.get(part) or drivers.devices.get(rid)
            if driver is not None:
                devices[need] = Fenced(driver, _epoch_of(holder, need), self.arbiter, rank, call.path)
        path = call.path
        new = Instance(call.component, None, None, bindings)  # type: ignore[arg-type]
        holder["it"] = new
        ctx = Context(path, dict(call.params or {}), {n: b[0] for n, b in bindings.items()},
                      lambda ev, **f: new.events.append([ev, plain(f)]),
                      lambda text: new.logs.append(str(text)),
                      lambda: new.now, devices=devices,
                      services={"shared": {}, "siblings": {},
                                "dependencies": lambda rid, k, v: new.dependencies.append([rid, k, v])})
        comp = self.entry_points[call.component]()
        new.component, new.ctx = comp, ctx
        comp.setup(ctx)  # may raise: handle() turns it into a failed start
        self.instances[path] = new
        return new

    def _serve(self, query: Query) -> Message | Reply:
        if isinstance(query.payload, ComponentBatch):
            if not query.payload.calls:
                return query.error("an empty batch")
            try:
                return self.handle_batch(query.payload)
            except Exception as e:
                log.warning("creator %s: a step batch failed: %s", self.host, e)
                return ComponentBatchReply([ComponentReply(error=f"{type(e).__name__}: {e}")])
        if not isinstance(query.payload, ComponentCall):
            return query.error("expected a drd.component.call")
        try:
            return self.handle(query.payload)
        except CreatorError as e:
            return query.error(str(e))
        except Exception as e:  # setup raised, a driver could not be built: this call fails, we go on
            log.warning("creator %s: %s of %s failed: %s", self.host, query.payload.op, query.payload.path, e)
            return ComponentReply(error=f"{type(e).__name__}: {e}")


def _epoch_of(holder: dict[str, Instance], need: str) -> Callable[[], int | None]:
    return lambda: holder["it"].epochs.get(need)


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
