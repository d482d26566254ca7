"""The manager's view in pages (issue #16): `missionctl resources` of a building of robots stays under the bus's
message limit, the client assembles every page into the whole, and a host coming or going between two pages makes
it start again rather than assemble two layouts. In-process on the local bus (which encodes every message as
zenoh's does); each reply's size is taken from the outside by the codec."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from drd.bus import LocalNetwork, Message, Query
from drd.bus.messages import MAX_SIZE, MalformedMessage, encode
from drd.cluster.keys import ClusterKeys
from drd.daemon.client import ClusterClient
from drd.daemon.controller import resources_page
from drd.daemon.messages import ResourcesReply, ResourcesRequest, RobotInfo, UnitInfo, WaiterInfo


def building(robots: int) -> ResourcesReply:
    """A manager's whole view: each robot a drive, a range sensor, a camera and a radio, some held and waited for."""
    units, aggregates = [], []
    for n in range(robots):
        rid = f"scout{n:04d}"
        parts = {p: f"{rid}.{p}" for p in ("drive", "ranges", "camera", "radio")}
        units += [UnitInfo(uid, part.title(), f"host{n // 20}", False, 1.0, 0.0, n % 7, [f"Wing{n % 50}/Watch-{n}"],
                           [], {"beams": 360, "max_range": 8.0}) for part, uid in parts.items()]
        aggregates.append(RobotInfo(rid, "Scout", f"host{n // 20}", parts, [f"Wing{n % 50}/Watch-{n}"]))
    queue = [WaiterInfo(f"Wing{n}/Launch-{n}", 5, f"Wing{n}", {"scout": "Scout"}) for n in range(300)]
    return ResourcesReply("lab", "controller", sorted(units, key=lambda u: u.id), aggregates, queue, {}, {})


def serve(net: LocalNetwork, wholes: Callable[[], ResourcesReply]) -> list[int]:
    """The controller's resources key, answering pages of `wholes()`; returns the sizes of the replies sent."""
    sizes: list[int] = []

    def answer(query: Query) -> Message:
        asked = query.payload
        assert isinstance(asked, ResourcesRequest)
        page = resources_page(wholes(), asked.after, asked.count)
        sizes.append(len(encode(page)))
        return page

    net.session("controller").serve(ClusterKeys("lab").resources, answer)
    return sizes


def test_1200_robots_come_in_pages_under_the_limit_and_assemble_whole() -> None:
    whole = building(1200)
    with pytest.raises(MalformedMessage, match="too large"):  # one reply could not carry it
        encode(whole)
    net = LocalNetwork()
    sizes = serve(net, lambda: whole)
    got = ClusterClient(net.session("missionctl"), "lab", timeout=30).resources()
    assert len(sizes) >= 3 and max(sizes) <= MAX_SIZE
    assert (got.units, got.robots, got.queue) == (whole.units, whole.robots, whole.queue) and got.next == 0


def test_a_host_coming_between_two_pages_makes_the_client_start_again() -> None:
    before, after = building(1000), building(1001)
    calls = [0]

    def wholes() -> ResourcesReply:
        calls[0] += 1
        return before if calls[0] <= 2 else after  # the layout changes after the second page

    net = LocalNetwork()
    serve(net, wholes)
    got = ClusterClient(net.session("missionctl"), "lab", timeout=30).resources()
    assert [r.id for r in got.robots] == [r.id for r in after.robots]  # the new layout, whole: nothing mixed
    assert len(got.units) == len(after.units)


def test_pages_cover_every_item_once_with_cursors_that_move_on() -> None:
    whole = building(300)
    seen: list[str] = []
    after = 0
    while True:
        page = resources_page(whole, after, count=100)
        assert len(page.units) + len(page.robots) + len(page.queue) <= 100
        seen += [u.id for u in page.units] + [r.id for r in page.robots] + [w.holder for w in page.queue]
        if not page.next:
            break
        assert page.next > after
        after = page.next
    assert seen == [u.id for u in whole.units] + [r.id for r in whole.robots] + [w.holder for w in whole.queue]
