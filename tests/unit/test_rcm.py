"""The Resource Controller Manager's rules, one scenario each (drd.rcm)."""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping

import pytest

from drd.rcm import (
    Aggregate,
    Candidate,
    Deadlock,
    Decision,
    Granted,
    NeedRequest,
    Released,
    Renewed,
    Request,
    Reserved,
    ResourceManager,
    Revoked,
    Unit,
    Unsatisfiable,
    Waiting,
)

CAMERA = NeedRequest("camera", "Camera")


def manager(*units: Unit, lease: float = 100.0, default_slice: float = 5.0) -> ResourceManager:
    rm = ResourceManager(lease=lease, default_slice=default_slice)
    for unit in units:
        rm.add_unit(unit, 0.0)
    return rm


def of(kind: type, decisions: Iterable[Decision]) -> list[Decision]:
    return [d for d in decisions if isinstance(d, kind)]


def granted(decisions: Iterable[Decision]) -> dict[str, Granted]:
    return {d.holder: d for d in decisions if isinstance(d, Granted)}


def carried_by(scout: Candidate, chosen: Mapping[str, Candidate]) -> bool:
    return scout.properties.get("carrier") == chosen["ranger"].id


# -- all-or-nothing and priorities ----------------------------------------------------------


def test_a_request_is_granted_whole_or_not_at_all() -> None:
    rm = manager(Unit("cam1", "Camera"), Unit("drive1", "Drive"))
    rm.request(Request("Other", 1, (NeedRequest("drive", "Drive"),)), 0.0)
    both = Request("Survey", 1, (CAMERA, NeedRequest("drive", "Drive")))
    assert rm.request(both, 0.0) == (Waiting("Survey", ("Other",)),)
    assert rm.holders("cam1") == ()  # the free camera is not taken alone
    decisions = rm.release("Other", 1.0)
    assert decisions[0] == Released("Other", ("drive1",), "release", ("drive",))
    grant = decisions[1]
    assert isinstance(grant, Granted) and grant.holder == "Survey"
    assert grant.assignment == {"camera": "cam1", "drive": "drive1"}
    assert grant.units == ("cam1", "drive1")


def test_lower_priority_waits_while_a_higher_one_waits_for_its_unit() -> None:
    rm = manager(Unit("cam1", "Camera"), Unit("drive1", "Drive"))
    rm.request(Request("Busy", 1, (NeedRequest("drive", "Drive"),)), 0.0)
    rm.request(Request("High", 1, (CAMERA, NeedRequest("drive", "Drive"))), 0.0)
    # The camera is free, but High (priority 1) waits for it: Low must not take it.
    assert rm.request(Request("Low", 2, (CAMERA,)), 0.0) == (Waiting("Low", ("High",)),)
    assert rm.queue() == ("High", "Low")
    decisions = rm.release("Busy", 1.0)
    assert list(granted(decisions)) == ["High"]
    assert list(granted(rm.release("High", 2.0))) == ["Low"]


def test_equal_priorities_are_served_in_request_order() -> None:
    rm = manager(Unit("cam1", "Camera"))
    for name in ("A", "B", "C", "D"):
        rm.request(Request(name, 1, (CAMERA,)), 0.0)
    assert rm.queue() == ("B", "C", "D")
    assert list(granted(rm.release("A", 1.0))) == ["B"]


def test_higher_priority_takes_the_unit_at_the_holders_slice_boundary() -> None:
    rm = manager(Unit("cam1", "Camera"))
    rm.request(Request("Low", 2, (NeedRequest("camera", "Camera", slice=5.0),)), 0.0)
    assert rm.request(Request("High", 1, (CAMERA,)), 1.0) == (Waiting("High", ("Low",)),)
    assert rm.tick(4.5) == ()  # never before the slice boundary
    revoked, grant = rm.tick(5.0)
    assert revoked == Revoked("Low", ("cam1",), "preempted", by="High")
    assert isinstance(grant, Granted) and grant.holder == "High" and not grant.resumed
    resumed = granted(rm.release("High", 20.0))["Low"]
    assert resumed.resumed and resumed.units == ("cam1",)


def test_a_units_own_slice_applies_when_the_need_sets_none() -> None:
    """hosts.yaml `slice: 60s` on a Ranger's drive: a mobile base is not handed over every 5 s."""
    rm = manager(Unit("drive", "Drive", slice=60.0), Unit("cam1", "Camera"))
    drive = NeedRequest("drive", "Drive")
    assert granted(rm.request(Request("A", 1, (drive, CAMERA)), 0.0))["A"].slice_until == 60.0
    rm.request(Request("B", 1, (drive,)), 1.0)
    assert rm.tick(59.0) == ()  # the default 5 s slice would have preempted A long ago
    assert isinstance(rm.tick(60.0)[0], Revoked)
    rm2 = manager(Unit("drive", "Drive", slice=60.0))
    short = NeedRequest("drive", "Drive", slice=2.0)  # `for 2s` in the mission wins over the unit's slice
    assert granted(rm2.request(Request("C", 1, (short,)), 0.0))["C"].slice_until == 2.0


