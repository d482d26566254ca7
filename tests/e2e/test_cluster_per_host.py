"""Each daemon its own identity (`security.per_host`, issue #17), on a real password cluster on loopback.

Every daemon authenticates as its host's name and may then speak only for its own host: a peer holding another
host's credentials (ranger2's: configured, never started) can neither fake ranger1's load or liveliness, nor call
its Creator, nor serve the controller's keys; the genuine daemons run a mission as before. Every process is ours
and killed by pid (`tests/cluster_support.py`).
"""

from __future__ import annotations

import json
import os
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from cluster_support import (
    MISSIONCTL,
    ROOT,
    DaemonCluster,
    assert_spoofing_fails,
    eventually,
    password_cluster,
    two_rangers_hosts,
)

from drd.daemon.client import ClusterClient

NAMES = ["controller", "ranger1", "ranger2", "ranger3"]
USERS = {"admin": "admin-secret", "alice": "operator-secret", "controller": "c-secret", "ranger1": "r1-secret",
         "ranger2": "r2-secret"}
SECURITY = ("{mode: password, user: admin, password_file: users, per_host: true, roles: {operator: [alice]}}")


def hosts(cluster: DaemonCluster) -> str:
    """The two-Ranger team (ranger2 never starts: its credentials are the attacker's) on our ports, with per-host
    identities, and a ranger3 that never starts either."""
    return two_rangers_hosts(cluster, SECURITY).replace(
        "\nhosts:\n", f"\nhosts:\n  ranger3:\n    endpoint: tcp/127.0.0.1:{cluster.ports[3]}\n    roles: [worker]\n", 1)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with password_cluster(tmp_path_factory.mktemp("per_host"), NAMES, SECURITY, USERS, hosts, NAMES[:2]) as c:
        eventually(lambda: up(c) >= {"controller", "ranger1"}, "both daemons to see each other", 30, poll=0.2)
        yield c


def missionctl(cluster: DaemonCluster, *args: str, timeout: float = 90) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args, "--config", str(cluster.hosts_file)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout, check=False, env={**os.environ, "DRD_USER": "alice"})


def up(cluster: DaemonCluster) -> set[str]:
    r = missionctl(cluster, "hosts", "--json", "--timeout", "2")
    return {h["name"] for h in json.loads(r.stdout)["hosts"] if h["state"] == "up"} if r.returncode == 0 else set()


def as_host(cluster: DaemonCluster, user: str) -> ClusterClient:
    """A session holding `user`'s credentials (a host's, or a client's), opened to the two running daemons (it is
    authenticated there)."""
    return ClusterClient.connect(cluster.endpoints[:2], cluster=cluster.name, timeout=5.0, options={
        "transport/auth/usrpwd/user": user, "transport/auth/usrpwd/password": USERS[user],
        "transport/auth/usrpwd/dictionary_file": str(cluster.folder / "users")})


def test_the_daemons_run_a_mission_each_under_its_own_identity(cluster: DaemonCluster, tmp_path: Path) -> None:
    (tmp_path / "m.mission").write_text("mission Short {\n    Wait(duration: 1s)\n}\n")
    run = missionctl(cluster, "run", str(tmp_path / "m.mission"), "--json", "--speed", "10")
    assert run.returncode == 0 and json.loads(run.stdout)["outcome"] == "success", run.stderr[-2000:]


def test_another_hosts_credentials_cannot_speak_for_ranger1_or_command_its_creator(cluster: DaemonCluster) -> None:
    rogue = as_host(cluster, "ranger2")
    try:
        assert_spoofing_fails(cluster, rogue, "ranger1", lambda: hosts_view(cluster))
    finally:
        rogue.close()


def hosts_view(cluster: DaemonCluster) -> dict[str, dict[str, Any]]:
    r = missionctl(cluster, "hosts", "--json", "--timeout", "2")
    assert r.returncode == 0, r.stderr
    return {h["name"]: h for h in json.loads(r.stdout)["hosts"]}


def test_another_hosts_credentials_cannot_keep_a_host_up_with_its_token(cluster: DaemonCluster) -> None:
    """A fake host token would make ranger3 (configured, never started) look up, its robots placeable."""
    rogue = as_host(cluster, "ranger2")
    fake = rogue.bus.declare_token(f"drd/{cluster.name}/host/ranger3")
    try:
        time.sleep(1.0)  # the token would have reached the daemons by now
        for _ in range(3):
            r = missionctl(cluster, "hosts", "--json", "--timeout", "2")
            view = {h["name"]: h for h in json.loads(r.stdout)["hosts"]}
            assert view["ranger3"]["state"] == "down", view["ranger3"]
    finally:
        fake.close()
        rogue.close()
