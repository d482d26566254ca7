"""A worker host that comes back after its lease ran out, and the workers after the controller's loss (recovery
audit D1, D2): real `drd start` processes on loopback, placement by instance count alone (a Wait goes to `alpha`,
the smaller name, then to `beta`).

- Frozen past its lease, `alpha` stayed "down" for the running mission's whole life after it reported again: its
  Wait, placed again on `beta`, could not be moved back (`host alpha is down`), and at the mission's end its old
  instance and worker process were never retired (listed `running` until the controller restarted). Now the
  mission takes it for a host again, and what it missed is retired.
- After the controller's loss the workers retired every instance but kept announcing them `running`.
"""

from __future__ import annotations

import json
import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.cluster_support import LEASE, DaemonCluster, corridor_hosts, eventually, serving_cluster

NAMES = ["controller", "ranger1", "alpha", "beta"]
MISSION = "mission Nap {\n    Wait(duration: 120s) as Hold\n}\n"


def hosts(c: DaemonCluster) -> str:
    text = corridor_hosts(c).replace("placement: {cpu: 1.0, memory: 0.5, instances: 0.2}",
                                     "placement: {cpu: 0, memory: 0, instances: 1}")
    ports = dict(zip(c.names, c.ports, strict=True))
    return text.rstrip() + "".join(f"\n  {h}:\n    endpoint: tcp/127.0.0.1:{ports[h]}\n    roles: [worker]"
                                   for h in ("alpha", "beta")) + "\n"


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path_factory.mktemp("host_return"), NAMES, hosts) as c:
        yield c


def ctl(c: DaemonCluster, *args: str) -> Any:
    r = c.missionctl(*args, "--config", str(c.hosts_file), "--json", timeout=60)
    assert r.returncode == 0, (args, r.stderr[-2000:], c.tails("controller"))
    return json.loads(r.stdout)


def instances(c: DaemonCluster, mid: str = "") -> list[tuple[str, str]]:
    return [(i["host"], i["name"]) for i in ctl(c, "components")["instances"] if not mid or i["mission"] == mid]


def frozen_past_the_lease(c: DaemonCluster, host: str) -> None:
    os.kill(c.pid(host), signal.SIGSTOP)
    try:
        time.sleep(1.6 * LEASE)
    finally:
        os.kill(c.pid(host), signal.SIGCONT)


def nap(c: DaemonCluster, tmp_path: Path) -> str:
    (tmp_path / "nap.mission").write_text(MISSION)
    mid = str(ctl(c, "run", str(tmp_path / "nap.mission"), "--detach")["id"])
    eventually(lambda: instances(c, mid) == [("alpha", "Nap/Hold")], "the Wait on alpha", 30,
               explain=lambda: c.tails("controller"))
    return mid


def test_a_host_back_after_its_lease_is_retired_at_the_end_and_can_take_a_move(cluster: DaemonCluster,
                                                                                tmp_path: Path) -> None:
    mid = nap(cluster, tmp_path)
    frozen_past_the_lease(cluster, "alpha")
    eventually(lambda: "beta" in {h for h, _ in instances(cluster, mid)}, "the Wait to go to beta", 30,
               explain=lambda: cluster.tails("controller"))
    eventually(lambda: {h["name"]: h["state"] for h in ctl(cluster, "hosts")["hosts"]}["alpha"] == "up",
               "alpha to report again", 30)
    moved = cluster.missionctl("migrate", f"{mid}/Nap/Hold", "--to", "alpha", "--config", str(cluster.hosts_file),
                               "--json", timeout=60)
    assert moved.returncode == 0 and json.loads(moved.stdout)["host"] == "alpha", (moved.stderr[-1500:],
                                                                                   cluster.tails("controller"))
    ctl(cluster, "stop", mid)
    eventually(lambda: instances(cluster, mid) == [], "every instance of the mission retired", 30,
               explain=lambda: cluster.tails("controller", "alpha"))


def test_an_instance_left_on_a_frozen_host_is_retired_when_it_is_back(cluster: DaemonCluster, tmp_path: Path) -> None:
    mid = nap(cluster, tmp_path)
    frozen_past_the_lease(cluster, "alpha")
    eventually(lambda: "beta" in {h for h, _ in instances(cluster, mid)}, "the Wait to go to beta", 30)
    ctl(cluster, "stop", mid)
    eventually(lambda: instances(cluster, mid) == [], "alpha's old instance retired too", 30,
               explain=lambda: cluster.tails("controller", "alpha"))


def test_after_the_controllers_loss_the_workers_announce_no_instance(cluster: DaemonCluster, tmp_path: Path) -> None:
    """Last in this module: the controller is killed."""
    nap(cluster, tmp_path)
    cluster.procs["controller"].send_signal(signal.SIGKILL)
    eventually(lambda: "every instance retired" in cluster.log("alpha"), "alpha to retire its instances", 30)
    eventually(lambda: instances(cluster) == [], "no instance announced running", 20,
               explain=lambda: cluster.tails("alpha"))