def test_a_holder_in_overtime_is_preempted_as_soon_as_a_contender_arrives() -> None:
    rm = manager(Unit("cam1", "Camera"))
    rm.request(Request("A", 1, (CAMERA,)), 0.0)
    assert rm.tick(7.0) == ()  # slice over, nobody waits: A keeps the camera
    revoked, grant = rm.request(Request("B", 1, (CAMERA,)), 8.0)
    assert revoked == Revoked("A", ("cam1",), "preempted", by="B")
    assert isinstance(grant, Granted) and grant.slice_until == 13.0
    assert rm.queue() == ("A",)


def test_a_preemption_takes_only_the_units_it_must_and_free_ones_for_the_rest() -> None:
    """Semantics audit 24, D1: two instances each needing a Scout (three free) and the one camera. The second
    preempted the first for the camera and took its Scout too (the first candidate, free once revoked), so the two
    took turns on one Scout while the others stood idle: a victim is resumed on its very units only."""
    rm = manager(Unit("cam1", "Camera"), *(Unit(f"scout{i}", "Scout") for i in (1, 2, 3)))
    needs = (NeedRequest("s", "Scout"), CAMERA)
    assert granted(rm.request(Request("A", 1, needs), 0.0))["A"].assignment == {"s": "scout1", "camera": "cam1"}
    revoked, grant = rm.request(Request("B", 1, needs), 6.0)  # A is in overtime: preempted for the camera
    assert isinstance(revoked, Revoked) and revoked.holder == "A"
    assert isinstance(grant, Granted) and grant.assignment == {"s": "scout2", "camera": "cam1"}
    assert granted(rm.tick(11.0))["A"].assignment == {"s": "scout1", "camera": "cam1"}  # back on its own Scout
    # however many candidates a later need has (only the search's first 64 solutions are ranked)
    many = manager(Unit("cam1", "Camera"), *(Unit(f"scout{i}", "Scout") for i in (1, 2, 3)),
                   *(Unit(f"drone{i}", "Drone") for i in range(1, 71)))
    three = (NeedRequest("s", "Scout"), CAMERA, NeedRequest("d", "Drone"))
    many.request(Request("A", 1, three), 0.0)
    grant = granted(many.request(Request("B", 1, three), 6.0))["B"]
    assert grant.assignment["s"] == "scout2" and grant.assignment["d"] != "drone1", grant.assignment


def test_a_preemption_keeps_to_the_kind_of_robot_the_search_prefers() -> None:
    """The free-units-first tie (above) never swaps in a candidate of another kind: a behavior steering with a
    drive of [Ranger, Scout] and a Ranger's laser that preempts the Ranger's holder takes the Ranger's drive, not
    the free wheels of a Scout in its magazine (the cluster's two-missions test caught that)."""
    rm = manager(Unit("ranger1.drive", "Drive"), Unit("ranger1.laser", "Ranges"), Unit("scout1.wheels", "Drive"))
    rm.add_aggregate(Aggregate("ranger1", "Ranger", {"drive": "ranger1.drive", "laser": "ranger1.laser"}), 0.0)
    rm.add_aggregate(Aggregate("scout1", "Scout", {"wheels": "scout1.wheels"}), 0.0)
    rm.request(Request("Patrol", 2, (NeedRequest("ranger", "Ranger"),)), 0.0)
    steer = (NeedRequest("drive", "Drive"), NeedRequest("ranges", "Ranges"))
    revoked, grant = rm.request(Request("Drive", 1, steer), 6.0)  # the patrol is in overtime
    assert isinstance(revoked, Revoked) and revoked.holder == "Patrol"
    assert isinstance(grant, Granted) and grant.assignment == {"drive": "ranger1.drive", "ranges": "ranger1.laser"}


def test_lower_priority_never_preempts_a_higher_one() -> None:
    rm = manager(Unit("cam1", "Camera"))
    rm.request(Request("High", 1, (CAMERA,)), 0.0)
    rm.request(Request("Low", 2, (CAMERA,)), 0.0)
    assert rm.tick(50.0) == ()
    assert rm.holders("cam1") == ("High",)


def test_fig8_equal_priorities_alternate_and_the_lower_one_waits_for_both() -> None:
    """The paper's Fig. 8: one Camera, slice 5 s, each holder needs 12 s of camera time."""
    rm = ResourceManager(lease=3.0, default_slice=5.0)
    rm.add_unit(Unit("cam", "Camera"), 0.0)
    spans: list[list[object]] = []  # [holder, start, end]

    def record(now: float, decisions: Iterable[Decision]) -> None:
        for d in decisions:
            if isinstance(d, Granted):
                spans.append([d.holder, now, None])
            elif isinstance(d, (Revoked, Released)):
                assert spans[-1][0] == d.holder and spans[-1][2] is None
                spans[-1][2] = now

    for holder, priority in (("A", 1), ("B", 1), ("C", 2)):
        record(0.0, rm.request(Request(holder, priority, (CAMERA,)), 0.0))
    held = {"A": 0.0, "B": 0.0, "C": 0.0}
    now = 0.0
    while rm.holders("cam") or rm.queue():
        now += 0.5
        (holder,) = rm.holders("cam")  # it held the camera during the last half second
        held[holder] += 0.5
        if held[holder] >= 12.0:
            record(now, rm.release(holder, now))
        else:
            record(now, rm.renew(holder, now))
        record(now, rm.tick(now))
        assert now < 100
    assert [tuple(span) for span in spans] == [
        ("A", 0.0, 5.0),
        ("B", 5.0, 10.0),
        ("A", 10.0, 15.0),
        ("B", 15.0, 20.0),
        ("A", 20.0, 22.0),
        ("B", 22.0, 24.0),
        ("C", 24.0, 36.0),
    ]


