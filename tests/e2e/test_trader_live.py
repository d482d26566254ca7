"""The trader's live properties on a real cluster (controller; ranger1 with its six Scouts and the simulator, as the
repository's hosts.yaml): while the corridor mission runs fast, ranger1's pose in a query changes as it drives, and a
Scout it launched no longer matches `Scout where carrier == "ranger1"` (on every daemon, from `missionctl query`
too); the run is stopped right after. Every process is ours and killed by pid (`tests/cluster_support.py`)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from cluster_support import DaemonCluster, corridor_hosts, corridor_run, eventually, serving_cluster

from drd.cluster.keys import ClusterKeys
from drd.daemon.messages import TraderReply, TraderRequest

NAMES = ["controller", "ranger1"]
SCOUTS = {f"scout{i}" for i in range(1, 7)}


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path_factory.mktemp("trader_live"), NAMES, corridor_hosts) as c:
        yield c


def offers(client: Any, cluster: DaemonCluster, text: str, host: str) -> list[dict[str, Any]]:
    """The trader of `host`'s daemon, asked directly."""
    reply = client.bus.call(ClusterKeys(cluster.name).db(host, "query"), TraderRequest(text), timeout=5.0)
    assert isinstance(reply, TraderReply), reply
    return reply.offers


def test_a_launched_scout_leaves_its_carrier_and_the_ranger_pose_moves(cluster: DaemonCluster,
                                                                       tmp_path: Path) -> None:
    client = cluster.client(timeout=5.0)
    before = client.query('Scout where carrier == "ranger1"').offers
    assert {o["id"] for o in before} == SCOUTS and all(o["live"] == {} for o in before)  # nothing runs: hosts.yaml
    with corridor_run(cluster, tmp_path / "trace.jsonl", speed=20.0):
        poses: list[tuple[float, float]] = []

        def moved() -> bool:
            [ranger] = client.query('Robot where id == "ranger1"').offers
            if {"x", "y", "heading"} <= set(ranger["live"]):
                poses.append((ranger["properties"]["x"], ranger["properties"]["y"]))
            return len(set(poses)) >= 2

        eventually(moved, "ranger1's live pose to change", 60, poll=0.3)
        [ranger] = client.query('Ranger where id == "ranger1"').offers
        assert 0 <= ranger["live"]["x"] <= 2.0  # seconds: the controller's report of this period, or the last one

        def launched() -> set[str]:
            return SCOUTS - {o["id"] for o in client.query('Scout where carrier == "ranger1"').offers}

        eventually(launched, "a Scout to be launched", 120, poll=0.5)
    gone = launched()  # the run is stopped; its launches stand until the next world starts
    assert gone
    for host in NAMES:  # every daemon's trader
        left = offers(client, cluster, 'Scout where carrier == "ranger1"', host)
        assert not gone & {o["id"] for o in left}
        out = {o["id"]: o for o in offers(client, cluster, "Robot", host)}
        assert {"ranger1"} | SCOUTS == set(out)  # a supertype's query: every robot
        for sid in gone:
            assert out[sid]["properties"]["carrier"] == "" and "carrier" in out[sid]["live"]
    r = cluster.missionctl("query", "Scout", "--json", "--config", str(cluster.hosts_file))
    assert r.returncode == 0, r.stderr
    shown = {o["id"]: o for o in json.loads(r.stdout)}
    assert all(shown[sid]["live"]["carrier"] >= 0 for sid in gone)  # the command line says which, and how old
