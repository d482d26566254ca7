"""The executive's history (soak audit defects 2 and 3): it never keeps more than `history` finished missions, even
when the last one ended between two steps, and a restarted one lists those that ended before, first."""

from __future__ import annotations

from drd.bus import LocalNetwork
from drd.executive import EntryPoints, Executive, MissionCommand, MissionStatus
from drd.manifests import load_catalog
from drd.runtime.clock import SimClock
from dsl import compile_text


def _executive(history: int) -> tuple[Executive, SimClock, LocalNetwork]:
    clock = SimClock()
    net = LocalNetwork()
    return Executive(net.session("c"), clock, EntryPoints(load_catalog()), history=history), clock, net


def _finished(ex: Executive) -> list[str]:
    return [m["id"] for m in ex.status().missions if m.get("outcome") is not None]


def test_status_keeps_history_finished_missions_when_the_last_one_is_stopped_between_steps() -> None:
    ex, clock, net = _executive(history=2)
    cat = load_catalog()
    quick = compile_text("mission Quick {\n    Wait(duration: 1s)\n}\n", cat, "q.mission").statechart
    slow = compile_text("mission Slow {\n    Wait(duration: 1h)\n}\n", cat, "s.mission").statechart
    assert quick is not None and slow is not None
    ex.submit(quick, "Quick-1")
    ex.submit(quick, "Quick-2")
    ex.submit(slow, "Slow-3")
    for _ in range(20):
        clock.advance(0.1)
        ex.step()
    assert _finished(ex) == ["Quick-1", "Quick-2"]
    reply = net.session("operator").call("drd/local/executive", MissionCommand("stop", "Slow-3"))
    assert isinstance(reply, MissionStatus) and reply.missions[0]["outcome"] == "stopped"
    assert _finished(ex) == ["Quick-2", "Slow-3"], "history 2: the first ended goes when the last ends"


def test_a_restarted_executive_lists_the_missions_that_ended_before_first_bounded_by_history() -> None:
    ex, clock, net = _executive(history=3)
    before = [(f"Old-{n}", {"id": f"Old-{n}", "mission": "Old", "outcome": "success", "reason": "", "time": n})
              for n in range(1, 5)]
    ex.restore_history(before)
    assert [m["id"] for m in ex.status().missions] == ["Old-2", "Old-3", "Old-4"]
    assert ex.status().missions[0] == {"id": "Old-2", "mission": "Old", "outcome": "success", "reason": "", "time": 2}
    cat = load_catalog()
    quick = compile_text("mission Quick {\n    Wait(duration: 1s)\n}\n", cat, "q.mission").statechart
    assert quick is not None
    ex.submit(quick, "Quick-5")
    for _ in range(20):
        clock.advance(0.1)
        ex.step()
    assert [m["id"] for m in ex.status().missions] == ["Old-3", "Old-4", "Quick-5"]
    reply = net.session("operator").call("drd/local/executive", MissionCommand("stop", "Old-4"))
    assert isinstance(reply, MissionStatus) and reply.missions[0]["already_ended"] is True
