"""Running a mission on the cluster: the controller's side of `missionctl run`.

`missionctl run` sends a `RunMission` with the mission's SOURCE text and file name to
`drd/<cluster>/missions/run`. The controller compiles it with its own catalog (a compiled object or code
from the wire is never trusted) and answers a `RunReply`: the mission id, or the located diagnostics
(rendered as `missionctl validate` prints them) when the mission is invalid.

A valid mission runs in lockstep with the simulator, on the thread of its world (`WorldRun`): each control
cycle (0.1 s of sim time) the simulation steps, then the executive steps under the executive's lock, its clock
at the simulation's new time; components on other hosts are stepped through their Creators
(`drd.cluster.remote`), and the gate operations no call carried go to the devices' hosts at the end of the
cycle (`drd.cluster.gates`). The step is made just before the cycle's first call to another host: carried by
that call when it is a batch to the simulator host (one round trip for both), else asked of the simulator
(`drd.sim.service`) on its own. `speed` caps the pace at that multiple
of real time. Records go out on `drd/<cluster>/mission/<id>/record` as for every mission of the executive.
The simulator holds one world: the missions of the cluster share it (a second `missionctl run` joins the world
the first one started, and the one Resource Controller Manager arbitrates their grants by priority); it stops
when its last mission ends, and each ended mission's processes are retired on every host it used.

A cluster of real robots has no host with the role simulator: its missions then run in no simulated world
(`NO_WORLD`). The loop runs its control cycles in real time, the executive's clock is the wall clock since the
world began, no step goes to any host, and the devices' drivers talk to the robots as they always do. A real robot
cannot go faster than real time, so `speed` other than 1 is refused, and so is a named world.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import threading
import time
from collections.abc import Callable, Collection, Container, Iterator, Mapping
from typing import Any

from drd.bus import Bus, Message, Query, Reply, message
from drd.bus.keys import is_concrete
from drd.cluster.gates import GateUpdate, GateUpdateReply, RemoteGates, deliver, take_pending
from drd.cluster.guard import SharedGuard
from drd.cluster.remote import ComponentCall, ComponentError, ComponentRouter, SimCycle, frozen_reason
from drd.cluster.telemetry import RemoteTelemetry
from drd.daemon.logs import PLACEMENT_LOGGER
from drd.daemon.migrate import Migrations
from drd.daemon.placements import PlacementLog
from drd.daemon.resume import Checkpoints, resume, wait_for_hosts
from drd.errors import MissionInputError, host_down_reason
from drd.hosts import Cluster, Role
from drd.journal import Journal
from drd.placement import HostView, Recent
from drd.profiling import Sampler
from drd.sim.service import SimReply, SimRequest, SimulationService
from drd.sim.service import key as sim_key
from dsl.catalog import Catalog

log = logging.getLogger("drd.daemon.missions")
placement_log = logging.getLogger(PLACEMENT_LOGGER)  # rate-limited by `drd start` (drd.daemon.logs)

#: Sim seconds per control cycle, as in the dry-run.
CONTROL_PERIOD = 0.1
#: Seconds a Creator or the simulator may take to answer one call, at least: a host counts as lost only once it
#: has not answered for its lease (`MissionRunner.patience`), so a short freeze delays the mission, never fails it.
CALL_TIMEOUT = 1.0
#: Seconds at most a placement counts on its host while the host's own announcements (its instances) lack it.
RECENT_PLACEMENT = 3.0
#: Wall seconds between two refreshes of the answers status queries get while the mission loop is held up.
REFRESH_EVERY = 0.5
#: The world of a cluster with no simulator host: its missions drive the real robots, in real time.
NO_WORLD = "none (real robots)"


@message("drd.mission.run", 4)
class RunMission(Message):
    """Run this mission source (`file` names it in diagnostics) in world `world` at `speed` x real time."""

    source: str
    file: str
    world: str = ""  # "": the cluster's (hosts.yaml `cluster.world`)
    speed: float = 1.0
    until: float = 1800.0
    seed: int = 0
    params: dict[str, str] | None = None  # --param NAME=VALUE: the mission's own variables (dsl.params)
    priority: int | None = None  # the mission's rank against the others (1 first); None: its `mission ... priority`
    #: The wall-clock time (`time.time()`) the client stops waiting for the reply; 0: it waits as long as it takes.
    #: The controller never starts a mission after it: a client that gave up never sees its mission start later.
    give_up_at: float = 0.0
    #: The texts of the files the mission imports, by the names the client read them by (relative to `file`'s
    #: folder, as the mission says): the controller never reads its own disk for a mission's imports.
    imports: dict[str, str] | None = None
    aliases: dict[str, str] | None = None  # other names of a file in `imports` (`dsl.loader.import_aliases`)


@message("drd.mission.run-reply", 2)
class RunReply(Message):
    """`mission` is the id of the started mission; when `ok` is false, `diagnostics` say why (rendered)."""

    mission: str
    ok: bool
    diagnostics: list[str]
    world: str = ""
    speed: float = 0.0
    started: float = 0.0
    base: float = 0.0  # the executive's time when the mission started (records' `at` minus this is its time)
    priority: int = 1


class SimTimeClock:
    """The executive's clock: the simulator's time plus an offset that keeps it monotonic across missions;
    `origin`, when the current world began on it (components see the world's time, `now - origin`, from 0 as in a
    dry-run). The same as `base` but for real robots resumed after a loss, whose clock goes on from the last save
    while their world's time goes on from its start."""

    def __init__(self) -> None:
        self.base = 0.0
        self.t = 0.0
        self.origin = 0.0

    def now(self) -> float:
        return self.t

    def start_mission(self) -> None:
        self.base = self.origin = self.t

    def set_sim(self, sim_time: float) -> None:
        self.t = self.base + sim_time


def request_data(req: RunMission) -> dict[str, Any]:
    """What the journal keeps of a run request (all but the client's patience)."""
    return {f.name: getattr(req, f.name) for f in dataclasses.fields(req) if f.name != "give_up_at"}