def test_equals_rotate_round_robin_without_starvation() -> None:
    rm = manager(Unit("cam1", "Camera"), default_slice=1.0)
    for name in ("A", "B", "C"):
        rm.request(Request(name, 1, (CAMERA,)), 0.0)
    order = [rm.holders("cam1")[0]]
    for step in range(1, 7):
        rm.tick(float(step))
        order.append(rm.holders("cam1")[0])
    assert order == ["A", "B", "C", "A", "B", "C", "A"]


def test_equals_take_turns_for_as_long_as_they_run() -> None:
    """Users audit 9, D1: each preemption pinned the re-queued need over its previous pin, one layer a slice, until
    comparing two needs overflowed the stack (a RecursionError after some 650 slices of a 5 s Fig. 8)."""
    rm = manager(Unit("cam1", "Camera"), default_slice=1.0)
    for name in ("A", "B"):
        rm.request(Request(name, 1, (NeedRequest("camera", "Camera", where=lambda c, _chosen: c.id == "cam1"),)), 0.0)
    order = [rm.holders("cam1")[0] for step in range(1, 3001) if rm.tick(float(step)) or True]
    assert order[-4:] == ["B", "A", "B", "A"] and order.count("A") == 1500


# -- sharable units, leases, fencing ---------------------------------------------------------


def test_sharable_units_never_exceed_capacity() -> None:
    rm = manager(Unit("radio", "RadioChannel", sharable=True, capacity=3.0))

    def radio(quantity: float) -> tuple[NeedRequest, ...]:
        return (NeedRequest("radio", "RadioChannel", quantity=quantity),)

    assert granted(rm.request(Request("A", 1, radio(2.0)), 0.0))
    assert granted(rm.request(Request("B", 1, radio(1.0)), 0.0))
    assert rm.request(Request("C", 1, radio(0.5)), 0.0) == (Waiting("C", ("A", "B")),)
    assert rm.holders("radio") == ("A", "B")
    assert rm.tick(60.0) == ()  # sharable units are never preempted
    assert list(granted(rm.release("B", 61.0))) == ["C"]
    assert rm.snapshot()["units"]["radio"]["load"] == 2.5


def test_leases_expire_unless_renewed() -> None:
    rm = manager(Unit("cam1", "Camera"), lease=3.0)
    (grant,) = rm.request(Request("A", 1, (CAMERA,)), 0.0)
    assert isinstance(grant, Granted) and grant.lease_until == 3.0
    rm.request(Request("B", 1, (CAMERA,)), 0.0)
    assert rm.renew("A", 2.0) == (Renewed("A", 5.0),)
    assert rm.tick(4.9) == ()
    released, regrant = rm.tick(5.0)
    assert released == Released("A", ("cam1",), "expired", ("camera",))
    assert isinstance(regrant, Granted) and regrant.holder == "B"
    assert rm.renew("A", 5.0) == ()  # too late: the lease is gone


def test_an_expired_lease_is_applied_by_any_later_call() -> None:
    rm = manager(Unit("cam1", "Camera"), lease=3.0)
    rm.request(Request("A", 1, (CAMERA,)), 0.0)
    decisions = rm.request(Request("B", 1, (CAMERA,)), 10.0)
    assert decisions[0] == Released("A", ("cam1",), "expired", ("camera",))
    assert granted(decisions)["B"].lease_until == 13.0


def test_epochs_strictly_increase_with_each_grant() -> None:
    rm = manager(Unit("cam1", "Camera"), Unit("radio", "RadioChannel", sharable=True, capacity=2.0))
    epochs = []
    for step in range(3):
        (grant,) = rm.request(Request(f"H{step}", 1, (CAMERA,)), float(step))
        assert isinstance(grant, Granted)
        epochs.append(grant.epochs["cam1"])
        rm.release(f"H{step}", float(step))
    assert epochs == [1, 2, 3]
    radio = (NeedRequest("radio", "RadioChannel"),)
    first = granted(rm.request(Request("R1", 1, radio), 5.0))["R1"]
    second = granted(rm.request(Request("R2", 1, radio), 5.0))["R2"]
    assert second.epochs["radio"] > first.epochs["radio"]


