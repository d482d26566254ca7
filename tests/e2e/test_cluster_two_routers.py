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
import os
import re
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil
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
    for ended in status["missions"]:  # the previous case's mission too, its world gone since
        assert isinstance(ended.get("started"), float) and ended["started"] <= ended["time"], (
            "an ended mission keeps `started` (newcomer audit 7: only while its world was open)", ended)
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


def linked_router(c: DaemonCluster, host: str) -> str:
    """The router `host`'s daemon is linked to: the one of hubA, hubB whose port its established sockets reach."""
    ports = {conn.raddr.port for conn in psutil.Process(c.pid(host)).net_connections(kind="tcp")
             if conn.raddr and conn.status == psutil.CONN_ESTABLISHED}
    [router] = [n for n in ("hubA", "hubB") if c.ports[c.names.index(n)] in ports]
    return router


def test_losing_one_of_two_routers_does_not_end_a_running_mission(tmp_path: Path) -> None:
    """kill -9 of the router a worker goes through, mid-mission (re-verification audit: each worker behind the dead
    router took the controller's token, gone with its link and back through the other router a moment later, for
    the controller's loss, retired every instance, and the mission failed on a Creator's refusal). Two routers
    only, the controller and two workers behind them; the mission's Waits spread over both workers. It runs on to
    its success, and no worker says it lost its controller."""
    names = ["hubA", "hubB", "controller", "w1", "w2"]
    roles = {"hubA": "[router]", "hubB": "[router]", "controller": "[controller]", "w1": "[worker]", "w2": "[worker]"}
    with running_cluster(tmp_path, names) as c:
        lines = ["cluster:", f"  name: {c.name}", "  security: {mode: none}", "  lease: 3000ms", "hosts:"]
        for name, port in zip(c.names, c.ports, strict=True):
            lines += [f"  {name}:", f"    endpoint: tcp/127.0.0.1:{port}", f"    roles: {roles[name]}"]
        c.hosts_file.write_text("\n".join(lines) + "\n")
        for name in names:
            c.start(name)
        c.wait_ready()
        c.wait_up()
        mission = tmp_path / "spread.mission"
        mission.write_text("mission Spread {\n    parallel all {\n        Wait(duration: 8s) as a\n"
                           "        Wait(duration: 8s) as b\n        Wait(duration: 8s) as c\n    }\n}\n")
        via = ["--config", str(c.hosts_file)]
        r = ctl(c, via, "run", str(mission), "--detach")
        assert r.returncode == 0, (r.stderr[-2000:], c.log("controller")[-3000:])
        mid = r.stdout.strip()
        eventually(lambda: {"w1", "w2"} <= set(re.findall(r"placement: Wait on (\w+)", c.log("controller"))),
                   "the Waits on both workers", 30, poll=0.05, explain=lambda: c.tails("controller"))
        router = linked_router(c, "w1")  # the one w1 goes through (zenoh picked it), seen from its sockets
        os.kill(c.pid(router), signal.SIGKILL)
        c.procs[router].wait(timeout=10)
        seen: list[Any] = []

        def ended() -> bool:
            status = ctl(c, via, "status", "--json")
            if status.returncode == 0:
                seen[:] = [m for m in json.loads(status.stdout)["missions"] if m["id"] == mid]
            return bool(seen) and seen[0].get("outcome") is not None

        eventually(ended, "the mission to end", 60, poll=0.5, explain=lambda: c.tails("controller", "w1", "w2"))
        assert seen[0]["outcome"] == "success", (seen, c.tails("controller", "w1", "w2"))
        assert "controller controller lost" not in c.log("w1") + c.log("w2"), c.tails("w1", "w2")
