"""The Component Creator of one host: runs the components whose devices this host owns.

It serves `drd/<cluster>/host/<host>/creator` with `drd.runtime.remote.ComponentCall`s from the controller's
executive (through `RemoteComponent` proxies) and answers each with a `ComponentReply`. It is closed:

- it instantiates only elementary behaviors declared by a manifest of its own catalog, from that manifest's
  entry point (never a module or class named on the wire);
- parameters must be declared by the manifest and of its declared type (`float`, `duration`, `int`...);
- a need's resource must be a device of this host; its driver is this host's (`drd.hw.drivers`), fenced by
  the grant's epoch as in the dry-run (`drd.runtime.fence.Fenced`).

Component code runs in worker processes (`drd.daemon.workers`): a pre-started container shared by the
instances whose manifest says `process: container` (and the same `scheduling`), or a process of its own for
`process: dedicated`. What stays here, on the trusted side: the checks above, the drivers and their fencing,
the arbitration below and the simulator. Inside the worker a component's devices are proxies: each method
call comes back over the pipe and runs here on the `Fenced` driver, so one call costs one pipe round trip plus
one per driver call, and a batch one round trip per run of consecutive steps in the same process. A worker
that dies fails the calls of its instances (`component process of X died (exit code -9)`) and nothing else;
the pool replaces it. A new mission retires the processes of the previous one. `Tune` (on the Creator's key)
changes the CPU affinity and nice of the process running an instance at run time.

Actuator commands of one control
cycle are arbitrated per driver as the dry-run's `Arbiter` does (highest priority, then the behavior
declared last), but executed at once: a lower-ranked command that comes after a higher-ranked one in the
same round is dropped, and one that comes before is overwritten, so the last setpoint is the same.

`sim` drivers reach the simulator through a `drd.sim.service.RemoteSimulation`, built per mission for the
world the call names; on the simulator host itself they call the simulation directly
(`drd.sim.service.LocalSimulation`, under the service's lock), as in the dry-run.
"""

from __future__ import annotations

import cProfile
import logging
import os
import pickle
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import psutil

from drd.bus import Bus, BusError, Message, Query, Reply
from drd.daemon.keys import ClusterKeys
from drd.daemon.messages import InstanceInfo
from drd.daemon.workers import (
    DEFAULT_SIZE,
    Tune,
    Tuned,
    Worker,
    WorkerDied,
    WorkerPool,
    apply_scheduling,
    device_methods,
    reading_key,
    scheduling_of,
)
from drd.hosts import Cluster
from drd.runtime.fence import Arbiter, Fenced, Proposal, is_command
from drd.runtime.remote import ComponentBatch, ComponentBatchReply, ComponentCall, ComponentReply
from dsl.catalog import Catalog, ComponentType, Kind, Process

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


#: Instance states, as announced to the Component Database.
RUNNING, SUSPENDED, TERMINATED, FAILED = "running", "suspended", "terminated", "failed"
_STATE_AFTER = {"start": RUNNING, "resume": RUNNING, "suspend": SUSPENDED, "terminate": TERMINATED}


@dataclass
class Instance:
    """A component instance as the Creator keeps it: the process running its code, and its fenced devices."""

    name: str
    bindings: dict[str, list[str]]
    worker: Worker
    devices: dict[str, Fenced] = field(default_factory=dict)
    epochs: dict[str, int | None] = field(default_factory=dict)
    setup: tuple[Any, ...] | None = None  # sent with its first call (entry point, resources, device methods)
    state: str = "starting"
    dead: str = ""  # how its process went, once it has
    notes: list[str] = field(default_factory=list)  # scheduling not applied: told in the start reply's logs
    readings: dict[str, frozenset[str]] = field(default_factory=dict)  # need -> its driver's `READINGS`
    reads: list[tuple[Any, ...]] = field(default_factory=list)  # readings of its last step: read ahead of the next
    asked: list[tuple[Any, ...]] = field(default_factory=list)  # readings it asked over the pipe in this step


class CreatorError(ValueError):
    """A call refused outright (unknown component, bad parameter, a device of another host)."""


