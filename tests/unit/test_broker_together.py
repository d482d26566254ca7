"""Missions entered at one instant ask for resources as one (`ResourceBroker.together`): the best rank is granted
first whatever the order they were entered in (a controller resuming its missions, a dry-run of several), and a
request withdrawn before the block ends is never asked (safety audit 7, D2)."""

from __future__ import annotations

from drd.rcm import Decision, Granted, NeedRequest, Request, ResourceManager, Unit
from drd.runtime.broker import ResourceBroker

DRIVE = NeedRequest("drive", "Drive")


def broker() -> tuple[ResourceBroker, list[Decision]]:
    rm = ResourceManager(lease=100.0, default_slice=60.0)
    rm.add_unit(Unit("drive1", "Drive"), 0.0)
    b = ResourceBroker(rm)
    heard: list[Decision] = []
    b.attach(heard.extend)
    return b, heard


def test_requests_of_one_block_are_granted_best_rank_first() -> None:
    b, heard = broker()
    with b.together():
        assert b.request(Request("Lesser/x", 1, (DRIVE,), "Lesser", mission_priority=2), 0.0) == ()
        b.request(Request("Better/x", 1, (DRIVE,), "Better", mission_priority=1), 0.0)
        assert heard == []  # nothing asked yet
    assert [d.holder for d in heard if isinstance(d, Granted)] == ["Better/x"]
    assert b.holders("drive1") == ("Better/x",)


def test_a_request_withdrawn_in_the_block_is_never_asked() -> None:
    b, heard = broker()
    with b.together():
        b.request(Request("Better/x/y", 1, (DRIVE,), "Better"), 0.0)
        b.cancel("Better/x", 0.0)  # its state was exited: a subtree's request goes with it
        b.request(Request("Lesser/x", 1, (DRIVE,), "Lesser", mission_priority=2), 0.0)
    assert [d.holder for d in heard if isinstance(d, Granted)] == ["Lesser/x"]


def test_without_a_block_the_first_request_is_granted_at_once() -> None:
    b, heard = broker()
    b.request(Request("Lesser/x", 1, (DRIVE,), "Lesser", mission_priority=2), 0.0)
    assert [d.holder for d in heard if isinstance(d, Granted)] == ["Lesser/x"]
