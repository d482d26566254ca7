"""Replies in pages (issue #16): the Component Database, the trader's offers and the controller's manager of a cluster
running thousands of instances or robots come under the bus's message limit, and the client assembles the pages
(from the daemon that answered first). In-process on the local bus; each reply's size taken by the codec."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from drd.bus import LocalNetwork, Message, Query
from drd.bus.messages import MAX_SIZE, MalformedMessage, encode
from drd.cluster.instances import InstanceInfo
from drd.cluster.keys import ClusterKeys
from drd.daemon.client import ClusterClient
from drd.daemon.controller import resources_page
from drd.daemon.daemon import components_page
from drd.daemon.messages import (
    ComponentsReply,
    ResourcesReply,
    ResourcesRequest,
    RobotInfo,
    UnitInfo,
    ViewRequest,
    WaiterInfo,
)


def crowded(instances: int) -> ComponentsReply:
    """A daemon's view of a cluster running `instances` component instances on 50 hosts, and 150 services."""
    running = [InstanceInfo(f"Building/Wing{n % 50}/Room[{n}]/Watch", "Watch", f"host{n % 50:02d}", "running",
                            f"drd/lab/host/host{n % 50:02d}/instances/Building/Wing{n % 50}/Room[{n}]/Watch",
                            10_000 + n, "Building-1") for n in range(instances)]
    services = [InstanceInfo(f"{kind}@host{n:02d}", kind, f"host{n:02d}", "running", f"drd/lab/host/host{n:02d}/{kind}")
                for n in range(50) for kind in ("creator", "status", "db")]
    types = {"Watch": [f"host{n:02d}" for n in range(50)], "Wait": ["host00"]}
    return ComponentsReply("lab", "host07", types, running, services)


def serve(net: LocalNetwork, host: str, key: str, page: Callable[[Message], Message]) -> list[int]:
    """`host` answering `key` with `page(request)`, declared up as a daemon is; the sizes of the replies sent."""
    sizes: list[int] = []

    def answer(query: Query) -> Message:
        assert query.payload is not None
        reply = page(query.payload)
        sizes.append(len(encode(reply)))
        return reply

    session = net.session(host)
    session.serve(key, answer)
    session.declare_token(ClusterKeys("lab").host(host))
    return sizes


def components_of(whole: ComponentsReply) -> Callable[[Message], Message]:
    def page(asked: Message) -> Message:
        assert isinstance(asked, ViewRequest)
        return components_page(whole, asked.after, asked.count)
    return page


def test_six_thousand_instances_come_in_pages_under_the_limit_and_assemble_whole() -> None:
    whole = crowded(6000)
    with pytest.raises(MalformedMessage, match="too large"):  # one reply could not carry it
        encode(whole)
    net = LocalNetwork()
    sizes = serve(net, "host07", ClusterKeys("lab").db("host07", "components"), components_of(whole))
    got = ClusterClient(net.session("missionctl"), "lab", timeout=30).components()
    assert len(sizes) >= 3 and max(sizes) <= MAX_SIZE
    assert got.instances == whole.instances and got.services == whole.services and got.types == whole.types


def test_a_page_holds_instances_then_services_with_one_cursor() -> None:
    whole = crowded(30)
    seen: list[str] = []
    after = 0
    while True:
        page = components_page(whole, after, count=25)
        assert len(page.instances) + len(page.services) <= 25 and page.types == whole.types
        seen += [f"i:{i.name}" for i in page.instances] + [f"s:{s.name}" for s in page.services]
        if not page.next:
            break
        after = page.next
    assert seen == [f"i:{i.name}" for i in whole.instances] + [f"s:{s.name}" for s in whole.services]


# --- the controller's manager ---------------------------------------------------------------------


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


def resources_of(wholes: Callable[[], ResourcesReply]) -> Callable[[Message], Message]:
    def page(asked: Message) -> Message:
        assert isinstance(asked, ResourcesRequest)
        return resources_page(wholes(), asked.after, asked.count)
    return page


def test_1200_robots_come_in_pages_under_the_limit_and_assemble_whole() -> None:
    whole = building(1200)
    with pytest.raises(MalformedMessage, match="too large"):  # one reply could not carry it
        encode(whole)
    net = LocalNetwork()
    sizes = serve(net, "controller", ClusterKeys("lab").resources, resources_of(lambda: whole))
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
    serve(net, "controller", ClusterKeys("lab").resources, resources_of(wholes))
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
