"""The embedded dry-run: the real executive, manager and components against the simulator, one process.

Everything a cluster would run, wired in-process: `hosts.yaml` gives the resources and which
driver each device uses (all `sim` here), the world file gives the building, a `LocalBus`
carries the records, and the simulator's clock is the executive's clock. Sim time runs as
fast as the CPU allows, or at `speed` times real time. The result is data (`DryRun`); the
CLI renders it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from drd.bus import LocalNetwork
from drd.executive import EntryPoints, Executive
from drd.hosts import Cluster
from drd.hw.drivers import HostDrivers, drivers_for
from drd.inject import Action, Injection
from drd.runtime import records as rec
from drd.runtime.trace import TraceWriter
from drd.sim.model import DoorState
from drd.sim.physics import Simulation
from drd.sim.world import World, check_hosts
from dsl.catalog import Catalog
from dsl.statechart import Statechart

#: Control period: components are stepped at 10 Hz of sim time.
CONTROL_PERIOD = 0.1


class SimulationClock:
    """The executive's clock is the simulator's (unlike `drd.runtime.clock.SimClock`, it is never advanced by hand)."""

    def __init__(self, sim: Simulation):
        self.sim = sim

    def now(self) -> float:
        return self.sim.time


@dataclass
class DryRun:
    """What happened: outcome, times, and the facts the report shows."""

    mission: str
    outcome: str | None
    reason: str
    sim_time: float
    wall_time: float
    records: list[rec.Record] = field(default_factory=list)
    doors: list[dict[str, Any]] = field(default_factory=list)
    scouts: list[dict[str, Any]] = field(default_factory=list)
    detections: list[dict[str, Any]] = field(default_factory=list)
    injections: list[dict[str, Any]] = field(default_factory=list)
    #: Ground-truth (t, x, y) trails of every robot and intruder, for the picture.
    tracks: dict[str, list[tuple[float, float, float]]] = field(default_factory=dict)
    #: The pace asked for (a multiple of real time), None for as fast as the machine allows.
    speed: float | None = None
    on_cluster: bool = False  # a `missionctl run` on a cluster's daemons, not a dry-run in this process

    @property
    def kept_up(self) -> bool:
        """Did the run keep (nearly: within 10 %, which a cluster's start-up takes) the pace it was asked for?"""
        return not self.speed or self.real_time_factor >= 0.9 * self.speed

    @property
    def real_time_factor(self) -> float:
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("inf")

    def timeline(self) -> list[dict[str, Any]]:
        """Each behavior instance: when it was entered and exited, and how it ended."""
        rows: dict[str, dict[str, Any]] = {}
        for r in self.records:
            if isinstance(r, rec.Entered):
                rows[r.path] = {"path": r.path, "entered": r.at, "exited": None, "status": "active"}
            elif isinstance(r, rec.Exited) and r.path in rows:
                rows[r.path].update(exited=r.at, status=r.status)
        return list(rows.values())

    def holds(self) -> list[dict[str, Any]]:
        """Who held what, when: one row per grant interval, ended by a revoke at a slice boundary, a release,
        the holder's exit or the end of the run. Fig. 8 shows up here as alternating rows."""
        rows: list[dict[str, Any]] = []
        open_: dict[str, dict[str, Any]] = {}

        def close(path: str, at: float, units: tuple[str, ...] | None, how: str) -> None:
            row = open_.get(path)
            if row is None:
                return
            gone = set(row["units"]) if units is None else set(units) & set(row["units"])
            if not gone:
                return
            del open_[path]
            rows.append({**row, "units": sorted(gone), "to": at, "ended": how})
            rest = sorted(set(row["units"]) - gone)
            if rest:
                open_[path] = {**row, "units": rest, "from": at}

        for r in self.records:
            if isinstance(r, rec.Granted):
                close(r.path, r.at, None, "regranted")
                open_[r.path] = {"path": r.path, "resources": dict(r.resources), "units": sorted(r.epochs),
                                 "from": r.at}
            elif isinstance(r, rec.Revoked):
                close(r.path, r.at, tuple(r.resources), "revoked")
            elif isinstance(r, rec.Released):
                close(r.path, r.at, tuple(r.resources), r.reason or "released")
            elif isinstance(r, rec.Exited):
                close(r.path, r.at, None, "exited")
        for path in list(open_):
            close(path, self.sim_time, None, "held at the end")
        return sorted(rows, key=lambda h: (h["from"], h["to"]))

    def waits(self) -> list[dict[str, Any]]:
        """Who waited for resources, from when until the grant (or until it gave up by exiting)."""
        rows: list[dict[str, Any]] = []
        since: dict[str, rec.Waiting] = {}
        for r in self.records:
            if isinstance(r, rec.Waiting):
                since.setdefault(r.path, r)
            elif isinstance(r, rec.Granted | rec.Exited) and r.path in since:
                w = since.pop(r.path)
                rows.append({"path": r.path, "from": w.at, "to": r.at, "needs": list(w.needs),
                             "ended": "granted" if isinstance(r, rec.Granted) else "exited"})
        rows += [{"path": p, "from": w.at, "to": self.sim_time, "needs": list(w.needs), "ended": "still waiting"}
                 for p, w in since.items()]
        return sorted(rows, key=lambda w: (w["from"], w["path"]))

    def to_dict(self) -> dict[str, Any]:
        return {"mission": self.mission, "outcome": self.outcome, "reason": self.reason,
                "sim_time": self.sim_time, "wall_time": self.wall_time,
                "real_time_factor": self.real_time_factor, "speed": self.speed,
                "timeline": self.timeline(), "holds": self.holds(), "waits": self.waits(),
                "injections": self.injections,
                "doors": self.doors, "scouts": self.scouts, "detections": self.detections}


def merged_drivers(cluster: Cluster, sim: Simulation, catalog: Catalog) -> HostDrivers:
    """Every host's drivers in one place: in a dry-run all hosts live in this process."""
    out = HostDrivers()
    for host in cluster.hosts:
        if host.devices:
            d = drivers_for(cluster, host.name, sim, catalog=catalog)
            out.devices.update(d.devices)
            out.robots.update(d.robots)
    return out


def run(chart: Statechart, cluster: Cluster, world: World, catalog: Catalog, *, seed: int = 0,
        until: float = 1800.0, speed: float | None = None, trace: IO[str] | None = None,
        registry: Any = None, progress: Callable[[Simulation, Executive], None] | None = None,
        progress_every: float = 1.0, injections: Sequence[Injection] = ()) -> DryRun:
    """Run `chart` to its end (or `until` seconds of sim time) and report; `injections` happen on the way."""
    problems = check_hosts(world, cluster)
    if problems:
        raise ValueError("\n".join(map(str, problems)))
    sim = Simulation(world, seed=seed)
    clock = SimulationClock(sim)
    drivers = merged_drivers(cluster, sim, catalog)
    bus = LocalNetwork().session("controller")
    late = {i.target for i in injections if i.action is Action.JOIN}  # hosts whose daemon starts later
    executive = Executive(bus, clock, registry or EntryPoints(catalog), cluster=cluster.name,
                          resources=[r for r in cluster.resources() if r.host not in late], lease=cluster.lease,
                          services={"drivers": drivers})
    result = DryRun(chart.name, None, "", 0.0, 0.0, speed=speed)
    listeners: list[Callable[[rec.Record], None]] = [result.records.append, lambda r: facts(result, r)]
    if trace is not None:
        listeners.append(TraceWriter(trace))
    start = time.perf_counter()
    mid = executive.submit(chart, listeners=listeners)
    mission = executive.missions[mid]
    next_progress = 0.0
    pending = sorted(injections)
    while not mission.finished and sim.time < until:
        sim.step(CONTROL_PERIOD)
        while pending and pending[0].at <= sim.time + 1e-9:
            result.injections.append(_inject(pending.pop(0), sim, executive, cluster))
        executive.step()
        if speed:
            lag = sim.time / speed - (time.perf_counter() - start)
            if lag > 0:
                time.sleep(lag)
        if progress is not None and sim.time >= next_progress:
            progress(sim, executive)
            next_progress = sim.time + progress_every
    if not mission.finished:
        mission.stop(f"sim time limit of {until:g} s reached")
    result.outcome, result.reason = mission.outcome, mission.reason
    result.sim_time, result.wall_time = sim.time, time.perf_counter() - start
    for scout in result.scouts:
        pose = sim.pose(scout["scout"])
        scout.update(x=round(pose.x, 2), y=round(pose.y, 2))
    result.tracks = {rid: sim.trajectory(rid) for rid in (*sim.robots, *sim.intruders())}
    executive.close()
    return result


def _inject(inj: Injection, sim: Simulation, executive: Executive, cluster: Cluster) -> dict[str, Any]:
    """Apply one injected failure now; the record says what it did."""
    what = str(inj)
    if inj.action is Action.JOIN:
        found = [r for r in cluster.resources() if r.host == inj.target]
        running = [m for m in executive.missions.values() if not m.finished]
        if running:
            running[0].add_resources(found)  # one pool: the other missions see them at their next step
        else:
            executive.pool.add(found, sim.time)
        what += f": {len(found)} resources joined the manager"
    elif inj.action is Action.KILL:
        robots = [r.id for r in cluster.host(inj.target).robots if r.id in sim.robots]
        for rid in robots:
            sim.lose(rid)  # nothing drives them any more
        executive.remove_host(inj.target)
        what += f": its resources left the manager; {', '.join(robots) or 'no robot'} stopped"
    elif inj.action is Action.LOSE:
        sim.lose(inj.target)
        executive.remove_resources(_robot_resources(cluster, inj.target))
        what += ": the robot and its resources are gone"
    elif sim.door(inj.target) is DoorState.BLOCKED:
        what += ": nothing happens, a blocked door stays blocked"
    else:
        state = {Action.BLOCK: DoorState.BLOCKED, Action.CLOSE: DoorState.CLOSED, Action.OPEN: DoorState.OPEN}
        sim.set_door(inj.target, state[inj.action])
        what += f": the door is now {state[inj.action].value}"
    return {"at": round(sim.time, 3), "action": inj.action.value, "target": inj.target, "injection": str(inj),
            "effect": what}


def _robot_resources(cluster: Cluster, robot: str) -> list[str]:
    """A lost robot takes its aggregate and the parts only it uses (not a radio channel shared with others)."""
    robots = cluster.robots
    mine = next((r for r in robots if r.id == robot), None)
    if mine is None:  # in the world but not in hosts.yaml: the manager never had it
        return []
    others = {u for r in robots if r.id != robot for u in r.parts.values()}
    return [robot, *(u for u in mine.parts.values() if u not in others)]


def facts(result: DryRun, r: rec.Record) -> None:
    """Doors found, Scouts placed and intruders seen, from the behaviors' events."""
    if not isinstance(r, rec.Event):
        return
    if r.name == "DoorDetected":
        result.doors.append({"at": r.at, "by": r.path, **r.fields})
    elif r.name == "ScoutLaunched":
        result.scouts.append({"at": r.at, "scout": r.fields.get("scout"), "by": r.path})
    elif r.name == "MotionDetected":
        result.detections.append({"at": r.at, "by": r.path, **r.fields})


def world_path(name: str, root: Path) -> Path:
    """`corridor` or `worlds/corridor.yaml` or any path."""
    p = Path(name)
    if p.suffix in (".yaml", ".yml") or p.exists():
        return p
    return root / "worlds" / f"{name}.yaml"
