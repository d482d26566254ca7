"""What a component author relies on, in a mission run in process (component audit D1, D2, D4): an output stays
readable when a transition, not the behavior itself, ends it; what a step emits is acted on once that step has
returned; a step's return value is a `Status` (or its string value) and anything else fails its state, saying
which component returned what. Tiny components of this module stand in for the catalog's."""

from __future__ import annotations

from typing import Any

import pytest

from drd.runtime import records as rec
from drd.runtime.component import Component, Status, StatusError, step_status
from dsl import compile_text
from dsl.catalog import Catalog
from tests.runtime_support import DOOR, INSIDE, LEAF, DoorFacer, DoorFinder, Harness, Idle, ranger_world

LOG: list[str] = []


class Finder(DoorFinder):
    sink = LOG.append


class Facer(DoorFacer):
    sink = LOG.append


REGISTRY = {"DetectDoor": Finder, "AlignRanger": Facer, "FollowCorridor": Idle}


def run(source: str, catalog: Catalog, registry: dict[str, Any]) -> Harness:
    result = compile_text(source, catalog, "t.mission")
    assert result.ok and result.statechart is not None, [d.message for d in result.diagnostics]
    LOG.clear()
    h = Harness(result.statechart, registry, ranger_world(1, 1))
    h.run(until=20.0, dt=0.1)
    return h


@pytest.mark.parametrize("source", [LEAF, INSIDE], ids=["the producer itself", "its parent"])
def test_an_output_is_read_after_an_event_transition_exits_its_producer(source: str, catalog: Catalog) -> None:
    """D1: `find -> face on DoorDetected` (or `Hunt -> face`, Hunt running DetectDoor) stops the producer; its
    door, set before it emitted, is what `face` is given (it was None: outputs were kept only on completion)."""
    h = run(source, catalog, REGISTRY)
    assert h.interp.outcome == "success", h.interp.reason
    assert f"face start {DOOR}" in LOG


def test_what_a_step_emits_is_acted_on_after_that_step_returned(catalog: Catalog) -> None:
    """D4: the transition on the event, its `terminate` and the next state's start come after the emitting step
    ended (they ran inside it, before `after emit`), as on a cluster: step, emit, terminate."""
    run(LEAF, catalog, REGISTRY)
    assert LOG == ["after emit", "terminate running", f"face start {DOOR}"]


class Returns(Component):
    value: Any = None

    def step(self, now: float) -> Any:
        return self.value


def returning(value: Any) -> dict[str, Any]:
    return {"Wait": type("Returns", (Returns,), {"value": value})}


WAIT = "mission M {\n    start -> w\n    Wait as w\n}\n"


@pytest.mark.parametrize("value", [None, "ok", "SUCCESS", 1, True], ids=repr)
def test_a_step_that_returns_no_status_fails_its_state_naming_the_component_and_the_value(
        value: Any, catalog: Catalog) -> None:
    """D2: it read as RUNNING (a forgotten `return` ran until the time limit, silently)."""
    h = run(WAIT, catalog, returning(value))
    assert h.interp.outcome == "failure"
    [exited] = [r for r in h.of(rec.Exited) if r.path == "M/w"]
    assert exited.status == "failure"
    assert exited.reason == (f"Wait.step returned {value}, not a Status "
                             "(return Status.RUNNING, Status.SUCCESS or Status.FAILURE)")


@pytest.mark.parametrize(("value", "outcome"), [(Status.SUCCESS, "success"), ("success", "success"),
                                                ("failure", "failure"), (Status.FAILURE, "failure")])
def test_a_status_or_its_string_value_is_taken_as_that_status(value: Any, outcome: str, catalog: Catalog) -> None:
    """The one rule a cluster applies too (a reply carries the status as its string): `"success"` succeeds."""
    h = run(WAIT, catalog, returning(value))
    assert h.interp.outcome == outcome
    assert h.clock.now() < 1.0, "it ended at its first step"


def test_the_rule_reads_a_value_and_its_str_alike() -> None:
    """A worker sends `str(value)`: the controller's reading of it must be the dry-run's reading of the value."""
    for value in (None, "ok", 3, "running", "success", "failure", Status.RUNNING):
        try:
            here: Status | str = step_status(value, "C")
        except StatusError as e:
            here = str(e)
        try:
            there: Status | str = step_status(str(value), "C")
        except StatusError as e:
            there = str(e)
        assert here == there, value
