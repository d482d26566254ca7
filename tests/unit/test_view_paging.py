"""The Component Database and the trader's offers in pages (issue #16): a cluster running thousands of component
instances answers `missionctl components` (and `status`) under the bus's message limit, and the client assembles
the pages from the daemon that answered first. In-process on the local bus; each reply's size taken by the codec."""

from __future__ import annotations

import pytest

from drd.bus import LocalNetwork, Message, Query
from drd.bus.messages import MAX_SIZE, MalformedMessage, encode
from drd.cluster.instances import InstanceInfo
from drd.cluster.keys import ClusterKeys
from drd.daemon.client import ClusterClient
from drd.daemon.daemon import components_page
from drd.daemon.messages import ComponentsReply, ViewRequest


def crowded(instances: int) -> ComponentsReply:
    """A daemon's view of a cluster running `instances` component instances on 50 hosts, and 150 services."""
    running = [InstanceInfo(f"Building/Wing{n % 50}/Room[{n}]/Watch", "Watch", f"host{n % 50:02d}", "running",
                            f"drd/lab/host/host{n % 50:02d}/instances/Building/Wing{n % 50}/Room[{n}]/Watch",
                            10_000 + n, "Building-1") for n in range(instances)]
    services = [InstanceInfo(f"{kind}@host{n:02d}", kind, f"host{n:02d}", "running", f"drd/lab/host/host{n:02d}/{kind}")
                for n in range(50) for kind in ("creator", "status", "db")]
    types = {"Watch": [f"host{n:02d}" for n in range(50)], "Wait": ["host00"]}
    return ComponentsReply("lab", "host07", types, running, services)


def serve(net: LocalNetwork, whole: ComponentsReply) -> list[int]:
    """host07's components key answering pages of `whole`; the sizes of the replies it sent."""
    sizes: list[int] = []

    def answer(query: Query) -> Message:
        asked = query.payload
        assert isinstance(asked, ViewRequest)
        page = components_page(whole, asked.after, asked.count)
        sizes.append(len(encode(page)))
        return page

    session = net.session("host07")
    session.serve(ClusterKeys("lab").db("host07", "components"), answer)
    session.declare_token(ClusterKeys("lab").host("host07"))
    return sizes


def test_six_thousand_instances_come_in_pages_under_the_limit_and_assemble_whole() -> None:
    whole = crowded(6000)
    with pytest.raises(MalformedMessage, match="too large"):  # one reply could not carry it
        encode(whole)
    net = LocalNetwork()
    sizes = serve(net, whole)
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
