"""`start -> X` in every form the spec allows (spec audit 7): a guard that does not hold is never entered (the
behavior fails instead of driving a robot), `when`/`after`/`on` start transitions wait for their trigger, the
first declared one enabled on entry wins, a start's actions run, and an empty body is done at once."""

from __future__ import annotations

import pytest

from drd.runtime import records as rec
from dsl import compile_text
from dsl.catalog import Catalog
from dsl.statechart import Statechart
from tests.runtime_support import Harness, Timed, ranger_world


def run(text: str, catalog: Catalog) -> Harness:
    r = compile_text(text, catalog, "t.mission")
    assert r.ok and r.statechart is not None, "\n".join(d.render(r.sources) for d in r.diagnostics)
    chart: Statechart = r.statechart
    h = Harness(chart, {"Wait": Timed}, ranger_world(1, 2))
    h.run(until=30)
    return h


def entered(h: Harness) -> list[tuple[float, str]]:
    return [(r.at, r.path) for r in h.of(rec.Entered)]


def test_a_start_whose_guard_is_false_is_not_entered_and_the_behavior_fails_naming_it(catalog: Catalog) -> None:
    h = run("""
mission M {
    needs ranger: Ranger
    start -> roll [ranger.battery > 2]
    Wait(duration: 3s) as roll
}""", catalog)
    assert h.interp.outcome == "failure"
    assert entered(h) == [(0.0, "M")]  # `roll` never started: its component never commanded the robot
    finished = h.of(rec.Finished)[-1]
    assert "no start transition of M is enabled" in finished.reason and "ranger.battery > 2" in finished.reason


def test_the_first_declared_start_enabled_on_entry_wins(catalog: Catalog) -> None:
    h = run("""
mission M {
    var n: int = 0
    start -> a [n > 0]
    start -> b when n == 0
    start -> c
    Wait(duration: 1s) as a
    Wait(duration: 1s) as b
    Wait(duration: 1s) as c
}""", catalog)
    assert h.interp.outcome == "success" and entered(h) == [(0.0, "M"), (0.0, "M/b")]


def test_a_start_waits_for_its_when_or_after_and_its_actions_run(catalog: Catalog) -> None:
    h = run("""
mission M {
    var n: int = 0
    start -> a when n == 5
    start -> b after 1s / set n = 7; log "late {n}"
    Wait(duration: 1s) as a
    Wait(duration: 1s) as b
}""", catalog)
    assert h.interp.outcome == "success"
    assert entered(h) == [(0.0, "M"), (0.0, "M/start"), (1.0, "M/b")]  # `a`'s condition never held
    assert [(r.at, r.trigger) for r in h.of(rec.Taken) if r.path == "M/start"] == [(1.0, "timeout")]
    assert [r.text for r in h.of(rec.Log)] == ["late 7"]


def test_a_start_on_an_event_waits_for_it(catalog: Catalog) -> None:
    h = run("""
mission M {
    parallel all { Zapper; Target }
}
behavior Zapper { Wait(duration: 2s); Wait -> done / emit Zap(k: 1) }
behavior Target {
    start -> A on Zap [event.k == 1]
    Wait(duration: 1s) as A
}""", catalog)
    assert h.interp.outcome == "success"
    assert (2.0, "M/Target/A") in entered(h) and not any(p == "M/Target/A" and at < 2.0 for at, p in entered(h))


def test_the_actions_of_a_lone_start_run(catalog: Catalog) -> None:
    h = run("""
mission M {
    var n: int = 0
    start -> p / set n = 5; log "set {n}"
    Wait(duration: 1s) as p
    p -> done [n == 5]
    p -> fail
}""", catalog)
    assert h.interp.outcome == "success" and [r.text for r in h.of(rec.Log)] == ["set 5"]


@pytest.mark.parametrize("text", ["mission W {}", "mission W { start -> e; Empty as e }\nbehavior Empty {}"])
def test_an_empty_body_is_done_at_once(catalog: Catalog, text: str) -> None:
    h = run(text, catalog)
    assert h.interp.outcome == "success" and h.clock.now() <= 0.5


def test_a_start_on_error_is_refused_where_it_is_written(catalog: Catalog) -> None:
    r = compile_text("mission M {\n    start -> a on error\n    Wait(duration: 1s) as a\n}\n", catalog, "t.mission")
    assert not r.ok
    (d,) = [d for d in r.diagnostics if "starting cannot fail" in d.message]
    assert (d.span.line, d.span.column) == (2, 5)


def test_the_drawings_start_with_the_start_transitions_and_hide_the_waiting_state(catalog: Catalog) -> None:
    from dsl.export import to_dot, to_mermaid

    r = compile_text("mission M {\n    start -> a when true\n    start -> b after 1s\n    Wait(duration: 1s) as a\n"
                     "    Wait(duration: 1s) as b\n}\n", catalog, "t.mission")
    assert r.statechart is not None
    mermaid = to_mermaid(r.statechart)
    assert "[*] --> s1 : when true" in mermaid and "[*] --> s2 : after 1s" in mermaid
    assert '"start' not in mermaid and 'label="start' not in to_dot(r.statechart)


def test_a_zero_timeout_is_shown_as_written(catalog: Catalog) -> None:
    """New-user audit 8: `after 0s` was shown `after 0ms`."""
    from dsl.export import trigger_label

    r = compile_text("mission M {\n    Wait(duration: 1s) as a\n    a -> a after 0s [false]\n}\n", catalog, "t.mission")
    assert r.statechart is not None
    (t,) = [t for s in r.statechart.states.values() for t in s.transitions if t.delay == 0]
    assert trigger_label(t) == "after 0s [false]"


def test_a_start_beside_a_plan_is_refused_where_it_is_written(catalog: Catalog) -> None:
    """A plan says which step runs first, as `start ->` does (spec: one or the other); beside a plan, a start was
    ignored, or with a guard taken over the plan's order."""
    r = compile_text("mission M {\n    plan { A < B }\n    Wait(duration: 1s) as A\n    Wait(duration: 1s) as B\n"
                     "    start -> B after 5s\n}\n", catalog, "t.mission")
    assert not r.ok
    (d,) = [d for d in r.diagnostics if "a plan starts its first step" in d.message]
    assert (d.span.line, d.span.column) == (5, 5)
