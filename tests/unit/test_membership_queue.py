"""The controller's queue of membership actions (`drd.daemon.controller.coalesced`): a host's return cancels its
departure while that is still queued (cluster audit 20, #2: a mission loop held up applied a removal after the host
had rejoined, and a waiter for its robot failed in between)."""

from __future__ import annotations

from drd.daemon.controller import Action, Membership, coalesced


def kinds(actions: list[Action]) -> list[tuple[str, str]]:
    return [(a.kind, a.host) for a in actions]


def queued(*actions: Action) -> list[Action]:
    out: list[Action] = []
    for action in actions:
        out = coalesced(out, action)
    return out


def test_a_return_after_a_queued_removal_keeps_the_resources_and_brings_them_online() -> None:
    got = queued(Action("offline", "r2"), Action("remove", "r2"), Action("add", "r2"))
    assert kinds(got) == [("offline", "r2"), ("online", "r2")]


def test_a_return_after_a_queued_offline_cancels_both() -> None:
    assert queued(Action("add", "r1"), Action("offline", "r2"), Action("online", "r2")) == [Action("add", "r1")]


def test_actions_of_other_hosts_and_applied_ones_are_kept_in_order() -> None:
    got = queued(Action("remove", "r2"), Action("offline", "r1"), Action("add", "r1"), Action("add", "r3"))
    assert kinds(got) == [("remove", "r2"), ("offline", "r1"), ("add", "r1"), ("add", "r3")]  # r1: no removal queued
    assert kinds(queued(Action("online", "r2"))) == [("online", "r2")]  # its offline was applied already


def test_the_membership_and_the_queue_agree_on_a_host_back_after_its_lease() -> None:
    """The view's own sequence: down, the lease runs out, up again, all before the mission loop applies any."""
    m = Membership(3.0, {"controller", "r2"})
    got = queued(*m.down("r2", 0.0), *m.due(3.0), *m.up("r2", 5.0))
    assert kinds(got) == [("offline", "r2"), ("online", "r2")] and "r2" in m.present


def test_a_call_that_did_not_answer_takes_a_host_offline_until_its_next_report() -> None:
    """A frozen host stops answering a lease before the view judges it down: the call's timeout takes its resources
    offline (the holder the call fails must not hand its robot to a waiter), its next report brings them back."""
    m = Membership(3.0, {"controller", "r2"})
    assert kinds(m.silent("r2")) == [("offline", "r2")]
    assert m.silent("r2") == [] and m.silent("r9") == []  # once; a host not in the manager has nothing to take
    assert kinds(m.heard("r2")) == [("online", "r2")] and m.heard("r2") == []


def test_a_suspected_host_that_goes_down_stays_offline_until_it_is_up_again() -> None:
    m = Membership(3.0, {"controller", "r2"})
    got = queued(*m.silent("r2"), *m.down("r2", 1.0), *m.heard("r2"))  # a report in flight: not the host back
    assert kinds(got) == [("offline", "r2"), ("offline", "r2")]
    assert m.silent("r2") == []  # down already: nothing more to suspect
    assert kinds(m.up("r2", 2.0)) == [("online", "r2")] and m.heard("r2") == []
