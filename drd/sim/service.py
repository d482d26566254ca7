"""The simulator as a cluster component: `SimulationService` on the `simulator` host, `RemoteSimulation` elsewhere.

The host with role `simulator` owns one `drd.sim.physics.Simulation` (the world of the running mission) and
serves it on one queryable, `drd/<cluster>/sim`, with `SimRequest` messages:

- `reset` (world name, seed): a fresh simulation for a new mission;
- `step` (dt): advance the physics; the controller calls it once per control cycle (lockstep);
- `call` (method, args): one of the `Simulation` methods the `sim` drivers use (`ranges`, `camera`,
  `set_velocity`, `launch`...), checked against `ALLOWED_METHODS`: nothing else is ever called, and the
  arguments are plain JSON values (never code);
- `attr` (name): one of `ALLOWED_ATTRS` (`jump_height`, `max_jump`);
- `multi` (args: `[[method, [args...]], ...]`): several `call`s in order in one request; the value is one
  `[value, error]` pair per call (a refused call does not stop the others);

Every `SimReply` carries the simulation's `time` and `version`, so that a `RemoteSimulation` keeps them
current without asking. On the other hosts the `sim` drivers get a `RemoteSimulation`: duck-typed to the
`Simulation` methods they call, each a bus request; it raises `SimError` when the simulator refused a call,
so the drivers report a `HardwareError` exactly as they do in the dry-run.
"""

from __future__ import annotations

import dataclasses
import math
import re
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drd.bus import Bus, Message, Query, Reply, message, typed_handler
from drd.bus.keys import is_concrete
from drd.profiling import Sampler
from drd.sim.observe import Observations, SensorTap

if TYPE_CHECKING:
    from drd.hosts import Cluster

#: The Simulation methods a remote driver may call (what components/sim/* use), and their arity bounds.
ALLOWED_METHODS: dict[str, tuple[int, int]] = {
    "ranges": (2, 4), "camera": (3, 4), "brightness": (3, 4), "odometry": (1, 1), "origin": (1, 1),
    "battery": (1, 1), "magazine": (1, 1),
    "set_max_speed": (2, 2), "set_velocity": (3, 3), "stop": (1, 1), "launch": (3, 3), "jump": (2, 2),
    "radio_ok": (3, 3), "pose": (1, 1), "command": (1, 1), "set_wheels": (3, 3), "light": (2, 2),
}
#: Commands that return nothing and change no reading before the next step: a `RemoteSimulation` queues them
#: and sends them together (`multi`) at the end of the Creator's call, before the controller steps the physics.
DEFERRED = frozenset({"set_velocity", "stop", "set_wheels"})
#: Readings that change only with `Simulation.version` (no noise drawn): a `RemoteSimulation` keeps them per version.
PER_VERSION = frozenset({"odometry", "origin", "battery", "magazine", "pose"})
#: At most this many calls in one `multi` request.
MAX_MULTI = 64
#: The error of a `multi` call not made because a guarded call before it (`[method, [args], true]`) was refused.
SKIPPED = "skipped: a guarded call before it was refused"  # (later DEFERRED commands are still made)
#: Plain attributes a remote driver may read once (at construction).
ALLOWED_ATTRS = frozenset({"jump_height", "max_jump", "time", "version"})
#: Only world names, resolved under `worlds/` of the simulator host: never a path from the wire.
WORLD_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$")
ROOT = Path(__file__).resolve().parents[2]


@message("drd.sim.request", 1)
class SimRequest(Message):
    """`op` is reset, step, call, multi or attr; see the module docstring."""

    op: str
    method: str = ""
    args: list[Any] | None = None
    world: str = ""
    seed: int = 0
    dt: float = 0.0


@message("drd.sim.reply", 1)
class SimReply(Message):
    """The value of a call (encoded by `encode_value`), and the simulation's time and version after it.

    `error` is set (and `value` None) when the simulator refused the call (a `SimError`: an unknown robot,
    a Scout that cannot jump now...)."""

    value: Any
    time: float
    version: int
    world: str = ""
    error: str = ""


def key(cluster: str) -> str:
    return f"drd/{cluster}/sim"


def world_key(cluster: str) -> str:
    """What a recording client reads of the running world (`WorldObserve`): open to every role, it changes
    nothing (the simulator's own key is the daemons' only, docs/security.md)."""
    return f"drd/{cluster}/world"


#: Readings a `WorldObservation` carries at most (a page; the client asks again from `next`).
OBSERVE_PAGE = 400


