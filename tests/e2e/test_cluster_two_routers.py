"""A cluster with two routers (docs/scale.md's fleet topology): each `missionctl` request reaches the controller
once (fleet audit, defect 1: `missionctl --config` was a zenoh peer linked to both routers, the controller got each
query once through each, and one `run` started two missions, `migrate` moved then answered the copy's "already
runs there" with exit 2).

Real daemons on loopback, every process ours and killed by pid: `hubA` a router only, `controller`, `w1` a
worker, `w2` a worker and the second router. Checked from outside, through `missionctl --config` and through
`--connect` given both routers: one `run --detach` starts one mission (`status --json`, and the controller's
log), `migrate` exits 0 and says where the Wait went, `stop` says it stopped the mission (not that it had
already ended).
"""

from __future__ import annotations

import json
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from cluster_support import DaemonCluster, eventually, running_cluster

from drd.daemon.security import transport
from drd.hosts import load_endpoints

NAMES = ["hubA", "controller", "w1", "w2"]
ROLES = {"hubA": "[router]", "controller": "[controller]", "w1": "[worker]", "w2": "[worker, router]"}
WORKERS = {"w1", "w2"}
PLACED = re.compile(r"placement: Wait on (\w+)")
STARTED = re.compile(r"mission (Hold-\d+) started")


def hosts(cluster: DaemonCluster) -> str:
    lines = ["cluster:", f"  name: {cluster.name}", "  security: {mode: none}", "  lease: 1000ms", "hosts:"]
    for name, port in zip(cluster.names, cluster.ports, strict=True):
        lines += [f"  {name}:", f"    endpoint: tcp/127.0.0.1:{port}", f"    roles: {ROLES[name]}"]
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    """The routers first (a client of the routers waits for one), then the others."""
    with running_cluster(tmp_path_factory.mktemp("two_routers"), NAMES) as c:
        c.hosts_file.write_text(hosts(c))
        for name in ("hubA", "w2", "controller", "w1"):
            c.start(name)
        c.wait_ready()
        c.wait_up()
        yield c


def ctl(cluster: DaemonCluster, via: list[str], *args: str) -> subprocess.CompletedProcess[str]:
    return cluster.missionctl(*args, *via, "--timeout", "10", timeout=60)


def answer(r: subprocess.CompletedProcess[str], cluster: DaemonCluster) -> Any:
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-2000:], cluster.log("controller")[-3000:])
    return json.loads(r.stdout)


@pytest.mark.parametrize("how", ["config", "connect"])
def test_run_migrate_and_stop_through_two_routers_each_act_once(cluster: DaemonCluster, tmp_path: Path,
                                                                 how: str) -> None:
    """`--config` (the routers from the hosts file), or `--connect` given both routers' endpoints."""
    routers = [e for n, e in zip(cluster.names, cluster.endpoints, strict=True) if "router" in ROLES[n]]
    via = ["--config", str(cluster.hosts_file)] if how == "config" else [w for e in routers for w in ("--connect", e)]
    mission = tmp_path / "hold.mission"
    mission.write_text("mission Hold {\n    Wait(duration: 60s) as w\n}\n")
    before = len(cluster.log("controller"))
    r = ctl(cluster, via, "run", str(mission), "--detach")
    assert r.returncode == 0, (r.stderr[-2000:], cluster.log("controller")[-3000:])
    mid = r.stdout.strip()
    assert STARTED.fullmatch(f"mission {mid} started"), r.stdout
    eventually(lambda: PLACED.search(cluster.log("controller")[before:]), "the Wait to be placed", 30, poll=0.05)
    host = PLACED.findall(cluster.log("controller")[before:])[0]
    assert host in WORKERS
    other = (WORKERS - {host}).pop()

    moved = answer(ctl(cluster, via, "migrate", f"{mid}/Hold/w", "--to", other, "--json"), cluster)
    assert (moved["source"], moved["host"], moved["component"]) == (host, other, "Wait"), moved

    stopped = answer(ctl(cluster, via, "stop", mid, "--json"), cluster)
    assert ([m["id"] for m in stopped["stopped"]], stopped["ended"]) == ([mid], []), stopped

    status = answer(ctl(cluster, via, "status", "--json"), cluster)
    started = STARTED.findall(cluster.log("controller")[before:])
    assert [m["id"] for m in status["missions"] if m["id"] in started] == [mid], f"one run, missions {started}"
    assert started == [mid]
    assert len(re.findall(r"Hold/w \(Wait\) moved from", cluster.log("controller")[before:])) == 1


def test_a_client_daemon_whose_first_router_is_down_joins_through_the_other(tmp_path: Path) -> None:
    """A client of the routers dials them in its own order (`Transport.others`); with the first one down when it
    starts, it joins through the second (it used to redial the first for ever: zenoh spends each attempt on it)."""
    with running_cluster(tmp_path, NAMES) as c:
        c.hosts_file.write_text(hosts(c))
        endpoint = next(iter(transport(load_endpoints(c.hosts_file)).others("w1").values()))
        down = c.names[c.endpoints.index(endpoint)]
        up = [n for n in ("hubA", "w2", "controller", "w1") if n != down]
        for name in up:
            c.start(name)
        c.wait_ready(up)
        c.wait_up(names=[n for n in up if n != "hubA"])
