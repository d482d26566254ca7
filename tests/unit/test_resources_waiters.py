"""`rcm/resources` as `missionctl status` shows it with several missions (multi-mission audit D2): each unit's
queue holds only the waiters that can take it (their claims, a `where` narrowing them), each waiter says its
mission's priority, its `where` and who is in its way with what they hold. Built from a real manager."""

from __future__ import annotations

from drd.daemon.controller import resources_reply
from drd.rcm import Aggregate, NeedRequest, Request, ResourceManager, Unit


class Pinned:
    """A `where` as the runtime gives it: a callable that keeps its expression (`expr`)."""

    def __init__(self, robot: str) -> None:
        from dsl import ast
        from dsl.parser import parse_expression

        parsed = parse_expression(f'ranger.id == "{robot}"')
        assert isinstance(parsed, ast.Expr)
        self.expr = parsed
        self.robot = robot

    def __call__(self, cand: object, chosen: object) -> bool:
        return getattr(cand, "id", None) == self.robot


def manager() -> ResourceManager:
    rm = ResourceManager()
    for robot in ("ranger1", "ranger2"):
        for part in ("drive", "camera"):
            rm.add_unit(Unit(f"{robot}.{part}", part.capitalize(), host=robot), 0.0)
        rm.add_aggregate(Aggregate(robot, "Ranger", {"drive": f"{robot}.drive", "camera": f"{robot}.camera"},
                                   host=robot), 0.0)
    return rm


def reply_of(rm: ResourceManager) -> dict[str, list[str]]:
    reply = resources_reply(rm.snapshot(), "c", "hq", {}, {}, rm.waiters())
    return {u.id: u.queue for u in reply.units}


def test_a_waiter_with_a_where_queues_only_for_the_robot_it_can_take() -> None:
    rm = manager()
    rm.request(Request("Hog-1/Hog/Hold", 1, (NeedRequest("ranger", "Ranger", where=Pinned("ranger2")),), "Hog-1", 1),
               0.0)
    rm.request(Request("Starved-2/Starved/WantEast", 1,
                       (NeedRequest("ranger", "Ranger", where=Pinned("ranger2")),), "Starved-2", 3), 0.0)
    queues = reply_of(rm)
    assert queues["ranger2.drive"] == queues["ranger2.camera"] == ["Starved-2/Starved/WantEast"]
    assert queues["ranger1.drive"] == queues["ranger1.camera"] == [], "it can never take ranger1"
    [waiter] = resources_reply(rm.snapshot(), "c", "hq", {}, {}, rm.waiters()).queue
    assert (waiter.priority, waiter.mission_priority) == (1, 3), "the mission's priority ranks it first"
    assert waiter.where == {"ranger": 'ranger.id == "ranger2"'}
    assert [(b.holder, b.holds, b.waiting) for b in waiter.blocked_by] == [("Hog-1/Hog/Hold", {"ranger": "ranger2"},
                                                                             False)]


def test_a_better_placed_waiter_is_named_as_waiting_first_and_the_queue_keeps_service_order() -> None:
    rm = manager()
    for robot in ("ranger1", "ranger2"):
        rm.request(Request(f"Hog-{robot}/Hog/Hold", 1, (NeedRequest("ranger", "Ranger", where=Pinned(robot)),),
                           f"Hog-{robot}", 1), 0.0)
    rm.request(Request("Low-3/Low/Any", 1, (NeedRequest("ranger", "Ranger"),), "Low-3", 3), 0.0)
    rm.request(Request("High-4/High/East", 2, (NeedRequest("ranger", "Ranger", where=Pinned("ranger2")),),
                       "High-4", 1), 0.0)
    queues = reply_of(rm)
    assert queues["ranger2.drive"] == ["High-4/High/East", "Low-3/Low/Any"], "mission priority first"
    assert queues["ranger1.drive"] == ["Low-3/Low/Any"]
    reply = resources_reply(rm.snapshot(), "c", "hq", {}, {}, rm.waiters())
    low = next(w for w in reply.queue if w.holder == "Low-3/Low/Any")
    assert low.where == {}
    named = {b.holder: (b.holds, b.waiting) for b in low.blocked_by}
    assert named["Hog-ranger1/Hog/Hold"] == ({"ranger": "ranger1"}, False)
    assert named["High-4/High/East"] == ({}, True)
