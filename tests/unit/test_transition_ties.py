"""Transitions of one state enabled at the same instant: the first declared wins, whatever their kinds (spec
audit D2); and `[a..*]` fails on entry when its resources allow fewer than `a` instances (spec audit D4)."""

from __future__ import annotations

from typing import Any

import pytest

from drd.runtime import records as rec
from drd.runtime.component import Status
from dsl import compile_text
from dsl.catalog import Catalog
from dsl.statechart import Statechart
from tests.runtime_support import Harness, Timed, ranger_world

#: `Target`'s child `Step` ends at t=2.0, when the sibling `Zapper` emits `Zap` (and `Zip`, with `zip`), and when
#: `Step`'s `after 2s` falls due. `{transitions}` are `Step`'s, in declaration order, then each target's
#: `X -> done / log "X"`.
TIE = """
mission M {{
    parallel all {{
        Zapper
        Target
    }}
}}
behavior Zapper {{ Wait(duration: 2s); Wait -> done / emit Zap(k: 1){zip} }}
behavior Target {{
    needs r: Ranger
    start -> Step
{transitions}
}}
behavior Step {{ Wait(duration: {step}) }}
"""


class FailsAt(Timed):
    """Fails once its duration has passed (a child failing at the same instant as the rest)."""

    def step(self, now: float) -> Status:
        return Status.FAILURE if super().step(now) is Status.SUCCESS else Status.RUNNING


class MarksAt(Timed):
    """Succeeds after its duration, and marks scout1 as it does: a `when` on the mark holds from that instant."""

    def step(self, now: float) -> Status:
        status = super().step(now)
        if status is Status.SUCCESS:
            self.update_dependency("ranger1.scout1", "carrier", "")  # launched: no longer in r's magazine
        return status


def compiled(text: str, catalog: Catalog) -> Statechart:
    r = compile_text(text, catalog, "t.mission")
    assert r.ok and r.statechart is not None, "\n".join(d.render(r.sources) for d in r.diagnostics)
    return r.statechart


def run(catalog: Catalog, transitions: list[str], *, step: str = "2s", leaf: Any = Timed,
        zip_too: bool = False) -> tuple[str | None, list[str], Harness]:
    """Run `TIE` with these transitions of `Step`: the outcome, the logs, the harness."""
    targets = sorted({t.split("-> ", 1)[1][0] for t in transitions} - {"d", "f"})
    written = " ".join(transitions)
    lines = [*transitions, *(f'{x} -> done / log "{x}"' for x in targets if f"{x} -> done" not in written)]
    text = TIE.format(transitions="\n".join(f"    {t}" for t in lines), step=step,
                      zip="; emit Zip(k: 2)" if zip_too else "")
    text += "".join(f"behavior {x} {{ Wait(duration: 1s) }}\n" for x in targets)
    registry: dict[str, Any] = {"Wait": Timed}
    if leaf is not Timed:
        class StepLeaf(leaf):  # type: ignore[misc,valid-type]
            def start(self) -> None:
                super().start()
                assert self.ctx is not None
                if not self.ctx.path.endswith("/Step/Wait"):
                    self.__class__ = Timed  # only Step's Wait fails or marks

        registry["Wait"] = StepLeaf
    h = Harness(compiled(text, catalog), registry, ranger_world(1, 2))
    outcome = h.run(until=30)
    return outcome, [r.text for r in h.of(rec.Log) if r.text in ("A", "B", "C")], h


def taken_at_2(h: Harness) -> list[tuple[str, str]]:
    return [(r.target.rsplit("/", 1)[-1], r.trigger) for r in h.of(rec.Taken)
            if r.path.endswith("/Step") and abs(r.at - 2.0) < 1e-6]


@pytest.mark.parametrize(("first", "second", "winner"), [
    ("Step -> A after 2s", "Step -> B", "A"),  # today: the completion won
    ("Step -> B", "Step -> A after 2s", "B"),
])
def test_completion_and_timeout_at_once(catalog: Catalog, first: str, second: str, winner: str) -> None:
    outcome, logs, h = run(catalog, [first, second])
    assert outcome == "success" and logs == [winner]
    assert taken_at_2(h) == [(winner, "timeout" if winner == "A" else "completion")]


