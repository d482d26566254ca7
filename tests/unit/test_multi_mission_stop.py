"""Several missions on one manager (multi-mission audit D1, D3, D4): a stop of several missions at once grants
nothing to a mission being stopped and keeps who it waited for; a waiting record names another mission's blocker
with that mission's id and what it held; a preemption by another mission names it. Two interpreters share one
manager in-process (what the executive does), on a SimClock; and the pure readers of those records."""

from __future__ import annotations

import json
from typing import Any

from drd.explain import Explainer, blocked
from drd.rcm import ResourceManager
from drd.runtime import records as rec
from drd.runtime.clock import SimClock
from drd.runtime.interpreter import Interpreter, stop_together
from drd.runtime.pool import ResourcePool
from drd.tracecheck import record_problem
from dsl import compile_text
from dsl.catalog import Catalog
from tests.runtime_support import Timed, ranger_world

HOG = """
mission Hog priority 1 {
    HoldIt
}
behavior HoldIt {
    needs ranger: Ranger where ranger.id == "ranger1"
    Observe(duration: 10min)
}
"""

STARVED = """
mission Starved priority 3 {
    WantIt
}
behavior WantIt {
    needs ranger: Ranger where ranger.id == "ranger1"
    Observe(duration: 5s)
}
"""

GUARD = """
mission Guard priority 2 {
    Post
}
behavior Post {
    needs ranger: Ranger where ranger.id == "ranger1" for 2s
    Observe(duration: 1min)
}
"""


class Team:
    """Missions sharing one manager, each with its own records (as the executive runs them)."""

    def __init__(self, catalog: Catalog, *missions: tuple[str, str, int]) -> None:
        self.clock = SimClock()
        self.pool = ResourcePool(ResourceManager(default_slice=2.0))
        self.pool.add(ranger_world(1, 0), 0.0)
        self.records: dict[str, list[rec.Record]] = {}
        self.interps: dict[str, Interpreter] = {}
        for text, mid, priority in missions:
            r = compile_text(text, catalog, "t.mission")
            assert r.ok and r.statechart is not None, [d.message for d in r.diagnostics]
            interp = Interpreter(r.statechart, {"Observe": Timed}, self.pool.broker, self.clock, pool=self.pool,
                                 mission=mid, priority=priority)
            self.records[mid] = []
            interp.attach(self.records[mid].append)
            self.interps[mid] = interp
            interp.start()

    def run(self, until: float) -> None:
        while self.clock.now() < until - 1e-9:
            self.clock.advance(0.5)
            for interp in self.interps.values():
                interp.step()

    def of(self, mid: str, kind: type[Any]) -> list[Any]:
        return [r for r in self.records[mid] if isinstance(r, kind)]


def test_missions_stopped_together_grant_nothing_to_each_other(catalog: Catalog) -> None:
    """Hog holds ranger1, Starved waits for it. Stopped one at a time, Hog's exit gave ranger1 to Starved, which
    entered WantIt's Observe in the stop and lost its `waiting` (before the fix: a granted and an entered)."""
    team = Team(catalog, (HOG, "Hog-1", 1), (STARVED, "Starved-2", 3))
    team.run(3.0)
    stop_together(team.interps.values(), "stopped by operator")
    assert team.of("Starved-2", rec.Granted) == []
    assert [r.path for r in team.of("Starved-2", rec.Entered)] == ["Starved", "Starved/WantIt"]
    assert all(i.outcome == "stopped" for i in team.interps.values())
    waiting = Explainer(team.records["Starved-2"]).waiting()
    assert waiting == [{"path": "Starved/WantIt", "since": 0.0, "needs": ["ranger: Ranger"], "blocked_by": [
        {"path": "Hog-1/Hog/HoldIt", "mission": "Hog-1", "holds": {"ranger": "ranger1"}}], "blockers": 1}]
    assert "Hog-1" not in team.pool.broker.rcm.snapshot()["holds"]  # the stop did give it back


def test_a_mission_of_the_same_name_is_named_by_its_id_not_read_as_itself(catalog: Catalog) -> None:
    """Two Guards share ranger1 in 2 s slices: the waiter's blocker and the preemptor are the other mission's
    behavior, `Guard-1/Guard/Post`, not `Guard/Post` (which read as blocked by itself); its holds are the
    other's ranger1, not the waiter's own `{}`."""
    team = Team(catalog, (GUARD, "Guard-1", 2), (GUARD, "Guard-2", 2))
    team.run(3.0)
    waits = [r for r in team.of("Guard-2", rec.Waiting) if r.blocked_by]
    assert [(r.blocked_by, r.holds) for r in waits] == [
        (("Guard-1/Guard/Post",), {"Guard-1/Guard/Post": {"ranger": "ranger1"}})]
    assert [r.reason for r in team.of("Guard-1", rec.Revoked)] == ["preempted by Guard-2/Guard/Post"]
    stop_together(team.interps.values(), "stopped by operator")


def test_a_blocker_of_the_same_mission_is_still_named_by_its_path() -> None:
    """Within one mission nothing changes: the path, and the holds from the mission's own grants."""
    wait = {"path": "M/B", "since": 0.0, "needs": [], "blocked_by": ["M/A", "Other-1/O/X"],
            "held": {"Other-1/O/X": {"cam": "c2"}}}
    assert blocked(wait, {"M/A": {"cam": "c1"}, "Other-1/O/X": {"cam": "wrong"}})["blocked_by"] == [
        {"path": "M/A", "holds": {"cam": "c1"}}, {"path": "Other-1/O/X", "mission": "Other-1", "holds": {"cam": "c2"}}]


def test_a_waiting_record_has_holds_only_when_another_mission_blocks() -> None:
    """One mission's traces stay as they were (no `holds: {}`); the field is checked when there."""
    assert "holds" not in rec.Waiting(1.0, "M/B", (), ("M/A",)).to_dict()
    line = rec.Waiting(1.0, "M/B", (), ("O-1/O/A",), {"O-1/O/A": {"r": "ranger1"}}).to_dict()
    assert line["holds"] == {"O-1/O/A": {"r": "ranger1"}}
    assert rec.from_dict(line) == rec.Waiting(1.0, "M/B", (), ("O-1/O/A",), {"O-1/O/A": {"r": "ranger1"}})
    parsed = json.loads(json.dumps(line))  # as a trace line reads back
    assert record_problem(parsed) is None
    problem = record_problem({**parsed, "holds": {"O-1/O/A": "ranger1"}})
    assert problem is not None and "holds" in problem
