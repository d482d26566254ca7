"""Any saved state of any mission comes back as it was (issue #16): the journal's property.

Hypothesis writes missions (the ownership property test's generator: nesting, `parallel`, plans,
multiplicities, slices, `release(x)`, timeouts, components that fail), runs each in the dry-run's executive for a
random number of control cycles, journaling its state after every cycle in the controller's SQLite journal, reads
that prefix of the journal back (it must equal the live state of that instant), then gives it to a new
executive over the same world (the robots where they are) and enters it again. Right after, the state tree read
back equals the saved one: the same states at the same paths, entered at the same times, with the same data,
outputs, finished regions and multiplicity counters. And the resumed mission keeps ownership to its end.
"""

from __future__ import annotations

import io
import json
import tempfile
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st

from drd.bus import LocalNetwork
from drd.daemon.resume import SEQ_GAP
from drd.dryrun import SimulationClock, merged_drivers
from drd.executive import EntryPoints, Executive
from drd.hosts import Cluster
from drd.journal import SqliteJournal, WorldState
from drd.runtime.snapshot import NodeImage, capture
from drd.runtime.trace import TraceWriter
from drd.sim.physics import Simulation
from drd.sim.world import World
from drd.tracecheck import check
from dsl.catalog import Catalog
from tests.properties.test_ownership_properties import REGISTRY, cat, compile_mission, mission_texts, team  # noqa: F401

EXAMPLES = 100
CONTROL_PERIOD = 0.1


def executive(cluster: Cluster, world: World, sim: Simulation, catalog: Catalog, network: LocalNetwork) -> Executive:
    places = {room.id: (room.x0, room.y0, room.x1, room.y1) for room in world.rooms}
    return Executive(network.session("controller"), SimulationClock(sim), EntryPoints(catalog, REGISTRY),
                     cluster=cluster.name, resources=cluster.resources(), lease=cluster.lease,
                     services={"drivers": merged_drivers(cluster, sim, catalog), "places": places})


def shape(image: NodeImage) -> dict[str, tuple[Any, ...]]:
    """What must come back: per path, the state, entry time, data, outputs, finished regions, counters and what
    it had given back (not the phase or the epochs: the grants are asked for anew)."""
    return {n.path: (n.state, round(n.entered, 6), json.dumps(n.data, sort_keys=True),
                     json.dumps(n.outputs, sort_keys=True), tuple(n.finished), tuple(n.counters), tuple(n.released))
            for n in image.walk()}


PROPERTY = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None, print_blob=False,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def test_a_saved_state_comes_back_as_it_was(cat: Catalog, team: tuple[Cluster, World]) -> None:  # noqa: F811
    seen: dict[str, int] = {}  # what the examples exercised: a generator gone blind must fail loudly

    @PROPERTY
    @given(text=mission_texts("M"), cycles=st.integers(1, 120))
    def comes_back(text: str, cycles: int) -> None:
        note(text)
        compared = resume_once(cat, team, text, cycles)
        for key in compared:
            seen[key] = seen.get(key, 0) + 1

    comes_back()
    assert seen.get("compared", 0) >= EXAMPLES // 2, seen
    assert seen.get("nested", 0) > 0 and seen.get("multiplicity", 0) > 0, seen


def resume_once(catalog: Catalog, setting: tuple[Cluster, World], text: str, cycles: int) -> list[str]:
    """Run, save, resume, compare, run to the end; what the example exercised."""
    cluster, world = setting
    chart = compile_mission(text, catalog)
    sim, network, trace = Simulation(world, seed=0), LocalNetwork(), io.StringIO()
    first = executive(cluster, world, sim, catalog, network)
    first.submit(chart, "M-1", listeners=[TraceWriter(trace, "M-1")])
    interp = first.missions["M-1"]
    with tempfile.TemporaryDirectory() as folder:  # the controller's journal, written after every cycle
        journal = SqliteJournal(Path(folder) / "journal.sqlite")
        journal.begin("M-1", {}, 1, 0.0, 0.0)
        for _ in range(cycles):
            if interp.finished:
                break
            sim.step(CONTROL_PERIOD)
            first.step()
            if interp.root is not None:
                journal.save({"M-1": (sim.time, capture(interp.root).to_dict())}, WorldState("w", 1, 0.0, sim.time, 0))
        if interp.finished or interp.root is None:
            journal.close()
            return []
        recorded = journal.running()[0].snapshot  # the journal's prefix, read back as a restart reads it
        journal.close()
    assert recorded is not None
    saved = NodeImage.from_dict(recorded)
    assert shape(saved) == shape(capture(interp.root))  # the journal holds the live state of that instant
    first.gates.orphan_all(sim.time, "controller lost")  # type: ignore[attr-defined]
    first.close()

    second = executive(cluster, world, sim, catalog, network)
    second.continue_records(first.sent + SEQ_GAP)  # as `drd.daemon.resume` does: records and epochs go on
    second.submit(chart, "M-1", listeners=[TraceWriter(trace, "M-1")], resume=saved, since=sim.time)
    again = second.missions["M-1"]
    exercised = []
    if again.root is not None and not again.finished:
        assert shape(capture(again.root)) == shape(saved)
        nodes = saved.walk()
        exercised = ["compared", *(["nested"] if any(n.path.count("/") > 1 for n in nodes) else []),
                     *(["multiplicity"] if any(n.counters for n in nodes) else []),
                     *(["released"] if any(n.released for n in nodes) else [])]
    for _ in range(300):
        if again.finished:
            break
        sim.step(CONTROL_PERIOD)
        second.step()
    records = [json.loads(line) for line in trace.getvalue().splitlines()]
    report = check(records, {u.id for u in cluster.resources() if getattr(u, "sharable", False)})
    assert report.ok, report.breaches[:5]
    return exercised