@message("drd.world.observe", 1)
class WorldObserve(Message):
    """Every robot's pose now, and the sensor readings numbered `after` or later (`drd.sim.observe`)."""

    after: int = 0


@message("drd.world.observation", 1)
class WorldObservation(Message):
    """The world at simulator time `time`: poses (x, y, heading) of the robots not in a magazine, who is in which
    (`carried`: Scout -> Ranger), the intruders (x, y), and a page of readings; `next` is the number to ask from,
    `more` says readings wait beyond this page, `missed` that some were dropped before this reader got them."""

    time: float
    world: str
    poses: dict[str, list[float]]
    carried: dict[str, str]
    intruders: dict[str, list[float]]
    readings: list[dict[str, Any]]
    next: int
    more: bool = False
    missed: bool = False


def world_file(name: str, beside: Sequence[Path] = (), root: Path = ROOT) -> Path:
    """`corridor` or `corridor.yaml` -> `worlds/corridor.yaml` of the first folder of `beside` that has it (the hosts
    file's folder, as `world_dirs` gives it: where `missionctl world generate` writes, and where a dry-run looks),
    else of this installation; ValueError otherwise. A name, never a path: it travels on the wire, and each host
    finds it in its own folders."""
    stem = name[:-5] if name.endswith(".yaml") else name
    stem = Path(stem).name if "/" in stem and Path(stem).parent.name == "worlds" else stem
    if not WORLD_NAME.match(stem):
        raise ValueError(f"bad world name {name!r}: give the name of a world under worlds/ (like corridor), beside "
                         "the hosts file or of drd's own")
    folders = [*(Path(b) / "worlds" for b in beside), root / "worlds"]
    for folder in folders:
        if (folder / f"{stem}.yaml").is_file():
            return folder / f"{stem}.yaml"
    known = sorted({p.stem for folder in folders for p in folder.glob("*.yaml")})
    raise ValueError(f"no world {stem!r} in {' or '.join(str(f) for f in folders)} (known: {', '.join(known)})")


def world_dirs(cluster: Cluster) -> tuple[Path, ...]:
    """The folder of the hosts file `cluster` was read from (its worlds/ comes first), or none when it was not read
    from a file."""
    source = Path(cluster.source)
    return (source.absolute().parent,) if source.is_file() else ()


# -- values on the wire ------------------------------------------------------------------------------