def test_a_manager_taking_over_grants_above_the_epochs_it_is_given() -> None:
    """A restarted or elected controller's manager starts empty: `epochs_above` keeps it from giving an epoch the
    one before gave, for the units it knows and for those that join later (safety audit 25, D1)."""
    rm = manager(Unit("cam1", "Camera"))
    rm.epochs_above(7)
    assert granted(rm.request(Request("A", 1, (CAMERA,)), 0.0))["A"].epochs == {"cam1": 8}
    rm.add_unit(Unit("cam2", "Camera"), 0.0)
    assert granted(rm.request(Request("B", 1, (CAMERA,)), 0.0))["B"].epochs == {"cam2": 8}
    rm.epochs_above(3)  # never lowers
    rm.release("A", 1.0)
    assert granted(rm.request(Request("C", 1, (CAMERA,)), 1.0))["C"].epochs == {"cam1": 9}
    assert rm.highest_epoch() == 9


# -- constraints, dependencies and the Static Dependency Database -------------------------------


def fleet() -> ResourceManager:
    rm = manager()
    for name in ("r1", "r2"):
        for part in ("drive", "cam", "launcher"):
            rm.add_unit(Unit(f"{name}.{part}", part.capitalize(), host=name), 0.0)
        parts = {part: f"{name}.{part}" for part in ("drive", "cam", "launcher")}
        rm.add_aggregate(Aggregate(name, "Ranger", parts, {"battery": 1.0}, host=name), 0.0)
    for scout, carrier in (("s1", "r2"), ("s2", "r2")):
        rm.add_unit(Unit(f"{scout}.wheels", "Wheels", host="r2"), 0.0)
        rm.add_aggregate(Aggregate(scout, "Scout", {"wheels": f"{scout}.wheels"}, {"carrier": carrier}, "r2"), 0.0)
    return rm


SCOUT_MISSION = (NeedRequest("ranger", "Ranger"), NeedRequest("scout", "Scout", where=carried_by))


def test_dependent_needs_are_solved_together_by_backtracking() -> None:
    rm = fleet()
    grant = granted(rm.request(Request("Survey", 1, SCOUT_MISSION), 0.0))["Survey"]
    # r1 comes first but carries no Scout: the solver backtracks to r2.
    assert grant.assignment == {"ranger": "r2", "scout": "s1"}
    assert grant.units == ("r2.drive", "r2.cam", "r2.launcher", "s1.wheels")


def test_a_launched_scout_leaves_its_magazine() -> None:
    rm = fleet()
    rm.set_property("s1", "carrier", None, 0.0)
    rm.set_property("s2", "carrier", "r1", 0.0)
    grant = granted(rm.request(Request("Survey", 1, SCOUT_MISSION), 1.0))["Survey"]
    assert grant.assignment == {"ranger": "r1", "scout": "s2"}


def test_a_property_change_reconsiders_the_waiters_of_that_type() -> None:
    rm = fleet()
    in_r1 = NeedRequest("scout", "Scout", where=lambda c, _: c.properties["carrier"] == "r1")
    rm.set_property("s2", "carrier", "r1", 0.0)
    assert granted(rm.request(Request("Busy", 1, (in_r1,)), 0.0))["Busy"].assignment == {"scout": "s2"}
    assert rm.request(Request("Survey", 1, (in_r1,)), 0.0) == (Waiting("Survey", ("Busy",)),)
    assert granted(rm.set_property("s1", "carrier", "r1", 1.0))["Survey"].assignment == {"scout": "s1"}
    rm.request(Request("Later", 1, (in_r1,)), 1.0)
    rm.set_property("s1", "carrier", None, 2.0)
    decisions = rm.set_property("s2", "carrier", None, 2.0)
    assert decisions == (Unsatisfiable("Later", "scout", "no Scout satisfies the constraint"),)
    assert rm.holders("s1.wheels") == ("Survey",)  # holders keep what they were granted


def test_unsatisfiable_requests_say_which_need_and_why() -> None:
    rm = fleet()
    rm.add_unit(Unit("radio", "RadioChannel", sharable=True, capacity=2.0), 0.0)
    cases = {
        (NeedRequest("sonar", "Sonar"),): ("sonar", "no Sonar is known"),
        (NeedRequest("radio", "RadioChannel", quantity=3.0),): (
            "radio",
            "quantity 3 exceeds the capacity of every RadioChannel",
        ),
        (NeedRequest("ranger", "Ranger", where=lambda c, _: c.properties["battery"] == 2),): (
            "ranger",
            "no Ranger satisfies the constraint",
        ),
        (NeedRequest("ranger", "Ranger", where=lambda c, _: c.id == "r1"), SCOUT_MISSION[1]): (
            "scout",
            "no Scout satisfies the constraint together with ranger",
        ),
    }
    for index, (needs, (need, reason)) in enumerate(cases.items()):
        holder = f"H{index}"
        assert rm.request(Request(holder, 1, needs), 0.0) == (Unsatisfiable(holder, need, reason),)
    assert rm.queue() == ()


def test_two_needs_of_one_type_take_two_units() -> None:
    rm = manager(Unit("cam1", "Camera"), Unit("cam2", "Camera"))
    stereo = (NeedRequest("left", "Camera"), NeedRequest("right", "Camera"))
    assert granted(rm.request(Request("Stereo", 1, stereo), 0.0))["Stereo"].units == ("cam1", "cam2")
    rm3 = manager(Unit("cam1", "Camera"))
    (unsat,) = rm3.request(Request("Stereo", 1, stereo), 0.0)
    assert isinstance(unsat, Unsatisfiable) and unsat.need == "right"


