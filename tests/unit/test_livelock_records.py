"""What a livelock leaves in the trace: the root's `exited` says why, as its `finished` does (semantics audit 18,
#5), and the per-transition bound takes one transition exactly MAX_REPEATS times (#6)."""

from __future__ import annotations

import pytest

from drd.runtime import records as rec
from dsl import compile_text
from dsl.catalog import Catalog
from tests.runtime_support import Harness, Timed, ranger_world

#: One state that feeds itself: each turn emits the event it listens to.
SELF_EMIT = """
mission M {
    start -> A
    Wait(duration: 100s) as A
    A -> A on Tick / emit Tick(n: 1)
    A -> A after 1s / emit Tick(n: 0)
}
"""

#: Two behaviors that feed each other: each of Pong's turns emits what moves Ping, and Ping's emit moves Pong.
RING = """
mission M { parallel all { Ping; Pong } }
behavior Ping {
    start -> A
    Wait(duration: 1s) as A
    Wait(duration: 9s) as B
    A -> B / emit Hit(n: 0)
    B -> A on Hit
    A -> B on Hit / emit Hit(n: 1)
}
behavior Pong {
    start -> C
    Wait(duration: 9s) as C
    C -> C on Hit / emit Hit(n: 2)
}
"""

#: A zero-time timer back to its own source.
ZERO_TIME = "mission M {\n start -> A\n Wait(duration: 1h) as A\n A -> A after 0s\n}\n"


def run(catalog: Catalog, text: str) -> Harness:
    result = compile_text(text, catalog, "t.mission")
    assert result.ok and result.statechart is not None
    h = Harness(result.statechart, {"Wait": Timed}, ranger_world(1, 0))
    assert h.run(until=5) == "failure"
    return h


@pytest.mark.parametrize("text", [SELF_EMIT, RING, ZERO_TIME], ids=["self_emit", "ring", "zero_time"])
def test_root_exited_says_why_a_livelock_failed_it(catalog: Catalog, text: str) -> None:
    h = run(catalog, text)
    reason = h.interp.reason
    assert reason.startswith("livelock: ")
    assert [(r.status, r.reason) for r in h.of(rec.Exited) if r.path == "M"] == [("failure", reason)]
    assert [r.reason for r in h.of(rec.Finished)] == [reason]


@pytest.mark.parametrize(("text", "looping", "trigger"), [
    (SELF_EMIT, ("M/A", "M/A"), "event"),  # its first turn, at 1 s, is the `after 1s` one: another transition
    (RING, ("M/Pong/C", "M/Pong/C"), "event"),
    (ZERO_TIME, ("M/A", "M/A"), "timeout"),
], ids=["self_emit", "ring", "zero_time"])
def test_one_transition_is_taken_exactly_max_repeats_times(catalog: Catalog, text: str, looping: tuple[str, str],
                                                          trigger: str) -> None:
    from drd.runtime.interpreter import MAX_REPEATS

    h = run(catalog, text)
    source, target = looping
    assert h.interp.reason.startswith(f"livelock: {source} -> {target} taken {MAX_REPEATS} times")
    turns = [r for r in h.of(rec.Taken) if (r.path, r.target, r.trigger) == (source, target, trigger)]
    assert len(turns) == MAX_REPEATS and len({r.at for r in turns}) == 1


def test_thousands_of_instances_finishing_together_are_no_livelock(catalog: Catalog) -> None:
    """Semantics audit 18, #4: with the instances limit raised, 11,000 Waits finishing at t=1 took 11,000 one-shot
    completions in one instant, and the fixed 10,000-transition backstop failed that loop-free mission; the bound
    grows by 10 per instance alive. A loop among them is still caught (by its own transition's count)."""
    from dsl.limits import Limits

    text = "mission Wide {\n    Inner[11000]\n}\nbehavior Inner {\n    Wait(duration: 1s)\n}\n"
    result = compile_text(text, catalog, "wide.mission", limits=Limits(instances=20_000))
    assert result.ok and result.statechart is not None, [d.message for d in result.diagnostics]
    h = Harness(result.statechart, {"Wait": Timed}, ranger_world(1, 0))
    assert h.run(until=5) == "success", h.interp.reason
