"""The roles of `cluster.security.roles` (issue #17): how hosts.yaml declares them, and the zenoh access control
the daemons get from them (`drd.daemon.acl`). The behavior on real daemons is in tests/test_cluster_roles.py."""

from __future__ import annotations

from pathlib import Path

import pytest

from drd.daemon.acl import access_control, check_roles
from drd.hosts import Cluster, HostsError, load_endpoints

HOSTS = """\
cluster:
  name: lab
  security: {security}
hosts:
  controller: {{endpoint: tcp/127.0.0.1:7447, roles: [controller]}}
"""


def cluster_with(tmp_path: Path, security: str) -> Cluster:
    (tmp_path / "users").write_text("drd:a\nalice:b\nbob:c\n")
    (tmp_path / "hosts.yaml").write_text(HOSTS.format(security=security))
    return load_endpoints(tmp_path / "hosts.yaml")


def test_roles_give_each_client_role_its_deny_rules(tmp_path: Path) -> None:
    c = cluster_with(tmp_path, "{mode: password, user: drd, password_file: users, roles: {operator: [alice],"
                               " observer: [bob]}}")
    acl = access_control(c)
    assert acl is not None and acl["enabled"] and acl["default_permission"] == "allow"
    subjects = {s["id"]: s for s in acl["subjects"]}
    assert subjects["operator"]["usernames"] == ["alice"] and subjects["observer"]["usernames"] == ["bob"]
    rules = {r["id"]: r for r in acl["rules"]}
    policies = {p["subjects"][0]: set(p["rules"]) for p in acl["policies"]}
    assert "operators-only" in policies["observer"] and "operators-only" not in policies["operator"]
    assert "drd/lab/missions/run" in rules["operators-only"]["key_exprs"]
    assert "drd/lab/host/*/creator" in rules["daemons-only"]["key_exprs"]
    assert {"put", "liveliness_token", "reply"} <= set(rules["clients-send-nothing"]["messages"])
    assert all(r["permission"] == "deny" and r["flows"] == ["ingress"] for r in acl["rules"])
    assert c.security.role_of("drd") == "daemon" and c.security.role_of("bob") == "observer"
    assert c.security.role_of("eve") is None


def test_without_roles_nothing_is_restricted_and_every_user_needs_a_role(tmp_path: Path) -> None:
    assert access_control(cluster_with(tmp_path, "{mode: password, user: drd, password_file: users}")) is None
    c = cluster_with(tmp_path, "{mode: password, user: drd, password_file: users, roles: {operator: [alice]}}")
    [problem] = check_roles(c, ["drd", "alice", "bob"])
    assert "user bob of" in str(problem) and "has no role" in str(problem) and "cluster.security.roles" in str(problem)


@pytest.mark.parametrize(("security", "message"), [
    ("{mode: none, roles: {operator: [alice]}}", "roles need identities"),
    ("{mode: password, user: drd, password_file: users, roles: {admin: [x]}}", "admin"),
    ("{mode: password, user: drd, password_file: users, roles: {operator: alice}}", "expected a list of names"),
    ("{mode: password, user: drd, password_file: users, roles: {operator: [a], observer: [a]}}",
     "a is already an operator"),
])
def test_bad_roles_are_refused_with_their_key(tmp_path: Path, security: str, message: str) -> None:
    with pytest.raises(HostsError) as e:
        cluster_with(tmp_path, security)
    assert "cluster.security.roles" in str(e.value) and message in str(e.value), str(e.value)


NETWORK = """\
cluster:
  name: lab
  security: {security}
hosts:
  controller: {{endpoint: tcp/10.1.2.3:7447, roles: [controller]}}
  ranger1: {{endpoint: tcp/127.0.0.1:7448, roles: [worker]}}
"""


def test_an_open_cluster_on_a_network_is_refused_unless_said_on_purpose(tmp_path: Path) -> None:
    from drd.daemon.security import SecurityError, transport

    (tmp_path / "hosts.yaml").write_text(NETWORK.format(security="{mode: none}"))
    cluster = load_endpoints(tmp_path / "hosts.yaml")
    with pytest.raises(SecurityError) as e:
        transport(cluster, daemon=True)
    assert "cluster.security" in str(e.value) and "controller listen beyond this machine" in str(e.value)
    assert "open: true" in str(e.value)
    transport(cluster)  # a client may still talk to it
    (tmp_path / "hosts.yaml").write_text(NETWORK.format(security="{mode: none, open: true}"))
    opened = transport(load_endpoints(tmp_path / "hosts.yaml"), daemon=True)
    assert opened.endpoints["controller"] == "tcp/10.1.2.3:7447"
    (tmp_path / "hosts.yaml").write_text(NETWORK.format(security="{mode: password, user: drd, password_file: u,"
                                                                  " open: true}"))
    with pytest.raises(HostsError) as bad:
        load_endpoints(tmp_path / "hosts.yaml")
    assert "cluster.security.open" in str(bad.value)


def test_drd_start_refuses_an_open_cluster_on_a_network_before_anything_runs(tmp_path: Path) -> None:
    import subprocess

    from tests.conftest import ROOT

    (tmp_path / "hosts.yaml").write_text(NETWORK.format(security="{mode: none}"))
    r = subprocess.run(["drd", "start", "--host", "ranger1", "--config", str(tmp_path / "hosts.yaml"), "--run-dir",
                        str(tmp_path / "run")], cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 2 and "mode none on a network" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not list((tmp_path / "run").rglob("*.pid"))
