"""Movable components on a real cluster: placed by the Load Balancer's policy, placed again when their host dies.

A `Wait` holds no device, so the controller's placer puts it on a `worker` host (ranger1 or spare, whichever
scores best). Killing that host with SIGKILL mid-mission must not fail the mission: the instance is started
again on the other worker and the mission succeeds. Real `drd start` processes on loopback, killed by pid.
"""

from __future__ import annotations

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
            "placement: {cpu: 1.0, memory: 0.5, instances: 0.2}", "placement: {cpu: 0, memory: 0, instances: 1}")) as c:
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
