"""A cluster through a zenoh router (issue #15): the controller's daemon runs a router in-process, the Ranger hosts
are its clients, so the fleet is a star, not a full mesh.

Real daemons on loopback (the two-Ranger team: controller + router, ranger1 with the simulator, ranger2), every
process ours and killed by pid. Checked from outside: a mission that needs ranger2's camera runs (the controller
reaches ranger2's Creator, and ranger2's drivers reach the simulator on ranger1, both through the router), and the
operating system's own sockets show each Ranger daemon connected to the router only, listening nowhere.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil
import pytest
from cluster_support import ROOT, DaemonCluster, running_cluster

NAMES = ["controller", "ranger1", "ranger2"]
MISSION = """\
mission Look {
    needs cam: Camera where cam.id == "ranger2.camera"
    Observe(duration: 2s)
}
"""


def hosts(cluster: DaemonCluster) -> str:
    text = (ROOT / "hosts.two_rangers.yaml").read_text()
    text = text.replace("name: corridor_two_rangers", f"name: {cluster.name}").replace("lease: 3s", "lease: 1000ms")
    text = text.replace("roles: [controller]", "roles: [controller, router]")
    for port, default in zip(cluster.ports, (7447, 7448, 7449), strict=True):
        text = text.replace(f"127.0.0.1:{default}", f"127.0.0.1:{port}")
    return text


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    """The Rangers' daemons first: a client of the routers waits for one (zenoh opens a client only connected)."""
    with running_cluster(tmp_path_factory.mktemp("routers"), NAMES) as c:
        c.hosts_file.write_text(hosts(c))
        for name in reversed(NAMES):
            c.start(name)
        c.wait_ready()
        c.wait_up()
        yield c


def tcp(pid: int) -> list[Any]:
    """The process's TCP sockets, as the operating system sees them."""
    return list(psutil.Process(pid).net_connections(kind="tcp"))


def test_the_rangers_talk_through_the_router_only_and_a_mission_runs(cluster: DaemonCluster, tmp_path: Path) -> None:
    (tmp_path / "look.mission").write_text(MISSION)
    r = cluster.missionctl("run", str(tmp_path / "look.mission"), "--config", str(cluster.hosts_file), "--json",
                           "--speed", "5", timeout=120)
    assert r.returncode == 0, (r.stderr[-2000:], cluster.log("controller")[-3000:])
    report = json.loads(r.stdout)
    assert report["outcome"] == "success"
    assert any(h["resources"].get("cam") == "ranger2.camera" for h in report["holds"]), report["holds"]
    router_port = cluster.ports[0]
    for name, port in zip(NAMES[1:], cluster.ports[1:], strict=True):
        conns = tcp(cluster.pid(name))
        assert not [c for c in conns if c.status == psutil.CONN_LISTEN and c.laddr.port == port], \
            f"{name} listens on its endpoint: it should be a client of the router"
        peers = {c.raddr.port for c in conns if c.status == psutil.CONN_ESTABLISHED and c.raddr}
        assert peers == {router_port}, f"{name} is connected to {peers}, not only to the router ({router_port})"
    router = tcp(cluster.pid("controller"))
    assert [c for c in router if c.status == psutil.CONN_LISTEN and c.laddr.port == router_port]