def run_key(cluster: str) -> str:
    return f"drd/{cluster}/missions/run"


class RoomsRefused(MissionInputError):
    """The mission names rooms the world lacks (`dsl.rooms`): its located diagnostics, rendered."""

    def __init__(self, lines: list[str]) -> None:
        super().__init__("; ".join(lines))
        self.lines = lines


def refuse_unknown_rooms(chart: Any, rooms: Collection[str], world: str, req: RunMission) -> None:
    """RoomsRefused when the mission names a room `world` lacks in an `inside(...)`: a geofence on a misspelled room
    would guard nothing (users audit 9, D6)."""
    from dsl.rooms import unknown_rooms

    found = unknown_rooms(chart, rooms, world)
    if found:
        raise RoomsRefused(render(found, {req.file or "<mission>": req.source}))


def render(diagnostics: list[Any], sources: dict[str, str]) -> list[str]:
    """Diagnostics as `missionctl validate` prints them (file:line:col, message, source line, caret), plain text."""
    return [d.render(sources) for d in diagnostics]


def mission_id(name: str, now: float, taken: Container[str]) -> str:
    """A new mission's id, `<name>-<number>`: the milliseconds of `now` modulo 10^7, the next number while that id
    is `taken`. Always a number after the last dash, which readers split off (`drd.cli.cluster.mission_name`): two
    missions of one name started in the same millisecond were `N-5` and `N-5x`, and the second's name was then
    read as `N-5x`."""
    number = int(now * 1000) % 10_000_000
    while f"{name}-{number}" in taken:
        number += 1
    return f"{name}-{number}"


def _given_up(req: RunMission) -> RunReply:
    """The refusal of a mission whose client stopped waiting before it could start (`RunMission.give_up_at`)."""
    late = time.time() - req.give_up_at
    log.warning("mission %s not started: its client gave up %.1f s ago", req.file, late)
    return RunReply("", False, [f"{req.file}: not started: the client stopped waiting {late:.1f} s before the "
                                "controller could start it"])


