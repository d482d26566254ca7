"""Scoped events (issue #12): `on E from X` hears only X's subtree, and instances of one multiplicity never hear
each other's events (one sighting is never counted twice), while the mission and the operator reach everyone.

Checked from the records a user sees (`log` lines, `taken` transitions), with test components that emit.
"""

from __future__ import annotations

import pytest

from drd.runtime import records as rec
from drd.runtime.component import Component, Status
from drd.runtime.interpreter import hears
from dsl import compile_text
from dsl.catalog import Catalog, ComponentType, Kind, RecordSpec
from dsl.statechart import Statechart
from tests.runtime_support import Harness, ranger_world

SHOUT = ComponentType("Shout", Kind.BEHAVIOR, "emits Ping once", entry_point="x:Shout",
                      events=(RecordSpec("Ping", {}),))
IDLE = ComponentType("Idle", Kind.BEHAVIOR, "runs until stopped", entry_point="x:Idle")


class Shout(Component):
    def step(self, now: float) -> Status:
        assert self.ctx is not None
        self.ctx.emit("Ping")
        return Status.SUCCESS


class Idle(Component):
    pass


REGISTRY = {"Shout": Shout, "Idle": Idle}


@pytest.fixture(scope="module")
def cat(catalog: Catalog) -> Catalog:
    return Catalog.of([*catalog.components.values(), SHOUT, IDLE])


def chart(text: str, cat: Catalog) -> Statechart:
    r = compile_text(text, cat, "t.mission")
    assert r.ok and r.statechart is not None, [d.render() for d in r.diagnostics]
    return r.statechart


def heard(h: Harness) -> list[tuple[str, str]]:
    return sorted((r.path, r.text) for r in h.of(rec.Log))


PAIRS = """\
mission M {
    Pair[3]
}

behavior Pair {
    var pings: int = 0
    parallel {
        Shout
        Idle
    }
    Idle -> Idle on Ping / set pings = pings + 1; log "heard {pings}"
}
"""


def test_instances_of_a_multiplicity_hear_their_own_events_only(cat: Catalog) -> None:
    h = Harness(chart(PAIRS, cat), REGISTRY, ranger_world())
    h.run(until=3.0)
    assert heard(h) == [(f"M/Pair[{i}]", "heard 1") for i in range(3)], "each instance heard one Ping: its own"


SIBLINGS = """\
mission M {
    parallel {
        Shout as a
        Shout as b
        Idle
    }
    Idle -> Idle on Ping from SENDER / log "ping"
}
"""


def test_on_event_from_a_sibling_hears_only_that_sibling(cat: Catalog) -> None:
    h = Harness(chart(SIBLINGS.replace("SENDER", "a"), cat), REGISTRY, ranger_world())
    h.run(until=3.0)
    assert heard(h) == [("M", "ping")]
    h = Harness(chart(SIBLINGS.replace(" from SENDER", ""), cat), REGISTRY, ranger_world())
    h.run(until=3.0)
    assert heard(h) == [("M", "ping"), ("M", "ping")], "without `from`, both siblings' pings count"


def test_on_event_from_an_unknown_child_is_a_located_error(cat: Catalog) -> None:
    r = compile_text(SIBLINGS.replace("SENDER", "c"), cat, "t.mission")
    [d] = [d for d in r.diagnostics if d.severity.value == "error"]
    assert d.span.line == 7 and "has no child c" in d.message and "a" in (d.hint or "")


def test_the_mission_and_the_operator_reach_every_instance(cat: Catalog) -> None:
    h = Harness(chart(PAIRS.replace("        Shout\n", ""), cat), REGISTRY, ranger_world())
    h.interp.start()
    h.clock.advance(0.5)
    h.interp.step()
    h.interp.emit("Ping")  # the operator
    h.clock.advance(0.5)
    h.interp.step()
    assert heard(h) == [(f"M/Pair[{i}]", "heard 1") for i in range(3)]


def test_hears() -> None:
    assert hears("M/Pair[0]", "M/Pair[0]/Watch")
    assert not hears("M/Pair[0]", "M/Pair[1]/Watch")
    assert hears("M/Pair[0]/Inner", "M/Other/Watch") and hears("M", "M/Pair[2]/Watch")
    assert hears("M/Pair[0]", "operator") and hears("M/Pair[0]", "M")
    assert not hears("M/A[1]/B[0]", "M/A[0]/B[0]/C") and hears("M/A[0]/B[0]", "M/A[0]/B[1]/C") is False
