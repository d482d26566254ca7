"""The controller's missions on disk: saved after each control cycle that changed them, resumed after a restart.

`Checkpoints` writes the state of each running mission of a world (`drd.runtime.snapshot.capture`) to the
journal (`drd.journal`) after a control cycle, when it changed; a mission's start and end are written by the
runner itself. `resume` is what a controller started on a journal that holds running missions does, once the
hosts are back (or a grace period passed): it rejoins the world the simulator still runs (the robots stand where
they stopped; a simulator that lost its world starts it again, and says so), with the hosts' drivers built anew
(fresh fences), numbers its records on from the journal's, and enters each mission again from its last state
under its own id. A mission that can no longer be compiled is ended in the journal with the reason, not resumed.
"""

from __future__ import annotations

import json
import logging
import time
from typing import Any

from drd.journal import Journal, Journaled, WorldState
from drd.runtime.snapshot import NodeImage, capture, property_changes

log = logging.getLogger("drd.daemon.resume")

#: How far a resumed executive's record numbers jump past the journal's last (the records sent between the last
#: save and the loss were never saved): numbers stay increasing, never reused.
SEQ_GAP = 100_000


class Checkpoints:
    """The last state saved of each mission, so a cycle that changed nothing writes nothing."""

    def __init__(self, journal: Journal) -> None:
        self.journal = journal
        self._saved: dict[str, str] = {}

    def save(self, runner: Any, world: Any) -> None:
        """After a control cycle of `world` (takes the runner's lock to read the missions)."""
        executive = runner.controller.executive
        changed: dict[str, tuple[float, dict[str, Any]]] = {}
        with runner.lock:
            now = runner.clock.now()
            for mid in world.missions():
                interp = executive.missions.get(mid)
                if interp is None or interp.root is None or interp.finished:
                    continue
                snapshot = capture(interp.root).to_dict()
                text = json.dumps(snapshot, sort_keys=True, separators=(",", ":"))
                if self._saved.get(mid) != text:
                    self._saved[mid] = text
                    changed[mid] = (now, snapshot)
            state = WorldState(world.name, world.generation, runner.clock.base, now, executive.sent,
                               property_changes(runner.cluster.resources(), executive.pool))
        self.journal.save(changed, state)  # every cycle: the clock and the record numbers move on

    def forget(self, mission: str) -> None:
        self._saved.pop(mission, None)


def resume(runner: Any, journal: Journal) -> list[str]:
    """Resume the journal's running missions on `runner` (see the module); the ids resumed."""
    jobs, state = journal.running(), journal.world()
    if not jobs:
        return []
    if state is None:  # started, and the controller was lost before a single cycle was saved
        state = WorldState("", 0, 0.0, max(j.base for j in jobs), 0)
    with runner.starting:
        world = _rejoin(runner, state, jobs[0])
        resumed: list[str] = []
        with runner.lock:
            executive = runner.controller.executive
            executive.continue_records(state.seq + SEQ_GAP)
            for rid, values in state.properties.items():
                for key, value in values.items():
                    executive.pool.set_property(rid, key, value, runner.clock.now())
            paused = max(0.0, time.time() - state.saved) if state.saved else 0.0
            for job in jobs:
                if _resume_one(runner, journal, world, job, paused):
                    resumed.append(job.id)
        if resumed:
            world.go()
    return resumed


def _rejoin(runner: Any, state: WorldState, first: Journaled) -> Any:
    """The world's loop again, on the simulator's world if it still runs it, else on a fresh one."""
    from drd.sim import load_world
    from drd.sim.service import SimRequest, world_file

    name = state.name or str(first.request.get("world") or runner.cluster.world)
    path = world_file(name)
    loaded = load_world(path)
    try:
        reply = runner.sim(SimRequest("attr", method="jump_height"))
        continues = reply.world == path.stem
    except Exception as e:  # the simulator lost its world (it ran on the controller's host, or restarted)
        log.warning("the simulator does not run world %s any more (%s): starting it again", path.stem, e)
        continues = False
    if not continues:
        reply = runner.sim(SimRequest("reset", world=path.stem, seed=int(first.request.get("seed") or 0)))
        log.warning("resumed missions run in a new world %s: its robots start from their start poses", path.stem)
    with runner.lock:
        runner.clock.base = state.base if continues else state.now - reply.time
        return runner.open_world(path.stem, loaded, reply, state.generation + 1,
                                 float(first.request.get("speed") or 1.0))


def _resume_one(runner: Any, journal: Journal, world: Any, job: Journaled, paused: float) -> bool:
    """Compile the journaled mission again and enter it from its last state (with the runner's lock held)."""
    from dsl import compile_text
    from dsl.params import ParamError, apply_params

    request = job.request
    compiled = compile_text(str(request.get("source", "")), runner.catalog, str(request.get("file") or "<mission>"))
    try:
        if not compiled.ok or compiled.statechart is None:
            raise ValueError("; ".join(d.message for d in compiled.diagnostics) or "it declares no mission")
        chart = apply_params(compiled.statechart, dict(request.get("params") or {}))
        image = NodeImage.from_dict(job.snapshot) if job.snapshot is not None else None
    except (ValueError, ParamError, KeyError, TypeError) as e:
        journal.finish(job.id, "failure", f"cannot resume after the controller was lost: {e}")
        log.error("mission %s cannot be resumed: %s", job.id, e)
        return False
    runner.submit(world, chart, job.id, job.priority, job.base, job.until, resume=image, since=job.at,
                  paused=paused)
    log.info("mission %s resumed from its state at %.1f s (%s)", job.id, job.at - job.base,
             "its saved state" if image is not None else "its start")
    return True


def wait_for_hosts(runner: Any, hosts: list[str], grace: float) -> list[str]:
    """Wait (at most `grace` seconds) until each of `hosts` is up; the ones still down."""
    deadline = time.monotonic() + grace
    while True:
        down = [h for h in hosts if runner.host_down(h)]
        if not down or time.monotonic() >= deadline:
            return down
        time.sleep(0.1)