class MissionRunner:
    """Serves `missions/run` on the controller and runs the accepted missions in lockstep (see the module doc).

    The missions of a cluster share its one simulated world: the first one starts it (a fresh simulation, at the
    seed and speed it asks), the next ones join it while it runs, and it stops when its last mission ends. Each
    mission ranks against the others by its priority (`RunMission.priority`, else its own `mission ... priority`),
    through the one Resource Controller Manager."""

    def __init__(self, bus: Bus, cluster: Cluster, catalog: Catalog, me: str, lock: threading.RLock,
                 controller: Any, clock: SimTimeClock, *, sim_service: SimulationService | None = None,
                 host_down: Callable[[str], bool] = lambda h: False,
                 host_views: Callable[[], list[HostView]] | None = None, journal: Journal | None = None,
                 term: float | None = None, frozen: Callable[[float], float] = lambda since: 0.0) -> None:
        """`journal`: where missions are saved each cycle and resumed from after a restart (`drd.journal`); `term`:
        this controller's term as its election gave it (`drd.cluster.election`), else its start time; `frozen`: how
        long this daemon was frozen after a time (`Daemon.frozen_since`), so a call it timed out is not the callee's
        fault."""
        self.bus = bus
        self.cluster = cluster
        self.catalog = catalog
        self.me = me
        self.lock = lock
        self.controller = controller
        self.clock = clock
        self.sim_service = sim_service
        self.host_down = host_down
        self.host_views = host_views
        self.frozen = frozen
        self._recent: list[Recent] = []  # placements their hosts may not announce yet, oldest first
        self._ended: list[Recent] = []  # placed instances that ended, which their hosts may still announce
        self.placements = PlacementLog(lambda: controller.executive.missions)  # for `missionctl status`
        self.began: dict[str, float] = {}  # mission -> the executive's time it began, while the executive lists it
        self.undelivered: set[str] = set()  # hosts whose last gate operations did not arrive (said once each)
        self.resource_hosts = {r.id: r.host for r in cluster.resources() if r.host}
        self.patience = max(CALL_TIMEOUT, cluster.lease)  # how long a call waits for a host that does not answer
        # this controller's term: hosts refuse the calls of an older one (`Creator`)
        self.term = time.time() if term is None else term
        self.simulator = next((h.name for h in cluster.hosts if Role.SIMULATOR in h.roles), None)
        # the devices' gates are on their hosts: every mission's grants reach them through these (`_deliver_gates`)
        self.gates = RemoteGates({u.id: u.host for u in cluster.resources() if u.host and type(u).__name__ == "Unit"},
                                 self._deliver_gates)
        executive = controller.executive
        executive.gates, executive.status_extras, executive.pending = self.gates, self._status_extras, self._pending
        # robots' pose and battery come with the hosts' replies; constraints are guarded on the devices' hosts
        self.telemetry = RemoteTelemetry({r.id: r.host for r in cluster.robots if r.host}, self._fetch,
                                         self.gates.send, clock.now, lambda host: self.host_down(host))
        self.gates.seen = self.telemetry.seen
        executive.pool.telemetry = self.telemetry
        executive.guard = self.guard = SharedGuard(executive.pool, self.gates.device_hosts, self.gates.send, clock.now)
        self.world: WorldRun | None = None
        self.starting = threading.Lock()
        self.generation = 0  # worlds started so far: a Creator builds its drivers again for a new one
        self.halting: list[str] = []  # hosts seen down whose simulated robots the loop stops now (`halt_host`)
        self.retirements: dict[str, list[ComponentCall]] = {}  # host -> retire calls it missed (`owed`)
        self._hosts_lock = threading.Lock()  # `halting` and `retirements`: the daemon's thread never waits for `lock`
        self.journal = journal
        self.checkpoints = Checkpoints(journal) if journal is not None else None
        self.suspending = False  # a maintenance stop: the missions stay journaled as running (`suspend`)
        if journal is not None:  # the history `missionctl status` listed before a restart
            executive.restore_history((f.id, f.status) for f in journal.finished())
        self._queryable = bus.serve(run_key(cluster.name), self._serve)
        self._migrations = Migrations(bus, self)  # `missionctl migrate` (drd.daemon.migrate)
        threading.Thread(target=self._warm_up, name="drd-compiler-warm-up", daemon=True).start()
        # the journal's missions waiting to be resumed (their hosts are not all back yet): no new run nor stop meanwhile
        self.resuming: list[str] = [job.id for job in journal.running()] if journal is not None else []
        if self.resuming:
            threading.Thread(target=self._resume, name="drd-resume", daemon=True).start()

    def _resume(self) -> None:
        """Resume the journal's missions once the hosts with devices (and the simulator's) are back, or after a
        grace of two leases and a few seconds: a host still down then is handled as during a run."""
        assert self.journal is not None
        hosts = sorted({h.name for h in self.cluster.hosts if h.devices} | ({self.simulator} if self.simulator else
                                                                               set()))
        try:
            down = wait_for_hosts(self, hosts, self.cluster.resume_grace)
            if down:
                log.warning("resuming without %s (still down)", ", ".join(down))
            resumed = resume(self, self.journal)
        except Exception:  # never leave the operator guessing: the journal stays for the next start
            log.exception("the journal's missions could not be resumed")
            return
        finally:
            self.resuming = []
        if resumed:
            log.info("resumed %d mission(s) from the journal: %s", len(resumed), ", ".join(resumed))

    def _pending(self) -> tuple[list[str], str]:
        """The executive's `pending`: asked from its queryable, which may serve before `resuming` is set."""
        return list(getattr(self, "resuming", ())), self._resuming_why()

    def _resuming_why(self) -> str:
        return (f"from its journal, once their hosts are back (at most {self.cluster.resume_grace:g} s after it"
                " started)")

    def _status_extras(self, mission: str) -> dict[str, Any]:
        """What the executive's status adds to a mission of this controller: `started`, the executive's time when
        it began (its `time` is the world's clock, which every mission of the world shares: the mission has run
        `time - started`), and its placements."""
        started = {"started": self.began[mission]} if mission in self.began else {}
        return {**started, **self.placements.extras(mission)}

    def _warm_up(self) -> None:
        """Build the parser's tables once, in the background (and cache them on disk for every later process):
        the operator's first `missionctl run` then compiles the corridor mission in about 80 ms rather than 180.
        Not a whole compile: the checker's imports (networkx among them) would hold 17 MB more on an idle
        controller, for 80 ms of one run (issue #15: an idle daemon <= 60 MB)."""
        from drd.cache import cache_parser_tables

        try:
            cache_parser_tables()
        except Exception:  # only ever a head start: the first run compiles as it would have
            log.debug("compiler warm-up failed", exc_info=True)

    @property
    def current(self) -> WorldRun | None:
        """The world running now, if any (one whose last mission ended takes no new one)."""
        world = self.world
        return world if world is not None and not world.closed else None

    def suspend(self) -> None:
        """A clean stop of this controller's daemon (`drd stop`, SIGTERM): end the world's loop without stopping
        its missions, so they stay journaled as running and the next `drd start` resumes them, as after a crash
        (docs/design.md, "A controller's clean stop suspends its missions"). Nothing more is said of them: an
        attached `missionctl run` waits for the controller as it would after a crash."""
        self.suspending = True
        world = self.world
        if world is not None:
            world.stopping.set()
            world.thread.join(timeout=5)
        with self.lock:
            self.controller.executive.abandon_missions()

    def close(self) -> None:
        self._queryable.close()
        self._migrations.close()
        world = self.world
        if world is not None:
            world.stopping.set()
            world.thread.join(timeout=5)
        if self.journal is not None:
            self.journal.close()

    def host_back(self, host: str) -> None:
        """`host` reports again after it was down: the running missions take it for a host again (`ComponentRouter
        .back`), its robots' live values are read afresh, and the retirements it missed meanwhile are sent to it, on
        a thread of their own (recovery audit D1: a frozen host's instances and worker processes of an ended mission
        ran on until the controller's restart, counted in its placement load)."""
        world = self.world
        for router in list(world.routers.values()) if world is not None else []:
            router.back(host)
        self.telemetry.forget(host)  # its robots are watched again: a restarted daemon watches none
        with self._hosts_lock:
            calls = self.retirements.pop(host, [])
        if calls:
            threading.Thread(target=self._retire_late, args=(host, calls), name=f"drd retire on {host}",
                             daemon=True).start()

    def owed(self, host: str, retire: ComponentCall) -> None:
        """`retire` could not reach `host` (down, or silent): sent when it is seen up again (`host_back`)."""
        with self._hosts_lock:
            owed = self.retirements.setdefault(host, [])
            if all(c.mission != retire.mission for c in owed):
                owed.append(retire)

    def _retire_late(self, host: str, calls: list[ComponentCall]) -> None:
        for call in calls:
            try:
                self.bus.call(f"drd/{self.cluster.name}/host/{host}/creator", call, self.patience)
            except Exception as e:  # it went again: its own controller loss retires what is left
                log.info("mission %s: %s did not confirm the late retirement: %s", call.mission, host, e)
            else:
                log.info("mission %s: %s retired its instances on its return", call.mission, host)

    def halt_host(self, host: str) -> None:
        """`host` went silent past its lease: its simulated robots stop at the next control cycle, as a zero
        Twist stops its `ros2` robots (recovery audit D0: a robots' host frozen for a lease and a half left its
        Ranger driving on in the simulator at its last setpoint, its holder gone, the gates' stops for that host
        dropped while it was down). Its robots stay in the world, stopped, whether it comes back or not."""
        if self.current is not None:
            with self._hosts_lock:
                self.halting.append(host)

    def _halt_robots(self) -> None:
        """Before the next cycle: the missions holding a drive of the hosts gone down record its stop (their gates,
        on that host, cannot: a trace showed the robot moving to the end; safety audit 8, D6), then their simulated
        robots stop (a `ros2` robot got its zero Twist from the daemon, `stop_robots`)."""
        with self._hosts_lock:
            hosts, self.halting = self.halting, []
        for host in hosts:
            self._record_halts(host)
        if self.simulator is None:
            return
        stop = functools.partial(SimRequest, "multi")
        for host, robots, done in self._robots_in_sim(hosts, lambda ids: stop(args=[["stop", [r]] for r in ids])):
            stopped = [rid for rid, (_value, error) in zip(robots, done, strict=False) if not error]
            log.warning("host %s down: its robots %s stopped in the simulation", host, ", ".join(stopped) or "(none)")

    def _record_halts(self, host: str) -> None:
        """A `halted` for each drive of `host` a running mission holds, in that mission, by its holder."""
        from drd.runtime.records import Halted

        drives = self._drives(host)
        with self.lock:
            executive = self.controller.executive
            now = self.clock.now()
            for unit in drives:
                for holder in executive.broker.holders(unit):
                    mission, _, path = holder.partition("/")
                    executive.record(mission, Halted(now, path, unit, "stop", f"host {host} down: its robots were"
                                                                              " stopped by the controller"))

    def _drives(self, host: str) -> list[str]:
        """The ids of `host`'s Drive devices: what moves a robot, and so what a halt is recorded for."""
        return [d.id for d in self.cluster.host(host).devices if d.type == "Drive"]

    def _robots_in_sim(self, hosts: list[str], request: Callable[[list[str]], SimRequest]
                       ) -> Iterator[tuple[str, list[str], Any]]:
        """For each of `hosts` with robots: (host, its robot ids, the simulator's answer to `request(ids)`); a host
        whose request fails is logged and passed over (the simulator's own loss is reported by the next step)."""
        for host in hosts:
            robots = [r.id for r in self.cluster.host(host).robots]
            if not robots:
                continue
            try:
                value = self.sim(request(robots)).value or []
            except Exception as e:
                log.warning("could not stop %s's robots in the simulator: %s", host, e)
                continue
            yield host, robots, value

    def sim(self, req: SimRequest) -> SimReply:
        if self.sim_service is not None:
            return self.sim_service.handle(req)
        gone = functools.partial(self.host_down, self.simulator or "")  # asked again while it is not down
        reply = self.bus.call_reaching(sim_key(self.cluster.name), req, self.patience, gone)
        if not isinstance(reply, SimReply):
            raise ValueError(f"the simulator answered a {type(reply).TYPE}")
        return reply

    def _serve(self, query: Query) -> Message | Reply:
        req = query.payload
        if not is_concrete(query.key):  # a run is asked by this exact key (drd.daemon.acl)
            return query.error(f"ask {query.queryable} by its exact key")
        if not isinstance(req, RunMission):
            return query.error("expected a drd.mission.run")
        try:
            return self.start(req)
        except ValueError as e:
            return query.error(str(e))

    def start(self, req: RunMission) -> RunReply:
        from drd.cache import cache_parser_tables
        from dsl import compile_text

        cache_parser_tables()  # done by the warm-up unless a run comes first
        if not (req.speed > 0) or not (req.until > 0):
            raise ValueError("speed and until must be positive")
        if req.priority is not None and req.priority < 1:
            raise ValueError("priority must be 1 or more (1 is the highest)")
        if len(req.source) + sum(len(k) + len(t) for k, t in [*(req.imports or {}).items(),
                                                               *(req.aliases or {}).items()]) > 1_000_000:
            raise ValueError("mission source (with its imports) larger than 1 MB")
        if self.simulator is None:
            real_run_refusal(self.cluster, req)
        if self.resuming:  # a world started now would be the one the resume rejoins: its clock went backwards
            raise ValueError(f"the controller is resuming {', '.join(self.resuming)} {self._resuming_why()}: run"
                             " this mission again when `missionctl status` lists them")
        limits = self.cluster.limits
        budget = limits.compile_seconds if not req.give_up_at else min(limits.compile_seconds,
                                                                       req.give_up_at - time.time())
        if budget <= 0:  # it waited behind other work until its client left: compiling it would be for nobody
            return _given_up(req)
        compiled = compile_text(req.source, self.catalog, req.file or "<mission>", budget, limits,
                                imports=req.imports or {}, aliases=req.aliases)
        if not compiled.ok or compiled.statechart is None:
            diags = render(list(compiled.diagnostics), dict(compiled.sources))
            return RunReply("", False, diags or [f"{req.file}: declares no mission to run"])
        from dsl.params import ParamError, apply_params

        try:
            chart = apply_params(compiled.statechart, dict(req.params or {}))
        except ParamError as e:
            return RunReply("", False, str(e).splitlines())
        priority = req.priority or chart.priority
        with self.starting:  # one start at a time: two first missions must not start two worlds
            try:
                return self._start(req, chart, priority)
            except RoomsRefused as e:
                return RunReply("", False, e.lines)

    def _start(self, req: RunMission, chart: Any, priority: int) -> RunReply:
        if req.give_up_at and time.time() > req.give_up_at:  # before a world is made for nobody
            return _given_up(req)
        world = self.current
        if world is not None:  # the mission joins the world that runs
            if req.world and req.world != world.name:
                raise ValueError(f"world {world.name} is running (missions {', '.join(world.missions())}): a mission"
                                 f" joins it; run this one in {world.name}, or after they end")
            places = self.controller.executive.pool.places
            if places:
                refuse_unknown_rooms(chart, set(places), world.name, req)
        else:
            if self.world is not None:  # its loop is ending: let it retire its missions first
                self.world.thread.join(timeout=10)
            world = self._new_world(req, chart)
        with self.lock:
            if world.closed:  # its last mission ended while this one was compiled: start the world again
                raise ValueError(f"world {world.name} ended just now: run the mission again")
            if req.give_up_at and time.time() > req.give_up_at:  # all or nothing: nobody would watch it run
                return _given_up(req)
            executive = self.controller.executive
            mid = mission_id(chart.name, time.time(), executive.missions)
            base = self.clock.now()
            if self.journal is not None:  # before its first record: a loss from now on resumes it
                self.journal.begin(mid, request_data(req), priority, base, req.until)
            self.submit(world, chart, mid, priority, base, req.until)
        world.go()
        log.info("mission %s started (%s, world %s, speed %gx, priority %d)", mid, req.file, world.name,
                 world.speed, priority)
        return RunReply(mid, True, [], world.name, world.speed, time.time(), base, priority)

    def submit(self, world: WorldRun, chart: Any, mid: str, priority: int, base: float, until: float,
               resume: Any = None, since: float = 0.0, paused: float = 0.0, earlier: Any = ()) -> None:
        """Start mission `mid` in `world` (or enter it again as `resume`, a `drd.runtime.snapshot.NodeImage`),
        its components reached through a router of its own (called with the lock held); `earlier`: records of it
        its hosts made while it had no controller (their halts), recorded before it is entered again."""
        executive = self.controller.executive
        known = executive.missions  # an ended mission keeps its `started` as long as its status is listed
        self.began = {m: t for m, t in self.began.items() if m in known}
        self.began[mid] = base
        router = ComponentRouter(self.bus, self.cluster.name, self.resource_hosts, self.me,
                                 local=executive.registry, mission=mid, world=world.name,
                                 active=functools.partial(_active, executive, mid), timeout=self.patience,
                                 dead=self.host_down, catalog=self.catalog,
                                 place=functools.partial(self.place, mission=mid) if self.host_views else None,
                                 ended=self.unplaced,
                                 gates=self.gates,
                                 records=executive.record, cycle=world.cycle, generation=world.generation,
                                 term=self.term, frozen=self.frozen, on_down=self.controller.apply_offline,
                                 clock=self.clock.now)
        world.add(mid, router, base, until)
        listeners = [functools.partial(self.checkpoints.note, mid)] if self.checkpoints is not None else []
        executive.submit(chart, mid, listeners=listeners, registry=router.registry(), priority=priority,
                         resume=resume, since=since, paused=paused, earlier=earlier)

    def _new_world(self, req: RunMission, chart: Any) -> WorldRun:
        if self.simulator is None:  # real robots: nothing to load or reset, the clock starts now
            with self.lock:
                self.clock.start_mission()
                self._reset_dependencies(self.controller.executive)
                return self.open_world(NO_WORLD, None, None, self.generation + 1, 1.0)
        from drd.sim import load_world
        from drd.sim.service import world_dirs, world_file
        from drd.sim.world import check_hosts

        path = world_file(req.world or self.cluster.world, world_dirs(self.cluster))
        loaded = load_world(path)
        problems = check_hosts(loaded, self.cluster)
        if problems:
            raise ValueError("; ".join(map(str, problems)))
        refuse_unknown_rooms(chart, {room.id for room in loaded.rooms}, path.stem, req)  # before the world starts
        try:
            reset = self.sim(SimRequest("reset", world=path.stem, seed=req.seed))
        except Exception as e:
            raise ValueError(f"the simulator on {self.simulator} did not start the world: {e}") from None
        with self.lock:
            self.clock.start_mission()
            self._reset_dependencies(self.controller.executive)
            return self.open_world(path.stem, loaded, reset, self.generation + 1, req.speed)

    def open_world(self, name: str, loaded: Any, reply: SimReply | None, generation: int,
                   speed: float) -> WorldRun:
        """The loop of the world the simulator runs (`reply`: its time and version now), for the hosts'
        drivers of `generation` (called with the lock held; the clock's base is set by the caller). With no
        `reply` (no simulator host), a loop in real time over the real robots, its clock at 0 now."""
        self.generation = generation
        world = WorldRun(self, name, generation, speed, real=reply is None)
        if reply is not None:
            world.cycle.sim_time, world.cycle.sim_version = reply.time, reply.version
            world.cycle.step_sim = lambda dt: self.sim(SimRequest("step", dt=dt))
            world.cycle.simulator = (self.simulator or "") if self.sim_service is None else ""  # a batch steps it
        else:
            world.cycle.sim_time = 0.0
        self.clock.set_sim(world.cycle.sim_time)
        world.cycle.origin = self.clock.origin
        self.telemetry.reset()  # the hosts build their drivers (and guards) again for the new world
        rooms = loaded.rooms if loaded is not None else ()
        self.controller.executive.pool.places = {r.id: (r.x0, r.y0, r.x1, r.y1) for r in rooms}
        self.world, self.halting = world, []
        return world

    def unplaced(self, host: str, component: str) -> None:
        """A placed instance of `component` on `host` ended (or moved away): it no longer counts there, though the
        host may announce it a while yet (`drd.placement.with_recent`)."""
        if self.host_views is not None:
            seen = next((v.running.get(component, 0) for v in self.host_views() if v.name == host), 0)
            self._ended.append(Recent(host, component, seen, time.monotonic()))

    def place(self, component: str, params: Mapping[str, Any], exclude: Mapping[str, str] | frozenset[str],
              mission: str = "") -> str:
        """The host for one more instance of a movable component (`drd.placement.place` over the Component
        Database's view of the hosts), or ComponentError naming every refused host and why. The hosts with the
        `worker` role take them (every host when none has it): the controller keeps its cycles for the mission.
        `exclude` maps the hosts where this instance's start failed to why (kept in the decision). With `mission`,
        the hosts of the devices its instance's state uses count (device affinity) and the decision is kept for
        `missionctl status` (`self.placements`)."""
        from drd.daemon.placements import near_devices
        from drd.placement import Placed, place, refused_last, shares, with_recent

        ct = self.catalog.get(component)
        if ct is None or self.host_views is None:
            raise ComponentError(f"{component} is not in the controller's catalog")
        if self.simulator is not None and self.host_down(self.simulator):  # no host could start it: not theirs
            raise ComponentError(f"host {self.simulator} is down: it ran the simulator, so the world is gone")
        reasons = exclude if isinstance(exclude, Mapping) else dict.fromkeys(exclude, "")
        # the retry after a start failed there (a host left out with no reason, a lost one, refused nothing)
        if refused_last(self._recent, component, {h for h, why in reasons.items() if why}):
            last = self._recent.pop()
            placement_log.warning("placement: %s refused %s: %s", last.host, component, reasons[last.host])
        now = time.monotonic()
        self._recent = [r for r in self._recent if now - r.at < RECENT_PLACEMENT]
        self._ended = [r for r in self._ended if now - r.at < RECENT_PLACEMENT]
        announced = self.host_views()
        # placements the hosts do not announce yet count, each once, so that a cycle's starts spread; instances
        # that ended and that they still announce do not
        views = with_recent(announced, self._recent, self._ended)
        interp = self.controller.executive.missions.get(mission) if mission else None
        path, devices = near_devices(getattr(interp, "root", None), component, self.resource_hosts)
        decision = place(ct, views, self.cluster.placement, params=params, exclude=exclude, role=str(Role.WORKER),
                         near=shares(devices))
        if decision.decision is not None and mission:
            self.placements.note(mission, path or component, decision.decision)
        if not isinstance(decision, Placed):
            raise ComponentError(decision.reason)
        seen = next((v.running.get(component, 0) for v in announced if v.name == decision.host), 0)
        self._recent.append(Recent(decision.host, component, seen, now))
        placement_log.info("placement: %s on %s (%s)", component, decision.host, "; ".join(decision.reasons))
        return decision.host

    def flush_gates(self, world: WorldRun) -> None:
        """Send the gate operations nobody carried this cycle (a device whose holder lost it stops now), and ask
        the hosts whose robots are watched and who sent nothing this cycle (`drd.cluster.telemetry`)."""
        for host in sorted(set(self.gates.hosts()) | set(self.telemetry.due())):
            self._update_gates(host, world)

    def _deliver_gates(self) -> None:
        """The gate operations queued so far, to their hosts now, their records delivered: a mission ending
        (`RemoteGates.settle`) has its halts recorded before its `finished`."""
        world = self.world
        if world is not None:
            for host in self.gates.hosts():
                self._update_gates(host, world)

    def take_pending(self, world: WorldRun) -> list[dict[str, Any]]:
        """What the devices' hosts recorded and did not send yet (the halts of a host that lost its controller), as
        wire records (`drd.cluster.gates.take_pending`): asked before a restore or after a freeze."""
        hosts = sorted(set(self.gates.device_hosts.values()))
        return take_pending(self.bus, self.cluster.name, hosts, GateUpdate([], world.name, world.generation, self.term),
                            self.patience, self.host_down)

    def _fetch(self, host: str) -> None:
        """`host`'s pending operations now, and its reply delivered (a robot's first read)."""
        world = self.world
        if world is not None:
            self._update_gates(host, world)

    def _update_gates(self, host: str, world: WorldRun) -> None:
        ops = self.gates.take(host) or []
        if self.host_down(host):
            self._unreached(host, ops, "is down")
            return
        try:
            reply = self.bus.call_reaching(f"drd/{self.cluster.name}/host/{host}/creator",
                                           GateUpdate(ops, world.name, world.generation, self.term), self.patience,
                                           functools.partial(self.host_down, host))
        except Exception as e:  # the host's loss is noticed by the membership and the next calls
            if host not in self.undelivered:  # once until it answers again (a lost worker's burst was 8 lines)
                log.warning("the gate operations for %s were not delivered: %s", host, e)
            self.undelivered.add(host)
            self._unreached(host, ops, "does not answer")
            return
        self.undelivered.discard(host)
        if isinstance(reply, GateUpdateReply):
            with self.lock:
                deliver(reply.records, self.controller.executive.record, self.telemetry.seen)

    def _unreached(self, host: str, ops: list[list[Any]], why: str) -> None:
        """The stops `ops` asked of `host`'s drives, which cannot reach it: each is recorded as a `halted` with that
        error, as a gate records a device it cannot reach, so the trace does not end with the robot moving (safety
        audit 8, D6). Its robots are stopped by the controller when the host is found down (`halt_host`)."""
        from drd.runtime.records import Halted

        drives = set(self._drives(host))
        with self.lock:
            for op in ops:
                match op:
                    case ["unbind" | "clear", str(device), str(whose), float() | int() as at, str(reason)] \
                            if device in drives:  # once per drive: its first stop (a leaf's unbind, its holder's)
                        drives.discard(device)
                        mission, _, path = whose.partition("/")
                        self.controller.executive.record(mission, Halted(
                            float(at), path, device, "stop", reason,
                            f"not sent: host {host} {why}; the controller stops its robots once it is found down"))

    def _reset_dependencies(self, executive: Any) -> None:
        """A new world puts every Scout back in its magazine: the Static Dependency Database starts again from
        hosts.yaml (a previous mission's launches set `carrier` to "")."""
        if any(not m.finished for m in executive.missions.values()):
            return
        for r in self.cluster.resources():
            if type(r).__name__ != "Aggregate" or executive.pool.view(r.id) is None:
                continue
            for k, v in dict(r.properties).items():
                try:
                    executive.pool.set_property(r.id, k, v, self.clock.now())
                except Exception:  # a property the manager does not track: leave it
                    log.debug("could not reset %s.%s", r.id, k, exc_info=True)


