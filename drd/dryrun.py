"""The embedded dry-run: the real executive, manager and components against the simulator, one process.

Everything a cluster would run, wired in-process: `hosts.yaml` gives the resources and which
driver each device uses (all `sim` here), the world file gives the building, a `LocalBus`
carries the records, and the simulator's clock is the executive's clock. Sim time runs as
fast as the CPU allows, or at `speed` times real time. The result is data (`DryRun`); the
CLI renders it.
"""

from __future__ import annotations

import functools
import gc
import threading
import time
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from drd.bus import LocalNetwork
from drd.errors import ConfigurationError, host_down_reason
from drd.executive import EntryPoints, Executive
from drd.explain import Explainer, LastRequest, within
from drd.hosts import Cluster, Role
from drd.hw.drivers import HostDrivers, drivers_for
from drd.inject import Action, Injection
from drd.record import Recorder
from drd.restart import ControllerLife
from drd.runtime import records as rec
from drd.runtime.interpreter import stop_together
from drd.runtime.trace import TraceWriter
from drd.sim.model import DoorState
from drd.sim.physics import Simulation
from drd.sim.world import World, charged, check_hosts, hosts_charges
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


#: Sim seconds below which a run's pace is not judged nor shown (recovery audit D4: a mission failing at 0.0 s
#: was reported `0x real time (2x asked: the cluster could not keep up)`).
PACE_MIN = 1.0


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
    priority: int = 1  # the mission's rank against the others sharing the team
    mission_id: str = ""
    #: Wall seconds the mission spent without a controller (a cluster's, lost and resumed): not the cluster's pace.
    away: float = 0.0

    @property
    def kept_up(self) -> bool:
        """Did the run keep (nearly: within 10 %, which a cluster's start-up takes) the pace it was asked for? A run
        of less than a second of sim time has no pace to judge (its start-up is all of it)."""
        if not self.speed or not self.paced:
            return True
        ran = self.wall_time - self.away
        return ran <= 0 or self.sim_time / ran >= 0.9 * self.speed

    @property
    def paced(self) -> bool:
        """Long enough (`PACE_MIN`) for its pace to mean something."""
        return self.sim_time >= PACE_MIN

    @property
    def real_time_factor(self) -> float:
        """Sim seconds per wall second, the time without a controller left out (it is not the run's pace:
        cluster audit 17, D4: 1.59x for a run at 3.65x with a 10 s outage)."""
        ran = self.wall_time - self.away
        return self.sim_time / ran if ran > 0 else float("inf")

    def timeline(self) -> list[dict[str, Any]]:
        """Each entry of a behavior instance, in the order entered: when it was entered and exited, and how it
        ended. A state entered again (a self-transition, a loop) gets a row per entry: its earlier runs happened.
        A restore from the journal ends the mission's entries in force as `controller lost`, at the time the journal
        saved (what ran after it was undone), and enters its states again (users audit 17, D3: they stayed
        `active` in the report of a mission that succeeded)."""
        rows: list[dict[str, Any]] = []
        open_: dict[str, dict[str, Any]] = {}  # path -> the row of its entry in force
        for r in self.records:
            if isinstance(r, rec.Entered):
                rows.append({"path": r.path, "entered": report_time(r.at), "exited": None, "status": "active"})
                open_[r.path] = rows[-1]
            elif isinstance(r, rec.Exited):
                entry = open_.pop(r.path, None)
                if entry is not None:
                    entry.update(exited=report_time(r.at), status=r.status)
            elif isinstance(r, rec.Restored):
                for path in [p for p in open_ if within(p, r.path)]:
                    entry = open_.pop(path)
                    entry.update(exited=max(entry["entered"], report_time(r.since)), status="controller lost")
        return rows

    def holds(self) -> list[dict[str, Any]]:
        """Who held what, when: one row per grant interval, ended by a revoke at a slice boundary, a release,
        the holder's exit or the end of the run. Fig. 8 shows up here as alternating rows. A hold that ends in
        part (`release(carrier)`) splits: each row names only the needs whose units it held."""
        rows: list[dict[str, Any]] = []
        open_: dict[str, dict[str, Any]] = {}
        owned: dict[str, dict[str, set[str]]] = {}  # holder -> need -> the ids it covers (itself and its parts)

        def close(path: str, at: float, units: tuple[str, ...] | None, how: str) -> None:
            row = open_.get(path)
            if row is None:
                return
            gone = set(row["units"]) if units is None else set(units) & set(row["units"])
            if not gone:
                return
            del open_[path]
            rest = set(row["units"]) - gone
            rows.append({**row, "resources": _needs_of(row["resources"], owned[path], gone, rest),
                         "units": sorted(gone), "to": report_time(at), "ended": how})
            if rest:
                open_[path] = {**row, "resources": _needs_of(row["resources"], owned[path], rest, gone),
                               "units": sorted(rest), "from": report_time(at)}

        for r in self.records:
            if isinstance(r, rec.Granted):
                close(r.path, r.at, None, "regranted")
                named = r.named  # held and shared alike: a report lists both
                needs = {k: v for k, v in named.items() if "." not in k}  # not each part of an aggregate
                owned[r.path] = {k: {v} | {u for part, u in named.items() if part.startswith(k + ".")}
                                 for k, v in needs.items()}
                open_[r.path] = {"path": r.path, "resources": needs, "units": sorted(r.epochs),
                                 "from": report_time(r.at)}
            elif isinstance(r, rec.Revoked):
                close(r.path, r.at, tuple(r.resources), "revoked")
            elif isinstance(r, rec.Released):
                close(r.path, r.at, tuple(r.resources), _ENDED.get(r.reason, r.reason or "released"))
            elif isinstance(r, rec.Exited):
                close(r.path, r.at, None, "exited")
        for path in list(open_):
            close(path, self.sim_time, None, "held at the end")
        return sorted(rows, key=lambda h: (h["from"], h["to"]))

    def waits(self) -> list[dict[str, Any]]:
        """Who waited for resources, from when until the grant (or until it gave up by exiting)."""
        rows: list[dict[str, Any]] = []
        since: dict[str, rec.Waiting] = {}
        asked = LastRequest()
        for r in self.records:
            if isinstance(r, rec.Waiting):
                since.setdefault(r.path, r)
                asked.take(r)
            elif isinstance(r, rec.Granted | rec.Exited) and r.path in since:
                w = since.pop(r.path)
                rows.append({"path": r.path, "from": report_time(w.at), "to": report_time(r.at),
                             "needs": list(w.needs) or asked.of(r.path),
                             "ended": "granted" if isinstance(r, rec.Granted) else "exited"})
            elif isinstance(r, rec.Restored):  # its waiters ask again, as the journal saved them (review)
                for path in [p for p in since if within(p, r.path)]:
                    w = since.pop(path)
                    rows.append({"path": path, "from": report_time(w.at), "to": report_time(max(w.at, r.since)),
                                 "needs": list(w.needs) or asked.of(path), "ended": "controller lost"})
        rows += [{"path": p, "from": report_time(w.at), "to": report_time(self.sim_time),
                  "needs": list(w.needs) or asked.of(p), "ended": "still waiting"}
                 for p, w in since.items()]
        return sorted(rows, key=lambda w: (w["from"], w["path"]))

    def logs(self) -> list[dict[str, Any]]:
        """Every `log` line of the run (the mission's `log` actions, the components' and the runtime's own), in
        order: what the mission said about itself is part of what happened."""
        return [{"at": report_time(r.at), "path": r.path, "text": r.text}
                for r in self.records if isinstance(r, rec.Log)]

    def events(self) -> list[dict[str, Any]]:
        """Every event the run emitted, by name, in the order each name first came: `[{name, count, at, by,
        fields}]`, the time, emitter and fields those of its first. Whatever the components are called: the doors,
        Scouts and detections below are the standard components' own events only."""
        seen: dict[str, dict[str, Any]] = {}
        for r in self.records:
            if isinstance(r, rec.Event):
                row = seen.get(r.name)
                if row is None:
                    seen[r.name] = {"name": r.name, "count": 1, "at": report_time(r.at), "by": r.path,
                                    "fields": dict(r.fields)}
                else:
                    row["count"] += 1
        return list(seen.values())

    def failure_chain(self) -> list[dict[str, Any]]:
        """Why the mission failed, from the mission down to each leaf that failed, each with its own reason
        (`[{path, reason, leaf}]`, parents before their children; empty unless the outcome is a failure).

        Built from the records alone (so a cluster's `missionctl run` explains the same way): a transition to
        `fail` (a timeout says `timed out after 2min`, an event its trigger), a child's failure, each failed
        instance of a multiplicity, and at the bottom the leaf's own words (its last `log` line, or the
        resource it lost)."""
        if self.outcome != "failure":
            return []
        return Explainer(self.records).chain(self.reason)

    def degraded(self) -> list[dict[str, Any]]:
        """What a successful mission lost on the way: the instances that failed (`[{path, at, reason}]`), so a
        success with 3 of 6 Watch states failed never reads as a plain success."""
        if self.outcome != "success":
            return []
        return Explainer(self.records).degraded()

    def still_active(self) -> list[dict[str, Any]]:
        """The leaves still active when a run was stopped (`--until`, the time limit, Ctrl-C, `missionctl stop`):
        `[{path, since, state}]`, `state` running, waiting (for resources) or suspended (preempted)."""
        if self.outcome != "stopped":
            return []
        return Explainer(self.records).still_active()

    def waiting(self) -> list[dict[str, Any]]:
        """What each behavior still waiting when the run was stopped waited for: `[{path, since, needs,
        blocked_by: [{path, holds}]}]`, `holds` what that holder held then (need -> resource id)."""
        if self.outcome != "stopped":
            return []
        return Explainer(self.records).waiting()

    def to_dict(self) -> dict[str, Any]:
        return {"mission": self.mission, "id": self.mission_id, "priority": self.priority,
                "outcome": self.outcome, "reason": self.reason,
                "sim_time": report_time(self.sim_time), "wall_time": self.wall_time,
                **({"controller_away": round(self.away, 3)} if self.away else {}),
                # null when no wall time is known (a replay of a recording cut before its end): JSON has no Infinity
                "real_time_factor": self.real_time_factor if self.wall_time > 0 else None, "speed": self.speed,
                "failure_chain": self.failure_chain(), "degraded": self.degraded(), "still_active": self.still_active(),
                "waiting": self.waiting(), "logs": self.logs(),
                "timeline": self.timeline(), "holds": self.holds(), "waits": self.waits(),
                "injections": self.injections, "events": self.events(),
                "doors": self.doors, "scouts": self.scouts, "detections": self.detections}


