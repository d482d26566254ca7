"""The controller's missions on disk: saved after each control cycle that changed them, resumed after a restart.

`Checkpoints` writes the state of each running mission of a world (`drd.runtime.snapshot.capture`) to the
journal (`drd.journal`) after a control cycle, when it changed; a mission's start and end are written by the
runner itself. `resume` is what a controller started on a journal that holds running missions does, once the
hosts are back (or a grace period passed): it rejoins the world the simulator still runs (the robots stand where
they stopped; a simulator that lost its world starts it again, and says so; real robots, with no simulator host,
go on in real time from the last saved instant), with the hosts' drivers built anew
(fresh fences), numbers its records on from the journal's, and enters each mission again from its last state
under its own id. A mission that can no longer be compiled is ended in the journal with the reason, not resumed.
Its running components are given back their journaled snapshots (`Component.restore`), or None when they kept
none: restarted, and told so. A mission whose components' snapshots changed (a Wait's start, a Watch's count)
is saved again at most once a second (`CLOCK_EVERY`), even when its states did not change.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from drd.journal import Journal, Journaled, WorldState
from drd.runtime.snapshot import NodeImage, capture, component_states, property_changes

log = logging.getLogger("drd.daemon.resume")

#: How far a resumed executive's record numbers jump past the journal's last (the records sent between the last
#: save and the loss were never saved): numbers stay increasing, never reused.
SEQ_GAP = 100_000


#: Records that change a mission's state tree (a state entered or left, a hold begun or ended...): only after one
#: of these is its state saved again (commands, events and logs change nothing that resuming needs).
STRUCTURAL = frozenset({"entered", "exited", "taken", "granted", "released", "revoked", "suspended", "resumed",
                        "reserved", "restored"})
#: Wall seconds between two saves of the world's clock and record numbers when no mission changed (the numbers
#: a resumed executive goes on from jump `SEQ_GAP` past the last saved anyway).
CLOCK_EVERY = 1.0


class Checkpoints:
    """Saves a mission's state after a control cycle in which it changed (`note` hears its records), and the
    world's clock at most once a second otherwise, with the missions whose components' snapshots changed since
    they were saved: a cycle that changed nothing costs nothing."""

    def __init__(self, journal: Journal) -> None:
        self.journal = journal
        self._dirty: set[str] = set()
        self._clock_saved = 0.0
        self._components: dict[str, dict[str, Any]] = {}  # mission -> its components' snapshots as last saved

    def note(self, mission: str, record: Any) -> None:
        """A record of `mission` (a listener of its interpreter): a structural one makes its state worth saving."""
        if record.kind in STRUCTURAL:
            self._dirty.add(mission)

    def save(self, runner: Any, world: Any) -> None:
        """After a control cycle of `world` (takes the runner's lock to read the missions)."""
        wall = time.monotonic()
        if not self._dirty and wall - self._clock_saved < CLOCK_EVERY:
            return
        executive = runner.controller.executive
        changed: dict[str, tuple[float, dict[str, Any]]] = {}
        with runner.lock:
            now = runner.clock.now()
            dirty, self._dirty = self._dirty, set()
            for mid in world.missions():
                interp = executive.missions.get(mid)
                if interp is None or interp.root is None or interp.finished:
                    self._components.pop(mid, None)
                    continue
                states = component_states(interp.root)
                if mid in dirty or states != self._components.get(mid):
                    changed[mid] = (now, capture(interp.root).to_dict())
                    self._components[mid] = states
            state = WorldState(world.name, world.generation, runner.clock.origin, now, executive.sent,
                               property_changes(runner.cluster.resources(), executive.pool))
        self._clock_saved = wall
        self.journal.save(changed, state)


def resume(runner: Any, journal: Journal) -> list[str]:
    """Resume the journal's running missions on `runner` (see the module); the ids resumed."""
    jobs, state = journal.running(), journal.world()
    if not jobs:
        return []
    alive = state.now if state is not None else 0.0  # the world's clock at the last save: the controller ran then
    if state is None:  # started, and the controller was lost before a single cycle was saved
        state = WorldState("", 0, 0.0, max(j.base for j in jobs), 0)
    with runner.starting:
        world = _rejoin(runner, state, jobs[0])
        if world is None:  # the simulator's world started again: nothing of the missions' state is in it
            _unresumable(runner, journal, jobs, state)
            return []
        halts = _halts(runner.take_pending(world))  # before anything is recorded of the restore (docs/trace.md)
        resumed: list[str] = []
        with runner.lock:
            executive = runner.controller.executive
            executive.continue_records(state.seq + SEQ_GAP)
            for rid, values in state.properties.items():
                for key, value in values.items():
                    try:
                        executive.pool.set_property(rid, key, value, runner.clock.now())
                    except KeyError:  # its host is still down (resumed without it): its robot is not in the manager
                        log.info("resuming without the saved %s of %s: its host's resources are not here", key, rid)
            paused = max(0.0, time.time() - state.saved) if state.saved else 0.0
            with executive.together():  # by priority, not by who is entered first (safety audit 7, D2)
                for job in jobs:
                    if _resume_one(runner, journal, world, job, paused, halts.get(job.id, []), alive):
                        resumed.append(job.id)
        if resumed:
            world.go()
    return resumed


def _rejoin(runner: Any, state: WorldState, first: Journaled) -> Any:
    """The world's loop again, on the simulator's world if it still runs it; None when the simulator lost it (its
    host stopped too: it answers, without that world), after starting a fresh one for the next mission. With no
    simulator host, a loop over the real robots again: their time goes on from the last save (the time the
    controller was away is not the missions'), and no simulator is asked anything."""
    from drd.daemon.missions import NO_WORLD
    from drd.sim import load_world
    from drd.sim.service import SimRequest, world_dirs, world_file

    if runner.simulator is None:
        with runner.lock:
            runner.clock.base, runner.clock.origin = state.now, state.base  # the world's time goes on too
            return runner.open_world(NO_WORLD, None, None, state.generation + 1, 1.0)
    name = (state.name if state.name != NO_WORLD else "") or str(first.request.get("world") or runner.cluster.world)
    path = world_file(name, world_dirs(runner.cluster))
    loaded = load_world(path)
    try:
        reply = runner.sim(SimRequest("attr", method="jump_height"))
        continues = reply.world == path.stem
    except Exception as e:  # the simulator lost its world (it ran on the controller's host, or restarted)
        log.warning("the simulator does not run world %s any more (%s): starting it again", path.stem, e)
        continues = False
    if not continues:  # a reset that answers says the simulator is there, without the world (one that does not
        # answer raises: the journal is kept for the next start)
        runner.sim(SimRequest("reset", world=path.stem, seed=int(first.request.get("seed") or 0)))
        return None
    with runner.lock:
        runner.clock.base = runner.clock.origin = state.base
        return runner.open_world(path.stem, loaded, reply, state.generation + 1,
                                 float(first.request.get("speed") or 1.0))


#: Why a journaled mission is not resumed when its simulated world is gone.
WORLD_GONE = ("cannot resume after the controller was lost: the simulator's world {world} started again (its host"
              " stopped too), its robots back at their start poses: the mission's state is not in it")


def _unresumable(runner: Any, journal: Journal, jobs: list[Journaled], state: WorldState) -> None:
    """End the journaled missions as failures that say why (journal and history: `missionctl status` and an
    attached `missionctl run` read it there), rather than enter their states in a world that knows none of them
    (a launched Scout back in its magazine: the mission hung)."""
    name = state.name or str(jobs[0].request.get("world") or runner.cluster.world)
    reason = WORLD_GONE.format(world=name)
    for job in jobs:
        status = {"mission": job.id.rpartition("-")[0] or job.id, "outcome": "failure", "reason": reason,
                  "time": round(state.now, 3), "started": round(job.base, 3)}
        journal.finish(job.id, "failure", reason, status)
        with runner.lock:
            runner.controller.executive.restore_history([(job.id, status)])
        log.error("mission %s: %s", job.id, reason)


def _halts(records: list[dict[str, Any]]) -> dict[str, list[Any]]:
    """The hosts' pending records (`MissionRunner.take_pending`: their halts when they lost the controller), by
    mission; telemetry and breaches are left out (nothing is guarded before the missions are entered again)."""
    from drd.cluster.gates import from_wire
    from drd.runtime.records import Record

    by: dict[str, list[Any]] = {}
    for data in records:
        found = from_wire(data)
        if found is not None and isinstance(found[1], Record):
            by.setdefault(found[0], []).append(found[1])
    return by


def _resume_one(runner: Any, journal: Journal, world: Any, job: Journaled, paused: float,
                halts: list[Any], alive: float = 0.0) -> bool:
    """Compile the journaled mission again and enter it from its last state (with the runner's lock held), after
    recording the halts its hosts made when they lost the controller (`halts`). Its state is the one saved at
    `job.at` (the last cycle that changed it), and it was still that state at the world's last save (`alive`,
    saved every second with the missions that changed since: one not among them had not changed): the report ends
    what was in force there, not at its last change (users audit 21, #1: 0.1 s, for a kill at 5 s)."""
    from dsl import compile_text
    from dsl.params import ParamError, apply_params

    request = job.request
    sent, aliases = request.get("imports"), request.get("aliases")
    compiled = compile_text(str(request.get("source", "")), runner.catalog, str(request.get("file") or "<mission>"),
                            limits=runner.cluster.limits,
                            imports={str(k): str(v) for k, v in sent.items()} if isinstance(sent, dict) else {},
                            aliases={str(k): str(v) for k, v in aliases.items()} if isinstance(aliases, dict) else {})
    try:
        if not compiled.ok or compiled.statechart is None:
            raise ValueError("; ".join(d.message for d in compiled.diagnostics) or "it declares no mission")
        chart = apply_params(compiled.statechart, dict(request.get("params") or {}))
        image = NodeImage.from_dict(job.snapshot) if job.snapshot is not None else None
    except (ValueError, ParamError, KeyError, TypeError) as e:
        journal.finish(job.id, "failure", f"cannot resume after the controller was lost: {e}")
        log.error("mission %s cannot be resumed: %s", job.id, e)
        return False
    since = max(job.at, alive)
    runner.submit(world, chart, job.id, job.priority, job.base, job.until, resume=image, since=since,
                  paused=paused, earlier=halts)
    log.info("mission %s resumed from its state at %.1f s (%s)", job.id, since - job.base,
             "its saved state" if image is not None else "its start")
    return True


def wait_for_hosts(runner: Any, hosts: list[str], grace: float) -> list[str]:
    """Wait (at most `grace` seconds) until each of `hosts` is up and the manager holds its resources (a standby
    elected sees the hosts up at once, and adds their resources a moment later: a resume in between found none);
    the ones still missing."""
    deadline = time.monotonic() + grace
    while True:
        down = [h for h in hosts if runner.host_down(h) or not runner.controller.holds(h)]
        if not down or time.monotonic() >= deadline:
            return down
        time.sleep(0.1)