class WorldRun:
    """One simulated world's lockstep loop (a thread) and the missions running in it; `real`: no simulated world,
    the cycles run in real time over the real robots (`NO_WORLD`)."""

    def __init__(self, runner: MissionRunner, name: str, generation: int, speed: float, real: bool = False) -> None:
        self.runner = runner
        self.name = name
        self.generation = generation
        self.speed = speed
        self.real = real
        self.began = time.perf_counter()  # a real world's clock: wall seconds since its loop began
        self.cycle = SimCycle()
        self.routers: dict[str, ComponentRouter] = {}
        self.deadlines: dict[str, tuple[float, float]] = {}  # mission -> (executive time to stop it, its `until`)
        self.stopping = threading.Event()
        self.started = False
        self.closed = False  # its loop takes no new mission (set under the runner's lock)
        self.cycles = 0
        self.refresh_at = 0.0  # when the answers kept for busy status queries are computed again
        self.freeze_taken = 0.0  # the freeze whose halts were taken (`_after_freeze`)
        self.thread = threading.Thread(target=self._loop, name=f"drd-world-{name}-{generation}", daemon=True)

    def go(self) -> None:
        """Start the world's loop, unless it runs already."""
        if not self.thread.is_alive() and not self.started:
            self.started = True
            self.thread.start()

    def add(self, mission: str, router: ComponentRouter, start: float, until: float) -> None:
        """A mission joins the world at executive time `start`, to be stopped `until` seconds later (called with
        the runner's lock held)."""
        self.routers[mission] = router
        self.deadlines[mission] = (start + until, until)

    def missions(self) -> list[str]:
        return sorted(self.routers)

    def _unfinished(self) -> list[str]:
        missions = self.runner.controller.executive.missions
        return [m for m in self.routers if m in missions and not missions[m].finished]

    def _loop(self) -> None:
        with Sampler("controller", every=1).run():  # DRD_PROFILE: this whole loop, dumped when it ends
            self._run()

    def _run(self) -> None:
        runner = self.runner
        # a resumed world goes on from its saved instant: paced from there (not from 0: it would stand still for
        # that instant / speed), and a real world's clock goes on from it too
        sim_time = first = max(0.0, self.cycle.sim_time)
        start = time.perf_counter()
        self.began = start - first
        pacer = Pacer(self.speed, first, start)
        watched = time.monotonic()
        try:
            while not self.stopping.is_set():
                with runner.lock:
                    if not self._unfinished():
                        self.closed = True
                        break
                if runner.halting:
                    runner._halt_robots()
                watched = self._after_freeze(watched)
                with runner.lock:
                    stepped = self._real_cycle(sim_time) if self.real else self._cycle(sim_time)
                if stepped is None:
                    break
                sim_time = stepped
                runner.flush_gates(self)
                if runner.checkpoints is not None:
                    runner.checkpoints.save(runner, self)
                if time.monotonic() >= self.refresh_at:  # what status queries get while a slow host holds us up
                    self.refresh_at = time.monotonic() + REFRESH_EVERY
                    with runner.lock:
                        runner.controller.serialized.refresh()
                self._retire_finished()
                self.cycles += 1
                lag = pacer.wait(sim_time, time.perf_counter())
                if lag > 0:
                    self.stopping.wait(lag)
            else:
                if runner.suspending:  # they stay journaled as running: the next start resumes them
                    self.closed = True
                else:
                    self._stop_all("the controller's daemon is stopping")
        except Exception:  # never leave a mission hanging silently
            log.exception("world %s: the run loop failed", self.name)
            self._stop_all("internal error in the controller's run loop (see its log)")
        runner.flush_gates(self)
        self._retire_finished(everyone=True)
        wall = time.perf_counter() - start
        log.info("world %s ended: %.1f s sim in %.2f s wall (%.1fx), %d cycles (%.2f ms each), sim steps not "
                 "carried by a batch %s", self.name, sim_time - first, wall, (sim_time - first) / wall if wall else 0.0,
                 self.cycles,
                 1000 * wall / max(1, self.cycles), self.cycle.steps_alone.as_dict())

    def _after_freeze(self, since: float) -> float:
        """Before a cycle: if this controller was frozen since `since` (past the lease, so its hosts stopped the
        robots), take the halts they made then, so they come before whatever this cycle does with the missions
        (a lease that expired meanwhile ends them). The time to watch from next."""
        runner = self.runner
        away = runner.frozen(since)
        if away and away != self.freeze_taken:
            self.freeze_taken = away
            records = runner.take_pending(self)
            with runner.lock:
                deliver(records, runner.controller.executive.record, runner.telemetry.seen)
                from drd.runtime.interpreter import stop_together  # the runtime: only on the controller

                executive = runner.controller.executive  # they cannot go on: fail them saying why (not "lost r
                stop_together([executive.missions[mid] for mid in self._unfinished()],  # (expired)"), together: none
                              frozen_reason(away), "failure")  # is granted what another's failure gives back
        return time.monotonic()

    def _cycle(self, sim_time: float) -> float | None:
        """One control cycle (the runner's lock held): the world's step, the executive's, the time limits. The
        world's time after it, or None when the simulator stopped answering (every mission then fails)."""
        runner, executive = self.runner, self.runner.controller.executive
        runner.controller.flush()  # hosts that came or went meanwhile: the manager learns it before the step
        # the world steps before the cycle's first call (carried by a batch to the simulator host, see
        # ComponentRouter.step_first); the executive's clock reads the time it will then have
        self.cycle.pending_step = CONTROL_PERIOD
        runner.clock.set_sim(sim_time + CONTROL_PERIOD)  # exactly the world's (Simulation.step)
        runner.guard.share(runner.telemetry.latest.get)  # other hosts' robots, for each host's constraints
        try:
            executive.step()
        except BaseException:
            self.cycle.pending_step = 0.0  # the stop that follows must not step the world
            raise
        router = next(iter(self.routers.values()))
        if self.cycle.pending_step and self.cycle.sim_error is None:  # no call this cycle
            try:
                router.step_first(None)
            except ComponentError:
                pass
        if self.cycle.sim_error is not None:
            self.closed = True
            sim = runner.simulator or ""
            why = (host_down_reason(sim, simulator=True) if sim and runner.host_down(sim)  # the dry-run's words
                   else f"the simulator on {sim} stopped answering: {self.cycle.sim_error}")
            from drd.runtime.interpreter import stop_together  # the runtime: only on the controller

            stop_together([executive.missions[mid] for mid in self._unfinished()], why,  # the world is gone: a failure,
                          "failure")  # as when a component finds it gone first; none granted what another gives back
            return None
        sim_time = self.cycle.sim_time
        runner.clock.set_sim(sim_time)
        now = runner.clock.now()
        for mid in self._unfinished():
            deadline, until = self.deadlines[mid]
            if now >= deadline - 1e-9:
                executive.missions[mid].stop(f"sim time limit of {until:g} s reached")
        return sim_time

    def _real_cycle(self, cycle_time: float) -> float:
        """One control cycle in real time (the runner's lock held): no world to step, the executive's clock at the
        wall seconds since the world began. The time the next cycle is due: the period after this one's, or now
        if the loop fell behind (a late cycle is not made up for by cycles in a burst)."""
        runner, executive = self.runner, self.runner.controller.executive
        runner.controller.flush()  # hosts that came or went meanwhile: the manager learns it before the step
        elapsed = time.perf_counter() - self.began
        self.cycle.sim_time = elapsed  # what the calls carry as the time of their instant
        runner.clock.set_sim(elapsed)
        runner.guard.share(runner.telemetry.latest.get)
        executive.step()
        now = runner.clock.now()
        for mid in self._unfinished():
            deadline, until = self.deadlines[mid]
            if now >= deadline - 1e-9:
                executive.missions[mid].stop(f"time limit of {until:g} s reached")
        return max(cycle_time + CONTROL_PERIOD, time.perf_counter() - self.began)

    def _stop_all(self, reason: str) -> None:
        """Close this world and stop every mission still running in it, saying why."""
        with self.runner.lock:
            self.closed = True
            for mid in self._unfinished():
                self.runner.controller.executive.missions[mid].stop(reason)

    def _retire_finished(self, everyone: bool = False) -> None:
        """Tell the hosts of each finished mission to retire its instances and processes, and log its figures."""
        runner = self.runner
        with runner.lock:
            missions = runner.controller.executive.missions
            done = [m for m in self.routers if everyone or m not in missions or missions[m].finished]
            ended = {m: self.routers.pop(m) for m in done}
            outcomes = {m: (missions[m].outcome, missions[m].reason) if m in missions else (None, "") for m in ended}
            listed = {m.get("id"): m for m in runner.controller.executive.status(0, 0, list(ended)).missions}
            if ended:
                runner.controller.executive.forget_finished()  # history, not history + 1, once the last one ended
        for mid, router in ended.items():
            outcome, reason = outcomes[mid]
            kept = everyone and self.stopping.is_set() and outcome is None  # journaled as running: the next start
            if runner.journal is not None and not kept:
                runner.journal.finish(mid, outcome or "stopped", reason, listed.get(mid))
            for host in sorted(set(router.stats.by_host) | set(router.batches.by_host)):
                retire = ComponentCall("retire", mid, "", world=self.name, generation=self.generation,
                                       term=runner.term)
                if host == runner.me:
                    continue
                if runner.host_down(host):  # retired when it is seen up again, if it ever is (`host_back`)
                    runner.owed(host, retire)
                    continue
                try:
                    router.call(host, retire)
                except Exception as e:  # a host that does not answer has lost the mission's processes, or owes them
                    log.info("mission %s: %s did not confirm the retirement: %s", mid, host, e)
                    runner.owed(host, retire)
            for path, host, how in router.placed:
                log.info("mission %s: %s %s on %s", mid, path, how, host)
            log.info("mission %s %s; component steps %s, step batches %s", mid, ending_said(outcome, reason, kept),
                     router.stats.as_dict(), router.batches.as_dict())


