"""The corridor mission to its end on a real cluster laid out as the repository's hosts.yaml: the simulator on
ranger1, beside the devices it serves (plus a spare worker). Each cycle's simulation step then rides on the
cycle's first step batch to ranger1 (`ComponentRouter.step_first`) and the Creator reads the simulation in its
own process. The result is compared with the embedded dry-run of the same files. Every process is ours and
killed by pid (`tests/cluster_support.py`).
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Iterator

import pytest
from cluster_support import ROOT, DaemonCluster, serving_cluster
from test_cluster_run import MISSION, NAMES, corridor_hosts, missionctl

SPEED = "50"
UNTIL = "300"


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path_factory.mktemp("cluster_sim_host"), NAMES,
                         lambda c: corridor_hosts(c, simulator="ranger1")) as c:
        yield c


def test_the_corridor_mission_runs_on_the_cluster_as_in_the_dry_run(cluster: DaemonCluster) -> None:
    from drd.dryrun import run as dry_run
    from drd.hosts import load_hosts
    from drd.manifests import load_catalog
    from drd.sim.world import load_world
    from dsl import compile_file

    cat = load_catalog()
    expected = dry_run(compile_file(ROOT / MISSION, cat).statechart, load_hosts(ROOT / "hosts.yaml", cat),
                       load_world(ROOT / "worlds" / "corridor.yaml"), cat, until=float(UNTIL))
    t0 = time.monotonic()
    r = missionctl(cluster, "run", MISSION, "--speed", SPEED, "--until", UNTIL, "--json", timeout=150)
    wall = time.monotonic() - t0
    assert r.returncode == (0 if expected.outcome == "success" else 1), r.stdout[:300] + r.stderr[-3000:]
    report = json.loads(r.stdout)
    assert report["outcome"] == (expected.outcome or "stopped")
    # Same behaviors, same world: the open doors are found and Scouts launched (the order in which the
    # RoomSurveillance instances take turns on the Ranger may differ, so the counts are compared loosely).
    assert report["doors"] and report["doors"][0]["at"] < 30
    assert {round(d["x"]) for d in report["doors"]} <= {round(d["x"]) for d in expected.doors} | {None}
    if expected.scouts:
        assert report["scouts"], "Scouts launched"
    assert report["sim_time"] > 0 and wall < 100
    ended = [line for line in cluster.log("controller").splitlines() if " ended: " in line]
    found = re.search(r"(\d+) cycles .* sim steps not carried by a batch \{'calls': (\d+),", ended[-1] if ended else "")
    assert found, ended[-1:]
    cycles, alone = int(found[1]), int(found[2])
    # a cycle whose first call is a start (a timer's transition) steps the world alone; the others carry it
    assert cycles > 1000 and alone <= cycles // 10, f"{alone} of {cycles} steps went alone"


def test_the_robots_stop_when_the_controller_dies(cluster: DaemonCluster) -> None:
    """Issue #16: with the controller gone nobody may grant a device, so ranger1's host stops every actuator and
    retires the instances. Seen from the robot's side: the simulator (on ranger1) reports what the Ranger
    executes. Last in this module: it kills the controller."""
    import os
    import signal

    from cluster_support import eventually

    from drd.sim.service import SimReply, SimRequest
    from drd.sim.service import key as sim_key

    client = cluster.client(timeout=5.0)

    def executing() -> tuple[float, float]:
        reply = client.bus.call(sim_key(cluster.name), SimRequest("call", "command", ["ranger1"]), timeout=5.0)
        assert isinstance(reply, SimReply) and not reply.error, reply
        v, omega = reply.value
        return float(v), float(omega)

    r = missionctl(cluster, "run", MISSION, "--speed", "2", "--detach")
    assert r.returncode == 0, r.stderr[-2000:]
    eventually(lambda: executing()[0] > 0.1, "the Ranger driving down the corridor", timeout=30.0)
    os.kill(cluster.pid("controller"), signal.SIGKILL)
    eventually(lambda: executing() == (0.0, 0.0), "the Ranger stopped by its own host", timeout=10.0)
    eventually(lambda: "every device stopped, every instance retired" in cluster.log("ranger1"),
               "ranger1 saying why", timeout=10.0)
