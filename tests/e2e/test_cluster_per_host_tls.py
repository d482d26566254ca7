"""Each daemon its own identity over mutual TLS (`security: {mode: tls, per_host: true}`, issue #17), on loopback.

Every daemon's certificate names its host (its common name); the cluster's CA also signed a certificate for
ranger2, a host that never starts: its holder is the attacker. It can neither fake ranger1's load nor call its
Creator, although its certificate is the cluster's; the daemons see each other up and serve `missionctl` as
usual. The throwaway PKI comes from `tests/e2e/test_daemon_tls.py` (skipped where neither the `cryptography` package
nor the `openssl` CLI is there). Every process is ours and killed by pid.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
from test_daemon_tls import Authority, pki_backend

from drd.daemon.client import ClusterClient
from drd.daemon.security import transport
from drd.hosts import load_hosts
from dsl.catalog import Catalog
from tests.cluster_support import DaemonCluster, assert_spoofing_fails, eventually, running_cluster

NAMES = ["controller", "ranger1", "ranger2"]
SECURITY = "{mode: tls, ca: tls/ca.pem, cert: tls/host.pem, key: tls/host.key, per_host: true}"


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    backend = pki_backend()
    folder = tmp_path_factory.mktemp("per_host_tls")
    ca = Authority(folder / "pki", "drd-test-cluster-ca", backend)
    with running_cluster(folder, NAMES, security=SECURITY) as c:
        ca.issue(folder / "tls", "missionctl")  # the operator's, beside the main hosts.yaml
        for name in NAMES:  # ranger2's is the attacker's: the cluster's CA, ranger2's name
            ca.issue(folder / name / "tls", name)
            (folder / name / "hosts.yaml").write_text(c.hosts_file.read_text())
        for name in NAMES[:2]:
            c.start(name, hosts_file=folder / name / "hosts.yaml")
        c.wait_ready(NAMES[:2])
        eventually(lambda: up(c) >= {"controller", "ranger1"}, "both daemons to see each other", 30, poll=0.2)
        yield c


def up(c: DaemonCluster) -> set[str]:
    r = c.missionctl("hosts", "--json", "--config", str(c.hosts_file), "--timeout", "2")
    return {h["name"] for h in json.loads(r.stdout)["hosts"] if h["state"] == "up"} if r.returncode == 0 else set()


def test_ranger2s_certificate_cannot_speak_for_ranger1_or_command_its_creator(cluster: DaemonCluster,
                                                                             catalog: Catalog) -> None:
    options = transport(load_hosts(cluster.folder / "ranger2" / "hosts.yaml", catalog)).options
    endpoints = [f"tls/127.0.0.1:{p}" for p in cluster.ports[:2]]
    rogue = ClusterClient.connect(endpoints, cluster=cluster.name, timeout=5.0, options=options)

    def view() -> dict[str, dict[str, Any]]:
        r = cluster.missionctl("hosts", "--json", "--config", str(cluster.hosts_file), "--timeout", "2")
        assert r.returncode == 0, r.stderr
        return {h["name"]: h for h in json.loads(r.stdout)["hosts"]}

    try:
        assert_spoofing_fails(cluster, rogue, "ranger1", view)
        assert view()["ranger1"]["state"] == "up"
    finally:
        rogue.close()
    assert all("Traceback" not in cluster.log(n) for n in NAMES[:2])


def test_the_acl_names_each_daemon_by_its_certificate(cluster: DaemonCluster, catalog: Catalog) -> None:
    from drd.daemon.acl import access_control

    acl = access_control(load_hosts(cluster.hosts_file, catalog))
    assert acl is not None
    subjects = {s["id"]: s for s in acl["subjects"]}
    assert subjects["host-ranger1"] == {"id": "host-ranger1", "cert_common_names": ["ranger1"]}
