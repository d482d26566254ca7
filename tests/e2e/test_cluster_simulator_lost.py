"""The simulator's host killed while a mission of movable components only runs there (own-world audit D4), on real
daemons on loopback: `ranger1` is the corridor's robots' and simulator's host, `zworker` another worker, placement
by instances alone (ties go to the smaller name), so the mission's `Wait` lands on ranger1. kill -9 of ranger1
ended the mission two ways by a race: `stopped` ("the simulator on ranger1 stopped answering") when the world's
step found it first, or a failure blaming the healthy zworker ("no host can run Wait ... zworker: excluded (its
start there failed: the simulator did not step ...)") when placing the Wait again came first. The world is gone
either way: the mission fails, and its reason says the simulator's host is gone, never that another refused."""

from __future__ import annotations

import json
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest
from cluster_support import DaemonCluster, corridor_hosts, eventually, serving_cluster

NAMES = ["controller", "ranger1", "zworker"]


def hosts(c: DaemonCluster) -> str:
    text = corridor_hosts(c).replace("  placement: {cpu: 1.0, memory: 0.5, instances: 0.2}",
                                     "  placement: {cpu: 0, memory: 0, instances: 1, affinity: 0}", 1)
    port = dict(zip(c.names, c.ports, strict=True))["zworker"]
    return text.rstrip() + f"\n  zworker:\n    endpoint: tcp/127.0.0.1:{port}\n    roles: [worker]\n"


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path, NAMES, hosts) as c:
        yield c


def mission_of(c: DaemonCluster, mid: str) -> dict[str, object]:
    r = c.missionctl("status", "--config", str(c.hosts_file), "--json", timeout=30)
    found = [m for m in json.loads(r.stdout)["missions"] if m["id"] == mid] if r.returncode == 0 else []
    return found[0] if found else {}


def test_losing_the_simulators_host_fails_the_mission_naming_it(cluster: DaemonCluster, tmp_path: Path) -> None:
    (tmp_path / "nap.mission").write_text("mission LongNap {\n    Wait(duration: 300s) as Idle\n}\n")
    r = cluster.missionctl("run", str(tmp_path / "nap.mission"), "--config", str(cluster.hosts_file), "--detach",
                           timeout=60)
    assert r.returncode == 0, r.stderr[-2000:]
    mid = r.stdout.strip()
    eventually(lambda: "placement: Wait on ranger1" in cluster.log("controller") and mission_of(cluster, mid),
               "the Wait to start on ranger1", 30, explain=lambda: cluster.tails("controller"))
    cluster.procs["ranger1"].send_signal(signal.SIGKILL)
    cluster.procs["ranger1"].wait(timeout=10)
    eventually(lambda: mission_of(cluster, mid).get("outcome") is not None, "the mission to end", 60,
               explain=lambda: cluster.tails("controller"))
    m = mission_of(cluster, mid)
    reason = str(m.get("reason"))
    assert m["outcome"] == "failure", (m, cluster.tails("controller"))
    assert "simulator" in reason and "ranger1" in reason, reason
    assert "no host can run" not in reason and "zworker" not in reason, reason