#: How the report words the end of a hold (the trace's `released` reasons).
_ENDED = {"exit": "exited", "release": "released"}

#: Digits a report's (and a trace's) times keep: sim time counts in float steps (0.1 s ten times would read
#: 0.9999999999999999), and a microsecond is far below the control period.
TIME_DIGITS = 6


def report_time(at: float) -> float:
    """A time as reports give it, the dry-run's and a cluster run's alike (`missionctl run` rounds the records it
    receives with this too): one rule, so the same run reads the same either way."""
    return round(at, TIME_DIGITS)


def _needs_of(needs: dict[str, str], owned: dict[str, set[str]], held: set[str], other: set[str]) -> dict[str, str]:
    """The needs of a grant a part of it (`held`, unit ids) covers, the rest (`other`) held on or let go: a need
    goes with the part holding any of its units; a need none of whose ids is a unit of either stays with both."""
    return {k: v for k, v in needs.items() if owned[k] & held or not owned[k] & other}


def merged_drivers(cluster: Cluster, sim: Simulation, catalog: Catalog,
                   services: Mapping[str, Any] | None = None) -> HostDrivers:
    """Every host's drivers in one place: in a dry-run all hosts live in this process. `services`: the backends of
    drivers other than `sim` (the served simulator's `ros2` link)."""
    out = HostDrivers()
    for host in cluster.hosts:
        if host.devices:
            d = drivers_for(cluster, host.name, sim, services=services, catalog=catalog)
            out.devices.update(d.devices)
            out.robots.update(d.robots)
    return out


