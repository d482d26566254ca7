"""The roles of `cluster.security.roles` (issue #17): how hosts.yaml declares them, and the zenoh access control
the daemons get from them (`drd.daemon.acl`). The behavior on real daemons is in tests/e2e/test_cluster_roles.py."""

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
    assert "cluster.security" in str(e.value) and "controller listens beyond this machine" in str(e.value)
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


PER_HOST = """\
cluster:
  name: lab
  security: {mode: password, user: drd, password_file: users, per_host: true}
hosts:
  controller: {endpoint: tcp/127.0.0.1:7447, roles: [controller, simulator]}
  ranger1: {endpoint: tcp/127.0.0.1:7448, roles: [worker]}
  ranger2: {endpoint: tcp/127.0.0.1:7449, roles: [worker]}
"""


def test_per_host_identities_let_each_daemon_speak_only_for_its_own_host(tmp_path: Path) -> None:
    """Issue #17: with `per_host`, a daemon's credentials are its host's, and the rules deny it every other host's
    keys, the controller's and the simulator's unless it has those roles."""
    from drd.daemon.security import transport

    (tmp_path / "users").write_text("drd:a\ncontroller:b\nranger1:c\nranger2:d\n")
    (tmp_path / "hosts.yaml").write_text(PER_HOST)
    c = load_endpoints(tmp_path / "hosts.yaml")
    acl = access_control(c)
    assert acl is not None
    policies = {p["subjects"][0]: set(p["rules"]) for p in acl["policies"]}
    rules = {r["id"]: r for r in acl["rules"]}
    subjects = {s["id"]: s["usernames"] for s in acl["subjects"]}
    assert subjects["host-ranger1"] == ["ranger1"]
    assert policies["host-ranger1"] == {"not-for-others-ranger1", "not-a-controller", "no-creator-calls",
                                        "not-the-simulator", "operators-only"}
    assert policies["host-controller"] == {"not-for-others-controller"}
    others = rules["not-for-others-ranger1"]["key_exprs"]
    assert "drd/lab/host/ranger2/**" in others and "drd/lab/host/controller" in others
    assert not any("ranger1" in k for k in others)
    assert {"put", "liveliness_token", "reply", "declare_queryable"} <= set(rules["not-for-others-ranger1"]["messages"])
    assert "drd/lab/missions/run" in rules["not-a-controller"]["key_exprs"]
    assert check_roles(c, ["drd", "controller", "ranger1", "ranger2"]) == []  # hosts' users are daemons
    assert transport(c, daemon=True, host="ranger1").options["transport/auth/usrpwd/user"] == "ranger1"
    assert transport(c, daemon=True, host="ranger1").options["transport/auth/usrpwd/password"] == "c"
    assert transport(c).options["transport/auth/usrpwd/user"] == "drd"  # a client: the administrators' user


@pytest.mark.parametrize("security", ["{mode: none, per_host: true}",
                                      "{mode: password, user: drd, password_file: users, per_host: yes please}"])
def test_per_host_needs_identities(tmp_path: Path, security: str) -> None:
    with pytest.raises(HostsError) as e:
        cluster_with(tmp_path, security)
    assert any("cluster.security.per_host" in str(p) for p in e.value.problems), e.value.problems


def test_with_tls_and_roles_a_certificate_in_no_role_may_do_nothing(tmp_path: Path) -> None:
    """Security audit D2: under `default_permission: allow` a certificate the CA signed for a name in no role
    matched no deny rule and acted as a daemon. With tls (both ends authenticated) and roles, the default is deny
    and each named subject is allowed everything but its deny rules."""
    c = cluster_with(tmp_path, "{mode: tls, ca: ca.pem, cert: c.pem, key: c.key, roles: {daemon: [drd],"
                               " operator: [alice], observer: [bob]}}")
    acl = access_control(c)
    assert acl is not None and acl["default_permission"] == "deny"
    subjects = {s["id"]: s["cert_common_names"] for s in acl["subjects"]}
    assert subjects == {"daemon": ["drd"], "operator": ["alice"], "observer": ["bob"]}
    policies = {p["subjects"][0]: p["rules"] for p in acl["policies"]}
    assert policies["daemon"] == ["everything"]
    assert "everything" in policies["observer"] and "operators-only" in policies["observer"]
    [everything] = [r for r in acl["rules"] if r["id"] == "everything"]
    assert everything["permission"] == "allow" and everything["key_exprs"] == ["**"]
    assert set(everything["flows"]) == {"ingress", "egress"}
    password = cluster_with(tmp_path, "{mode: password, user: drd, password_file: users, roles: {operator: [alice],"
                                      " observer: [bob]}}")
    assert access_control(password)["default_permission"] == "allow"  # type: ignore[index]  # one-way: see module

