"""Failover to a standby controller (issue #16): two controller hosts share a 3-member etcd cluster (started here),
etcd elects the one that acts, and when it dies the other takes the mission over under the same id.

Real processes on loopback: three `etcd` members, `controller` and `controller2` (both with the controller role),
ranger1 (the Ranger, its Scouts and the simulator). kill -9 of the acting controller mid-corridor-mission at
`--speed 20`: the standby is elected, resumes the mission from the replicated journal, and the same `missionctl
run` follows it to success. Then a SIGSTOP of the acting controller: the other takes over; after SIGCONT the old
one finds itself fenced, steps down, and nothing it sends is taken: its term is older, so ranger1 refuses a
command carrying it. Every process is ours and killed by pid. No timing is asserted (bench/failover.py measures
the takeover)."""

from __future__ import annotations

import json
import re
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest
from cluster_support import (
    MISSIONCTL,
    ROOT,
    DaemonCluster,
    corridor_hosts,
    eventually,
    read_trace,
    running,
    running_cluster,
)
from etcd_support import EtcdCluster, etcd_cluster, need_etcd

from drd.bus.zenoh_bus import ZenohBus
from drd.cluster.gates import GateUpdate, GateUpdateReply
from drd.cluster.remote import ComponentCall, ComponentReply
from drd.errors import BusFailure

NAMES = ["controller", "ranger1", "controller2"]
CORRIDOR = ROOT / "missions" / "corridor_surveillance.mission"


def failover_hosts(cluster: DaemonCluster, etcd: EtcdCluster) -> str:
    """The repository's hosts.yaml with a second controller host and the etcd store, on the test's ports."""
    text = corridor_hosts(cluster)
    urls = ", ".join(etcd.urls)
    text = text.replace("  world: corridor", f"  world: corridor\n  store: {{etcd: [{urls}]}}", 1)
    port = dict(zip(cluster.names, cluster.ports, strict=True))["controller2"]
    return text + f"\n  controller2:\n    endpoint: tcp/127.0.0.1:{port}\n    roles: [controller]\n"


@pytest.fixture(scope="module")
def etcd(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EtcdCluster]:
    need_etcd()
    with etcd_cluster(tmp_path_factory.mktemp("etcd"), 3) as e:
        yield e


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory, etcd: EtcdCluster) -> Iterator[DaemonCluster]:
    with running_cluster(tmp_path_factory.mktemp("failover"), NAMES) as c:
        c.hosts_file.write_text(failover_hosts(c, etcd))
        c.start("controller")  # first, so it is the one elected
        c.wait_ready(["controller"])
        eventually(lambda: "elected the acting controller" in c.log("controller"), "controller to be elected", 30)
        c.start("ranger1")
        c.start("controller2")
        c.wait_ready()
        c.wait_up()
        eventually(lambda: "standby controller: controller acts" in c.log("controller2"), "controller2 standing by",
                   30)
        yield c


def acting(cluster: DaemonCluster) -> str:
    """The controller whose log says it was elected last (and not fenced since)."""
    found = []
    for name in ("controller", "controller2"):
        for m in re.finditer(r"elected the acting controller \(term (\d+)", cluster.log(name)):
            found.append((int(m.group(1)), name))
    return max(found)[1]


def term_of(cluster: DaemonCluster, name: str) -> int:
    """Its latest term, 0 before it was first elected (a standby not elected yet: `eventually` asks again)."""
    found = re.findall(r"elected the acting controller \(term (\d+)", cluster.log(name))
    return max((int(t) for t in found), default=0)


def mission_time(cluster: DaemonCluster, mission: str) -> float | None:
    """The mission's time as the acting executive says it, running or already ended (at --speed 20 a resumed
    mission may end between two asks on a slow machine); None while none answers (a frozen one holds a query up
    until zenoh drops its link) or it is busy."""
    try:
        missions = cluster.client().missions()
    except BusFailure:
        return None
    for m in missions:
        if m.get("id") == mission and isinstance(m.get("time"), int | float):
            return float(m["time"])
    return None


def run_cmd(cluster: DaemonCluster, trace: Path) -> list[str]:
    return [*MISSIONCTL, "run", str(CORRIDOR), "--config", str(cluster.hosts_file), "--speed", "20", "--json",
            "--trace", str(trace)]


def started(cluster: DaemonCluster, trace: Path, after: float = 30.0) -> str:
    """The followed mission's id, once it has run `after` seconds of sim time."""
    eventually(lambda: trace.exists() and any(r["kind"] == "granted" for r in read_trace(trace)),
               "the mission to run", 60, poll=0.1)
    mission = str(read_trace(trace)[0]["mission"])
    eventually(lambda: max(r["at"] for r in read_trace(trace)) > after, f"{after:g} s of the mission", 60, poll=0.2)
    return mission


def check_report(cluster: DaemonCluster, run: object, out: str, err: str, mission: str, trace: Path,
                 noticed: bool = True) -> None:
    """The attached client's report: the same mission to success, resumed once, its records numbered on (and, if
    `noticed`, the client said the controller was away and back: a handover may be too quick to notice)."""
    assert getattr(run, "returncode", None) == 0, (out[-2000:], err[-3000:], cluster.log("controller")[-3000:],
                                                   cluster.log("controller2")[-3000:])
    report = json.loads(out)
    assert report["outcome"] == "success" and report["id"] == mission, report
    assert not noticed or ("controller" in err and "resumed" in err), err[-2000:]  # the client said what happened
    recs = read_trace(trace)
    assert {r["mission"] for r in recs} == {mission}
    assert len([r for r in recs if r["kind"] == "restored"]) == 1
    seqs = [r["seq"] for r in recs]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs), "records are numbered on, never again"