# -- hot-plug ----------------------------------------------------------------------------------


def test_host_loss_releases_its_holders_and_rejects_waiters_that_cannot_be_met() -> None:
    rm = fleet()
    r2 = NeedRequest("ranger", "Ranger", where=lambda c, _: c.id == "r2")
    rm.request(Request("OnR2", 1, (r2,)), 0.0)
    rm.request(Request("AlsoR2", 1, (r2,)), 0.0)
    rm.request(Request("AnyRanger", 2, (NeedRequest("ranger", "Ranger"),)), 0.0)
    rm.request(Request("SecondRanger", 2, (NeedRequest("ranger", "Ranger"),)), 0.0)
    decisions = rm.remove_host("r2", 1.0)
    assert decisions[0] == Released("OnR2", ("r2.drive", "r2.cam", "r2.launcher"), "host lost", ("ranger",),
                                    ("r2", "r2.cam", "r2.drive", "r2.launcher"))
    assert Unsatisfiable("AlsoR2", "ranger", "no Ranger satisfies the constraint while host r2 is down (its resources"
                         " are not in the manager)") in decisions
    assert rm.queue() == ("SecondRanger",)
    assert rm.snapshot()["aggregates"].keys() == {"r1"}


def test_a_host_seen_down_keeps_its_grants_but_gives_nothing_new_until_it_is_back() -> None:
    """Cluster audit 19, #1: in the lease after a host died, a waiter was granted the robot its holder had just given
    back, and failed at once: the robot's components could not run on the dead host."""
    rm = fleet()
    any_ranger = (NeedRequest("ranger", "Ranger"),)
    rm.request(Request("OnR1", 1, (NeedRequest("ranger", "Ranger", where=lambda c, _: c.id == "r1"),)), 0.0)
    rm.request(Request("OnR2", 1, (NeedRequest("ranger", "Ranger", where=lambda c, _: c.id == "r2"),)), 0.0)
    rm.request(Request("Waiter", 2, any_ranger), 0.0)
    assert rm.set_host_offline("r2", True, 1.0) == ()
    assert rm.holders("r2.drive") == ("OnR2",) and rm.renew("OnR2", 1.5) == (Renewed("OnR2", 101.5),)
    assert not granted(rm.release("OnR2", 2.0)) and rm.queue() == ("Waiter",)
    assert not granted(rm.request(Request("Scouting", 1, (NeedRequest("scout", "Scout"),)), 2.0))
    back = granted(rm.set_host_offline("r2", False, 3.0))
    assert back["Scouting"].assignment == {"scout": "s1"} and back["Waiter"].assignment == {"ranger": "r2"}


def test_a_host_offline_past_its_lease_loses_its_grants_and_its_waiters_keep_waiting() -> None:
    rm = fleet()
    rm.request(Request("OnR2", 1, (NeedRequest("ranger", "Ranger", where=lambda c, _: c.id == "r2"),)), 0.0)
    rm.request(Request("OnR1", 1, (NeedRequest("ranger", "Ranger", where=lambda c, _: c.id == "r1"),)), 0.0)
    rm.request(Request("Waiter", 2, (NeedRequest("ranger", "Ranger"),)), 0.0)
    rm.set_host_offline("r2", True, 1.0)
    lost = rm.remove_host("r2", 4.0)
    assert [(d.holder, d.reason) for d in of(Released, lost)] == [("OnR2", "host lost")] and not granted(lost)
    assert rm.queue() == ("Waiter",)  # r1 is still there: it waits for it
    for part in ("drive", "cam", "launcher"):  # the host back later: its resources added again, online
        rm.add_unit(Unit(f"r2.{part}", part.capitalize(), host="r2"), 5.0)
    back = rm.add_aggregate(Aggregate("r2", "Ranger", {p: f"r2.{p}" for p in ("drive", "cam", "launcher")}, {},
                                      host="r2"), 5.0)
    assert granted(back)["Waiter"].assignment == {"ranger": "r2"}


def test_a_need_only_a_down_hosts_robot_would_meet_names_that_host() -> None:
    """Cluster audit 19, #4: a mission needing ranger2 while its host was down failed "no Ranger satisfies the
    constraint", as if the constraint were wrong."""
    rm = fleet()
    r2 = (NeedRequest("ranger", "Ranger", where=lambda c, _: c.id == "r2"),)
    ghost = (NeedRequest("ranger", "Ranger", where=lambda c, _: c.id == "r9"),)
    rm.remove_host("r2", 1.0)
    assert rm.request(Request("OnR2", 1, r2), 2.0) == (Unsatisfiable(
        "OnR2", "ranger", "no Ranger satisfies the constraint while host r2 is down (its resources are not in the"
                          " manager)"),)
    assert rm.request(Request("OnR9", 1, ghost), 2.0) == (
        Unsatisfiable("OnR9", "ranger", "no Ranger satisfies the constraint"),)  # no host down would meet it
    rm.add_unit(Unit("r2.drive", "Drive", host="r2"), 3.0)  # back: what it had is no longer shelved
    assert rm.request(Request("Again", 1, r2), 3.0) == (
        Unsatisfiable("Again", "ranger", "no Ranger satisfies the constraint"),)