@dataclass(frozen=True)
class Mission:
    """One mission of a dry-run: its chart and its priority against the others (None: the chart's own)."""

    chart: Statechart
    priority: int | None = None


def team(cluster: Cluster, world: World, catalog: Catalog, *, seed: int = 0, registry: Any = None,
         late: Collection[str] = ()) -> tuple[Simulation, Executive]:
    """The world simulated and one executive over the team of `cluster` (its hosts' devices driven in the
    simulation), in this process: what a dry-run runs missions on. `late`: hosts whose devices join later."""
    sim = simulation(cluster, world, seed)
    return sim, executive_over(cluster, world, sim, catalog, registry, [r.id for r in cluster.resources()
                                                                        if r.host in late])


def simulation(cluster: Cluster, world: World, seed: int = 0) -> Simulation:
    """The world a dry-run simulates; when a device of `cluster` is on `driver: ros2`, served as ROS 2 robots in this
    process, in lockstep with its steps (`drd.sim.ros2.LockstepSimulation`: close it after the run)."""
    world = charged(world, hosts_charges(cluster))  # hosts.yaml's `battery` where the world gives no start charge
    if not any(d.driver == "ros2" for h in cluster.hosts for d in h.devices):
        return Simulation(world, seed=seed)
    from drd.sim.ros2 import LockstepSimulation  # zenoh and rosbags: only for a team of ROS 2 robots

    sim = LockstepSimulation(world, seed=seed)
    sim.serve(cluster)
    return sim


