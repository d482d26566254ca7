"""A controller SIGSTOPped for twice the lease, then SIGCONTed (bus audit defect 5): real `drd start` processes on
loopback. Its workers rightly take it for lost meanwhile; on waking it says that it was the one frozen, and blames
no healthy host for its own silence."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator

import pytest

from tests.cluster_support import (
    LEASE,
    MISSIONCTL,
    DaemonCluster,
    corridor_hosts,
    eventually,
    read_trace,
    running,
    serving_cluster,
)

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


def test_a_mission_of_a_controller_frozen_past_the_lease_fails_saying_so(cluster: DaemonCluster,
                                                                         tmp_path_factory: pytest.TempPathFactory
                                                                         ) -> None:
    """Its hosts stopped the robots and retired its instances while the controller was silent: on waking, the
    mission fails with the controller's freeze as its reason (docs/daemon.md), not with whatever lost grant the
    first cycle after the wake-up tripped on (`lost rover_a (expired)`: safety audit 7, D5)."""
    import json

    folder = tmp_path_factory.mktemp("frozen-mission")
    (folder / "hold.mission").write_text("mission HoldOn {\n    needs r: Ranger\n    Wait(duration: 120s)\n}\n")
    config = ["--config", str(cluster.hosts_file)]
    r = cluster.missionctl("run", str(folder / "hold.mission"), *config, "--detach", timeout=60)
    assert r.returncode == 0, r.stderr[-2000:]
    mid = r.stdout.strip()

    def mission() -> dict[str, object]:
        got = cluster.missionctl("status", *config, "--json", timeout=30)
        found = [m for m in json.loads(got.stdout)["missions"] if m["id"] == mid] if got.returncode == 0 else []
        return found[0] if found else {}

    eventually(lambda: mission().get("time", 0) > 1.0, "the mission to run", 30, explain=lambda: cluster.tails())
    # a waiter for the Ranger (faults audit 21, #4): the holder's failure must not hand it the Ranger before its own
    (folder / "wait.mission").write_text("mission WaitFor priority 2 {\n    needs r: Ranger\n"
                                         "    Observe(duration: 5s)\n}\n")
    trace = folder / "wait.jsonl"
    cmd = [*MISSIONCTL, "run", str(folder / "wait.mission"), *config, "--json", "--trace", str(trace)]
    with running(cmd) as waiter:
        eventually(lambda: trace.exists() and any(r["kind"] == "waiting" for r in read_trace(trace)),
                   "the waiter to wait", 30, explain=lambda: cluster.tails())
        pid = cluster.pid("controller")
        os.kill(pid, signal.SIGSTOP)
        try:
            time.sleep(FREEZE)
        finally:
            os.kill(pid, signal.SIGCONT)
        eventually(lambda: mission().get("outcome") is not None, "the mission to end", 30,
                   explain=lambda: cluster.tails())
        out, _ = waiter.communicate(timeout=60)
    ended = mission()
    assert ended["outcome"] == "failure", ended
    assert str(ended["reason"]).startswith("ControllerFrozen: this controller was frozen for"), ended
    assert json.loads(out)["reason"].startswith("ControllerFrozen: "), out[-1000:]
    assert [r["kind"] for r in read_trace(trace) if r["kind"] in ("granted", "entered")] == ["entered"], \
        "the waiter failed as it waited, granted nothing"  # its root entered at its start, nothing after