class Creator:
    def __init__(self, bus: Bus | None, cluster: Cluster, host: str, catalog: Catalog, *,
                 sim_service: Any = None, pool: WorkerPool | None = None,
                 workers: int | None = None, on_change: Callable[[], None] | None = None) -> None:
        """`pool`: the worker processes to use (default: a pool of `workers` idle ones, else `$DRD_WORKERS`, else
        2, owned and closed by this Creator); `on_change` is called when the announced instances change."""
        self.cluster = cluster
        self.host = host
        self.catalog = catalog
        self.instances: dict[str, Instance] = {}
        self.mission = ""
        self.calls = 0
        self.arbiter = CycleArbiter()
        self._sim_service = sim_service  # this host's own SimulationService (drd.sim.service), if it has one
        self._bus = bus
        self._drivers: Any = None
        self._sim: Any = None  # a RemoteSimulation, when the drivers reach the simulator through requests
        self._world: Any = None  # the simulation the drivers use (local or remote), for its `version`
        self._ahead_version: int | None = None  # the world's version when the current run's readings were read
        mine = cluster.host(host)
        self._devices = {d.id for d in mine.devices} | {r.id for r in mine.robots}  # what a need may be bound to
        self._command_errors: list[tuple[str, str]] = []  # (instance path, error) of setpoints that raised
        self._lock = threading.Lock()
        self._own_pool = pool is None
        self.pool = pool if pool is not None else WorkerPool(_pool_size(workers), preload=behavior_modules(catalog))
        self._workers: dict[int, Worker] = {}  # the processes taken from the pool for this mission, by pid
        self._on_change = on_change
        self._dirty = False
        self._infos: list[InstanceInfo] = []
        self.key = f"drd/{cluster.name}/host/{host}/creator"
        self._keys = ClusterKeys(cluster.name)
        self._tokens: dict[str, Any] = {}  # instance path -> its liveliness token
        # DRD_PROFILE=path: profile the step batches (cProfile), dumped to path.<host> every 200 batches
        self._profile_path = os.environ.get("DRD_PROFILE", "")
        self._profile = cProfile.Profile() if self._profile_path else None
        self._profiled = 0
        self._queryable = bus.serve(self.key, self._serve) if bus else None

    def close(self) -> None:
        """Stop serving and kill every worker process (the pool's too, if this Creator owns it)."""
        if self._queryable is not None:
            self._queryable.close()
        with self._lock:
            self._retire_all()
            self.instances.clear()
            self._dirty = False
            self._infos = []
            self._sync_tokens(set())
        if self._own_pool:
            self.pool.close()

    def names(self) -> list[tuple[str, str]]:
        """(instance path, component) of the instances of the current mission."""
        return [(path, inst.name) for path, inst in self.instances.items()]

    def instance_infos(self) -> list[InstanceInfo]:
        """The instances to announce: those of the current mission not terminated (`failed` if their process died)."""
        return list(self._infos)

    # -- the seam: one call in, one reply out ---------------------------------------------------------

    def handle(self, call: ComponentCall) -> ComponentReply:
        with self._lock:
            if self._sim is not None:
                self._sim.owner = call.path
            try:
                inst = self._prepare(call)
                reply = self._run(inst.worker, [(call, inst)], {})[0]
            finally:
                refused = self._flush_sim()
                self._publish()
            if refused and not reply.error:
                reply = ComponentReply(reply.status, reply.outputs, reply.events, reply.logs, reply.shared,
                                       reply.dependencies, refused[0][1])
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
        """Consecutive steps whose instances share a process go to it in one round trip (a run); the worker
        stops a run where this loop would have stopped, and `latest` chains shared dicts across runs."""
        replies: list[ComponentReply] = []
        latest: dict[str, Any] = {}  # shared dict id on the controller -> its value after the last step
        with self._lock:
            owners: dict[str, int] = {}
            stepped = self._step_world(batch.sim_step) if batch.sim_step else None
            try:
                calls, i = batch.calls, 0
                while i < len(calls):
                    run: list[tuple[ComponentCall, Instance]] = []
                    refused = ""
                    while i < len(calls):
                        call = calls[i]
                        if call.op != "step":
                            raise CreatorError(f"a batch holds steps only, not {call.op!r}")
                        try:
                            inst = self._prepare(call)
                        except CreatorError as e:
                            refused = f"{self.host}'s Creator refused step of {call.path}: {e}"
                            break
                        if run and inst.worker is not run[0][1].worker:
                            break
                        run.append((call, inst))
                        i += 1
                    if run:
                        for k, (call, _) in enumerate(run):
                            owners[call.path] = len(replies) + k
                        got = self._run(run[0][1].worker, run, latest)
                        replies += got
                        last = got[-1]
                        if len(got) < len(run) or last.events or last.dependencies or last.error:
                            break  # the controller reacts to this before the next step
                    if refused:
                        replies.append(ComponentReply(error=refused))
                        break
            except Exception as e:  # the world stepped: the reply must still say so, or the controller is behind
                if stepped is None:
                    raise
                log.warning("creator %s: a step batch failed after its simulation step: %s", self.host, e)
                replies.append(ComponentReply(error=f"{type(e).__name__}: {e}"))
            finally:
                for path, error in self._flush_sim():
                    at = owners.get(path)
                    if at is not None and at < len(replies) and not replies[at].error:
                        r = replies[at]
                        replies[at] = ComponentReply(r.status, r.outputs, r.events, r.logs, r.shared, r.dependencies,
                                                    error)
                self._publish()
        if stepped is None:
            return ComponentBatchReply(replies)
        return ComponentBatchReply(replies, stepped.time, stepped.version)

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
        """Send the actuator commands the drivers queued (one request): [(instance path, error)] of refusals, with
        the setpoint commands that raised here (sent by workers without waiting, see `_exchange`)."""
        refused, self._command_errors = self._command_errors, []
        sim = self._sim
        if sim is None or not hasattr(sim, "flush"):
            return refused
        sim.owner = ""
        refused += [(path, f"component raised HardwareError: {error}") for path, error in sim.flush()]
        return refused

    def _prepare(self, call: ComponentCall) -> Instance:
        """Everything before the call goes to the worker: checks, mission, sim clock, placement, epochs."""
        if call.op not in OPS:
            raise CreatorError(f"unknown op {call.op!r}: use {', '.join(OPS)}")
        if call.mission != self.mission:
            self._new_mission(call.mission)
        if self._sim is not None and call.sim_version > self._sim.version:  # a batch that stepped knows better
            self._sim.sync(call.sim_time, call.sim_version)
        inst = self.instances.get(call.path)
        if call.op == "start":
            inst = self._start_instance(call, inst)
        elif inst is None:
            raise CreatorError(f"no instance {call.path} of mission {call.mission} on {self.host}")
        if call.epochs is not None:
            inst.epochs.update(call.epochs)
        self.arbiter.round = (call.now, call.op == "step")
        return inst

    def _run(self, worker: Worker, run: list[tuple[ComponentCall, Instance]],
             latest: dict[str, Any]) -> list[ComponentReply]:
        """Calls of instances of one worker, in one round trip (plus one per driver request); a prefix of replies."""
        first, inst0 = run[0]
        if inst0.dead:
            return [ComponentReply(error=f"component process of {first.path} {inst0.dead}")]
        msgs = []
        aheads: list[dict[tuple[Any, ...], Any] | None] = []
        self._ahead_version = getattr(self._world, "version", None)
        for call, inst in run:
            self.calls += 1
            ahead = self._read_ahead(call.path, inst) if call.op == "step" else None
            aheads.append(ahead)
            msgs.append((call.path, call.op, call.now, call.status, call.shared, call.shared_ids, call.siblings,
                         call.params if call.op == "start" else None, inst.setup, ahead))
            inst.setup = None
        try:
            raw = self._exchange(worker, ("run", msgs, latest))
        except WorkerDied as e:
            self._worker_died(worker, str(e))
            return [ComponentReply(error=f"component process of {first.path} {e}")]
        replies = []
        for (call, inst), ahead, (status, outputs, events, logs, shared, deps, error, setup_failed, unused) in zip(
                run, aheads, raw, strict=False):
            if ahead is not None or inst.asked:
                inst.reads = _reads_next(ahead, unused, inst.asked)
            if setup_failed:  # setup raised: the start fails and the instance is forgotten
                self._forget(call.path)
                replies.append(ComponentReply(error=error))
                continue
            if inst.notes:
                logs, inst.notes = [*inst.notes, *logs], []
            state = _STATE_AFTER.get(call.op)
            if state is not None and state != inst.state:
                inst.state = state
                self._dirty = True
            replies.append(ComponentReply(status, outputs, events, logs, shared, deps, error))
            if shared is not None and call.shared_ids:
                for name, ref in call.shared_ids.items():
                    if name in shared:
                        latest[ref] = shared[name]
        return replies

    def _exchange(self, worker: Worker, msg: tuple[Any, ...]) -> Any:
        """Send `msg`, serve the worker's driver requests until its final `done`; WorkerDied if it goes."""
        worker.send(msg)
        while True:
            got = worker.recv(self.pool.call_timeout)
            kind = got[0] if isinstance(got, tuple) and got else None
            if kind == "done":
                return got[1]
            if kind in ("dev", "attr") and len(got) >= 4:
                self._device_request(worker, got)
                continue
            if kind == "cmd" and len(got) >= 6:  # a setpoint: no answer awaited, a refusal fails the step after
                error = self._device_request(worker, got, answer=False)
                if error is not None:
                    self._command_errors.append((got[1], f"component raised {type(error).__name__}: {error}"))
                continue
            worker.kill()
            raise WorkerDied(f"sent an unexpected message ({str(kind)[:40]}): killed")

    def _device_request(self, worker: Worker, req: tuple[Any, ...], answer: bool = True) -> Exception | None:
        """Run one driver call (or attribute read) of a component in `worker` on its fenced driver; answer it
        (or, for a setpoint command, return what it raised). An answer tells the worker when the world changed
        since its readings were read ahead (a launch): it then asks for the rest of the run's readings."""
        kind, path, need, name = req[:4]
        args, kwargs = (req[4], req[5]) if len(req) >= 6 else ((), {})
        try:
            inst = self.instances.get(path) if isinstance(path, str) else None
            if inst is None or inst.worker is not worker:
                raise LookupError(f"no instance {path!r} in this process")
            if kind != "cmd" and isinstance(need, str) and name in inst.readings.get(need, ()):
                key = reading_key(kind, need, name, args, kwargs)
                if key is not None and key not in inst.asked:
                    inst.asked.append(key)
            result: tuple[Any, ...] = ("ok", self._device_value(inst, path, kind, need, name, args, kwargs))
        except Exception as e:  # the component sees the driver's exception, as it would in process
            if not answer:
                return e
            result = ("raise", e)
        if not answer:
            return None
        changed: tuple[str, ...] = ()
        if self._ahead_version is not None and getattr(self._world, "version", None) != self._ahead_version:
            changed, self._ahead_version = ("changed",), None
        try:
            worker.send((*result, *changed))
        except (pickle.PicklingError, TypeError, AttributeError) as e:
            what = f"{type(result[1]).__name__}: {result[1]}" if result[0] == "raise" else "its result"
            worker.send(("raise", RuntimeError(f"{need}.{name}: {what} cannot be sent to the component process"
                                               f" ({e})"), *changed))
        return None

    def _device_value(self, inst: Instance, path: str, kind: str, need: Any, name: Any, args: Any,
                      kwargs: Any) -> Any:
        """A driver call (`dev`, `cmd`) or attribute read (`attr`) of instance `path` on its fenced driver."""
        fenced = inst.devices.get(need) if isinstance(need, str) else None
        if fenced is None:
            raise LookupError(f"{path}: no device for need {need!r} (have: {', '.join(inst.devices) or 'none'})")
        if not isinstance(name, str) or name.startswith("_"):
            raise AttributeError(f"{need}: no public attribute {name!r}")
        if self._sim is not None:
            self._sim.owner = path
        target = getattr(fenced, name)
        if kind in ("dev", "cmd"):
            return target(*args, **kwargs)
        if callable(target):
            raise TypeError(f"{need}.{name} is a method: call it")
        return target

    def _read_ahead(self, path: str, inst: Instance) -> dict[tuple[Any, ...], Any] | None:
        """The readings `inst` made in its last step, read now for this one (`READINGS` of the `sim` drivers: a
        function of the world's instant, so reading ahead changes nothing); each saves a pipe round trip. One
        that raises is left out: asked over the pipe, it raises there as it would have."""
        inst.asked = []
        if not inst.reads or self._ahead_version is None:
            return None
        ahead: dict[tuple[Any, ...], Any] = {}
        for key in inst.reads:
            kind, need, name, args, kwargs = key
            try:
                ahead[key] = self._device_value(inst, path, kind, need, name, args, dict(kwargs))
            except Exception:
                continue
        return ahead or None

    # -- processes ----------------------------------------------------------------------------------------

    def _place(self, ct: ComponentType) -> tuple[Worker, list[str]]:
        """The process for a new instance of `ct`: the mission's container with the same scheduling (not tuned
        since), else a pre-started worker from the pool (always, for `process: dedicated`)."""
        sched = ct.scheduling
        key = (tuple(sched.cores) if sched.cores is not None else None, sched.nice)
        if ct.process is not Process.DEDICATED:
            for w in self._workers.values():
                if w.kind == "container" and w.key == key and not w.tuned and w.alive:
                    return w, []
        w = self.pool.take()
        w.kind = "dedicated" if ct.process is Process.DEDICATED else "container"
        w.key = key
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
            inst = self.instances.get(path)
            if inst is not None and inst.worker is worker:
                inst.dead, inst.state = reason, FAILED
        log.warning("creator %s: component process %d (%s) %s", self.host, worker.pid, ", ".join(names) or "idle",
                    reason)
        self._workers.pop(worker.pid, None)
        self.pool.release(worker)
        self._dirty = True

    def _forget(self, path: str) -> None:
        """Drop an instance: from its container (which goes on), or with its dedicated process."""
        inst = self.instances.pop(path, None)
        if inst is None:
            return
        self._dirty = True
        w = inst.worker
        w.instances.discard(path)
        if w.died:
            return
        if w.kind == "dedicated" or not w.alive:
            self._workers.pop(w.pid, None)
            self.pool.release(w)
            return
        try:
            w.send(("drop", [path]))
        except WorkerDied:
            self._worker_died(w, w.died)

    def _retire_all(self) -> None:
        for w in self._workers.values():
            self.pool.release(w)
        self._workers.clear()

    def _publish(self) -> None:
        """Refresh what `instance_infos` says, and tell the daemon (to announce it) when it changed."""
        if not self._dirty:
            return
        self._dirty = False
        infos = [InstanceInfo(path, inst.name, self.host, inst.state, self.key, inst.worker.pid)
                 for path, inst in self.instances.items() if inst.state not in (TERMINATED, "starting")]
        if infos != self._infos:
            self._infos = infos
            self._sync_tokens({i.name for i in infos})
            if self._on_change is not None:
                self._on_change()

    def _sync_tokens(self, running: set[str]) -> None:
        """A liveliness token per running instance (`drd/<c>/instance/<host>/<path>`): it vanishes when the
        instance ends or its daemon dies, so a peer sees either without asking."""
        if self._bus is None:
            return
        for path in [p for p in self._tokens if p not in running]:
            self._tokens.pop(path).close()
        for path in running - self._tokens.keys():
            try:
                self._tokens[path] = self._bus.declare_token(self._keys.instance(self.host, path))
            except (ValueError, BusError) as e:  # a path that is no key (never for compiled missions): say so once
                log.warning("creator %s: no liveliness token for %s: %s", self.host, path, e)

    # -- run-time scheduling ------------------------------------------------------------------------------

    def tune(self, req: Tune) -> Tuned:
        """Set cores and/or nice of the process running `req.instance`; what it runs with now and who shares it.

        Raises CreatorError: unknown instance, cores or nice out of range, or the OS refused (privileges)."""
        with self._lock:
            inst = self.instances.get(req.instance)
            if inst is None or inst.state in (TERMINATED, "starting"):
                running = sorted(p for p, i in self.instances.items() if i.state not in (TERMINATED, "starting"))
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
            return Tuned(req.instance, self.host, w.pid, w.kind, now_cores, now_nice,
                         sorted(w.instances - {req.instance}))

    # -- helpers ----------------------------------------------------------------------------------------

    def _new_mission(self, mission: str) -> None:
        """A new mission: the previous one's processes are retired (killed; the pool has fresh ones ready)."""
        self._retire_all()
        self.instances.clear()
        self.mission = mission
        self._drivers = self._sim = self._world = None
        self._dirty = True

    def _drivers_for(self, world: str) -> Any:
        if self._drivers is None:
            from drd.hw.drivers import drivers_for
            from drd.sim.service import RemoteSimulation

            service = self._sim_service
            local = service.local(world) if service is not None else None
            if local is not None:  # the simulator is in this process: direct calls, as in the dry-run
                sim: Any = local
            elif service is not None:
                sim = self._sim = RemoteSimulation(service.handle, world)
            elif self._bus is not None:
                sim = self._sim = RemoteSimulation.over(self._bus, self.cluster.name, world)
            else:
                sim = None
            self._drivers = drivers_for(self.cluster, self.host, sim, catalog=self.catalog)
            self._world = sim
        return self._drivers

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
        for need, binding in (call.bindings or {}).items():
            if len(binding) != 3 or binding[0] not in self._devices:
                raise CreatorError(f"{call.path}: need {need} is bound to {binding[0] if binding else '?'},"
                                   f" not a device of {self.host}")
        return ct

    def _start_instance(self, call: ComponentCall, inst: Instance | None) -> Instance:
        ct = self._check(call)
        bindings = dict(call.bindings or {})
        if inst is not None and not inst.dead and inst.name == call.component and inst.bindings == bindings:
            return inst  # the worker resets its params and outputs on start
        if inst is not None:
            self._forget(call.path)
        drivers = self._drivers_for(call.world)
        devices: dict[str, Fenced] = {}
        methods: dict[str, list[str]] = {}
        commands: dict[str, list[str]] = {}  # setpoints: sent by the worker without waiting for an answer
        readings: dict[str, frozenset[str]] = {}
        rank = (int((call.rank or [0, 0])[0]), int((call.rank or [0, 0])[1]))
        holder: dict[str, Instance] = {}
        for need, (rid, robot, part) in bindings.items():
            by_robot = drivers.robots.get(robot, {}) if robot and part else {}
            driver = by_robot.get(part) or drivers.devices.get(rid)
            if driver is not None:
                devices[need] = Fenced(driver, _epoch_of(holder, need), self.arbiter, rank, call.path)
                methods[need] = device_methods(driver)
                readings[need] = frozenset(getattr(driver, "READINGS", ()))
                commands[need] = setpoints(driver, methods[need])
        worker, notes = self._place(ct)
        assert ct.entry_point is not None
        new = Instance(call.component, bindings, worker, devices,
                       setup=(ct.entry_point, {n: b[0] for n, b in bindings.items()}, methods, commands),
                       notes=notes, readings=readings)
        holder["it"] = new
        self.instances[call.path] = new
        worker.instances.add(call.path)
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
        if isinstance(query.payload, Tune):
            try:
                return self.tune(query.payload)
            except CreatorError as e:
                return query.error(str(e))
        if not isinstance(query.payload, ComponentCall):
            return query.error("expected a drd.component.call")
        try:
            return self.handle(query.payload)
        except CreatorError as e:
            return query.error(str(e))
        except Exception as e:  # a driver could not be built, no worker could start: this call fails, we go on
            log.warning("creator %s: %s of %s failed: %s", self.host, query.payload.op, query.payload.path, e)
            return ComponentReply(error=f"{type(e).__name__}: {e}")


