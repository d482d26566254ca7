"""A forged controller's term fences nobody (bus audit, defect 1): a Creator call carrying a huge term, from a zenoh
session of the test's own, is refused and changes nothing, so a mission run afterwards on the same cluster goes on
under the real controller; the real controller's term (its daemon's start time) is the one ranger1 adopted.

Real daemons on loopback (controller; ranger1 with the simulator), every process ours and killed by pid."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from cluster_support import ROOT, DaemonCluster, corridor_hosts, serving_cluster

from drd.bus.zenoh_bus import ZenohBus
from drd.cluster.gates import GateUpdate, GateUpdateReply
from drd.cluster.remote import ComponentBatch, ComponentBatchReply, ComponentCall, ComponentReply

NAMES = ["controller", "ranger1"]
FORGED = 9.9e15


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path_factory.mktemp("forged"), NAMES, corridor_hosts) as c:
        yield c


def corridor(cluster: DaemonCluster, trace: Path) -> tuple[int, str, str]:
    """`missionctl run` of the corridor mission for 20 s of simulated time: exit code, stdout, stderr."""
    run = cluster.missionctl("run", str(ROOT / "missions" / "corridor_surveillance.mission"), "--config",
                             str(cluster.hosts_file), "--speed", "20", "--until", "20", "--json", "--trace",
                             str(trace), timeout=120)
    return run.returncode, run.stdout, run.stderr


def forge(cluster: DaemonCluster, term: float) -> list[str]:
    """Every kind of Creator call a controller makes, carrying `term`: what ranger1 answered to each."""
    bus = ZenohBus(connect=[cluster.endpoints[NAMES.index("ranger1")]], name="test-forged-term")
    key = f"drd/{cluster.name}/host/ranger1/creator"
    try:
        answers = []
        for call in (ComponentCall("no-such-op", "", "", term=term), ComponentCall("retire", "Forged-1", "", term=term),
                     ComponentCall("start", "Forged-1", "Mission/Corridor", "Corridor", "corridor", term=term)):
            reply = bus.call(key, call, timeout=5)
            assert isinstance(reply, ComponentReply), reply
            answers.append(reply.error or "")
        batch = bus.call(key, ComponentBatch([ComponentCall("step", "Forged-1", "Mission", "Mission", "corridor",
                                                            term=term)]), timeout=5)
        assert isinstance(batch, ComponentBatchReply), batch
        answers.append(batch.replies[0].error or "")
        gates = bus.call(key, GateUpdate([["clear", "ranger1", "x", 0.0, "forged"]], "corridor", 0, term), timeout=5)
        assert isinstance(gates, GateUpdateReply) and gates.records == [], gates  # nothing applied, nothing halted
        return answers
    finally:
        bus.close()


def controller_term(cluster: DaemonCluster) -> float:
    """The term ranger1 adopted, as it logged it: the real controller's (its daemon's start time)."""
    started = re.findall(r"the controller of term ([0-9.]+) acts now", cluster.log("ranger1"))
    assert started, cluster.log("ranger1")[-3000:]
    return float(started[-1])


def test_a_forged_term_is_refused_and_the_next_mission_runs(cluster: DaemonCluster, tmp_path: Path) -> None:
    code, out, err = corridor(cluster, tmp_path / "before.jsonl")
    assert "refuses" not in out + err and "sim time limit of 20 s" in out + err, (code, out[-2000:], err[-2000:])
    term = controller_term(cluster)
    assert abs(term - cluster.client().daemon_status("controller").started) < 1e-3  # its start time, as it says
    answers = forge(cluster, FORGED)
    assert all("refuses the call: term 9900000000000000 is no controller's" in a for a in answers), answers
    assert all(f"the live controller's term is {term:.3f}" in a for a in answers), answers
    # a term just above the real one is no more a controller's than a huge one
    assert all("is no controller's" in a for a in forge(cluster, term + 1.0)), "term + 1 was taken"
    code, out, err = corridor(cluster, tmp_path / "after.jsonl")
    assert "refuses" not in out + err and "sim time limit of 20 s" in out + err, (code, out[-2000:], err[-2000:])
    log = cluster.log("ranger1")
    assert "refused a call of an unvouched term: term 9900000000000000 is no controller's" in log, log[-3000:]
    assert "the controller of term 9900000000000000" not in log
    records = [json.loads(line) for line in (tmp_path / "after.jsonl").read_text().splitlines() if line.strip()]
    assert any(r["kind"] == "granted" for r in records), records[:5]  # the real controller's grants reached it
    assert "refuses a call" not in cluster.log("controller")