def test_the_standby_takes_the_mission_over_when_the_acting_controller_is_killed(cluster: DaemonCluster,
                                                                                 tmp_path: Path) -> None:
    first = acting(cluster)
    standby = "controller2" if first == "controller" else "controller"
    old_term = term_of(cluster, first)
    trace = tmp_path / "run.jsonl"
    with running(run_cmd(cluster, trace)) as run:
        mission = started(cluster, trace)
        cluster.procs[first].send_signal(signal.SIGKILL)
        cluster.procs[first].wait(timeout=10)
        eventually(lambda: "elected the acting controller" in cluster.log(standby), f"{standby} to be elected", 30)
        out, err = run.communicate(timeout=240)
    check_report(cluster, run, out, err, mission, trace)
    assert term_of(cluster, standby) > old_term  # etcd's revisions: a later election has a larger term
    assert f"mission {mission} resumed" in cluster.log(standby)
    [status] = [m for m in cluster.client().missions() if m.get("id") == mission]
    assert status["outcome"] == "success" and status["resumed"]["paused"] > 0, status
    eventually(lambda: not [i for i in cluster.client().components().instances if i.mission == mission],
               "ranger1 to retire the mission's instances", 10)
    cluster.start(first)  # back as a standby: the other one acts
    cluster.wait_ready([first])
    eventually(lambda: f"standby controller: {standby} acts" in cluster.log(first), f"{first} standing by", 30)


def test_a_frozen_controller_that_wakes_up_is_fenced_and_its_term_refused(cluster: DaemonCluster,
                                                                         tmp_path: Path) -> None:
    first = acting(cluster)
    standby = "controller2" if first == "controller" else "controller"
    old_term = term_of(cluster, first)
    trace = tmp_path / "run.jsonl"
    frozen = cluster.procs[first]
    with running(run_cmd(cluster, trace)) as run:
        mission = started(cluster, trace, after=20.0)
        frozen.send_signal(signal.SIGSTOP)
        try:
            eventually(lambda: "elected the acting controller" in cluster.log(standby)
                       and term_of(cluster, standby) > old_term, f"{standby} to be elected", 30)
            eventually(lambda: (mission_time(cluster, mission) or 0.0) > 0.0, "the mission running again", 30,
                       explain=lambda: cluster.tails(standby, "ranger1"))
        finally:
            frozen.send_signal(signal.SIGCONT)
        eventually(lambda: "stepped down, a standby again" in cluster.log(first), f"{first} to step down", 30)
        out, err = run.communicate(timeout=240)
    check_report(cluster, run, out, err, mission, trace)
    log = cluster.log(first)
    assert f"fenced: this controller (term {old_term}) stops acting" in log, log[-3000:]
    assert frozen.poll() is None  # it stays, as a standby
    eventually(lambda: f"standby controller: {standby} acts" in cluster.log(first), f"{first} standing by", 30)
    # nothing of the old term is taken on the robot's host: a command carrying it is refused, naming the terms
    bus = ZenohBus(connect=[cluster.endpoints[NAMES.index("ranger1")]], name="test-old-term")
    try:
        key = f"drd/{cluster.name}/host/ranger1/creator"
        reply = bus.call(key, ComponentCall("step", mission, "Mission", "Mission", "corridor", term=float(old_term)),
                         timeout=5)
        assert isinstance(reply, ComponentReply) and "refuses a call from an older controller" in (reply.error or "")
        gates = bus.call(key, GateUpdate([], "corridor", 0, float(old_term)), timeout=5)
        assert isinstance(gates, GateUpdateReply) and gates.records == []
    finally:
        bus.close()
    assert "refused a call from an older controller" in cluster.log("ranger1")


def test_a_clean_stop_of_the_acting_controller_hands_its_mission_over(cluster: DaemonCluster, tmp_path: Path) -> None:
    """SIGTERM (as `drd stop`): the controller stops acting first, then drops its lease; the standby resumes the
    mission (not stopped: with a store, a stopping controller's missions go on elsewhere)."""
    first = acting(cluster)
    standby = "controller2" if first == "controller" else "controller"
    old_term = term_of(cluster, first)
    trace = tmp_path / "run.jsonl"
    with running(run_cmd(cluster, trace)) as run:
        mission = started(cluster, trace, after=20.0)
        cluster.procs[first].send_signal(signal.SIGTERM)
        assert cluster.procs[first].wait(timeout=30) == 0
        eventually(lambda: term_of(cluster, standby) > old_term, f"{standby} to be elected", 30)
        out, err = run.communicate(timeout=240)
    check_report(cluster, run, out, err, mission, trace, noticed=False)
    after = cluster.log(first).split("received SIGTERM")[-1]
    assert "stops acting" not in after and "stepped down" not in after  # it resigned; nobody fenced it
    assert "ended stopped" not in after and "the world is gone" not in after, after  # cluster audit 17, D5
    cluster.start(first)
    cluster.wait_ready([first])
    eventually(lambda: f"standby controller: {standby} acts" in cluster.log(first), f"{first} standing by", 30)