def executive_over(cluster: Cluster, world: World, sim: Simulation, catalog: Catalog, registry: Any = None,
                   gone: Collection[str] = ()) -> Executive:
    """An executive over the team of `cluster` in the world `sim` runs, without the resources in `gone`."""
    drivers = merged_drivers(cluster, sim, catalog, getattr(sim, "services", None))
    sync = getattr(sim, "sync", None)
    if callable(sync):  # served over ROS 2: the new drivers get the robots' state before any behavior reads it
        sync()
    places = {room.id: (room.x0, room.y0, room.x1, room.y1) for room in world.rooms}
    executive = Executive(LocalNetwork().session("controller"), SimulationClock(sim), registry or EntryPoints(catalog),
                          cluster=cluster.name, resources=[r for r in cluster.resources() if r.id not in gone],
                          lease=cluster.lease, services={"drivers": drivers, "places": places})
    executive.absent(r for r in cluster.resources() if r.id in gone)  # hosts down or not joined yet
    return executive


def run(chart: Statechart, cluster: Cluster, world: World, catalog: Catalog, **options: Any) -> DryRun:
    """Run `chart` to its end (or `until` seconds of sim time) and report (options as `run_many`)."""
    return run_many([Mission(chart)], cluster, world, catalog, **options)[0]


def run_many(missions: Sequence[Mission], cluster: Cluster, world: World, catalog: Catalog, *, seed: int = 0,
             until: float = 1800.0, speed: float | None = None, trace: IO[str] | None = None,
             registry: Any = None, progress: Callable[[Simulation, Executive], None] | None = None,
             progress_every: float = 1.0, injections: Sequence[Injection] = (),
             stop: threading.Event | None = None, recorder: Recorder | None = None) -> list[DryRun]:
    """Run missions together on one team until all have ended (or `until` seconds of sim time), one report each.

    They share the world, the robots and the one Resource Controller Manager, which ranks their requests by the
    missions' priorities, then their behaviors'. `injections` happen on the way; `trace` gets every mission's
    records, each with its mission's id. Setting `stop` (the operator's Ctrl-C) stops the missions still running
    between two control cycles, never inside one, and the reports say what ran so far. `recorder` gets every
    record, the robots' poses each cycle and each run's summary (`drd.record`, an MCAP file). ConfigurationError:
    no mission, or a world and a hosts file that disagree (what the run raises besides is not the user's input)."""
    if not missions:
        raise ConfigurationError("no mission to run")
    problems = check_hosts(world, cluster)
    if problems:
        raise ConfigurationError("\n".join(map(str, problems)))
    late = {i.target for i in injections if i.action is Action.JOIN}  # hosts whose daemon starts later
    sim, executive = team(cluster, world, catalog, seed=seed, registry=registry, late=late)
    life = ControllerLife(executive, functools.partial(executive_over, cluster, world, sim, catalog, registry),
                          cluster.resources(), [r.id for r in cluster.resources() if r.host in late],
                          grace=cluster.resume_grace,
                          down=[h.name for h in cluster.hosts if h.devices and h.name in late],
                          **_controllers(cluster))
    if recorder is not None:  # served live: a viewer there from the start gets the messages at 0 too
        recorder.wait_for_viewer()
    start = time.perf_counter()
    if recorder is not None:
        recorder.scene(world, starts=True)
        recorder.watch(sim)  # what the sensors read, launches, landings and door changes, from now on
    ends: dict[str, tuple[float, float]] = {}  # mission id -> (sim, wall) seconds at its end: its own report's times
    results: list[DryRun] = []
    due = _Injections(injections, sim, life, cluster, results)
    with life.together():  # missions of one instant: by priority, not by their order on the command line
        results += [_submit(life, m, n, speed, trace, recorder, functools.partial(_note_end, ends, start))
                    for n, m in enumerate(missions, 1)]
        due.at_start()  # before their first grants (asked when this block ends)
    with _Heap() as heap:
        _loop(life, sim, until, speed, stop, progress, progress_every, recorder, heap, due, start)
    why = "stopped by operator" if stop is not None and stop.is_set() else f"sim time limit of {until:g} s reached"
    life.end(why)
    _conclude(results, [life.interpreters[r.mission_id or ""] for r in results], sim, time.perf_counter() - start,
              ends)
    close = getattr(sim, "close", None)
    if callable(close):  # the served robots' sessions (ROS 2)
        close()
    if recorder is not None:
        recorder.end([summary(r) for r in results], sim.time)
    return results