@pytest.mark.parametrize(("first", "second", "winner"), [
    ("Step -> A on Zap", "Step -> B after 2s", "A"),  # today: the timeout won
    ("Step -> B after 2s", "Step -> A on Zap", "B"),
])
def test_event_and_timeout_at_once(catalog: Catalog, first: str, second: str, winner: str) -> None:
    outcome, logs, _ = run(catalog, [first, second], step="1h")
    assert outcome == "success" and logs == [winner]


@pytest.mark.parametrize(("first", "second", "winner"), [
    ("Step -> A on Zap", "Step -> B", "A"),  # today: the completion won
    ("Step -> B", "Step -> A on Zap", "B"),
])
def test_event_and_completion_at_once(catalog: Catalog, first: str, second: str, winner: str) -> None:
    outcome, logs, _ = run(catalog, [first, second])
    assert outcome == "success" and logs == [winner]


def test_two_events_of_one_instant_first_declared_wins(catalog: Catalog) -> None:
    """Zap is emitted before Zip, at the same instant: the transition declared first (on Zip) wins."""
    outcome, logs, _ = run(catalog, ["Step -> A on Zip", "Step -> B on Zap"], step="1h", zip_too=True)
    assert outcome == "success" and logs == ["A"]  # today: Zap, dispatched first, won


@pytest.mark.parametrize(("first", "second", "winner"), [
    ("Step -> A when count(Scout where scout.carrier == r) < 2", "Step -> B", "A"),  # today: completion
    ("Step -> B", "Step -> A when count(Scout where scout.carrier == r) < 2", "B"),
])
def test_change_and_completion_at_once(catalog: Catalog, first: str, second: str, winner: str) -> None:
    outcome, logs, _ = run(catalog, [first, second], leaf=MarksAt)
    assert outcome == "success" and logs == [winner]


@pytest.mark.parametrize(("first", "second", "winner"), [
    ("Step -> A after 2s", "Step -> B on error", "A"),  # today: on error won
    ("Step -> B on error", "Step -> A after 2s", "B"),
])
def test_failure_and_timeout_at_once(catalog: Catalog, first: str, second: str, winner: str) -> None:
    """An `on error` enabled catches the failure; the first declared enabled transition is taken."""
    outcome, logs, _ = run(catalog, [first, second], leaf=FailsAt)
    assert outcome == "success" and logs == [winner]


def test_a_timer_does_not_swallow_an_uncaught_failure(catalog: Catalog) -> None:
    """No `on error` (or a false one): the failure propagates, even with a timeout due at that instant."""
    for transitions in (["Step -> A after 2s"], ["Step -> A after 2s", "Step -> B on error [false]"]):
        outcome, logs, h = run(catalog, transitions, leaf=FailsAt)
        assert outcome == "failure" and logs == [], transitions
        assert [r.trigger for r in h.of(rec.Taken) if r.path.endswith("/Step")] == [], transitions


def test_a_false_guard_does_not_enable(catalog: Catalog) -> None:
    outcome, logs, _ = run(catalog, ["Step -> A after 2s [false]", "Step -> C on Zap [event.k == 2]", "Step -> B"])
    assert outcome == "success" and logs == ["B"]


def test_an_event_that_lost_a_tie_is_still_heard(catalog: Catalog) -> None:
    """The timeout wins; Zap is then dispatched as usual: A, entered at that instant, hears it and goes to C."""
    text = ["Step -> A after 2s", "Step -> B on Zap", "A -> C on Zap"]
    outcome, logs, _ = run(catalog, text, step="1h")
    assert outcome == "success" and logs == ["C"]


def test_an_event_moves_a_state_once(catalog: Catalog) -> None:
    """Zap wins the tie ahead of its dispatch: the state it enters (B) does not hear the same Zap again."""
    text = ["Step -> B on Zap", "Step -> A after 2s", "B -> C on Zap"]
    outcome, logs, _ = run(catalog, text, step="1h")
    assert outcome == "success" and logs == ["B"]


class SaysAndEnds(Timed):
    """Step's Wait: emits an event in the step it ends in (as DetectDoor emits DoorDetected in the step it succeeds),
    then fails when its `duration` is 2 s (the tests' choice), else succeeds. Any other Wait is a plain `Timed`."""

    def start(self) -> None:
        super().start()
        assert self.ctx is not None
        if not self.ctx.path.endswith("/Step"):
            self.__class__ = Timed

    def step(self, now: float) -> Status:
        if super().step(now) is not Status.SUCCESS:
            return Status.RUNNING
        assert self.ctx is not None
        self.ctx.emit("ScoutLaunched")  # an event the manifests declare, which no Wait emits otherwise
        return Status.FAILURE if self.needed == 2.0 else Status.SUCCESS


