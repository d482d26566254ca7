"""Replies in pages (issue #16): no reply of the executive outgrows the transport, and the client assembles them.

The executive runs in-process on the local bus (which encodes every message as zenoh's does); the client is the one
`missionctl` uses. Each reply's size is measured from the outside, by the codec's encoded length.
"""

from __future__ import annotations

from typing import Any

import pytest

from drd.bus import LocalNetwork, Message
from drd.bus.messages import MAX_SIZE, encode
from drd.daemon.client import ClusterClient
from drd.executive import KEPT_RECORDS, EntryPoints, Executive
from drd.executive_messages import MissionCommand, MissionRecords, MissionStatus
from drd.manifests import load_catalog
from drd.paging import PAGE_BYTES, fill, page_count
from drd.runtime import records as rec
from drd.runtime.clock import SimClock
from dsl import compile_text


class Measured(ClusterClient):
    """The client, with every reply it got and that reply's size on the wire."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.replies: list[tuple[Message, int]] = []
        call = self.bus.call

        def measured(key: str, payload: Message | None = None, timeout: float = 2.0) -> Message:
            reply = call(key, payload, timeout)
            self.replies.append((reply, len(encode(reply))))
            return reply

        self.bus.call = measured  # type: ignore[method-assign]


@pytest.fixture(scope="module")
def crowded() -> tuple[LocalNetwork, Executive]:
    """An executive with a full history (1,000 finished missions) and 80 running ones with 200 instances each
    (their active trees are what makes the status big), and one mission with its records kept in full."""
    cat = load_catalog()
    net = LocalNetwork()
    clock = SimClock()
    ex = Executive(net.session("controller"), clock, EntryPoints(cat), history=1000)
    quick = compile_text("mission Quick {\n    Wait(duration: 1s)\n}\n", cat, "q.mission").statechart
    wide = compile_text("mission Wide {\n    Wait(duration: 1h)[200]\n}\n", cat, "w.mission").statechart
    assert quick is not None and wide is not None
    for n in range(1, 1101):  # 100 more than the history keeps: the oldest go
        ex.submit(quick, f"Quick-{n}")
    for n in range(1, 81):
        ex.submit(wide, f"Wide-{n}")
    for _ in range(15):
        clock.advance(0.1)
        ex.step()
    talker = ex.missions["Wide-1"]
    for i in range(KEPT_RECORDS):  # a chatty mission: its kept records are over a megabyte
        talker.record(rec.Log(clock.now(), "Wide/Wait[1]", f"line {i} " + "x" * 700))
    return net, ex


def test_a_full_history_and_wide_missions_come_in_pages_each_within_the_transport(
        crowded: tuple[LocalNetwork, Executive]) -> None:
    net, ex = crowded
    finished = [m for m, interp in ex.missions.items() if interp.finished]
    assert len(finished) == 1000 and "Quick-100" not in ex.missions and "Quick-101" in ex.missions
    client = Measured(net.session("missionctl"), "local", timeout=30)
    missions = client.missions()
    assert [m["id"] for m in missions] == list(ex.missions)  # every one, once, in the order they started
    sizes = [size for _reply, size in client.replies]
    assert len(sizes) > 5 and max(sizes) <= MAX_SIZE, sizes
    assert sum(sizes) > MAX_SIZE  # one reply of it all would not have gone through
    widest = max(len(reply.missions) for reply, _ in client.replies if isinstance(reply, MissionStatus))
    assert widest <= page_count(0)
    print(f"\n{len(missions)} missions in {len(sizes)} pages, {sum(sizes)} bytes, the largest {max(sizes)}")


def test_small_pages_and_one_mission(crowded: tuple[LocalNetwork, Executive]) -> None:
    net, ex = crowded
    client = Measured(net.session("missionctl"), "local", timeout=30)
    assert [m["id"] for m in client.missions(count=7)] == list(ex.missions)
    assert all(len(r.missions) <= 7 for r, _ in client.replies if isinstance(r, MissionStatus))
    client.replies.clear()
    [one] = client.missions("Wide-7")
    assert one["id"] == "Wide-7" and one["outcome"] is None and len(one["tree"]["children"][0]["children"]) == 200
    assert len(client.replies) == 1
    assert client.missions("Quick-3") == []  # dropped from the history: none, not an error


def test_a_mission_with_many_records_is_caught_up_in_pages(crowded: tuple[LocalNetwork, Executive]) -> None:
    net, ex = crowded
    kept = list(ex.kept["Wide-1"])
    assert len(kept) == KEPT_RECORDS and sum(len(encode(r)) for r in kept) > MAX_SIZE
    client = Measured(net.session("missionctl"), "local", timeout=30)
    got = client.records("Wide-1")
    assert [r.seq for r in got] == [r.seq for r in kept]  # every record, once, in order
    sizes = [size for _reply, size in client.replies]
    assert len(sizes) >= 3 and max(sizes) <= MAX_SIZE, sizes
    middle = kept[len(kept) // 2].seq
    client.replies.clear()
    assert [r.seq for r in client.records("Wide-1", middle, count=50)] == [r.seq for r in kept if r.seq > middle]
    assert all(len(r.records) <= 50 for r, _ in client.replies if isinstance(r, MissionRecords))


def test_a_stop_answers_with_the_stopped_mission_only(crowded: tuple[LocalNetwork, Executive]) -> None:
    net, _ex = crowded
    bus = net.session("operator")
    reply = bus.call("drd/local/executive", MissionCommand("stop", "Wide-80"))
    assert isinstance(reply, MissionStatus) and [m["id"] for m in reply.missions] == ["Wide-80"]
    assert reply.missions[0]["outcome"] == "stopped" and len(encode(reply)) <= MAX_SIZE


def test_fill_takes_what_fits_and_says_where_to_go_on() -> None:
    items = [(n, "x" * 10) for n in range(1, 11)]
    assert fill(items, len, 3) == (["x" * 10] * 3, 3)
    assert fill(items, len, 0, budget=35) == (["x" * 10] * 3, 3)  # 11 bytes each, with its comma
    assert fill(items[8:], len, 5) == (["x" * 10] * 2, 0)  # the last page
    assert fill([(1, "y" * 100)], len, 5, budget=10) == (["y" * 100], 0)  # alone over the budget: alone
    assert fill([], len, 5) == ([], 0)
    assert page_count(0) > 0 and page_count(10**9) <= 1000 and PAGE_BYTES < MAX_SIZE


def test_a_busy_controller_answers_a_page_it_gave_before_and_refuses_one_it_did_not() -> None:
    """While the mission loop holds the executive's lock, a read gets the last answer to the same query (the kept
    first page for a plain status), never another page's: a client following `next` would loop or skip."""
    import threading

    from drd.bus import RemoteError
    from drd.daemon.controller import SerializedBus

    net = LocalNetwork()
    lock = threading.RLock()
    served = SerializedBus(net.session("controller"), lock)
    served.busy_wait = 0.05

    def answer(query: Any) -> Message:
        cmd = query.payload
        return MissionStatus(0.0, [{"id": f"{cmd.mission or 'all'}@{cmd.after}"}], 0)

    served.serve("drd/local/executive/status", answer)
    served.keep("drd/local/executive/status", lambda: MissionStatus(0.0, [{"id": "kept"}], 0))
    client = net.session("missionctl")

    def ask(mission: str = "", after: int = 0) -> list[Any]:
        reply = client.call("drd/local/executive/status", MissionCommand("status", mission, after=after))
        assert isinstance(reply, MissionStatus)
        return [m["id"] for m in reply.missions]

    assert ask("M-1") == ["M-1@0"]
    with lock:
        served.refresh()
    held = threading.Event()
    release = threading.Event()

    def loop() -> None:
        with lock:
            held.set()
            release.wait(10)

    threading.Thread(target=loop, daemon=True).start()
    held.wait(5)
    try:
        assert ask() == ["kept"]
        assert ask("M-1") == ["M-1@0"]
        with pytest.raises(RemoteError, match="busy"):
            ask(after=5)
    finally:
        release.set()
    assert ask(after=5) == ["all@5"]
