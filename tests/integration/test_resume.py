"""A mission entered again from its saved state (`drd.runtime.snapshot`): the controller is lost mid-mission,
a new executive over the same world (the robots stay where they are) resumes it from the last snapshot.

What is checked is what an outsider sees: the mission ends as an undisturbed run does, its trace (the lost
controller's records, then the new one's) passes the ownership check with no double hold, the timers keep
their deadlines, and the snapshot survives JSON (what the journal stores) and a SQLite journal."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest

from drd.daemon.resume import SEQ_GAP
from drd.dryrun import SimulationClock, merged_drivers
from drd.executive import EntryPoints, Executive
from drd.hosts import load_hosts
from drd.journal import SqliteJournal, WorldState
from drd.runtime.snapshot import NodeImage, capture
from drd.runtime.trace import TraceWriter
from drd.sim import Simulation
from drd.sim.world import load_world
from drd.tracecheck import check
from dsl import compile_text
from dsl.catalog import Catalog
from dsl.statechart import Statechart
from tests.conftest import ROOT

CONTROL_PERIOD = 0.1


def chart_of(catalog: Catalog, text: str) -> Statechart:
    r = compile_text(text, catalog, "m.mission")
    assert r.ok and r.statechart is not None, [d.message for d in r.diagnostics]
    return r.statechart


class Team:
    """The corridor world and one executive over it; `lose_controller` replaces the executive, not the world."""

    def __init__(self, catalog: Catalog) -> None:
        from drd.bus.local import LocalNetwork

        self.catalog = catalog
        self.cluster = load_hosts(ROOT / "hosts.yaml", catalog)
        world = load_world(ROOT / "worlds" / "corridor.yaml")
        self.sim = Simulation(world, seed=0)
        self.places = {room.id: (room.x0, room.y0, room.x1, room.y1) for room in world.rooms}
        self.network = LocalNetwork()
        self.trace = io.StringIO()
        self.executive = self._executive()

    def _executive(self) -> Executive:
        drivers = merged_drivers(self.cluster, self.sim, self.catalog)  # new drivers, as a new controller's hosts
        return Executive(self.network.session("controller"), SimulationClock(self.sim), EntryPoints(self.catalog),
                         cluster=self.cluster.name, resources=self.cluster.resources(), lease=self.cluster.lease,
                         services={"drivers": drivers, "places": self.places})

    def submit(self, chart: Statechart, resume: NodeImage | None = None) -> str:
        return self.executive.submit(chart, "M-1", listeners=[TraceWriter(self.trace, "M-1")], resume=resume)

    def run(self, seconds: float) -> None:
        end = self.sim.time + seconds
        while self.sim.time < end - 1e-9:
            mission = self.executive.missions.get("M-1")
            if mission is not None and mission.finished:
                break
            self.sim.step(CONTROL_PERIOD)
            self.executive.step()

    def lose_controller(self) -> NodeImage:
        """The last snapshot, through JSON; the old executive's robots stopped (its hosts' gates orphaned)."""
        interp = self.executive.missions["M-1"]
        assert interp.root is not None
        image = NodeImage.from_dict(json.loads(json.dumps(capture(interp.root).to_dict())))
        gates: Any = self.executive.gates
        gates.orphan_all(self.sim.time, "controller lost")
        self.executive.close()
        sent, self.executive = self.executive.sent, self._executive()
        self.executive.continue_records(sent + SEQ_GAP)  # as `drd.daemon.resume` does: records and epochs go on
        return image

    def records(self) -> list[dict[str, Any]]:
        return [json.loads(line) for line in self.trace.getvalue().splitlines()]


TIMED = """
mission Timed {
    var laps: int = 0
    start -> First
    Wait(duration: 100s) as First
    First -> Second after 3s / set laps = laps + 1
    Observe(duration: 100s) as Second
    Second -> done after 10s [laps == 1]
}
"""


def test_a_resumed_mission_keeps_its_state_its_data_and_its_timers_deadlines(catalog: Catalog) -> None:
    team = Team(catalog)
    chart = chart_of(catalog, TIMED)
    team.submit(chart)
    team.run(7.0)  # in Second since 3 s; its `after 10s` falls due at 13 s
    image = team.lose_controller()
    assert [n.path for n in image.walk()] == ["Timed", "Timed/Second"]
    assert image.data["laps"] == 1
    team.run(2.0)  # the controller is away for 2 s of the world's time
    team.submit(chart, resume=image)
    team.run(60.0)
    interp = team.executive.missions["M-1"]
    assert interp.outcome == "success", interp.reason
    recs = team.records()
    done = [r for r in recs if r["kind"] == "taken" and r["target"] == "Timed/done"]
    assert done and abs(done[0]["at"] - 13.0) < 0.15, done  # the deadline kept, `laps` restored (the guard)
    restored = [r for r in recs if r["kind"] == "restored"]
    assert len(restored) == 1 and restored[0]["path"] == "Timed"
    entered = [r["path"] for r in recs if r["kind"] == "entered"]
    assert entered.count("Timed/First") == 1, "the state left before the loss is not entered again"
    ended = [r for r in recs if r["kind"] == "released" and r["reason"] == "controller lost"]
    assert ended and all(r["at"] == restored[0]["at"] for r in ended)
    assert check(recs, {"ranger1.radio"}).ok, check(recs, {"ranger1.radio"}).breaches


def test_the_corridor_mission_resumed_mid_way_succeeds_with_one_holder_per_device(catalog: Catalog) -> None:
    source = (ROOT / "missions" / "corridor_surveillance.mission").read_text()
    chart = chart_of(catalog, source)
    team = Team(catalog)
    team.submit(chart)
    team.run(40.0)
    image = team.lose_controller()
    live = [n.path for n in image.walk()]
    assert any("[" in p for p in live), live  # inside the multiplicity
    team.run(0.5)
    team.submit(chart, resume=image)
    team.run(1200.0)
    interp = team.executive.missions["M-1"]
    assert interp.outcome == "success", interp.reason
    recs = team.records()
    result = check(recs, {"ranger1.radio"})
    assert result.ok, result.breaches
    entered = [r for r in recs if r["kind"] == "entered"]
    restored = next(i for i, r in enumerate(recs) if r["kind"] == "restored")
    again = {r["path"] for r in recs[restored:] if r["kind"] == "entered"}
    assert set(live) <= again, set(live) - again  # every state it was in is entered again
    assert len(entered) > len(live)
    # an instance that had given its Ranger back (`release(ranger)` after the launch) does not take it again,
    # and each gets back the very Scout it had
    gave_back = {n.path for n in image.walk() if "ranger" in n.released}
    assert gave_back, [(n.path, n.released) for n in image.walk()]
    regranted = {r["path"]: r["resources"] for r in recs[restored:] if r["kind"] == "granted"}
    for n in image.walk():
        if n.path in regranted and n.grant:
            assert regranted[n.path].get("scout") == n.grant.get("scout"), (n.path, regranted[n.path], n.grant)
            assert ("ranger" in regranted[n.path]) == (n.path not in gave_back), (n.path, regranted[n.path])


def test_the_executive_gives_a_client_the_records_it_missed(catalog: Catalog) -> None:
    """A client whose session found a restarted controller late asks for what it missed (`records` after N)."""
    from drd.executive_messages import MissionCommand, MissionRecords

    team = Team(catalog)
    team.submit(chart_of(catalog, TIMED))
    team.run(4.0)
    client = team.network.session("client")
    everything = client.call("drd/corridor/executive", MissionCommand("records", "M-1"), timeout=2)
    assert isinstance(everything, MissionRecords) and everything.records
    seqs = [r.seq for r in everything.records]
    assert seqs == sorted(seqs) and seqs[0] == 1 and everything.records[0].kind == "entered"
    later = client.call("drd/corridor/executive", MissionCommand("records", "M-1", after=seqs[2]), timeout=2)
    assert isinstance(later, MissionRecords) and [r.seq for r in later.records] == seqs[3:]


PAUSE = "mission Pause {\n    Wait(duration: 10s)\n}\n"


def test_a_resumed_mission_restores_its_running_wait_from_the_journaled_snapshot(catalog: Catalog,
                                                                                 tmp_path: Path) -> None:
    team = Team(catalog)
    chart = chart_of(catalog, PAUSE)
    team.submit(chart)
    team.run(4.0)
    image = team.lose_controller()
    journal = SqliteJournal(tmp_path / "journal.db")
    journal.begin("M-1", {"source": PAUSE}, 0, 0.0, 60.0)
    journal.save({"M-1": (4.0, image.to_dict())}, WorldState("corridor", 1, 0.0, 4.0, 10))
    saved = journal.running()[0].snapshot
    journal.close()
    assert saved is not None
    image = NodeImage.from_dict(saved)
    leaf = [n for n in image.walk() if n.component is not None]
    assert len(leaf) == 1 and leaf[0].component is not None
    began = leaf[0].component[0]["began"]
    assert began == pytest.approx(0.0, abs=0.15) and leaf[0].component[0]["steps"] >= 30
    team.run(3.0)  # the controller is away for 3 s of the world's time
    team.submit(chart, resume=image)
    team.run(30.0)
    interp = team.executive.missions["M-1"]
    assert interp.outcome == "success", interp.reason
    exits = [r for r in team.records() if r["kind"] == "exited" and r["path"] == "Pause/Wait"]
    assert exits and exits[-1]["at"] == pytest.approx(began + 10.0, abs=0.15), exits  # not 7 + 10 s
