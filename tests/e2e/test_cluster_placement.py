"""Movable components on a real cluster: placed by the Load Balancer's policy, placed again when their host dies.

A `Wait` holds no device, so the controller's placer puts it on a `worker` host (ranger1 or spare, whichever
scores best). Killing that host with SIGKILL mid-mission must not fail the mission: the instance is started
again on the other worker and the mission succeeds. Real `drd start` processes on loopback, killed by pid.
"""

from __future__ import annotations

import json
import re
import signal
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from cluster_support import MISSIONCTL, DaemonCluster, eventually, running, serving_cluster, succeeded
from test_cluster_run import NAMES, corridor_hosts

PLACED = re.compile(r"placement: Wait on (\w+)")
STARTED = re.compile(r"mission Pause-\d+ started")


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    # corridor_hosts keeps the simulator on the controller: we kill a worker, not the world
    # placement by instances alone: on one machine every host reports the same, noisy, CPU load
    with serving_cluster(tmp_path_factory.mktemp("cluster_placement"), NAMES, lambda c: corridor_hosts(c).replace(
            "placement: {cpu: 1.0, memory: 0.5, instances: 0.2}",
            "placement: {cpu: 0, memory: 0, instances: 1, affinity: 10}")) as c:
        yield c


def placements(c: DaemonCluster) -> list[str]:
    return PLACED.findall(c.log("controller"))


def test_movable_components_started_in_one_cycle_spread_over_the_workers(cluster: DaemonCluster,
                                                                         tmp_path: Path) -> None:
    """Issue #15: the hosts' reports lag a cycle's placements, so two started together went to one host."""
    mission = tmp_path / "pair.mission"
    mission.write_text("mission Pair {\n    parallel all {\n        Wait(duration: 2s) as a\n"
                       "        Wait(duration: 2s) as b\n    }\n}\n")
    before = len(placements(cluster))
    r = cluster.missionctl("run", str(mission), "--config", str(cluster.hosts_file), "--speed", "8", "--json",
                           timeout=90)
    assert r.returncode == 0, r.stderr[-2000:]
    assert sorted(placements(cluster)[before:]) == ["ranger1", "spare"]


NEAR = """mission Near {
    Escort
}

behavior Escort {
    needs ranger: Ranger
    Wait(duration: 40s)
}
"""


def test_a_movable_component_goes_near_its_robot_and_status_says_why(cluster: DaemonCluster, tmp_path: Path) -> None:
    """Issue #15: device affinity, and each decision explained in `missionctl status` (text and --json). The Wait
    serves a state holding ranger1's Ranger: it goes to ranger1 (affinity 10: 1,000 points) whatever the
    instances, the controller is filtered (no worker role), and status says so while the mission runs."""
    mission = tmp_path / "near.mission"
    mission.write_text(NEAR)
    before = len(placements(cluster))
    cmd = [*MISSIONCTL, "run", str(mission), "--config", str(cluster.hosts_file), "--speed", "8", "--json"]
    with running(cmd) as proc:
        def placed() -> bool:
            assert proc.poll() is None, proc.communicate()
            return len(placements(cluster)) > before

        eventually(placed, "the Wait to be placed", 30, poll=0.05)
        assert placements(cluster)[before:] == ["ranger1"], cluster.log("controller")[-3000:]
        text = cluster.missionctl("status", "--config", str(cluster.hosts_file), timeout=30)
        assert text.returncode == 0, text.stderr[-2000:]
        shown = " ".join(text.stdout.split())  # the line wraps at the terminal's width
        assert "placement Escort/Wait -> ranger1 (score " in shown and "affinity -1e+03 vs 0" in shown, text.stdout
        assert "filtered controller: no worker role)" in shown, text.stdout
        r = cluster.missionctl("status", "--config", str(cluster.hosts_file), "--json", timeout=30)
        assert r.returncode == 0, r.stderr[-2000:]
        near = next(m for m in json.loads(r.stdout)["missions"] if str(m["id"]).startswith("Near-"))
        [entry] = near["placements"]
        assert (entry["instance"], entry["host"], entry["how"]) == ("Near/Escort/Wait", "ranger1", "placed")
        record = entry["decision"]
        assert record["filtered"] == {"controller": ["no worker role"]}
        scored = {s["host"]: {p["plugin"]: p["points"] for p in s["parts"]} for s in record["scored"]}
        assert scored["ranger1"]["affinity"] == -1000.0 and scored["spare"]["affinity"] == 0.0
        out, err = proc.communicate(timeout=60)
    succeeded(cluster, proc, out, err)


def test_a_movable_component_goes_to_a_worker_and_moves_when_its_host_is_killed(cluster: DaemonCluster,
                                                                               tmp_path: Path) -> None:
    mission = tmp_path / "pause.mission"
    mission.write_text("mission Pause {\n    Wait(duration: 40s)\n}\n")
    cmd = [*MISSIONCTL, "run", str(mission), "--config", str(cluster.hosts_file), "--speed", "8", "--json"]
    with running(cmd) as proc:
        def started() -> bool:
            assert proc.poll() is None, proc.communicate()
            return STARTED.search(cluster.log("controller")) is not None

        eventually(started, "the mission to start", 30, poll=0.05)
        time.sleep(0.5)  # a few cycles of steps on the first host
        first = placements(cluster)[0]
        assert first in ("ranger1", "spare"), "a worker takes it, never the controller"
        cluster.procs[first].send_signal(signal.SIGKILL)
        out, err = proc.communicate(timeout=60)
    succeeded(cluster, proc, out, err)
    moved = placements(cluster)
    other = ({"ranger1", "spare"} - {first}).pop()
    assert moved[-1] == other, moved
    log = cluster.log("controller")
    assert f"re-placed on {other}" in log, log[-3000:]
