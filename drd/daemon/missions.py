"""Running a mission on the cluster: the controller's side of `missionctl run`.

`missionctl run` sends a `RunMission` with the mission's SOURCE text and file name to
`drd/<cluster>/missions/run`. The controller compiles it with its own catalog (a compiled object or code
from the wire is never trusted) and answers a `RunReply`: the mission id, or the located diagnostics
(rendered as `missionctl validate` prints them) when the mission is invalid.

A valid mission runs in lockstep with the simulator, on a thread of its own (`MissionRun`): each control
cycle (0.1 s of sim time) the simulation steps, then the executive steps under the daemon's lock, its clock
at the simulation's new time; components on other hosts are stepped through their Creators
(`drd.runtime.remote`). The step is made just before the cycle's first call to another host: carried by
that call when it is a batch to the simulator host (one round trip for both), else asked of the simulator
(`drd.sim.service`) on its own. `speed` caps the pace at that multiple
of real time. Records go out on `drd/<cluster>/mission/<id>/record` as for every mission of the executive.
One cluster mission runs at a time: the simulator holds one world.
"""

from __future__ import annotations

import cProfile
import logging
import os
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

from drd.bus import Bus, Message, Query, Reply, message
from drd.hosts import Cluster, Role
from drd.placement import HostView
from drd.runtime.remote import ComponentError, ComponentRouter
from drd.sim.service import SimReply, SimRequest, SimulationService
from drd.sim.service import key as sim_key
from dsl.catalog import Catalog

log = logging.getLogger("drd.daemon.missions")

#: Sim seconds per control cycle, as in the dry-run.
CONTROL_PERIOD = 0.1
#: Seconds a Creator or the simulator may take to answer one call before its host counts as lost.
CALL_TIMEOUT = 1.0


@message("drd.mission.run", 1)
class RunMission(Message):
    """Run this mission source (`file` names it in diagnostics) in world `world` at `speed` x real time."""

    source: str
    file: str
    world: str = ""  # "": the cluster's (hosts.yaml `cluster.world`)
    speed: float = 1.0
    until: float = 1800.0
    seed: int = 0
    params: dict[str, str] | None = None  # --param NAME=VALUE: the mission's own variables (dsl.params)


@message("drd.mission.run-reply", 1)
class RunReply(Message):
    """`mission` is the id of the started mission; when `ok` is false, `diagnostics` say why (rendered)."""

    mission: str
    ok: bool
    diagnostics: list[str]
    world: str = ""
    speed: float = 0.0
    started: float = 0.0
    base: float = 0.0  # the executive's time at sim time 0 (records' `at` minus this is sim time)


class SimTimeClock:
    """The executive's clock: the simulator's time plus an offset that keeps it monotonic across missions."""

    def __init__(self) -> None:
        self.base = 0.0
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def start_mission(self) -> None:
        self.base = self.t

    def set_sim(self, sim_time: float) -> None:
        self.t = self.base + sim_time


def run_key(cluster: str) -> str:
    return f"drd/{cluster}/missions/run"


def render(diagnostics: list[Any], sources: dict[str, str]) -> list[str]:
    """Diagnostics as `missionctl validate` prints them (file:line:col, message, source line, caret), plain text."""
    from dsl.errors import caret, source_line

    out = []
    for d in diagnostics:
        lines = [f"{d.span}: {d.severity.value}: {d.message}"]
        line = source_line(d.span, sources)
        if line is not None:
            line = "".join(ch if ch.isprintable() else "\ufffd" for ch in line.expandtabs(1))
            start, width = caret(d.span, line)
            gutter = f"{d.span.line:>5} | "
            lines += [gutter + line, " " * (len(gutter) - 2) + "| " + " " * start + "^" * width]
        lines += [f"  note: {where}: {text}" for text, where in d.notes]
        if d.hint:
            lines.append(f"  hint: {d.hint}")
        out.append("\n".join(lines))
    return out


