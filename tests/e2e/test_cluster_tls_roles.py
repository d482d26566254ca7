"""Roles over mutual TLS (`security: {mode: tls, roles: ...}`): a certificate the cluster's CA signed for a name in
no role may do nothing (security audit D2: `mallory`'s certificate acted as a daemon and stopped missions).

Real daemons on loopback: `controller` and `ranger1` share the daemons' certificate (`drd-daemon`, listed under
`roles.daemon`); `missionctl` presents `alice`'s (an operator). `mallory`'s certificate is the cluster CA's too,
in no role: its session can neither stop a running mission nor make a host that never started look up with a fake
token. The throwaway PKI comes from tests/e2e/test_daemon_tls.py. Every process is ours and killed by pid.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from test_daemon_tls import Authority, pki_backend

from drd.bus import BusTimeout
from drd.bus.zenoh_bus import ZenohBus
from drd.daemon.security import transport
from drd.executive_messages import MissionCommand
from drd.hosts import load_hosts
from dsl.catalog import Catalog
from tests.cluster_support import DaemonCluster, eventually, running_cluster

NAMES = ["controller", "ranger1", "ghost"]  # ghost is configured, never started
ROLES = {"controller": "controller", "ranger1": "worker", "ghost": "worker"}
SECURITY = ("{mode: tls, ca: tls/ca.pem, cert: tls/host.pem, key: tls/host.key, roles: {daemon: [drd-daemon],"
            " operator: [alice], observer: [bob]}}")


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    backend = pki_backend()
    folder = tmp_path_factory.mktemp("tls_roles")
    ca = Authority(folder / "pki", "drd-test-cluster-ca", backend)
    with running_cluster(folder, NAMES, security=SECURITY) as c:
        lines = ["cluster:", f"  name: {c.name}", f"  security: {SECURITY}", "  lease: 1000ms", "hosts:"]
        for name, port in zip(c.names, c.ports, strict=True):  # no devices: a Wait needs no simulator
            lines += [f"  {name}: {{endpoint: tcp/127.0.0.1:{port}, roles: [{ROLES[name]}]}}"]
        c.hosts_file.write_text("\n".join(lines) + "\n")
        ca.issue(folder / "tls", "alice")  # missionctl's, beside the main hosts.yaml
        for name, common_name in (("controller", "drd-daemon"), ("ranger1", "drd-daemon"), ("mallory", "mallory"),
                                  ("bob", "bob"), ("ghost", "alice")):
            ca.issue(folder / name / "tls", common_name)
            (folder / name / "hosts.yaml").write_text(c.hosts_file.read_text())
        for name in NAMES[:2]:
            c.start(name, hosts_file=folder / name / "hosts.yaml")
        c.wait_ready(NAMES[:2])
        eventually(lambda: states(c).get("ranger1") == "up", "the daemons to see each other", 30, poll=0.2,
                   explain=lambda: c.tails("controller", "ranger1"))
        yield c


def states(c: DaemonCluster) -> dict[str, str]:
    r = c.missionctl("hosts", "--json", "--config", str(c.hosts_file), "--timeout", "2")
    return {h["name"]: h["state"] for h in json.loads(r.stdout)["hosts"]} if r.returncode == 0 else {}


def test_a_certificate_in_no_role_can_neither_stop_a_mission_nor_fake_a_host(cluster: DaemonCluster, tmp_path: Path,
                                                                            catalog: Catalog) -> None:
    (tmp_path / "hold.mission").write_text("mission Hold {\n    Wait(duration: 60s)\n}\n")
    run = cluster.missionctl("run", str(tmp_path / "hold.mission"), "--detach", "--config", str(cluster.hosts_file))
    assert run.returncode == 0, (run.stderr[-2000:], cluster.tails("controller"))
    mid = run.stdout.strip()
    options = transport(load_hosts(cluster.folder / "mallory" / "hosts.yaml", catalog)).options
    endpoints = [f"tls/127.0.0.1:{p}" for p in cluster.ports[:2]]
    with ZenohBus(connect=endpoints, options=options, name="mallory") as rogue:
        with pytest.raises(BusTimeout):
            rogue.call(f"drd/{cluster.name}/executive", MissionCommand("stop"), timeout=2.0)
        token = rogue.declare_token(f"drd/{cluster.name}/host/ghost")
        time.sleep(1.0)  # a token the daemons took would have reached them by now
        assert states(cluster).get("ghost") != "up"
        token.close()
    status = cluster.missionctl("status", "--json", "--config", str(cluster.hosts_file))
    [mission] = [m for m in json.loads(status.stdout)["missions"] if m["id"] == mid]
    assert mission.get("outcome") is None, mission  # still running: mallory's stop never arrived
    stopped = cluster.missionctl("stop", mid, "--json", "--config", str(cluster.hosts_file))
    assert stopped.returncode == 0 and [m["id"] for m in json.loads(stopped.stdout)["stopped"]] == [mid]


def test_missionctl_refuses_at_once_what_its_certificates_role_may_not_do(cluster: DaemonCluster) -> None:
    """The daemons drop a request a role may not make, without a reply (security audit D4: `stop` waited, then
    said "nothing answers there"): missionctl reads its certificate's common name and refuses first, as it does
    for a password user."""
    bob = cluster.folder / "bob" / "hosts.yaml"
    r = cluster.missionctl("stop", "--all", "--config", str(bob), "--timeout", "10")
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "certificate bob is an observer: it may watch the cluster" in r.stderr, r.stderr
    assert "use an operator's certificate" in r.stderr and "nothing answers" not in r.stderr, r.stderr
    watched = cluster.missionctl("hosts", "--json", "--config", str(bob))
    assert watched.returncode == 0 and {h["name"] for h in json.loads(watched.stdout)["hosts"]} >= {"controller"}
    r = cluster.missionctl("status", "--config", str(cluster.folder / "mallory" / "hosts.yaml"))
    assert r.returncode == 2 and "certificate mallory has no role in the hosts file" in r.stderr, r.stderr


def test_a_daemon_whose_certificate_is_no_daemons_is_refused_at_start(cluster: DaemonCluster) -> None:
    """ghost's certificate names alice, an operator: every daemon would drop what it sends, so it would run alone
    without an error anywhere; it is refused before it starts, naming the file and the key."""
    r = cluster.drd("start", "--host", "ghost", "--config", str(cluster.folder / "ghost" / "hosts.yaml"), "--run-dir",
                    str(cluster.folder / "ghost" / "run"), timeout=60)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "cluster.security.cert" in r.stderr and "the certificate's common name is alice" in r.stderr, r.stderr
    assert "a name listed under cluster.security.roles.daemon" in r.stderr and "Traceback" not in r.stderr
