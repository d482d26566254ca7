"""Issue #15: a running movable component moved between hosts (`missionctl migrate`), and resumed from its last
snapshot when its host is killed, on a real cluster (real `drd start` processes on loopback, killed by pid).

A `Wait` is placed on a worker host (ranger1 or spare). Moved to the other one mid-wait, and back, it keeps its
deadline (its state's exit, in the trace's mission time, is its entry plus its duration: a Wait started afresh
after the move would end a whole duration after it) and its step count (the state the second move takes along
has counted on from the first's). Moving what cannot move, or to a host that cannot take it, is refused with
exit code 2 and nothing moves. Last, the host running a Wait is killed with SIGKILL: the Wait goes on elsewhere
from its last snapshot and still ends at its original deadline.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from cluster_support import MISSIONCTL, DaemonCluster, eventually, read_trace, running, serving_cluster, succeeded
from test_cluster_run import NAMES, corridor_hosts

PLACED = re.compile(r"placement: Wait on (\w+)")
WORKERS = {"ranger1", "spare"}
DURATION = 40.0
#: The trace's times are the executive's cycles: an exit is at most a couple of cycles after its due time.
SLACK = 0.5


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path_factory.mktemp("cluster_migrate"), NAMES, lambda c: corridor_hosts(c).replace(
            "placement: {cpu: 1.0, memory: 0.5, instances: 0.2}", "placement: {cpu: 0, memory: 0, instances: 1}")) as c:
        yield c


def migrate(cluster: DaemonCluster, instance: str, host: str) -> subprocess.CompletedProcess[str]:
    return cluster.missionctl("migrate", instance, "--to", host, "--config", str(cluster.hosts_file), "--json",
                              "--timeout", "20", timeout=60)


def started_wait(cluster: DaemonCluster, proc: subprocess.Popen[str], name: str) -> tuple[str, str]:
    """Once mission `name` runs (the controller says so; the trace `missionctl run` writes may lag): its id, and
    the host its Wait was placed on."""
    before = cluster.log("controller")
    started = re.compile(rf"mission ({name}-\d+) started")

    def running() -> bool:
        assert proc.poll() is None, proc.communicate()
        return started.search(cluster.log("controller")[len(before):]) is not None

    eventually(running, f"mission {name} to start", 60, poll=0.05)
    now = cluster.log("controller")[len(before):]
    hosts = PLACED.findall(now)
    assert hosts and hosts[-1] in WORKERS, "a worker takes it, never the controller"
    found = started.search(now)
    assert found is not None
    return found.group(1), hosts[-1]


def span(trace: Path, path: str) -> tuple[float, float]:
    """When the state at `path` was entered and exited (mission time), each once."""
    recs = read_trace(trace)
    entered = [r["at"] for r in recs if r["kind"] == "entered" and r["path"] == path]
    exited = [r["at"] for r in recs if r["kind"] == "exited" and r["path"] == path]
    assert len(entered) == 1 and len(exited) == 1, (entered, exited)
    return float(entered[0]), float(exited[0])


def moved(r: subprocess.CompletedProcess[str]) -> dict[str, Any]:
    assert r.returncode == 0, r.stderr[-2000:]
    reply: dict[str, Any] = json.loads(r.stdout)
    return reply


def test_a_wait_moved_twice_keeps_its_deadline_and_its_count(cluster: DaemonCluster, tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    mission, trace = tmp_path / "pause.mission", tmp_path / "trace.jsonl"
    mission.write_text(f"mission Pause {{\n    Wait(duration: {DURATION:g}s) as Hold\n}}\n")
    cmd = [*MISSIONCTL, "run", str(mission), "--config", str(cluster.hosts_file), "--speed", "2", "--json",
           "--trace", str(trace)]
    with running(cmd) as proc:
        mid, first = started_wait(cluster, proc, "Pause")
        other = (WORKERS - {first}).pop()
        monkeypatch.setenv("COLUMNS", "200")
        listed = cluster.missionctl("components", "--config", str(cluster.hosts_file), timeout=30)
        assert f"{mid}/Pause/Hold" in listed.stdout, listed.stdout  # what migrate takes (docs audit 9)
        time.sleep(1.0)  # a few seconds of mission time on the first host
        there = moved(migrate(cluster, f"{mid}/Pause/Hold", other))
        assert (there["source"], there["host"], there["component"]) == (first, other, "Wait")
        status = json.loads(cluster.missionctl("status", "--config", str(cluster.hosts_file), "--json").stdout)
        [placed] = [p for m in status["missions"] if m["id"] == mid for p in m["placements"]]
        assert (placed["host"], placed["how"]) == (other, "migrated"), placed  # not where it was (audit 24, #5)
        time.sleep(1.0)
        back = moved(migrate(cluster, "Pause/Hold", first))  # its path alone: one mission runs it
        assert (back["source"], back["host"]) == (other, first)
        out, err = proc.communicate(timeout=90)
    succeeded(cluster, proc, out, err)
    entered, exited = span(trace, "Pause/Hold")
    assert there["state"]["began"] == back["state"]["began"] == pytest.approx(entered, abs=SLACK)
    assert back["state"]["steps"] > there["state"]["steps"] > 0  # counted on across the first move
    assert exited - entered == pytest.approx(DURATION, abs=SLACK)  # its deadline, not a whole duration after a move
    log = cluster.log("controller")
    assert f"moved from {first} to {other}" in log and f"moved from {other} to {first}" in log


def test_what_cannot_move_is_refused_and_nothing_moves(cluster: DaemonCluster, tmp_path: Path) -> None:
    mission, trace = tmp_path / "look.mission", tmp_path / "trace.jsonl"
    mission.write_text("mission Look {\n    parallel all {\n        Wait(duration: 40s) as Hold\n"
                       "        Observe(duration: 40s) as Film\n    }\n}\n")
    cmd = [*MISSIONCTL, "run", str(mission), "--config", str(cluster.hosts_file), "--speed", "2", "--json",
           "--trace", str(trace)]
    with running(cmd) as proc:
        mid, host = started_wait(cluster, proc, "Look")
        other = (WORKERS - {host}).pop()
        refusals = {
            f"{mid}/Look/Film": (other, "cannot move: its manifest does not say `movable: true`"),
            f"{mid}/Look/Nowhere": (other, f"no running instance {mid}/Look/Nowhere"),
            f"{mid}/Look/Hold": ("mars", "unknown host 'mars'"),
        }
        for instance, (to, reason) in refusals.items():
            r = migrate(cluster, instance, to)
            assert r.returncode == 2 and reason in json.loads(r.stderr)["error"], (instance, r.stderr)
        r = migrate(cluster, f"{mid}/Look/Hold", "controller")
        assert r.returncode == 2 and "does not run components" in r.stderr, r.stderr
        out, err = proc.communicate(timeout=90)
    succeeded(cluster, proc, out, err)
    assert "moved from" not in cluster.log("controller").split(f"mission {mid} started")[-1]


def test_a_move_not_answered_within_the_timeout_says_its_outcome_is_unknown(cluster: DaemonCluster,
                                                                           tmp_path: Path) -> None:
    """Cluster audit 10, D3: the client gave up (exit 2, "no reply"), which says nothing moved, while the
    controller went on and sometimes moved it. Now it says whether it moved is not known, and where to look."""
    mission = tmp_path / "linger.mission"
    mission.write_text("mission Linger {\n    Wait(duration: 30s) as Hold\n}\n")
    cmd = [*MISSIONCTL, "run", str(mission), "--config", str(cluster.hosts_file), "--speed", "2", "--json"]
    with running(cmd) as proc:
        mid, host = started_wait(cluster, proc, "Linger")
        other = (WORKERS - {host}).pop()
        pid = cluster.pid(other)
        for _ in range(3):
            os.kill(pid, signal.SIGSTOP)  # it takes the start, and answers nothing until it is let go
            try:
                r = cluster.missionctl("migrate", f"{mid}/Linger/Hold", "--to", other, "--config",
                                       str(cluster.hosts_file), "--timeout", "0.3", timeout=60)
            finally:
                os.kill(pid, signal.SIGCONT)
            if f"host {other} is down" not in r.stderr:
                break
            # the client took longer to start than the lease on a loaded machine, and the frozen host was rightly
            # judged down before the move was asked: once it is back, again
            cluster.wait_up(names=[other], timeout=30)
        assert r.returncode == 2, (r.stdout, r.stderr)
        assert "whether it moved is not known" in r.stderr and "missionctl components" in r.stderr, r.stderr
        out, err = proc.communicate(timeout=90)
    succeeded(cluster, proc, out, err)


def test_a_host_frozen_past_the_lease_no_longer_lists_what_it_retired(cluster: DaemonCluster, tmp_path: Path) -> None:
    """Cluster audit 14, D2: woken, the host retired its instance and announced so before its session was back: the
    controller's Component Database listed the dead instance `running` (its pid gone) beside its re-placed copy."""
    from cluster_support import LEASE

    mission = tmp_path / "frozen.mission"
    mission.write_text(f"mission Frozen {{\n    Wait(duration: {DURATION:g}s) as Hold\n}}\n")
    cmd = [*MISSIONCTL, "run", str(mission), "--config", str(cluster.hosts_file), "--speed", "2", "--json"]
    with running(cmd) as proc:
        _mid, host = started_wait(cluster, proc, "Frozen")
        os.kill(cluster.pid(host), signal.SIGSTOP)
        try:
            time.sleep(7 * LEASE)  # the audit's freeze: 7 s past a 3 s lease
        finally:
            os.kill(cluster.pid(host), signal.SIGCONT)

        def listed() -> list[tuple[str, int]]:
            r = cluster.missionctl("components", "--config", str(cluster.hosts_file), "--json", timeout=30)
            return [(i["host"], i["pid"]) for i in json.loads(r.stdout)["instances"] if i["name"].endswith("Hold")]

        eventually(lambda: [h for h, _pid in listed()] == [(WORKERS - {host}).pop()],
                   "only the re-placed Wait listed", 30, poll=0.5)
        assert all(os.path.exists(f"/proc/{pid}") for _h, pid in listed())
        out, err = proc.communicate(timeout=120)
    succeeded(cluster, proc, out, err)


