"""Spec audit D1 and D3 ("Resources"): requests of one instant are granted by priority, not by who asked first;
a behavior preempted at a slice boundary is resumed on the resources taken from it, not on others of the type."""

from __future__ import annotations

from collections.abc import Iterable
from typing import TypeVar

from drd.rcm import Decision, Granted, NeedRequest, Request, ResourceManager, Revoked, Unit, Unsatisfiable
from drd.runtime import records as rec
from dsl import compile_text
from dsl.catalog import Catalog
from tests.runtime_support import Harness, Timed, ranger_world

CAMERA = NeedRequest("camera", "Camera")
D = TypeVar("D")


def of(kind: type[D], decisions: Iterable[Decision]) -> list[D]:
    return [d for d in decisions if isinstance(d, kind)]


def two_cameras() -> ResourceManager:
    rm = ResourceManager(lease=100.0, default_slice=1.0)
    rm.add_unit(Unit("cam1", "Camera"), 0.0)
    rm.add_unit(Unit("cam2", "Camera"), 0.0)
    return rm


def test_a_preempted_holder_does_not_resume_on_another_free_unit() -> None:
    """A holds cam1, B cam2; C takes cam1 from A at A's slice boundary. When B gives cam2 back, A must not resume on
    it (before the fix it did: `Granted(A, cam2, resumed)`); it resumes on cam1 once C gives it back."""
    rm = two_cameras()
    rm.request(Request("A", 1, (CAMERA,)), 0.0)
    rm.request(Request("B", 1, (CAMERA,)), 0.5)
    out = rm.request(Request("C", 1, (CAMERA,)), 1.2)  # A's slice is over, B's is not
    assert [(d.holder, d.units) for d in of(Revoked, out)] == [("A", ("cam1",))]
    assert [(d.holder, d.assignment) for d in of(Granted, out)] == [("C", {"camera": "cam1"})]
    assert of(Granted, rm.release("B", 1.3)) == []  # cam2 is free, but it is not what A had
    assert "A" in rm.queue()
    resumed = of(Granted, rm.release("C", 1.4))
    assert [(d.holder, d.assignment, d.resumed) for d in resumed] == [("A", {"camera": "cam1"}, True)]


def test_a_suspended_holder_whose_resource_is_lost_fails_naming_it() -> None:
    """The resource a suspended holder waits for is removed: it can never resume, so `Unsatisfiable` names it
    (it does not wait forever, and it is not moved to another camera)."""
    rm = two_cameras()
    rm.request(Request("A", 1, (CAMERA,)), 0.0)
    rm.request(Request("B", 1, (CAMERA,)), 0.5)
    rm.request(Request("C", 1, (CAMERA,)), 1.2)  # A suspended, pinned to cam1
    rm.release("B", 1.3)
    out = rm.remove(["cam1"], 1.4)
    lost = of(Unsatisfiable, out)
    assert [(d.holder, d.need) for d in lost] == [("A", "camera")]
    assert "cam1" in lost[0].reason and "suspended" in lost[0].reason
    assert of(Granted, out) == [] and "A" not in rm.queue()


PRIORITIES = """
mission M {
    parallel all {
        Sooner
        Later
    }
}
behavior Sooner priority 3 {
    needs c: Camera
    Observe(duration: 2s)
}
behavior Later priority 1 {
    needs c: Camera
    Observe(duration: 2s)
}
"""


def run(text: str, catalog: Catalog, resources: list[object]) -> Harness:
    r = compile_text(text, catalog, "t.mission")
    assert r.ok and r.statechart is not None, [d.message for d in r.diagnostics]
    h = Harness(r.statechart, {"Observe": Timed}, resources)
    assert h.run(until=120) == "success", h.interp.reason
    return h


def test_requests_of_one_instant_are_granted_by_priority_not_declaration_order(catalog: Catalog) -> None:
    """Sooner (priority 3) is declared first; Later (priority 1) must get the camera at t=0 and Sooner wait for
    it (before the fix Sooner got it and Later waited 2 s)."""
    h = run(PRIORITIES, catalog, [Unit("ranger1.camera", "Camera")])
    grants = [(r.at, r.path.rsplit("/", 1)[-1]) for r in h.of(rec.Granted)]
    assert grants == [(0.0, "Later"), (2.0, "Sooner")]
    blocked = [r.blocked_by for r in h.of(rec.Waiting) if r.path.endswith("Sooner") and r.blocked_by]
    assert blocked == [("M/Later",)]


def test_a_lone_request_is_granted_and_started_in_the_same_instant(catalog: Catalog) -> None:
    """Deferring a request to the end of its run to completion keeps its timing: granted at t=0, its component
    entered at t=0 (its children start in the same step)."""
    h = run("mission M { Solo }\nbehavior Solo { needs c: Camera\n Observe(duration: 1s) }", catalog,
            [Unit("ranger1.camera", "Camera")])
    assert [r.at for r in h.of(rec.Granted)] == [0.0]
    assert [r.at for r in h.of(rec.Entered) if r.path.endswith("Observe")] == [0.0]


ROUND_ROBIN = """
mission Ibis {
    Spot[3]
}
behavior Spot {
    needs s: Scout
    Observe(duration: 12s)
}
"""


def test_each_instance_resumes_on_the_scout_taken_from_it(catalog: Catalog) -> None:
    """Three instances round-robin on two Scouts: every grant after an instance's first names the Scout of its
    first (before the fix Spot[0] was resumed on the other Scout)."""
    h = run(ROUND_ROBIN, catalog, ranger_world(1, 2))
    first: dict[str, str] = {}
    resumed = 0
    for r in h.of(rec.Granted):
        scout = r.resources["s"]
        resumed += r.path in first
        assert first.setdefault(r.path, scout) == scout, (r.path, r.at, first[r.path], scout)
    assert resumed >= 2  # preemption did happen
    assert len(h.of(rec.Suspended)) == resumed


def test_a_preempted_holder_is_said_to_wait_again_blocked_by_its_preemptor(catalog: Catalog) -> None:
    """Suspended at a slice boundary, a holder is queued again: a `waiting` record right after its `suspended`
    names the instance that took its Scout (before, nothing said it waited, so a report of a mission stopped
    then listed it neither as waiting nor as having waited)."""
    h = run(ROUND_ROBIN, catalog, ranger_world(1, 2))
    took = {r.at: r.path for r in h.of(rec.Granted)}
    for suspended in h.of(rec.Suspended):
        again = [r for r in h.of(rec.Waiting) if r.path == suspended.path and r.at == suspended.at and r.blocked_by]
        assert len(again) == 1, (suspended, h.of(rec.Waiting))
        assert again[0].blocked_by == (took[suspended.at],)