def _loop(life: ControllerLife, sim: Simulation, until: float, speed: float | None, stop: threading.Event | None,
          progress: Callable[[Simulation, Executive], None] | None, progress_every: float,
          recorder: Recorder | None, heap: _Heap, due: _Injections, start: float) -> None:
    """Step the world and the controller by control cycles until the missions end, `until` or `stop`."""
    next_progress = 0.0
    while not life.finished() and sim.time < until - 1e-6:  # 0.1 s steps add up
        if stop is not None and stop.is_set():
            break
        sim.step(CONTROL_PERIOD)
        due.now()
        if life.executive is not None:  # a dead controller steps nothing
            life.executive.step()
        if recorder is not None:
            recorder.cycle(sim)  # where everyone is, and what changed in this cycle
        heap.cycle()
        if speed:
            lag = sim.time / speed - (time.perf_counter() - start)
            if lag > 0:
                time.sleep(lag)
        if progress is not None and sim.time >= next_progress:
            if life.executive is not None:
                progress(sim, life.executive)
            next_progress = sim.time + progress_every
    due.left_over()


class _Heap:
    """Keeps the collector's full passes off what a run keeps (the world, the team, its records): frozen at the
    start and every `every` control cycles (`gc.freeze`), thawed at the end.

    Nothing in a run depends on when cycles are collected. A 1,000-robot run holds a million objects that live to
    its end, and each full pass of the collector walked them all: 22 passes, 6.8 s of a 63 s run (120 s of sim
    time); frozen every 2 s of sim time, 1 pass. What dies after being frozen (little: a few hundred objects in
    30 s) is collected after the run. A process whose heap someone else froze, or whose collector is off, is
    left as it is."""

    def __init__(self, every: int = 20) -> None:
        self.every, self.cycles, self.on = every, 0, False

    def __enter__(self) -> _Heap:
        self.on = gc.isenabled() and gc.get_freeze_count() == 0
        if self.on:
            gc.freeze()
        return self

    def cycle(self) -> None:
        self.cycles += 1
        if self.on and self.cycles % self.every == 0:
            gc.freeze()

    def __exit__(self, *exc: object) -> None:
        if self.on:
            gc.unfreeze()
            self.on = False


def _submit(life: ControllerLife, m: Mission, n: int, speed: float | None, trace: IO[str] | None,
            recorder: Recorder | None = None, ended: Callable[[str, rec.Record], None] | None = None) -> DryRun:
    """Start mission number `n` on the executive; its report gathers its records (and the trace gets them);
    `ended(mission id, record)` hears them too."""
    result = DryRun(m.chart.name, None, "", 0.0, 0.0, speed=speed, priority=m.priority or m.chart.priority)
    mid = f"{m.chart.name}-{n}"
    listeners: list[Callable[[rec.Record], None]] = [result.records.append, functools.partial(facts, result)]
    if trace is not None:
        listeners.append(TraceWriter(trace, mid))
    if recorder is not None:
        listeners.append(functools.partial(recorder.record, mid))
    if ended is not None:
        listeners.append(functools.partial(ended, mid))
    result.mission_id = mid
    life.submit(m.chart, mid, listeners, result.priority)
    return result


def summary(r: DryRun) -> dict[str, Any]:
    """What a recording keeps of a run besides its records, for `rebuilt` to give the same report."""
    return {"mission": r.mission, "id": r.mission_id, "records": r.mission_id or r.mission,  # their mission key
            "priority": r.priority, "speed": r.speed,
            "sim_time": r.sim_time, "wall_time": r.wall_time, "on_cluster": r.on_cluster,
            "injections": r.injections, "scouts": r.scouts,
            **({"controller_away": r.away} if r.away else {})}  # its replay's pace leaves it out too