def test_a_wait_whose_host_is_killed_resumes_elsewhere_with_its_remaining_time(cluster: DaemonCluster,
                                                                                tmp_path: Path) -> None:
    """Last in this module: a worker host is killed."""
    mission, trace = tmp_path / "pause.mission", tmp_path / "trace.jsonl"
    mission.write_text(f"mission Pause {{\n    Wait(duration: {DURATION:g}s) as Hold\n}}\n")
    cmd = [*MISSIONCTL, "run", str(mission), "--config", str(cluster.hosts_file), "--speed", "2", "--json",
           "--trace", str(trace)]
    with running(cmd) as proc:
        _mid, first = started_wait(cluster, proc, "Pause")
        time.sleep(1.5)  # some of its time goes by on the first host
        cluster.procs[first].send_signal(signal.SIGKILL)
        out, err = proc.communicate(timeout=90)
    succeeded(cluster, proc, out, err)
    other = (WORKERS - {first}).pop()
    assert f"Pause/Hold re-placed on {other}" in cluster.log("controller")
    said = [r["text"] for r in read_trace(trace) if r["kind"] == "log"]
    assert f"Wait placed again on {other} from its last snapshot: its host {first} was lost" in said, said
    entered, exited = span(trace, "Pause/Hold")
    assert exited - entered == pytest.approx(DURATION, abs=SLACK)  # its remaining time, not its whole duration