def setpoints(driver: object, methods: list[str] | None = None) -> list[str]:
    """The commands a worker sends without waiting for an answer: setpoints (`is_command`), except those the
    driver says change its readings at once (`CHANGES_READINGS`, a hop): their answer says the world changed,
    so the worker stops using the readings read ahead of the step. `methods`: `device_methods(driver)`, when
    the caller has them already."""
    sudden = getattr(driver, "CHANGES_READINGS", ())
    if methods is None:
        methods = device_methods(driver)
    return [m for m in methods if m not in sudden and is_command(getattr(driver, m))]


#: At most this many readings of one instance are read ahead of its step.
MAX_AHEAD = 32


def _reads_next(ahead: dict[tuple[Any, ...], Any] | None, unused: Any,
                asked: list[tuple[Any, ...]]) -> list[tuple[Any, ...]]:
    """What to read ahead of an instance's next step: what it read in this one, from ahead (all but `unused`)
    or over the pipe (`asked`)."""
    left = {tuple(k) for k in unused} if isinstance(unused, list) else set()
    reads = [k for k in ahead or () if k not in left]
    return (reads + [k for k in asked if k not in (ahead or {})])[:MAX_AHEAD]


def behavior_modules(catalog: Catalog) -> list[str]:
    """The modules of the catalog's elementary behaviors: the fork server imports them once for every worker."""
    return sorted({ct.entry_point.partition(":")[0] for ct in catalog.components.values()
                   if ct.kind is Kind.BEHAVIOR and ct.entry_point})


def _pool_size(workers: int | None) -> int:
    if workers is not None:
        return workers
    text = os.environ.get("DRD_WORKERS", "")
    try:
        return int(text) if text else DEFAULT_SIZE
    except ValueError:
        log.warning("DRD_WORKERS=%r is not a number: using %d idle workers", text, DEFAULT_SIZE)
        return DEFAULT_SIZE


def _os_reason(e: BaseException) -> str:
    if isinstance(e, psutil.AccessDenied | PermissionError):
        return ("permission denied (raising a process's priority, a lower nice, needs root or CAP_SYS_NICE;"
                " some cores may be outside this daemon's cgroup)")
    if isinstance(e, psutil.NoSuchProcess):
        return "the process is gone"
    return f"{type(e).__name__}: {e}"


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
