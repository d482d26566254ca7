"""A standby controller's host frozen past its lease while it holds a robot's drivers: real `drd start` processes on
loopback and a one-member etcd (started here) electing the controller. `controller` acts; `ranger1` has the
controller role too (a standby) and holds ranger1's drivers; `sim` runs the world. A freeze of a host with the
controller role used to be taken for its own controller's (whose grants froze with it), so the standby's gates
kept the Ranger's last setpoint on waking and the simulator drove it on with no holder. Asserted on the robot's
side: its pose in the running world stops changing once its host is back."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from cluster_support import DaemonCluster, corridor_hosts, eventually, running_cluster
from etcd_support import EtcdCluster, etcd_cluster, need_etcd
from test_cluster_frozen_robots_host import freeze_while_driving

pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed")

NAMES = ["controller", "ranger1", "sim"]


def standby_hosts(c: DaemonCluster, etcd: EtcdCluster) -> str:
    """The corridor's hosts with the etcd store, ranger1 a standby controller and the simulator on a host of its own."""
    text = corridor_hosts(c).replace("roles: [worker, simulator]", "roles: [worker, controller]")
    text = text.replace(f"  name: {c.name}", f"  name: {c.name}\n  store: {{etcd: [{', '.join(etcd.urls)}]}}", 1)
    port = dict(zip(c.names, c.ports, strict=True))["sim"]
    return text.rstrip() + f"\n  sim:\n    endpoint: tcp/127.0.0.1:{port}\n    roles: [worker, simulator]\n"


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    need_etcd()
    with etcd_cluster(tmp_path_factory.mktemp("etcd"), 1) as etcd, \
            running_cluster(tmp_path_factory.mktemp("frozen_standby"), NAMES) as c:
        c.hosts_file.write_text(standby_hosts(c, etcd))
        c.start("controller")  # first, so it is the one elected
        c.wait_ready(["controller"])
        eventually(lambda: "elected the acting controller" in c.log("controller"), "controller to be elected", 30)
        c.start("ranger1")
        c.start("sim")
        c.wait_ready()
        c.wait_up()
        eventually(lambda: "standby controller: controller acts" in c.log("ranger1"), "ranger1 standing by", 30)
        yield c


def test_a_standby_controllers_robot_stops_when_its_host_wakes_from_a_freeze(cluster: DaemonCluster,
                                                                            tmp_path: Path) -> None:
    freeze_while_driving(cluster, tmp_path, "Drive3")
    assert "every device stopped" in cluster.log("ranger1"), cluster.tails("ranger1")