def test_resources_shelved_at_the_start_name_their_host_until_it_joins() -> None:
    """Cluster audit 20, #4: a controller restarted while ranger2 was down never had its resources; a mission that
    needed it failed "no Ranger satisfies the constraint"."""
    rm = manager(Unit("r1.drive", "Drive", host="r1"))
    rm.shelve("r2", [Unit("r2.drive", "Drive", host="r2"), Unit("r1.drive", "Drive", host="r1")])  # r1's: known
    on_r2 = (NeedRequest("drive", "Drive", where=lambda c, _: c.id == "r2.drive"),)
    [unsat] = rm.request(Request("OnR2", 1, on_r2), 1.0)
    assert isinstance(unsat, Unsatisfiable) and unsat.reason.endswith("while host r2 is down (its resources are not"
                                                                      " in the manager)")
    assert granted(rm.add_unit(Unit("r2.drive", "Drive", host="r2"), 2.0)) == {}  # joined: nothing waited
    assert granted(rm.request(Request("Again", 1, on_r2), 2.0))["Again"].units == ("r2.drive",)


def test_a_lost_robot_fails_only_its_holder_and_the_next_waiter_gets_another() -> None:
    rm = fleet()
    scout = (NeedRequest("scout", "Scout"),)
    rm.request(Request("WithS1", 1, scout), 0.0)
    rm.request(Request("WithS2", 1, scout), 0.0)
    rm.request(Request("Third", 1, scout), 0.0)
    decisions = rm.remove(["s1", "s1.wheels", "not-there"], 1.0)
    assert decisions[0] == Released("WithS1", ("s1.wheels",), "resource lost", ("scout",), ("s1", "s1.wheels"))
    assert "s1" not in rm.snapshot()["aggregates"] and rm.holders("s2.wheels") == ("WithS2",)
    assert rm.queue() == ("Third",)  # s2 is still held; Third waits for it, not for the lost s1
    assert granted(rm.release("WithS2", 2.0))["Third"].assignment == {"scout": "s2"}


def test_a_lost_host_names_what_it_took_not_what_went_with_it() -> None:
    """Users audit 15, D2: a behavior holding a robot on each of two hosts failed "lost crawler_a (host lost)" when
    the other host, the Hauler's, was killed: the reason named the first resource of the grant."""
    rm = fleet()
    both = (NeedRequest("first", "Ranger", where=lambda c, _: c.id == "r1"),
            NeedRequest("second", "Ranger", where=lambda c, _: c.id == "r2"))
    rm.request(Request("Escort", 1, both), 0.0)
    [released] = [d for d in rm.remove_host("r2", 1.0) if isinstance(d, Released)]
    assert released.holder == "Escort" and set(released.units) == {"r1.drive", "r1.cam", "r1.launcher", "r2.drive",
                                                                  "r2.cam", "r2.launcher"}
    assert released.lost == ("r2", "r2.cam", "r2.drive", "r2.launcher")


def test_a_new_unit_serves_waiters_and_epochs_survive_hot_plug() -> None:
    rm = manager(Unit("cam1", "Camera", host="h1"))
    rm.request(Request("A", 1, (CAMERA,)), 0.0)
    rm.request(Request("B", 1, (CAMERA,)), 0.0)
    assert granted(rm.add_unit(Unit("cam2", "Camera", host="h2"), 1.0))["B"].units == ("cam2",)
    rm.remove_host("h1", 2.0)
    rm.add_unit(Unit("cam1", "Camera", host="h1"), 3.0)
    grant = granted(rm.request(Request("C", 1, (CAMERA,)), 3.0))["C"]
    assert grant.epochs == {"cam1": 2}  # not 1 again: fencing survives the host's return


# -- deadlocks ---------------------------------------------------------------------------------


def nested_deadlock(child_priority: int) -> tuple[ResourceManager, tuple[Decision, ...]]:
    rm = manager(Unit("X", "Camera"), Unit("Y", "Drive"))
    x = NeedRequest("x", "Camera")
    y = NeedRequest("y", "Drive")
    rm.request(Request("A", 1, (x,)), 0.0)
    rm.request(Request("B", 1, (y,)), 0.0)
    assert rm.request(Request("A/child", child_priority, (y,)), 1.0) == (Waiting("A/child", ("B",)),)
    return rm, rm.request(Request("B/child", 1, (x,)), 2.0)


def test_a_wait_for_cycle_cancels_the_most_recent_of_equal_priority() -> None:
    rm, decisions = nested_deadlock(child_priority=1)
    assert decisions == (
        Waiting("B/child", ("A",)),
        Deadlock(("A", "A/child", "B", "B/child"), victim="B/child"),
    )
    assert rm.queue() == ("A/child",)