SAYS = """
mission M {{
    start -> Step
    Wait(duration: {duration}) as Step
{transitions}
}}
"""


@pytest.mark.parametrize(("duration", "transitions", "outcome", "logs"), [
    # semantics audit 11, D1: the event was handled before the step's own end, so the failure was lost
    ("2s", ["Step -> A on ScoutLaunched"], "failure", []),
    ("2s", ["Step -> A on ScoutLaunched", "Step -> B on error"], "success", ["A"]),  # caught: the first declared wins
    ("2s", ["Step -> B on error", "Step -> A on ScoutLaunched"], "success", ["B"]),
    # D2: the completion declared first lost to the event the step emitted
    ("1s", ["Step -> B", "Step -> A on ScoutLaunched"], "success", ["B"]),
    ("1s", ["Step -> A on ScoutLaunched", "Step -> B"], "success", ["A"]),
], ids=["failure-uncaught", "failure-caught-event-first", "failure-caught-error-first", "completion-first",
        "event-first"])
def test_a_step_that_emits_and_ends_at_once(catalog: Catalog, duration: str, transitions: list[str], outcome: str,
                                            logs: list[str]) -> None:
    targets = sorted({t.split("-> ", 1)[1][0] for t in transitions})
    lines = [*transitions, *(f'{x} -> done / log "{x}"' for x in targets), *(f"Wait as {x}" for x in targets)]
    text = SAYS.format(duration=duration, transitions="\n".join(f"    {t}" for t in lines))
    h = Harness(compiled(text, catalog), {"Wait": SaysAndEnds}, ranger_world(1, 2))
    assert h.run(until=30) == outcome, h.interp.reason
    assert [r.text for r in h.of(rec.Log) if r.text in ("A", "B")] == logs


# ------------------------------------------------------------------ D4: [a..*]
SPOTS = "mission M {{ Spot[{bounds}] }}\nbehavior Spot {{ needs s: Scout\n Wait(duration: 2s) }}"


def test_a_star_multiplicity_fails_on_entry_when_its_resources_allow_fewer_than_a(catalog: Catalog) -> None:
    h = Harness(compiled(SPOTS.format(bounds="7..*"), catalog), {"Wait": Timed}, ranger_world(1, 6))
    assert h.run(until=60) == "failure"
    assert "Spot[7..*] needs at least 7 instances, but the resources allow only 6" in h.interp.reason
    assert not [r for r in h.of(rec.Entered) if "Spot[" in r.path]  # failed on entry: no instance at all


def test_a_star_multiplicity_nothing_can_serve_says_why(catalog: Catalog) -> None:
    """With no resource at all, the reason says why none ever will (the manager's words, as an instance asking
    would have had them: re-verification audit, t08)."""
    text = "mission M { Spot[2..*] }\nbehavior Spot { needs s: Scout where s.id == \"nobody\"\n Wait(duration: 2s) }"
    h = Harness(compiled(text, catalog), {"Wait": Timed}, ranger_world(1, 6))
    assert h.run(until=60) == "failure"
    assert h.interp.reason.endswith("allow only 0 (one per distinct set its needs accept: s: Scout): resource need s"
                                    " can never be satisfied: no Scout satisfies the constraint"), h.interp.reason


@pytest.mark.parametrize(("bounds", "instances"), [("7", 7), ("7..9", 9), ("3..*", 6)])
def test_other_multiplicities_queue_as_before(catalog: Catalog, bounds: str, instances: int) -> None:
    h = Harness(compiled(SPOTS.format(bounds=bounds), catalog), {"Wait": Timed}, ranger_world(1, 6))
    assert h.run(until=60) == "success"
    assert len({r.path for r in h.of(rec.Entered) if r.path.count("/") == 1 and "Spot[" in r.path}) == instances