def encode_value(value: Any) -> Any:
    """Simulator results as JSON: dataclasses (Pose, Flight, Detection) as tagged dicts, tuples as lists."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {"__type": type(value).__name__,
                **{f.name: encode_value(getattr(value, f.name)) for f in dataclasses.fields(value)}}
    if isinstance(value, tuple | list):
        return [encode_value(v) for v in value]
    if isinstance(value, dict):
        return {str(k): encode_value(v) for k, v in value.items()}
    if isinstance(value, float) and not math.isfinite(value):
        return {"__float": repr(value)}
    if hasattr(value, "value") and type(value).__module__.startswith("drd."):  # an enum (DoorState)
        return value.value
    return value


def _decoders() -> dict[str, Callable[..., Any]]:
    from drd.sim import Detection, Flight, Pose

    return {"Pose": Pose, "Flight": Flight, "Detection": Detection}


def decode_value(value: Any, types: dict[str, Callable[..., Any]] | None = None) -> Any:
    """The inverse of `encode_value`, for the allow-listed result types only (anything else stays a dict)."""
    types = types if types is not None else _decoders()
    if isinstance(value, list):
        return [decode_value(v, types) for v in value]
    if isinstance(value, dict):
        if "__float" in value:
            return float(value["__float"])
        kind = value.get("__type")
        fields = {k: decode_value(v, types) for k, v in value.items() if k != "__type"}
        if isinstance(kind, str) and kind in types:
            if kind == "Flight":
                fields["start"], fields["end"] = tuple(fields["start"]), tuple(fields["end"])
            return types[kind](**fields)
        return fields
    return value


# -- the service -------------------------------------------------------------------------------------

class LocalSimulation:
    """A simulation in this process, as the `sim` drivers of the simulator host's own Creator see it: each method
    call runs at once under the service's lock. No request objects, no JSON values, nothing deferred: readings
    and commands behave exactly as in the dry-run."""

    __slots__ = ("_sim", "_service")

    def __init__(self, sim: Any, service: SimulationService) -> None:
        self._sim = sim
        self._service = service

    def __getattr__(self, name: str) -> Any:
        value = getattr(self._sim, name)
        if not callable(value):
            return value
        service, sim = self._service, self._sim

        def call(*args: Any, **kwargs: Any) -> Any:
            with service._lock:
                if service.sim is not sim:  # a `reset` replaced the world under us: never drive a stale one
                    from drd.sim import SimError

                    raise SimError(f"the world was reset: {name} on a simulation that is gone")
                return value(*args, **kwargs)
        return call


class SimulationService:
    """Owns the simulation of the running mission and answers `SimRequest`s (one lock: calls are serialized)."""

    def __init__(self, bus: Bus | None, cluster: str, *, root: Path = ROOT, beside: Sequence[Path] = (),
                 charges: Mapping[str, float] | None = None) -> None:
        """`charges`: hosts.yaml's `battery` of each robot (`drd.sim.world.hosts_charges`), its start charge in every
        world this service loads that does not give one."""
        self.cluster = cluster
        self.charges = dict(charges or {})
        self.root, self.beside = root, tuple(beside)  # where worlds are found (`world_file`)
        self.sim: Any = None
        self.world_name = ""
        self.calls = 0
        self._lock = threading.Lock()
        self._sampler = Sampler("sim", every=500)  # DRD_PROFILE: requests from other hosts only
        self.observations = Observations()  # what the running simulation's sensors read (`drd/<c>/world`)
        self._queryable = bus.serve(key(cluster), self._serve) if bus is not None else None
        self._world_queryable = (bus.serve(world_key(cluster), typed_handler(WorldObserve, self.observe, (ValueError,),
                                                                          exact=False))
                                 if bus is not None else None)

    def local(self, world: str) -> LocalSimulation | None:
        """The running simulation for drivers of this very process (the simulator host's Creator), or None when
        it is not `world` (the caller then goes through requests, which say what is wrong)."""
        with self._lock:
            if self.sim is None or self.world_name != world:
                return None
            return LocalSimulation(self.sim, self)

    def reset(self, world: str, seed: int = 0) -> SimReply:
        from drd.sim import Simulation, load_world
        from drd.sim.world import charged

        path = world_file(world, self.beside, self.root)
        sim = Simulation(charged(load_world(path), self.charges), seed=seed)
        observations = Observations()
        SensorTap(observations).tap(sim)  # every reading, whoever reads: a recording client may ask for them
        with self._lock:
            self.sim, self.world_name, self.observations = sim, path.stem, observations
            return SimReply(None, sim.time, sim.version, path.stem)

    def handle(self, req: SimRequest) -> SimReply:
        """Answer one request; raises ValueError for a request that is refused outright."""
        if req.op == "reset":
            return self.reset(req.world, req.seed)
        from drd.sim import SimError

        with self._lock:
            sim = self.sim
            if sim is None:
                raise ValueError("no simulation is running (the controller resets it when a mission starts)")
            self.calls += 1
            if req.op == "step":
                if not (0 < req.dt <= 1.0):
                    raise ValueError(f"step dt must be in (0, 1] s, got {req.dt}")
                sim.step(req.dt)
                return SimReply(None, sim.time, sim.version, self.world_name)
            if req.op == "attr":
                if req.method not in ALLOWED_ATTRS:
                    raise ValueError(f"attribute {req.method!r} is not served (allowed: {sorted(ALLOWED_ATTRS)})")
                return SimReply(encode_value(getattr(sim, req.method)), sim.time, sim.version, self.world_name)
            if req.op == "multi":
                calls = list(req.args or [])
                if len(calls) > MAX_MULTI or not all(isinstance(c, list) and len(c) in (2, 3) and isinstance(c[0], str)
                                                     and isinstance(c[1], list) and (len(c) == 2 or c[2] is True)
                                                     for c in calls):
                    raise ValueError(f"multi takes up to {MAX_MULTI} [method, [args]] (or [method, [args], true])")
                out: list[list[Any]] = []
                guard_refused = False  # a guarded call was refused: the later calls not in DEFERRED are not made
                for call in calls:
                    if guard_refused and call[0] not in DEFERRED:
                        out.append([None, SKIPPED])
                        continue
                    try:
                        out.append([encode_value(self._call(sim, call[0], call[1])), ""])
                    except SimError as e:
                        out.append([None, str(e) or type(e).__name__])
                        guard_refused = guard_refused or len(call) == 3
                return SimReply(out, sim.time, sim.version, self.world_name)
            if req.op != "call":
                raise ValueError(f"unknown op {req.op!r}: use reset, step, call, multi or attr")
            try:
                value = self._call(sim, req.method, list(req.args or []))
            except SimError as e:
                return SimReply(None, sim.time, sim.version, self.world_name, error=str(e) or type(e).__name__)
            return SimReply(encode_value(value), sim.time, sim.version, self.world_name)

    @staticmethod
    def _call(sim: Any, method: str, args: list[Any]) -> Any:
        """One allow-listed method with plain arguments (SimError passes through; ValueError if refused)."""
        bounds = ALLOWED_METHODS.get(method)
        if bounds is None:
            raise ValueError(f"method {method!r} is not served (allowed: {', '.join(sorted(ALLOWED_METHODS))})")
        if not bounds[0] <= len(args) <= bounds[1]:
            raise ValueError(f"{method} takes {bounds[0]}..{bounds[1]} arguments, got {len(args)}")
        if any(isinstance(a, dict | list) for a in args):
            raise ValueError(f"{method}: arguments must be plain values")
        from drd.sim import SimError

        try:
            return getattr(sim, method)(*args)
        except SimError:
            raise
        except (TypeError, ValueError) as e:
            raise ValueError(f"{method}: {e}") from None

    def close(self) -> None:
        for queryable in (self._queryable, self._world_queryable):
            if queryable is not None:
                queryable.close()

    def observe(self, req: WorldObserve) -> WorldObservation:
        """The poses now and a page of readings (see `WorldObservation`); ValueError when no world runs."""
        with self._lock:
            sim, observations = self.sim, self.observations
            if sim is None:
                raise ValueError("no simulation is running (the controller resets it when a mission starts)")
            carried = {scout: r.id for r in sim.world.rangers for scout in sim.magazine(r.id)}
            poses = {rid: [p.x, p.y, p.heading] for rid in sim.robots if rid not in carried and (p := sim.pose(rid))}
            intruders = {iid: [x, y] for iid, (x, y) in sim.intruders().items()}
            now, name = sim.time, self.world_name
        # a cursor past the last reading asks for what comes next (one of 10**30 was echoed back in a reply no
        # encoder could write: wire audit 10, D4)
        readings, nxt, missed = observations.after(max(0, min(req.after, observations.next)), OBSERVE_PAGE)
        return WorldObservation(now, name, poses, carried, intruders, readings, nxt,
                                more=nxt < observations.next, missed=missed)

    def _serve(self, query: Query) -> Message | Reply:
        if not is_concrete(query.key):  # only the controller and the drivers ask, by this exact key
            return query.error(f"ask {query.queryable} by its exact key")
        if not isinstance(query.payload, SimRequest):
            return query.error("expected a drd.sim.request")
        with self._sampler.run():  # the controller's own requests are in its own profile
            try:
                return self.handle(query.payload)
            except ValueError as e:
                return query.error(str(e))


# -- the proxy ---------------------------------------------------------------------------------------

class RemoteSimulation:
    """A `Simulation` seen over the bus: what the `sim` drivers call, each a request to the simulator host.

    `time` and `version` are those of the last reply (the Creator also sets them from each step request,
    so a driver's per-instant cache works without a request). `world` is loaded locally from the same
    world name (every host has the same `worlds/`).

    Fewer round trips, same results: the commands of `DEFERRED` are queued (with the `owner`, the instance
    path the Creator is running) and sent by `flush()` in one `multi` request, which the Creator makes at the
    end of each call or batch, so before the controller steps the physics; any other call flushes them
    first, so the simulator sees every call in the order made. The readings of `PER_VERSION` are kept per
    sim version, and every reading request carries the queued commands before it and fetches along the
    odometry of the robots read so far (noiseless readings): one round trip per reading (see `_method`)."""

    def __init__(self, call: Callable[[SimRequest], SimReply], world: str, *, root: Path = ROOT,
                 beside: Sequence[Path] = ()) -> None:
        self._call = call
        self._world_name = world
        self._root, self._beside = root, tuple(beside)
        self._world: Any = None
        self._attrs: dict[str, Any] = {}
        self.time = 0.0
        self.version = 0
        self.calls = 0
        self.seconds = 0.0
        self.owner = ""
        self._queued: list[tuple[str, str, list[Any]]] = []  # (owner, method, args)
        self._cached: dict[tuple[Any, ...], Any] = {}  # (method, *args) -> value at self._cached_version
        self._cached_version = -1
        self._robots: dict[str, None] = {}  # robots whose odometry was read: fetched along each reading
        self._refused: list[tuple[str, str]] = []  # refused commands of other owners, for the next flush()

    @classmethod
    def over(cls, bus: Bus, cluster: str, world: str, timeout: float = 1.0,
             beside: Sequence[Path] = ()) -> RemoteSimulation:
        k = key(cluster)

        def call(req: SimRequest) -> SimReply:
            reply = bus.call(k, req, timeout=timeout)
            if not isinstance(reply, SimReply):
                raise TypeError(f"expected a drd.sim.reply, got a {type(reply).TYPE}")
            return reply
        return cls(call, world, beside=beside)

    def sync(self, time_: float, version: int) -> None:
        self.time, self.version = time_, version

    def flush(self) -> list[tuple[str, str]]:
        """Send the queued commands; [(owner, error)] for those the simulator refused (and for commands sent
        along an earlier reading whose refusal was not their owner's to see then)."""
        refused, self._refused = self._refused, []
        if not self._queued:
            return refused
        queued, self._queued = self._queued, []
        try:
            results = self._request(SimRequest("multi", args=[[m, a] for _, m, a in queued]))
        except Exception as e:  # the simulator did not answer (its host frozen or gone): each command failed, and
            # its owner says so; never the handler that flushed (the host serving it is not the one at fault)
            why = f"the simulator did not take the command: {type(e).__name__}: {e}"
            return refused + [(owner, why) for owner, _, _ in queued]
        return refused + [(owner, str(err)) for (owner, _, _), (_, err) in zip(queued, results, strict=False) if err]

    def _fresh(self) -> dict[tuple[Any, ...], Any]:
        if self._cached_version != self.version:
            self._cached.clear()
            self._cached_version = self.version
        return self._cached

    def _method(self, name: str, args: list[Any]) -> Any:
        """One reading (or a command, queued): a single `multi` request carries the queued commands first (each
        of the caller's guarded: if one is refused the reading is not made and the caller gets the refusal, as
        if they had been flushed before), then the reading, then the odometry of every robot read before and
        not yet known at this version (noiseless readings, so fetching them early changes no result)."""
        if name in DEFERRED:
            self._queued.append((self.owner, name, args))
            return None
        cached = self._fresh()
        key_ = (name, *args)
        if name in PER_VERSION and key_ in cached:
            return cached[key_]
        if name == "odometry" and len(args) == 1 and isinstance(args[0], str):
            self._robots.setdefault(args[0], None)
        if len(self._queued) >= MAX_MULTI:
            self._refused += self.flush()
        queued, self._queued = self._queued, []
        calls: list[list[Any]] = [[m, a, True] if owner == self.owner else [m, a] for owner, m, a in queued]
        calls.append([name, args])
        along = [r for r in self._robots if ("odometry", r) not in cached and key_ != ("odometry", r)]
        along = along[:MAX_MULTI - len(calls)]
        calls += [["odometry", [r]] for r in along]
        results = self._request(SimRequest("multi", args=calls))
        n = len(queued)
        refused = [(owner, str(err)) for (owner, _, _), (_, err) in zip(queued, results[:n], strict=False) if err]
        self._refused += [(owner, err) for owner, err in refused if owner != self.owner]
        fresh = self._fresh()
        for robot, (odometry, error) in zip(along, results[n + 1:], strict=False):
            if not error:
                fresh[("odometry", robot)] = decode_value(odometry)
        mine = [err for owner, err in refused if owner == self.owner]
        value, error = results[n] if len(results) > n else (None, "no reply")
        if mine or error:
            from drd.sim import SimError

            raise SimError(mine[0] if mine else error)
        value = decode_value(value)
        if name in PER_VERSION:
            fresh[key_] = value
        return value

    @property
    def world(self) -> Any:
        if self._world is None:
            from drd.sim import load_world

            self._world = load_world(world_file(self._world_name, self._beside, self._root))
        return self._world

    def _request(self, req: SimRequest) -> Any:
        from drd.sim import SimError

        t0 = time.perf_counter()
        reply = self._call(req)
        self.calls += 1
        self.seconds += time.perf_counter() - t0
        self.time, self.version = reply.time, reply.version
        if reply.error:
            raise SimError(reply.error)
        if req.op == "multi":
            return list(reply.value or [])
        return decode_value(reply.value)

    def _attr(self, name: str) -> Any:
        if name not in self._attrs:
            self._attrs[name] = self._request(SimRequest("attr", name))
        return self._attrs[name]

    @property
    def jump_height(self) -> float:
        return float(self._attr("jump_height"))

    @property
    def max_jump(self) -> float:
        return float(self._attr("max_jump"))

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_") or name not in ALLOWED_METHODS:
            raise AttributeError(f"RemoteSimulation has no {name!r} (served: {', '.join(sorted(ALLOWED_METHODS))})")

        def method(*args: Any) -> Any:
            value = self._method(name, list(args))
            return tuple(value) if name == "magazine" else value
        method.__name__ = name
        return method