def rebuilt(run: Mapping[str, Any], records: Sequence[rec.Record],
            where: Callable[[str], tuple[float, float] | None] | None = None) -> DryRun:
    """The report of a recorded run, from its records (outcome, timeline, holds, waits, logs, doors, detections)
    and its summary (times, injections, where the Scouts ended). A summary without the Scouts (a recording cut
    short) keeps those its records launched, each where `where(scout)` says it was last (readers audit 13, D6)."""
    finished = next((r for r in reversed(records) if isinstance(r, rec.Finished)), None)
    end = f"the recording ends at {float(run['sim_time']):.1f} s, before the run did"
    result = DryRun(str(run["mission"]), finished.outcome if finished else "unfinished",
                    finished.reason if finished else end,
                    float(run["sim_time"]), float(run.get("wall_time") or 0.0), speed=run.get("speed"),
                    on_cluster=bool(run.get("on_cluster")), priority=int(run.get("priority") or 1),
                    mission_id=str(run.get("id") or ""))
    for r in records:
        result.records.append(r)
        facts(result, r)
    result.away = float(run.get("controller_away") or 0.0)  # records audit 26, D1
    result.injections = list(run.get("injections") or [])
    if "scouts" in run:
        result.scouts = list(run.get("scouts") or [])
    elif where is not None:
        for scout in result.scouts:
            last = where(str(scout["scout"]))
            if last is not None:
                scout.update(x=round(last[0], 2), y=round(last[1], 2))
    return result


def _note_end(ends: dict[str, tuple[float, float]], start: float, mid: str, record: rec.Record) -> None:
    """Mission `mid`'s sim and wall seconds when it finished (`run_many`'s `ends`)."""
    if isinstance(record, rec.Finished):
        ends[mid] = (record.at, time.perf_counter() - start)


def _conclude(results: list[DryRun], running: list[Any], sim: Simulation, wall: float,
              ends: Mapping[str, tuple[float, float]]) -> None:
    """Each report's outcome, its own times (a mission that ended before the others, at its end: semantics audit
    1), the Scouts where they ended, and every robot's track."""
    tracks = {rid: sim.trajectory(rid) for rid in (*sim.robots, *sim.intruders())}
    for interp, result in zip(running, results, strict=True):
        result.outcome, result.reason = interp.outcome, interp.reason
        result.sim_time, result.wall_time = ends.get(result.mission_id or "", (sim.time, wall))
        for scout in result.scouts:
            pose = sim.pose(scout["scout"])
            scout.update(x=round(pose.x, 2), y=round(pose.y, 2))
            if sim.state(scout["scout"]) == "lost":  # where it was lost: it has no place at the end (worlds audit 17)
                scout["lost"] = True
        result.tracks = tracks


def _inject(inj: Injection, sim: Simulation, life: ControllerLife, cluster: Cluster,
            later: Sequence[Injection] = (), leaving: dict[str, float] | None = None) -> dict[str, Any]:
    """Apply one injected failure now (`later`: the injections still to come; `leaving`: killed hosts -> when their
    resources leave the manager, one lease after the kill, as on a cluster); the record says what it did."""
    leaving = {} if leaving is None else leaving
    what = str(inj)
    executive = life.executive  # None while the controller is down: the manager learns it when it starts again
    controller = inj.action in (Action.KILL, Action.RESTART) and Role.CONTROLLER in cluster.host(inj.target).roles
    if inj.action is Action.KILL and controller:
        restarting = any(i.action is Action.RESTART and (i.target == inj.target or i.target in life.standbys_later)
                         for i in later)  # with an election, any controller started again resumes
        what += ": " + life.kill(sim.time, inj.target, restarting)
    elif inj.action is Action.RESTART and controller:
        what += ": " + life.restart(sim.time, inj.target)
    elif inj.action in (Action.JOIN, Action.RESTART):
        found = [r for r in cluster.resources() if r.host == inj.target]
        life.gone.difference_update(r.id for r in found)
        life.down.discard(inj.target)
        back = leaving.pop(inj.target, None) is not None  # within its lease: the manager still has its resources
        if executive is not None:
            executive.host_restarted([r.id for r in found])
        if executive is not None and back and all(r.id in executive.pool.candidates for r in found):
            executive.set_host_offline(inj.target, False)
            what += ": back within its lease, its resources may be granted again"
        else:
            if executive is not None:
                executive.add_resources([r for r in found if r.id not in executive.pool.candidates])
            what += f": {len(found)} resources joined the manager"
    elif inj.action is Action.KILL:
        robots = _halt_host_robots(sim, cluster, inj.target)
        ids = [r.id for r in cluster.resources() if r.host == inj.target]
        life.gone.update(ids)
        if cluster.host(inj.target).devices:  # a controller started again waits for it
            life.down.add(inj.target)
        if Role.SIMULATOR in cluster.host(inj.target).roles:  # the world is gone with it, as on a cluster
            _world_lost(executive, inj.target)
            what += (": it ran the simulator, so the world is gone: every mission failed;"
                     f" {', '.join(robots) or 'no robot'} stopped")
        else:
            if executive is not None:
                executive.host_died(inj.target, ids)
            leaving[inj.target] = sim.time + cluster.lease
            what += (f": its components died with it, {', '.join(robots) or 'no robot'} stopped; its resources are"
                     f" granted to no one new and leave the manager at {leaving[inj.target]:.1f} s (its lease) unless"
                     " it restarts")
    elif inj.action is Action.LOSE:
        sim.lose(inj.target)
        life.gone.update(_robot_resources(cluster, inj.target))
        if executive is not None:
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


