"""A controller SIGSTOPped for twice the lease, then SIGCONTed (bus audit defect 5): real `drd start` processes on
loopback. Its workers rightly take it for lost meanwhile; on waking it says that it was the one frozen, and blames
no healthy host for its own silence."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator

import pytest

from tests.cluster_support import LEASE, DaemonCluster, corridor_hosts, eventually, serving_cluster

pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed")

NAMES = ["controller", "ranger1"]
FREEZE = 2 * LEASE


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path_factory.mktemp("freeze"), NAMES, corridor_hosts) as c:  # ranger1 simulates
        yield c


def test_a_controller_frozen_longer_than_the_lease_blames_nobody_but_itself(cluster: DaemonCluster) -> None:
    client = cluster.client()
    pid = cluster.pid("controller")
    stopped_at = time.time()
    os.kill(pid, signal.SIGSTOP)
    try:
        time.sleep(FREEZE)
    finally:
        os.kill(pid, signal.SIGCONT)

    def frozen() -> bool:
        return any(e.kind == "frozen" and e.host == "controller" for e in client.hosts(200).events)

    eventually(frozen, "the controller to say it was frozen", 10, explain=lambda: cluster.tails())
    time.sleep(2 * LEASE)  # past the grace it gave the others: their silence would count from now on
    reply = client.hosts(200)
    assert reply.answered_by == "controller"
    said = [e for e in reply.events if e.kind == "frozen"]
    assert len(said) == 1 and "longer than the lease" in said[0].detail, said  # once, not at every tick
    blamed = [e for e in reply.events if e.kind == "down" and e.at >= stopped_at]
    assert blamed == [], blamed  # ranger1 never stopped reporting: no "silent: no load report for 2.x s"
    assert {h.name: h.state for h in reply.hosts} == {"controller": "up", "ranger1": "up"}
    # ranger1, the one that kept running, rightly took the silent controller for lost meanwhile
    assert "controller controller lost (silent: no load report" in cluster.log("ranger1")
