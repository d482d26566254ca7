"""The embedded dry-run: the real executive, manager and components against the simulator, one process.

Everything a cluster would run, wired in-process: `hosts.yaml` gives the resources and which
driver each device uses (all `sim` here), the world file gives the building, a `LocalBus`
carries the records, and the simulator's clock is the executive's clock. Sim time runs as
fast as the CPU allows, or at `speed` times real time. The result is data (`DryRun`); the
CLI renders it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from drd.bus import LocalNetwork
from drd.executive import EntryPoints, Executive
from drd.hosts import Cluster
from drd.hw.drivers import HostDrivers, drivers_for
from drd.runtime import records as rec
from drd.runtime.trace import TraceWriter
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
    #: Ground-truth (t, x, y) trails of every robot and intruder, for the picture.
    tracks: dict[str, list[tuple[float, float, float]]] = field(default_factory=dict)

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
        return [{"at": r.at, "path": r.path, "resources": r.resources} for r in self.records
                if isinstance(r, rec.Granted)]

    def to_dict(self) -> dict[str, Any]:
        return {"mission": self.mission, "outcome": self.outcome, "reason": self.reason,
                "sim_time": self.sim_time, "wall_time": self.wall_time,
                "real_time_factor": self.real_time_factor, "timeline": self.timeline(), "holds": self.holds(),
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
        progress_every: float = 1.0) -> DryRun:
    """Run `chart` to its end (or `until` seconds of sim time) and report."""
    problems = check_hosts(world, cluster)
    if problems:
        raise ValueError("\n".join(map(str, problems)))
    sim = Simulation(world, seed=seed)
    clock = SimulationClock(sim)
    drivers = merged_drivers(cluster, sim, catalog)
    bus = LocalNetwork().session("controller")
    executive = Executive(bus, clock, registry or EntryPoints(catalog), cluster=cluster.name,
                          resources=cluster.resources(), lease=cluster.lease,
                          services={"drivers": drivers})
    result = DryRun(chart.name, None, "", 0.0, 0.0)
    listeners: list[Callable[[rec.Record], None]] = [result.records.append, lambda r: _facts(result, r, sim)]
    if trace is not None:
        listeners.append(TraceWriter(trace))
    start = time.perf_counter()
    mid = executive.submit(chart, listeners=listeners)
    mission = executive.missions[mid]
    next_progress = 0.0
    while not mission.finished and sim.time < until:
        sim.step(CONTROL_PERIOD)
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


def _facts(result: DryRun, r: rec.Record, sim: Simulation) -> None:
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
