"""Missions submitted together (a dry-run's start, a controller resuming) are granted when the block ends, outside a
run to completion: a component that failed as it started was handled at the next step, so its state ended a cycle
later than a mission started alone (users audit 21, #2: 0.1 s in a dry-run, 0.0 s on a cluster). Asserted from the
records."""

from __future__ import annotations

from drd.bus import LocalNetwork
from drd.executive import EntryPoints, Executive
from drd.rcm import Unit
from drd.runtime import records as rec
from drd.runtime.clock import SimClock
from drd.runtime.component import Component, Status
from dsl import compile_text
from dsl.catalog import Catalog, ComponentType, Kind

BALK = ComponentType("Balk", Kind.BEHAVIOR, "raises as it starts", entry_point="x:Balk")
CAMERA = ComponentType("Camera", Kind.RC, "a camera")
MISSION = """\
mission M {
    needs cam: Camera
    start -> Try
    Balk as Try
    Try -> done on error
}
"""


class _Balk(Component):
    def start(self) -> None:
        raise RuntimeError("no sensor")

    def step(self, now: float) -> Status:
        return Status.RUNNING


def ended(together: bool) -> list[tuple[str, float]]:
    cat = Catalog.of([BALK, CAMERA])
    chart = compile_text(MISSION, cat, "m.mission").statechart
    assert chart is not None
    clock = SimClock()
    ex = Executive(LocalNetwork().session("c"), clock, EntryPoints(cat, {"Balk": _Balk}),
                   resources=[Unit("r.camera", "Camera")])
    records: list[rec.Record] = []
    if together:
        with ex.together():
            mid = ex.submit(chart, listeners=[records.append])
    else:
        mid = ex.submit(chart, listeners=[records.append])
    ex.run(lambda: clock.advance(0.1), until=5)
    assert ex.missions[mid].outcome == "success"
    return [(r.path, r.at) for r in records if isinstance(r, rec.Exited)]


def test_a_component_failing_as_it_starts_ends_its_state_at_once_when_granted_together() -> None:
    assert ended(together=True) == ended(together=False) == [("M/Try", 0.0), ("M", 0.0)]