def test_a_wait_for_cycle_cancels_the_lowest_priority_first() -> None:
    rm, decisions = nested_deadlock(child_priority=3)
    assert decisions[-1] == Deadlock(("A", "A/child", "B", "B/child"), victim="A/child")
    assert rm.queue() == ("B/child",)


def test_a_cycle_closed_by_a_grant_is_found_too() -> None:
    rm = manager(Unit("X", "Camera"), Unit("Y", "Drive"))
    x, y = NeedRequest("x", "Camera"), NeedRequest("y", "Drive")
    rm.request(Request("C", 1, (x,)), 0.0)
    rm.request(Request("B", 1, (y,)), 0.0)
    rm.request(Request("A", 1, (x,)), 0.0)  # waits for C
    rm.request(Request("A/child", 1, (y,)), 0.0)  # waits for B; A holds nothing yet: no cycle
    assert rm.request(Request("B/child", 1, (x,)), 0.0) == (Waiting("B/child", ("A", "C")),)
    decisions = rm.release("C", 1.0)  # X goes to A, which closes A -> A/child -> B -> B/child -> A
    assert decisions[1:] == (
        granted(decisions)["A"],
        Deadlock(("A", "A/child", "B", "B/child"), victim="B/child"),
    )


def test_a_child_asking_for_its_ancestors_unit_is_a_deadlock_not_a_preemption() -> None:
    rm = manager(Unit("cam1", "Camera"))
    rm.request(Request("A", 1, (CAMERA,)), 0.0)
    rm.tick(10.0)  # A is in overtime, but its own child may not take its camera
    decisions = rm.request(Request("A/child", 1, (CAMERA,)), 10.0)
    assert decisions[-1] == Deadlock(("A", "A/child"), victim="A/child")
    assert rm.holders("cam1") == ("A",)


def test_alternatives_are_not_mistaken_for_a_deadlock() -> None:
    rm = manager(Unit("cam1", "Camera"), Unit("cam2", "Camera"), Unit("Y", "Drive"))
    rm.request(Request("A", 1, (CAMERA,)), 0.0)  # cam1
    rm.request(Request("C", 1, (CAMERA,)), 0.0)  # cam2
    rm.request(Request("B", 1, (NeedRequest("y", "Drive"),)), 0.0)
    rm.request(Request("A/child", 1, (NeedRequest("y", "Drive"),)), 0.0)
    decisions = rm.request(Request("B/child", 1, (CAMERA,)), 0.0)
    # B/child may still get cam2 from C: no cycle is certain yet.
    assert decisions == (Waiting("B/child", ("A", "C")),)


# -- reservations, cancel, partial release, queries --------------------------------------------


def test_a_reservation_is_served_ahead_of_its_equals_once_due() -> None:
    rm = manager(Unit("cam1", "Camera"))
    rm.request(Request("A", 1, (CAMERA,)), 0.0)
    rm.request(Request("B", 1, (CAMERA,)), 1.0)
    assert rm.reserve(Request("R", 1, (CAMERA,)), 2.0, at=3.0) == (Reserved("R", 3.0),)
    assert rm.queue() == ("B",)
    assert rm.tick(3.0) == (Waiting("R", ("A",)),)
    assert rm.queue() == ("R", "B")
    revoked, grant = rm.tick(5.0)
    assert isinstance(revoked, Revoked) and revoked.by == "R"
    assert isinstance(grant, Granted) and grant.holder == "R"


def test_cancel_withdraws_a_grant_a_wait_or_a_reservation() -> None:
    rm = manager(Unit("cam1", "Camera"))
    rm.request(Request("A", 1, (CAMERA,)), 0.0)
    rm.request(Request("B", 1, (CAMERA,)), 0.0)
    rm.reserve(Request("R", 1, (CAMERA,)), 0.0, at=50.0)
    assert rm.cancel("B", 1.0) == (Released("B", (), "cancelled"),)
    assert rm.cancel("R", 1.0) == (Released("R", (), "cancelled"),)
    assert rm.cancel("A", 1.0) == (Released("A", ("cam1",), "cancelled", ("camera",)),)
    assert rm.cancel("nobody", 1.0) == ()
    assert rm.tick(60.0) == ()


def test_partial_release_by_need_name_keeps_the_rest() -> None:
    rm = manager(Unit("cam1", "Camera"), Unit("drive1", "Drive"))
    rm.request(Request("A", 1, (CAMERA, NeedRequest("drive", "Drive"))), 0.0)
    rm.request(Request("B", 1, (NeedRequest("drive", "Drive"),)), 0.0)
    released, grant = rm.release("A", 1.0, units=["drive"])
    assert released == Released("A", ("drive1",), "release", ("drive",))
    assert isinstance(grant, Granted) and grant.holder == "B"
    assert rm.holders("cam1") == ("A",)
    assert rm.release("A", 2.0, units=["cam1"]) == (Released("A", ("cam1",), "release", ("camera",)),)
    assert "A" not in rm.snapshot()["holds"]


