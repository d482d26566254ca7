"""Test components and a harness for running compiled missions on a simulated clock."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from drd.rcm import Aggregate, ResourceManager, Unit
from drd.runtime import records as rec
from drd.runtime.clock import SimClock
from drd.runtime.component import Component, Status
from drd.runtime.interpreter import Interpreter
from drd.runtime.pool import ResourcePool
from dsl.statechart import Statechart


class Timed(Component):
    """Succeeds after `duration` seconds of un-suspended time (default 1 s)."""

    def start(self) -> None:
        assert self.ctx is not None
        self.needed = float(self.ctx.params.get("duration", 1.0))
        self.active = 0.0
        self.last = self.ctx.now()
        self.suspended = False

    def step(self, now: float) -> Status:
        if not self.suspended:
            self.active += now - self.last
        self.last = now
        return Status.SUCCESS if self.active >= self.needed - 1e-9 else Status.RUNNING

    def suspend(self) -> None:
        self.suspended = True

    def resume(self) -> None:
        assert self.ctx is not None
        self.suspended = False
        self.last = self.ctx.now()


class Forever(Component):
    """Runs until stopped; counts lifecycle calls so tests can check shutdown."""

    calls: list[tuple[str, str]] = []

    def start(self) -> None:
        assert self.ctx is not None
        Forever.calls.append(("start", self.ctx.path))

    def terminate(self, status: Status) -> None:
        assert self.ctx is not None
        Forever.calls.append(("terminate", self.ctx.path))


class Fails(Component):
    def step(self, now: float) -> Status:
        return Status.FAILURE


class Raises(Component):
    def step(self, now: float) -> Status:
        raise RuntimeError("sensor on fire")


class Emits(Component):
    """Emits MotionDetected(area) once, then succeeds."""

    def step(self, now: float) -> Status:
        assert self.ctx is not None
        self.ctx.emit("MotionDetected", area=0.5, x=1.0, y=2.0)
        return Status.SUCCESS


def ranger_world(rangers: int = 1, scouts_each: int = 2) -> list[Any]:
    out: list[Any] = []
    for r in range(1, rangers + 1):
        rid = f"ranger{r}"
        parts = {}
        for part, typ in (("drive", "Drive"), ("ranges", "RangeSensor"), ("camera", "Camera"),
                          ("launcher", "Launcher")):
            out.append(Unit(f"{rid}.{part}", typ, host=rid))
            parts[part] = f"{rid}.{part}"
        out.append(Aggregate(rid, "Ranger", parts, {"battery": 1.0}, host=rid))
        for s in range(1, scouts_each + 1):
            sid = f"{rid}.scout{s}"
            sparts = {}
            for part, typ in (("wheels", "Drive"), ("foot", "Jump"), ("camera", "Camera")):
                out.append(Unit(f"{sid}.{part}", typ, host=rid))
                sparts[part] = f"{sid}.{part}"
            out.append(Unit(f"{sid}.radio", "RadioChannel", sharable=True, capacity=10, host=rid))
            sparts["radio"] = f"{sid}.radio"
            out.append(Aggregate(sid, "Scout", sparts, {"carrier": rid, "battery": 1.0}, host=rid))
    return out


class Harness:
    """An interpreter on a SimClock with every record kept."""

    def __init__(self, chart: Statechart, registry: dict[str, Any], resources: Iterable[Any],
                 slice_: float = 5.0):
        self.clock = SimClock()
        self.rcm = ResourceManager(default_slice=slice_)
        self.pool = ResourcePool(self.rcm)
        self.pool.add(resources, 0.0)
        self.records: list[rec.Record] = []
        self.interp = Interpreter(chart, registry, self.rcm, self.clock, pool=self.pool)
        self.interp.attach(self.records.append)

    def run(self, until: float = 600.0, dt: float = 0.5) -> str | None:
        if self.interp.root is None:
            self.interp.start()
        while not self.interp.finished and self.clock.now() < until:
            self.clock.advance(dt)
            self.interp.step()
        return self.interp.outcome

    def of(self, kind: type[rec.Record]) -> list[Any]:
        return [r for r in self.records if isinstance(r, kind)]


class FailsFirst(Timed):
    """Instance [0] fails; the others run their duration."""

    def step(self, now: float) -> Status:
        assert self.ctx is not None
        if "[0]/" in self.ctx.path:
            return Status.FAILURE
        return super().step(now)


COMPONENTS = {c.__name__: c for c in (Timed, Forever, Fails, Raises, Emits, FailsFirst)}


#: An output read after an event transition exits its producer (component audit D1): the producer itself (LEAF), or
#: its parent, a parallel that stops it (INSIDE). `face` reads the door `find`/DetectDoor left.
LEAF = """
mission M {
    needs bot: Ranger
    start -> find
    DetectDoor as find
    find -> face on DoorDetected
    AlignRanger as face
}
"""

INSIDE = """
mission M {
    needs bot: Ranger
    start -> Hunt
    Hunt -> face on DoorDetected
    AlignRanger as face
}
behavior Hunt {
    parallel until DetectDoor { FollowCorridor; DetectDoor }
}
"""


#: The door a `DoorFinder` sets as its output.
DOOR = {"width": 0.9, "x": 1.0, "y": 2.0, "side": "left"}


class DoorFinder(Component):
    """Stands in for DetectDoor: at its second step sets its door, emits DoorDetected and runs on. What it does is
    said to `sink` (a subclass sets it: a list in process, a file a worker process writes)."""

    sink: Callable[[str], None]

    def start(self) -> None:
        self.steps = 0

    def step(self, now: float) -> Status:
        assert self.ctx is not None
        self.steps += 1
        if self.steps == 2:
            self.ctx.outputs["door"] = dict(DOOR)
            self.ctx.emit("DoorDetected", width=0.9, x=1.0, y=2.0)
            self.sink("after emit")
        return Status.RUNNING

    def terminate(self, status: Status) -> None:
        self.sink(f"terminate {status}")


class DoorFacer(Component):
    """Stands in for AlignRanger: says the door it was given (to `sink`), then succeeds."""

    sink: Callable[[str], None]

    def start(self) -> None:
        assert self.ctx is not None
        self.sink(f"face start {self.ctx.inputs.get('door')}")

    def step(self, now: float) -> Status:
        return Status.SUCCESS


class Idle(Component):
    """Runs until stopped."""

    def step(self, now: float) -> Status:
        return Status.RUNNING


def traced_dry_run(chart: Statechart, catalog: Any, injections: Iterable[str], until: float) -> list[dict[str, Any]]:
    """The trace's records of a dry-run of `chart` on hosts.yaml's team in the corridor world, with `--inject`s."""
    import io
    import json
    from pathlib import Path

    from drd import inject
    from drd.dryrun import run
    from drd.hosts import load_hosts
    from drd.sim.world import load_world

    root = Path(__file__).resolve().parents[1]
    cluster, world = load_hosts(root / "hosts.yaml", catalog), load_world(root / "worlds" / "corridor.yaml")
    known = {"hosts": {h.name for h in cluster.hosts}, "robots": {r.id for r in cluster.robots},
             "doors": {d.id for d in world.doors}}
    trace = io.StringIO()
    run(chart, cluster, world, catalog, until=until, trace=trace,
        injections=inject.parse_all(list(injections), **known))
    return [json.loads(line) for line in trace.getvalue().splitlines()]
