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