class MissionRunner:
    """Serves `missions/run` on the controller and runs each accepted mission in lockstep (see module doc)."""

    def __init__(self, bus: Bus, cluster: Cluster, catalog: Catalog, me: str, lock: threading.RLock,
                 controller: Any, clock: SimTimeClock, *, sim_service: SimulationService | None = None,
                 host_down: Callable[[str], bool] = lambda h: False,
                 host_views: Callable[[], list[HostView]] | None = None) -> None:
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
        self.resource_hosts = {r.id: r.host for r in cluster.resources() if r.host}
        self.simulator = next((h.name for h in cluster.hosts if Role.SIMULATOR in h.roles), None)
        self.current: MissionRun | None = None
        self.lost: list[str] = []  # hosts seen down whose robots the running mission's loop stops in the simulator
        self._queryable = bus.serve(run_key(cluster.name), self._serve)
        threading.Thread(target=self._warm_up, name="drd-compiler-warm-up", daemon=True).start()

    def _warm_up(self) -> None:
        """Compile an empty mission once, in the background: the compiler's imports and the parser's tables then
        cost the daemon's start, not the operator's first `missionctl run` (0.5-0.65 s on a 2-core machine)."""
        from drd.cache import cache_parser_tables
        from dsl import compile_text

        try:
            cache_parser_tables()
            compile_text("mission WarmUp { }", self.catalog, "<warm-up>")
        except Exception:  # only ever a head start: the first run compiles as it would have
            log.debug("compiler warm-up failed", exc_info=True)

    def close(self) -> None:
        self._queryable.close()
        run = self.current
        if run is not None:
            run.stopping.set()
            run.thread.join(timeout=5)

    def host_lost(self, host: str) -> None:
        """A host's resources left the manager: it went down and did not come back within the lease (called
        with the daemon's lock held). Its robots leave the simulation at the next control cycle, when the
        mission loop talks to the simulator anyway; a short freeze costs nothing, as for its grants."""
        if self.current is not None:
            self.lost.append(host)

    def _lose_robots(self) -> None:
        with self.lock:
            hosts, self.lost = self.lost, []
        for host in hosts:
            robots = [r.id for r in self.cluster.host(host).robots]
            if not robots:
                continue
            try:
                gone = self.sim(SimRequest("lose", args=robots)).value or []
            except Exception as e:  # the simulator's own loss is reported by the next step
                log.warning("could not stop %s's robots in the simulator: %s", host, e)
                continue
            log.info("host %s lost: its robots %s left the simulation (nothing drives them)", host,
                     ", ".join(gone) or "(none were there)")

    def sim(self, req: SimRequest) -> SimReply:
        if self.sim_service is not None:
            return self.sim_service.handle(req)
        reply = self.bus.call(sim_key(self.cluster.name), req, timeout=CALL_TIMEOUT)
        if not isinstance(reply, SimReply):
            raise ValueError(f"the simulator answered a {type(reply).TYPE}")
        return reply

    def _serve(self, query: Query) -> Message | Reply:
        req = query.payload
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
        if len(req.source) > 1_000_000:
            raise ValueError("mission source larger than 1 MB")
        compiled = compile_text(req.source, self.catalog, req.file or "<mission>")
        if not compiled.ok or compiled.statechart is None:
            diags = render(list(compiled.diagnostics), dict(compiled.sources))
            return RunReply("", False, diags or [f"{req.file}: declares no mission to run"])
        from dsl.params import ParamError, apply_params

        try:
            chart = apply_params(compiled.statechart, dict(req.params or {}))
        except ParamError as e:
            return RunReply("", False, str(e).splitlines())
        if self.current is not None and self.current.thread.is_alive():
            raise ValueError(f"mission {self.current.mission} is running: one mission at a time on a cluster"
                             f" (missionctl stop {self.current.mission})")
        if self.simulator is None:
            raise ValueError("no host has the role simulator in hosts.yaml: the sim drivers need one")
        from drd.sim import load_world
        from drd.sim.service import world_file
        from drd.sim.world import check_hosts

        path = world_file(req.world or self.cluster.world)
        problems = check_hosts(load_world(path), self.cluster)
        if problems:
            raise ValueError("; ".join(map(str, problems)))
        try:
            reset = self.sim(SimRequest("reset", world=path.stem, seed=req.seed))
        except Exception as e:
            raise ValueError(f"the simulator on {self.simulator} did not start the world: {e}") from None
        with self.lock:
            executive = self.controller.executive
            self.clock.start_mission()
            self.clock.set_sim(reset.time)
            self._reset_dependencies(executive)
            mid = f"{chart.name}-{int(time.time() * 1000) % 10_000_000}"
            router = ComponentRouter(self.bus, self.cluster.name, self.resource_hosts, self.me,
                                     node=lambda path: _find(executive, mid, path), local=executive.registry,
                                     mission=mid, world=path.stem, timeout=CALL_TIMEOUT, dead=self.host_down,
                                     catalog=self.catalog, place=self.place if self.host_views else None)
            router.sim_time, router.sim_version = reset.time, reset.version
            router.step_sim = lambda dt: self.sim(SimRequest("step", dt=dt))
            router.simulator = self.simulator if self.sim_service is None else ""  # a batch there steps it
            run = MissionRun(self, mid, router, req)
            self.current, self.lost = run, []
            executive.submit(chart, mid, registry=router.registry())
        run.thread.start()
        log.info("mission %s started (%s, world %s, speed %gx)", mid, req.file, path.stem, req.speed)
        return RunReply(mid, True, [], path.stem, req.speed, time.time(), self.clock.base)


    def place(self, component: str, params: Mapping[str, Any], exclude: frozenset[str]) -> str:
        """The host for one more instance of a movable component (`drd.placement.place` over the Component
        Database's view of the hosts), or ComponentError naming every refused host and why. The hosts with the
        `worker` role take them (every host when none has it): the controller keeps its cycles for the mission."""
        from drd.placement import Placed, place

        ct = self.catalog.get(component)
        if ct is None or self.host_views is None:
            raise ComponentError(f"{component} is not in the controller's catalog")
        workers = [h.name for h in self.cluster.hosts if Role.WORKER in h.roles]
        decision = place(ct, self.host_views(), self.cluster.placement, params=params, exclude=exclude,
                         affinity=workers or None)
        if not isinstance(decision, Placed):
            raise ComponentError(decision.reason)
        log.info("placement: %s on %s (%s)", component, decision.host, "; ".join(decision.reasons))
        return decision.host

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