def _world_lost(executive: Executive | None, host: str) -> None:
    """The simulator's host died: every mission still running fails with a cluster's words."""
    if executive is not None:  # together: none is granted what another's failure gives back, as on a cluster
        stop_together(list(executive.missions.values()), host_down_reason(host, simulator=True), "failure")


def _halt_host_robots(sim: Simulation, cluster: Cluster, host: str) -> list[str]:
    """A killed host's robots stop where they are and stay in the world, bodies the others' lasers see, as a
    cluster's simulator keeps them (records audit 18, #1: they were lost, and a Ranger drove through where one
    stood); a `restart` gives them back to the manager as they are. A robot lost before stays lost."""
    robots = [r.id for r in cluster.host(host).robots if r.id in sim.robots and sim.state(r.id) != "lost"]
    for rid in robots:
        sim.stop(rid)  # its daemon is gone: nothing drives it any more
    return robots


def _controllers(cluster: Cluster) -> dict[str, Any]:
    """The controller hosts, the acting one first, and the election's lease: several with a replicated store (a
    standby takes over as on the cluster), else the one controller."""
    from drd.cluster.election import election_ttl

    if cluster.store.replicated and len(cluster.controllers) > 1:
        return {"controllers": [h.name for h in cluster.controllers], "election": float(election_ttl(cluster.lease))}
    return {"controllers": [cluster.controller.name]}


class _Injections:
    """The injections of a dry-run, each applied in the control cycle that reaches its time, its effect added to
    every report; a standby's takeover told on the row of the kill that caused it."""

    def __init__(self, injections: Sequence[Injection], sim: Simulation, life: ControllerLife, cluster: Cluster,
                 results: list[DryRun]) -> None:
        self.pending = sorted(injections)
        self.sim, self.life, self.cluster, self.results = sim, life, cluster, results
        self.electing: dict[str, Any] | None = None  # the row that says a standby will take over
        self.leaving: dict[str, float] = {}  # a killed host -> when its resources leave the manager
        self.killed: dict[str, dict[str, Any]] = {}  # a killed host -> the row of its kill

    def now(self) -> None:
        """Apply those due at the simulation's time, then let the controllers' life go on (an election)."""
        sim, life = self.sim, self.life
        for host, at in sorted(self.leaving.items(), key=lambda item: (item[1], item[0])):
            if at <= sim.time + 1e-9:  # its lease ran out: its resources leave, their holders lose them
                del self.leaving[host]
                if life.executive is not None:  # (a controller down has no manager: it starts without them)
                    life.executive.remove_host(host)
                    self.killed[host]["effect"] += f"; at {sim.time:.1f} s its resources left the manager"
        while self.pending and self.pending[0].at <= sim.time + 1e-9:
            before = (life.takeover, life.resuming)
            effect = self._apply(self.pending.pop(0))
            if (life.takeover, life.resuming) != before and (life.takeover or life.resuming) is not None:
                self.electing = effect  # it says when the standby took over, or the controller resumed
        taken = life.tick(sim.time)
        if taken is not None and self.electing is not None:
            self.electing["effect"] += f"; at {sim.time:.1f} s {taken}"

    def at_start(self) -> None:
        """Apply those at 0 s before the missions' first grants (cluster audit 20, #7: `kill ranger2 at 0s` took
        effect at 0.1 s, and ranger2 had been granted meanwhile), up to the first that kills or restarts a
        controller: that one needs the missions' first cycle, and so do those after it (they keep their order)."""
        while self.pending and self.pending[0].at <= 1e-9:
            inj = self.pending[0]
            if inj.action in (Action.KILL, Action.RESTART) and Role.CONTROLLER in self.cluster.host(inj.target).roles:
                return
            self._apply(self.pending.pop(0))

    def _apply(self, inj: Injection) -> dict[str, Any]:
        """Apply one injection now; its row, added to every report (and kept as its host's kill)."""
        effect = _inject(inj, self.sim, self.life, self.cluster, self.pending, self.leaving)
        if inj.target in self.leaving:
            self.killed[inj.target] = effect
        for result in self.results:
            result.injections.append(effect)
        return effect

    def left_over(self) -> None:
        """The missions ended first: say so of those never applied, rather than drop them without a word."""
        for inj in self.pending:
            for result in self.results:
                result.injections.append(_not_injected(inj, self.sim.time))


