"""A fleet through two zenoh routers (issue #15): N real daemons on loopback, N from $DRD_SCALE_DAEMONS (default 12,
what CI affords; `DRD_SCALE_DAEMONS=50 pytest tests/e2e/test_cluster_scale.py` runs the issue's 50).

The repository's corridor hosts (the controller, and ranger1 with the simulator and the Scouts), both also routers,
and N - 2 compute hosts (`worker` only, no devices), every one a zenoh client of the routers. Checked from outside:
every host up in `missionctl hosts --json` and `missionctl status --json` (answered by the controller, roles as
the file says, ranger1's devices in the manager, no error), every client daemon connected to routers only, and a
mission of parallel Waits (movable: no device) placed by the controller on more than one host and run to success.
Placement weighs instance counts only (`cpu: 0, memory: 0`): on one machine every host reports the same CPU load.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil
import pytest
from cluster_support import DaemonCluster, corridor_hosts, eventually, running_cluster

N = int(os.environ.get("DRD_SCALE_DAEMONS", "12"))
ROUTERS = ("controller", "ranger1")
NAMES = ["controller", "ranger1", *(f"worker{i}" for i in range(2, N))]
WAITS = 6
MISSION = "mission Spread {\n    parallel all {\n" + "".join(
    f"        Wait(duration: 3s) as w{i}\n" for i in range(1, WAITS + 1)) + "    }\n}\n"


def fleet_hosts(cluster: DaemonCluster) -> str:
    """The corridor hosts with both hosts routers, a 3 s lease (fifty daemons start at once on two cores), placement
    by instance count, and one plain worker per remaining name, each on its free port."""
    text = corridor_hosts(cluster, lease="3s")
    text = text.replace("roles: [controller]", "roles: [controller, router]")
    text = text.replace("roles: [worker, simulator]", "roles: [worker, simulator, router]")
    weights = "placement: {cpu: 1.0, memory: 0.5, instances: 0.2}"
    assert weights in text and text.rstrip().endswith("properties: {battery: 1.0}"), "hosts.yaml changed shape"
    text = text.replace(weights, "placement: {cpu: 0, memory: 0, instances: 1}")
    for name, port in zip(cluster.names[2:], cluster.ports[2:], strict=True):
        text += f"  {name}:\n    endpoint: tcp/127.0.0.1:{port}\n    roles: [worker]\n"
    return text


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    """The routers first (a client of the routers waits for one), then every other daemon at once."""
    with running_cluster(tmp_path_factory.mktemp("scale"), NAMES, lease=3.0) as c:
        c.hosts_file.write_text(fleet_hosts(c))
        c.endpoints = [e for name, e in zip(c.names, c.endpoints, strict=True) if name in ROUTERS]
        for name in sorted(NAMES, key=lambda n: n not in ROUTERS):
            c.start(name, extra=("--load-period", "1"))  # the last one counts: a daemon's default period
        eventually(lambda: all_running(c), f"{N} daemons to start", timeout=60.0 + 2.0 * N, poll=0.2)
        c.wait_up(timeout=60.0 + 2.0 * N)
        yield c


def all_running(c: DaemonCluster) -> bool:
    """Every daemon has declared its services (its pidfile says `running`); one that exited fails the test. The
    whole fleet shares one deadline: fifty daemons on two cores start together, not one after the other."""
    for name, proc in c.procs.items():
        if proc.poll() is not None:
            pytest.fail(f"drd {name} exited with {proc.returncode}:\n{c.log(name)[-3000:]}")
    return all((c.pidfile(name) or {}).get("state") == "running" for name in c.names)


def whole_fleet_status(fleet: DaemonCluster) -> dict[str, Any]:
    """`missionctl status --json` once it shows the whole fleet: answered by the controller, every host up, no
    error. Polled (bounded): on two cores shared with other test runs, one answer may come while a host's load
    report is late or a request times out; a host that never comes up, or an error that stays, still fails."""
    last: dict[str, Any] = {}

    def whole() -> bool:
        nonlocal last
        r = fleet.missionctl("status", "--json", "--config", str(fleet.hosts_file), "--timeout", "10", timeout=60)
        last = json.loads(r.stdout) if r.returncode == 0 else {"stderr": r.stderr[-2000:]}
        return (r.returncode == 0 and last["answered_by"] == "controller" and last["errors"] == {}
                and {h["name"] for h in last["hosts"] if h["state"] == "up"} == set(NAMES))

    try:
        eventually(whole, "a status of the whole fleet", timeout=90.0, poll=1.0)
    except pytest.fail.Exception:
        pytest.fail(f"no status of the whole fleet within 90 s; the last: {json.dumps(last)[:3000]}")
    return last


def test_every_host_is_up_and_status_is_the_whole_fleet(fleet: DaemonCluster) -> None:
    def all_up() -> bool:
        r = fleet.missionctl("hosts", "--json", "--config", str(fleet.hosts_file), timeout=60)
        assert r.returncode == 0, r.stderr[-2000:]
        return {h["name"]: h["state"] for h in json.loads(r.stdout)["hosts"]} == dict.fromkeys(NAMES, "up")

    eventually(all_up, f"missionctl hosts to show all {N} hosts up", timeout=90.0, poll=1.0)
    status = whole_fleet_status(fleet)
    roles = {h["name"]: h["roles"] for h in status["hosts"]}
    assert roles == {"controller": ["controller", "router"], "ranger1": ["worker", "simulator", "router"],
                     **{name: ["worker"] for name in NAMES[2:]}}
    units = {u["id"]: u["host"] for u in status["resources"]["units"]}
    assert units["ranger1.drive"] == "ranger1" and any(u.endswith("scout1.camera") for u in units), sorted(units)
    assert set(units.values()) == {"ranger1"}  # the compute hosts have no devices


def test_the_clients_are_linked_to_the_routers_only(fleet: DaemonCluster) -> None:
    router_ports = {p for name, p in zip(fleet.names, fleet.ports, strict=True) if name in ROUTERS}
    for name, port in zip(fleet.names, fleet.ports, strict=True):
        if name in ROUTERS:
            continue
        conns = psutil.Process(fleet.pid(name)).net_connections(kind="tcp")
        assert not [c for c in conns if c.status == psutil.CONN_LISTEN and c.laddr.port == port], name
        peers = {c.raddr.port for c in conns if c.status == psutil.CONN_ESTABLISHED and c.raddr}
        assert peers and peers <= router_ports, f"{name} is linked to {peers}, not only to the routers"


def test_a_mission_of_parallel_waits_is_placed_across_hosts(fleet: DaemonCluster, tmp_path: Path) -> None:
    (tmp_path / "spread.mission").write_text(MISSION)
    config = str(fleet.hosts_file)
    r = fleet.missionctl("run", str(tmp_path / "spread.mission"), "--config", config, "--speed", "5", "--json",
                         timeout=180)
    assert r.returncode == 0, (r.stderr[-2000:], fleet.log("controller")[-3000:])
    report = json.loads(r.stdout)
    assert report["outcome"] == "success"
    missions = [m for m in whole_fleet_status(fleet)["missions"] if m.get("placements")]
    assert missions, "no mission with placements in status"
    mission = missions[-1]
    placed = {p["instance"]: p["host"] for p in mission["placements"]}
    assert len(placed) == WAITS, placed
    assert set(placed.values()) <= set(NAMES[1:])  # workers only: the controller has no worker role
    assert len(set(placed.values())) > 1, f"every Wait went to one host: {placed}"