def test_a_suspended_holder_resumes_only_the_needs_it_still_had() -> None:
    rm = manager(Unit("cam1", "Camera"), Unit("drive1", "Drive"))
    rm.request(Request("A", 1, (CAMERA, NeedRequest("drive", "Drive"))), 0.0)
    rm.release("A", 1.0, units=["drive"])
    rm.request(Request("B", 1, (CAMERA,)), 2.0)
    rm.tick(5.0)  # A revoked in favour of B
    resumed = granted(rm.release("B", 6.0))["A"]
    assert resumed.resumed and resumed.assignment == {"camera": "cam1"}


def test_releasing_a_suspended_holder_withdraws_its_queued_request() -> None:
    rm = manager(Unit("cam1", "Camera"))
    rm.request(Request("A", 1, (CAMERA,)), 0.0)
    rm.request(Request("B", 1, (CAMERA,)), 0.0)
    rm.tick(5.0)  # A suspended, queued again
    assert rm.queue() == ("A",)
    assert rm.release("A", 6.0) == (Released("A", (), "release"),)
    assert rm.release("B", 7.0) == (Released("B", ("cam1",), "release", ("camera",)),)


def charged(ranger: Candidate, chosen: Mapping[str, Candidate]) -> bool:
    battery = ranger.properties["battery"]
    return isinstance(battery, float) and battery > 0.5


def test_set_property_without_now_uses_the_last_time_and_reservations_are_checked() -> None:
    rm = fleet()
    rm.request(Request("A", 1, (NeedRequest("ranger", "Ranger", where=lambda c, _: c.id == "r1"),)), 4.0)
    assert rm.set_property("r2", "battery", 0.1) == ()
    assert rm.snapshot()["time"] == 4.0
    assert rm.request(Request("B", 1, (NeedRequest("ranger", "Ranger", where=charged),)), 4.0) == (
        Waiting("B", ("A",)),
    )
    grant = granted(rm.set_property("r2", "battery", 0.9))["B"]
    assert grant.assignment == {"ranger": "r2"} and grant.lease_until == 104.0
    (unsat,) = rm.reserve(Request("R", 1, (NeedRequest("sonar", "Sonar"),)), 4.0, at=10.0)
    assert unsat == Unsatisfiable("R", "sonar", "no Sonar is known")


def test_snapshot_is_plain_json() -> None:
    rm = fleet()
    rm.request(Request("Survey", 1, SCOUT_MISSION, mission="Corridor"), 0.0)
    rm.request(Request("Other", 2, (NeedRequest("ranger", "Ranger", where=lambda c, _: c.id == "r2"),)), 0.0)
    snap = json.loads(json.dumps(rm.snapshot()))
    assert snap["holds"]["Survey"]["assignment"] == {"ranger": "r2", "scout": "s1"}
    assert snap["queue"][0]["holder"] == "Other"
    assert snap["units"]["r2.cam"]["holders"] == {"Survey": 1.0}


def test_misuse_is_refused() -> None:
    rm = manager(Unit("cam1", "Camera"))
    rm.request(Request("A", 1, (CAMERA,)), 5.0)
    with pytest.raises(ValueError, match="already has a request"):
        rm.request(Request("A", 1, (CAMERA,)), 5.0)
    with pytest.raises(ValueError, match="time went backwards"):
        rm.tick(4.0)
    with pytest.raises(ValueError, match="already registered"):
        rm.add_unit(Unit("cam1", "Camera"), 5.0)
    with pytest.raises(ValueError, match="unknown part units"):
        rm.add_aggregate(Aggregate("r9", "Ranger", {"cam": "nope"}), 5.0)
    with pytest.raises(ValueError, match="duplicate need names"):
        Request("B", 1, (CAMERA, CAMERA))


def test_a_preempted_holder_resumes_on_what_it_held_though_its_where_no_longer_holds_of_it() -> None:
    """A Scout moved off its Ranger while held (its own LaunchScout threw it): preempted, the holder waits for that
    very Scout and Ranger and resumes on them, as a holder that was not preempted keeps them (safety audit 25, D2:
    it was Unsatisfiable, and its mission failed; before that, found by the stateful test, it waited for ever)."""

    def carried(scout: Candidate, chosen: Mapping[str, Candidate]) -> bool:
        return scout.properties.get("carrier") == chosen["ranger"].id

    rm = manager(Unit("cam2", "Camera"), Unit("drive2", "Drive"), Unit("s2", "Scout", properties={"carrier": "r2"}),
                 default_slice=1.0)
    rm.add_aggregate(Aggregate("r2", "Ranger", {"drive": "drive2", "camera": "cam2"}, {}), 0.0)
    needs = (NeedRequest("ranger", "Ranger"), NeedRequest("scout", "Scout", where=carried))
    assert of(Granted, rm.request(Request("M1", 1, needs), 0.0))
    rm.set_property("s2", "carrier", "", 0.5)  # launched: no Scout rides on r2 any more
    out = rm.request(Request("M2", 1, (CAMERA,)), 2.0)  # M1's slice is over: M2 takes the camera
    assert [type(d) for d in out] == [Revoked, Granted] and "M1" in rm.queue(), out
    back = granted(rm.release("M2", 3.0))["M1"]
    assert back.resumed and set(back.units) == {"drive2", "cam2", "s2"}, back