def _not_injected(inj: Injection, now: float) -> dict[str, Any]:
    """The report's row of an injection that never happened: the run ended (at `now`) before its time."""
    return {"at": inj.at, "action": inj.action.value, "target": inj.target, "injection": str(inj),
            "effect": f"{inj} (the run ended at {now:.1f} s, before it)", "skipped": True}


def _robot_resources(cluster: Cluster, robot: str) -> list[str]:
    """A lost robot takes its aggregate and the parts only it uses (not a radio channel shared with others)."""
    robots = cluster.robots
    mine = next((r for r in robots if r.id == robot), None)
    if mine is None:  # in the world but not in hosts.yaml: the manager never had it
        return []
    others = {u for r in robots if r.id != robot for u in r.parts.values()}
    return [robot, *(u for u in mine.parts.values() if u not in others)]


def facts(result: DryRun, r: rec.Record) -> None:
    """Doors found, Scouts placed and intruders seen, from the standard behaviors' events (a mission of other
    components has none of them: `DryRun.events` counts every event by name)."""
    if not isinstance(r, rec.Event):
        return
    if r.name == "DoorDetected":
        result.doors.append({"at": report_time(r.at), "by": r.path, **r.fields})
    elif r.name == "ScoutLaunched":
        result.scouts.append({"at": report_time(r.at), "scout": r.fields.get("scout"), "by": r.path})
    elif r.name == "MotionDetected":
        result.detections.append({"at": report_time(r.at), "by": r.path, **r.fields})


def merged(reports: Sequence[DryRun]) -> DryRun:
    """Several missions' reports as one, for the picture of the team's run (their doors, Scouts, sightings)."""
    first = reports[0]
    out = DryRun(" + ".join(r.mission for r in reports), first.outcome, first.reason, first.sim_time,
                 first.wall_time, tracks=first.tracks, speed=first.speed)
    for r in reports:
        out.records += r.records
        out.doors += r.doors
        out.scouts += r.scouts
        out.detections += r.detections
    return out


#: The worlds that come with drd (beside the packages, in a source tree or an editable install).
SHIPPED_WORLDS = Path(__file__).resolve().parents[1] / "worlds"


def locate_world(name: str, roots: Sequence[Path]) -> tuple[Path | None, list[Path]]:
    """Where the world `name` is, and every path tried, in order (for an error that says where it looked).

    A name (`corridor`) is `<root>/worlds/<name>.yaml` for each root (the folder of the hosts file that names
    it, and for `--world` first the working directory), else the worlds that ship with drd; a path (`x.yaml`,
    `worlds/corridor.yaml`) is itself when absolute, else relative to each root, else a shipped world of
    that file name. So a dry-run finds its world from any directory."""
    p = Path(name)
    if p.suffix in (".yaml", ".yml") or "/" in name or p.is_absolute():
        tried = [p] if p.is_absolute() else [root / p for root in roots] + [SHIPPED_WORLDS / p.name]
    else:
        tried = [root / "worlds" / f"{name}.yaml" for root in roots] + [SHIPPED_WORLDS / f"{name}.yaml"]
    unique: list[Path] = []
    for path in tried:
        if not any(path.absolute() == u.absolute() for u in unique):
            unique.append(path)
    return next((path for path in unique if path.is_file()), None), unique


def world_path(name: str, root: Path) -> Path:
    """`corridor` or `worlds/corridor.yaml` or any path, as `locate_world` finds it from `root` (the first path
    tried when it is nowhere, for the error to name)."""
    found, tried = locate_world(name, [root])
    return found or tried[0]