def ending_said(outcome: str | None, reason: str, kept: bool) -> str:
    """How the controller's log says a mission left it: `ended failure (…)`, or, journaled as running by a clean
    stop, `suspended for the next start` (it said `ended None ()`, which read as a bug)."""
    if kept:
        return "suspended for the next start"
    return f"ended {outcome or 'stopped'}" + (f" ({reason})" if reason else "")


def real_run_refusal(cluster: Cluster, req: RunMission) -> None:
    """ValueError saying why a cluster with no simulator host cannot run `req` as asked: it names a world, asks a
    speed other than real time, or a device of the cluster still has a `sim` driver (drd start refuses that too)."""
    from drd.preflight import sim_driver_problems

    why = "no host has the role simulator in hosts.yaml: missions run on the real robots"
    if req.world:
        raise ValueError(f"--world {req.world}: {why}, in no simulated world (remove --world)")
    if req.speed != 1.0:
        raise ValueError(f"--speed {req.speed:g}: {why}, in real time: a real robot cannot go faster or slower"
                         " (remove --speed)")
    problems = sim_driver_problems(cluster)
    if problems:
        raise ValueError("; ".join(problems))


#: Seconds behind the asked pace after which the loop paces afresh from now rather than catching up: a short lag
#: (a cycle's jitter) is made up, so the pace averages out to the asked one; a stall is not.
BEHIND = 0.25


class Pacer:
    """How long the world loop waits after a cycle so the world goes at most `speed` times real time, paced from
    where its loop (re)started (a world resumed at 112.7 s goes on at once). A stall longer than `BEHIND` (a slow
    host, a move to a frozen one) is not made up for by running faster than asked after it: the pace starts
    afresh (cluster audit 17, D2: 5.1 s of sim time in 0.81 s at `--speed 1` after a 5 s stall). Pure."""

    def __init__(self, speed: float, sim_time: float, now: float) -> None:
        self.speed, self.first, self.start = speed, sim_time, now

    def wait(self, sim_time: float, now: float) -> float:
        """Seconds to wait now, at `sim_time` of the world and `now` of the wall clock (0: go on at once)."""
        lag = (sim_time - self.first) / self.speed - (now - self.start)
        if lag < -BEHIND:
            self.first, self.start = sim_time, now
        return max(0.0, lag)


def _active(executive: Any, mission: str) -> Any:
    """The mission's components in step order (for a router's batches), none once it is gone."""
    interp = executive.missions.get(mission)
    return interp.host.active() if interp is not None else ()