class MissionRun:
    """One mission's lockstep loop (a thread)."""

    def __init__(self, runner: MissionRunner, mission: str, router: ComponentRouter, req: RunMission) -> None:
        self.runner = runner
        self.mission = mission
        self.router = router
        self.req = req
        self.stopping = threading.Event()
        self.cycles = 0
        self.thread = threading.Thread(target=self._loop, name=f"drd-mission-{mission}", daemon=True)

    def _loop(self) -> None:
        runner, req = self.runner, self.req
        start = time.perf_counter()
        sim_time = max(0.0, self.router.sim_time)
        profile_path = os.environ.get("DRD_PROFILE", "")  # cProfile of this loop, dumped to path.controller
        prof = cProfile.Profile() if profile_path else None
        if prof is not None:
            prof.enable()
        try:
            while not self.stopping.is_set():
                with runner.lock:
                    interp = runner.controller.executive.missions.get(self.mission)
                    if interp is None or interp.finished:
                        break
                if runner.lost:
                    runner._lose_robots()
                with runner.lock:
                    # the world steps before the cycle's first call (carried by a batch to the simulator host,
                    # see ComponentRouter.step_first); the executive's clock reads the time it will then have
                    self.router.pending_step = CONTROL_PERIOD
                    runner.clock.set_sim(sim_time + CONTROL_PERIOD)  # exactly the world's (Simulation.step)
                    try:
                        runner.controller.executive.step()
                    except BaseException:
                        self.router.pending_step = 0.0  # the stop that follows must not step the world
                        raise
                    if self.router.pending_step and self.router.sim_error is None:  # no call this cycle
                        try:
                            self.router.step_first(None)
                        except ComponentError:
                            pass
                    if self.router.sim_error is not None:
                        interp.stop(f"the simulator on {runner.simulator} stopped answering: {self.router.sim_error}")
                        break
                    sim_time = self.router.sim_time
                    runner.clock.set_sim(sim_time)
                    if not interp.finished and sim_time >= req.until:
                        interp.stop(f"sim time limit of {req.until:g} s reached")
                self.cycles += 1
                lag = sim_time / req.speed - (time.perf_counter() - start)
                if lag > 0:
                    self.stopping.wait(lag)
            else:
                with runner.lock:
                    interp = runner.controller.executive.missions.get(self.mission)
                    if interp is not None and not interp.finished:
                        interp.stop("the controller's daemon is stopping")
        except Exception:  # never leave a mission hanging silently
            log.exception("mission %s: the run loop failed", self.mission)
            with runner.lock:
                interp = runner.controller.executive.missions.get(self.mission)
                if interp is not None and not interp.finished:
                    interp.stop("internal error in the controller's run loop (see its log)")
        wall = time.perf_counter() - start
        if prof is not None:
            prof.disable()
            prof.dump_stats(f"{profile_path}.controller")
        stats = self.router.stats.as_dict()
        for path, host, how in self.router.placed:
            log.info("mission %s: %s %s on %s", self.mission, path, how, host)
        with runner.lock:
            interp = runner.controller.executive.missions.get(self.mission)
            outcome = (interp.outcome, interp.reason) if interp is not None else (None, "")
        log.info("mission %s ended %s (%s)", self.mission, *outcome)
        log.info("mission %s ended: %.1f s sim in %.2f s wall (%.1fx), %d cycles (%.2f ms each), sim steps not "
                 "carried by a batch %s, component steps %s, step batches %s, other lifecycle calls %s", self.mission,
                 sim_time, wall, sim_time / wall if wall else 0.0, self.cycles, 1000 * wall / max(1, self.cycles),
                 self.router.steps_alone.as_dict(), stats, self.router.batches.as_dict(),
                 self.router.stats.seconds and round(self.router.stats.seconds * 1000 / max(1, self.cycles), 3))


def _find(executive: Any, mission: str, path: str) -> tuple[Any, Any] | None:
    interp = executive.missions.get(mission)
    if interp is None:
        return None
    for node in interp.active():
        if node.path == path:
            return node, interp
    return None
