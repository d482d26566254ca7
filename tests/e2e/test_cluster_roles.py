"""Roles on a password cluster (issue #17): zenoh's own access control, configured from `security.roles`.

Real daemons on loopback (controller with the simulator, ranger1; ranger2 is in the hosts file but never
started), users `drd` (the daemons), `alice` (operator) and `bob` (observer). What is checked is what each can do
from outside: through `missionctl` as each user (`DRD_USER`), and with raw sessions sending what a curious or
hostile client would (a mission request, a fake load report, a fake liveliness token, a Creator call).
"""

from __future__ import annotations

import json
import os
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from cluster_support import MISSIONCTL, ROOT, DaemonCluster, eventually, password_cluster, two_rangers_hosts

from drd.bus import BusTimeout, LoadReport
from drd.cluster.remote import ComponentCall
from drd.daemon.client import ClusterClient
from drd.daemon.missions import RunMission, run_key

NAMES = ["controller", "ranger1", "ranger2"]
USERS = {"drd": "daemons-secret", "alice": "operator-secret", "bob": "observer-secret"}
SECURITY = "{mode: password, user: drd, password_file: users, roles: {operator: [alice], observer: [bob]}}"
MISSION = "mission Short {\n    Wait(duration: 1s)\n}\n"


def hosts(cluster: DaemonCluster) -> str:
    """The repository's two-Ranger team (ranger2 never starts) on our ports, with the roles."""
    return two_rangers_hosts(cluster, SECURITY)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with password_cluster(tmp_path_factory.mktemp("roles"), NAMES, SECURITY, USERS, hosts, NAMES[:2]) as c:
        eventually(lambda: _up(c) >= {"controller", "ranger1"}, "both daemons to see each other", 30, poll=0.2)
        yield c


def missionctl(cluster: DaemonCluster, user: str, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args, "--config", str(cluster.hosts_file)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout, check=False, env={**os.environ, "DRD_USER": user})


def _up(cluster: DaemonCluster) -> set[str]:
    r = missionctl(cluster, "alice", "hosts", "--json", "--timeout", "2")
    return {h["name"] for h in json.loads(r.stdout)["hosts"] if h["state"] == "up"} if r.returncode == 0 else set()


def session(cluster: DaemonCluster, user: str) -> ClusterClient:
    """A raw client session as `user`: it sends whatever it likes."""
    return ClusterClient.connect(cluster.endpoints[:2], cluster=cluster.name, timeout=5.0, options={
        "transport/auth/usrpwd/user": user, "transport/auth/usrpwd/password": USERS[user],
        "transport/auth/usrpwd/dictionary_file": str(cluster.folder / "users")})


def missions(cluster: DaemonCluster) -> list[dict[str, Any]]:
    r = missionctl(cluster, "bob", "status", "--json", "--timeout", "2")
    assert r.returncode == 0, r.stderr
    return list(json.loads(r.stdout)["missions"])


def test_an_observer_watches_but_cannot_run_even_with_a_raw_request(cluster: DaemonCluster, tmp_path: Path) -> None:
    status = missionctl(cluster, "bob", "status", "--json", "--timeout", "2")
    assert status.returncode == 0, status.stderr
    assert {h["name"] for h in json.loads(status.stdout)["hosts"] if h["state"] == "up"} >= {"controller", "ranger1"}
    (tmp_path / "m.mission").write_text(MISSION)
    run = missionctl(cluster, "bob", "run", str(tmp_path / "m.mission"))
    assert run.returncode == 2 and "user bob is an observer" in run.stderr and "not run a mission" in run.stderr
    stop = missionctl(cluster, "bob", "stop", "--all")
    assert stop.returncode == 2 and "not stop a mission" in stop.stderr
    bob = session(cluster, "bob")
    try:  # what missionctl refuses, the daemons refuse too: the request never reaches the controller
        with pytest.raises(BusTimeout):  # dropped where it arrives: no answer at all
            bob.bus.call(run_key(cluster.name), RunMission(MISSION, "m.mission"), timeout=2.0)
    finally:
        bob.close()
    assert not [m for m in missions(cluster) if m.get("id", "").startswith("Short")], "nothing ran"


def test_an_operator_runs_a_mission(cluster: DaemonCluster, tmp_path: Path) -> None:
    (tmp_path / "m.mission").write_text(MISSION)
    run = missionctl(cluster, "alice", "run", str(tmp_path / "m.mission"), "--json", "--speed", "10")
    assert run.returncode == 0, run.stderr[-2000:]
    assert json.loads(run.stdout)["outcome"] == "success"


def test_a_client_cannot_fake_a_load_a_host_or_a_creator_call(cluster: DaemonCluster) -> None:
    alice = session(cluster, "alice")
    try:
        token = alice.bus.declare_token(f"drd/{cluster.name}/host/ranger2")  # a host that never started
        faking = threading.Event()

        def fake_loads() -> None:  # twice as often as ranger1 reports: without the rules, the view would show it
            while not faking.is_set():
                alice.bus.put(f"drd/{cluster.name}/host/ranger1/load", LoadReport("ranger1", 99.5, 99.5, 9.5, 42,
                                                                                  time.time()))
                time.sleep(0.1)

        thread = threading.Thread(target=fake_loads, daemon=True)
        thread.start()
        try:
            with pytest.raises(BusTimeout):  # the Creator is the controller's to call: dropped, no answer
                alice.bus.call(f"drd/{cluster.name}/host/ranger1/creator",
                               ComponentCall("retire", "Short-1", ""), timeout=2.0)
            for _ in range(3):
                r = missionctl(cluster, "alice", "hosts", "--json", "--timeout", "2")
                view = {h["name"]: h for h in json.loads(r.stdout)["hosts"]}
                assert view["ranger2"]["state"] == "down", view["ranger2"]
                assert view["ranger1"]["cpu"] != 99.5 and view["ranger1"]["instances"] != 42, view["ranger1"]
        finally:
            faking.set()
            thread.join(timeout=5)
        token.close()
    finally:
        alice.close()
    assert "Traceback" not in cluster.log("ranger1")


def test_a_user_without_a_role_is_refused_by_missionctl(cluster: DaemonCluster) -> None:
    (cluster.folder / "users").write_text("".join(f"{u}:{p}\n" for u, p in {**USERS, "eve": "x"}.items()))
    try:
        r = missionctl(cluster, "eve", "status", "--timeout", "2")
        assert r.returncode == 2 and "user eve has no role" in r.stderr, r.stderr
    finally:
        (cluster.folder / "users").write_text("".join(f"{u}:{p}\n" for u, p in USERS.items()))


def test_an_operators_recording_has_the_poses_and_scans_though_only_daemons_may_ask_the_simulator(
        cluster: DaemonCluster, tmp_path: Path) -> None:
    """Issue #13: on a closed cluster a client may not ask the simulator (`drd/<c>/sim`, daemons only); the world's
    poses and readings come from its own key, which every role may read."""
    from collections import Counter

    from mcap.reader import make_reader

    run = missionctl(cluster, "alice", "run", "missions/corridor_surveillance.mission", "--speed", "5", "--until",
                     "10", "--record", str(tmp_path / "run.mcap"), "--json", timeout=120)
    assert run.returncode == 1, run.stderr[-2000:]  # stopped at --until
    with (tmp_path / "run.mcap").open("rb") as fh:
        counts = Counter(channel.topic for _s, channel, _m in make_reader(fh).iter_messages())
    assert counts["/drd/tf"] > 5 and counts["/drd/scan/ranger1"] > 20, counts