@pytest.mark.parametrize("outer", ["Box -> Esc after 2s", "Box -> Esc on Zap"])
def test_an_ancestors_transition_wins_over_an_inner_completion_of_the_same_instant(catalog: Catalog,
                                                                                   outer: str) -> None:
    """Semantics audit 24, D5: at 2 s `In` ends (its completion goes to `In2`) as the outer `after 2s` falls due
    (or a sibling emits `Zap`): the inner completion was taken first, its action ran and `In2` was entered, then
    left at once. docs/design.md's rule for one instant: the ancestor's is taken."""
    text = f"""
mission M {{
    parallel any {{
        Zapper
        Outer
    }}
}}
behavior Zapper {{ Wait(duration: 2s); Wait -> done / emit Zap(k: 1) }}
behavior Outer {{
    needs r: Ranger
    start -> Box
    {outer} / log "outer"
    Esc -> done after 10s
    Wait(duration: 1s) as Esc
}}
behavior Box {{ start -> In; Wait(duration: 2s) as In; In -> In2 / log "inner"; Wait(duration: 5s) as In2 }}
"""
    h = Harness(compiled(text, catalog), {"Wait": Timed}, ranger_world(1, 2))
    h.run(until=3)
    logs = [r.text for r in h.of(rec.Log)]
    entered = [r.path for r in h.of(rec.Entered)]
    assert "outer" in logs and "inner" not in logs, logs
    assert not any(p.endswith("/In2") for p in entered), entered


#: `Zapper` emits `Zap` at 2 s beside `Target`, whose transitions each test gives.
ZAP_AT_2S = """
mission M {
    parallel all {
        Zapper
        Target
    }
}
behavior Zapper { Wait(duration: 2s); Wait -> done / emit Zap(k: 1) }
"""
GUARDED_LATE = ZAP_AT_2S + """behavior Target {
    needs r: Ranger
    start -> Step
    Step -> A on Zap
    Step -> B after 1s [count(Scout where scout.carrier == r) < 2]
    A -> done / log "A"
    B -> done / log "B"
}
behavior Step { Wait(duration: 1h) }
behavior A { Wait(duration: 1s) }
behavior B { Wait(duration: 1s) }
"""


class ZapMarks(Timed):
    """The Zapper's Wait launches scout1 as it ends: the guard on the Scouts carried holds from that instant."""

    def step(self, now: float) -> Status:
        status = super().step(now)
        assert self.ctx is not None
        if status is Status.SUCCESS and self.ctx.path.endswith("Zapper/Wait"):
            self.update_dependency("ranger1.scout1", "carrier", "")
        return status


def test_a_guarded_after_due_earlier_but_enabled_only_now_keeps_to_the_declaration_order(catalog: Catalog) -> None:
    """Review of semantics audit 24, D4: the `after` due at 1 s whose guard holds only from 2 s beat the `on Zap`
    declared before it at 2 s; it was not enabled alone before, so the first declared wins."""
    h = Harness(compiled(GUARDED_LATE, catalog), {"Wait": ZapMarks}, ranger_world(1, 2))
    h.run(until=30)
    assert [r.text for r in h.of(rec.Log)] == ["A"]


DEAF = ZAP_AT_2S + """behavior Target {
    needs r: Ranger
    start -> Step
    Step -> Box on Zap
    Step -> X after 2s
    Box -> Esc on Zap / log "moved again"
    Box -> done
    X -> done
    Esc -> done
}
behavior Step { Wait(duration: 1h) }
behavior X { Wait(duration: 1s) }
behavior Esc { Wait(duration: 1s) }
behavior Box {
    start -> Scan
    Spot[0..count(Scout where scout.id == "nobody")] as Scan
    Scan -> Rest / log "inner"
    Wait(duration: 5s) as Rest
}
behavior Spot { needs s: Scout
 Wait(duration: 2s) }
"""


def test_a_state_an_event_entered_is_not_moved_again_by_it_through_an_inner_completion(catalog: Catalog) -> None:
    """Review of semantics audit 24, D5: `Zap` took `Step -> Box`, Box's empty multiplicity completed on entry,
    and the ancestor-first rule then let the same `Zap` take `Box -> Esc`: one event moved a state twice."""
    h = Harness(compiled(DEAF, catalog), {"Wait": Timed}, ranger_world(1, 2))
    h.run(until=4)
    assert "moved again" not in [r.text for r in h.of(rec.Log)]
    assert [r.target.rsplit("/", 1)[-1] for r in h.of(rec.Taken) if r.path.endswith("/Step")] == ["Box"]
