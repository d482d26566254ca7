"""Two missions share one Ranger by priority on a real 2-daemon cluster (controller + simulator, ranger1).

A low-priority patrol (`--priority 2`) follows the corridor with ranger1 in 4 s slices; a second `missionctl run`
of a mission that declares `priority 1` joins it while it runs and needs the same drive. What is asserted is
what the operator and an outside tool see: both `missionctl run` reports (apart, each a success), and the two
`--trace` files checked together by `missionctl check-trace --together` and read record by record: the patrol's
drive revoked for the other mission, nobody but the holder moving the drive, the patrol resumed afterwards.
Every process is ours and killed by pid (`tests/cluster_support.py`).
"""

from __future__ import annotations

import functools
import json
import math
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NamedTuple

import pytest
from cluster_support import (
    MISSIONCTL,
    ROOT,
    DaemonCluster,
    corridor_hosts,
    eventually,
    read_trace,
    running,
    serving_cluster,
)

NAMES = ["controller", "ranger1"]

LOW = """\
mission Low {
    Patrol
    Patrol -> done after 30s
}

behavior Patrol {
    needs ranger: Ranger for 4s
    FollowCorridor(speed: 0.3)
}
"""

HIGH = """\
mission High priority 1 {
    start -> Pause
    Wait(duration: 1s) as Pause
    Pause -> Drive
    FollowCorridor(speed: 0.2) as Drive
    Drive -> done after 10s
}
"""

CONSTRAINED = """\
mission Fenced {
    needs ranger: Ranger
    constraint home: distance(ranger, point(1, 0)) <= 6
    FollowCorridor(speed: 0.5)
}
"""

HANDLED = """\
mission Fenced {
    needs ranger: Ranger
    constraint home: distance(ranger, point(1, 0)) <= 6
    start -> Out
    FollowCorridor(speed: 0.5) as Out
    Out -> Home on violation [event.name == "home"]
    ReturnToStart(speed: 0.5) as Home
}
"""


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path_factory.mktemp("cluster_multi"), NAMES,
                         functools.partial(corridor_hosts, simulator_on_controller=True)) as c:
        yield c


class TwoRuns(NamedTuple):
    """What the low-priority patrol and the High run that joined it left behind, for the assertions to read."""

    low: subprocess.Popen[str]
    low_out: str
    low_err: str
    low_trace: Path
    high: subprocess.Popen[str]
    high_out: str
    high_err: str
    high_trace: Path
    ambiguous: subprocess.CompletedProcess[str]  # `missionctl stop` without an id while both ran
    seen: list[tuple[Any, dict[str, list[str]]]]  # the blocked waiter status showed, with the queues


def run_low_then_high(cluster: DaemonCluster, tmp_path: Path) -> TwoRuns:
    """Start the patrol, let High join it once it runs, try an ambiguous stop while both run, and wait for both:
    the processes and the live status views are here, so the test reads only what they left."""
    (tmp_path / "low.mission").write_text(LOW)
    (tmp_path / "high.mission").write_text(HIGH)
    low_trace, high_trace = tmp_path / "low.jsonl", tmp_path / "high.jsonl"
    config = ["--config", str(cluster.hosts_file), "--speed", "4", "--json"]
    low_cmd = [*MISSIONCTL, "run", str(tmp_path / "low.mission"), *config, "--priority", "2", "--trace", str(low_trace)]
    high_cmd = [*MISSIONCTL, "run", str(tmp_path / "high.mission"), *config, "--speed", "8",  # the world stays at 4x
                "--trace", str(high_trace)]
    client = cluster.client()
    with running(low_cmd) as low:
        def patrolling() -> bool:
            assert low.poll() is None, low.communicate()
            return any(m.get("outcome") is None and "Low" in str(m.get("id")) for m in client.missions())

        eventually(patrolling, "the low-priority patrol to run", 30, poll=0.1)
        with running(high_cmd) as high:
            eventually(lambda: sum(m.get("outcome") is None for m in client.missions()) == 2, "both to run", 30,
                       poll=0.05)
            seen: list[tuple[Any, dict[str, list[str]]]] = []
            eventually(lambda: blocked_waiter(client, seen), "a waiter blocked by the other mission", 30, poll=0.05)
            ambiguous = cluster.missionctl("stop", "--config", str(cluster.hosts_file), timeout=30)
            high_out, high_err = high.communicate(timeout=90)
        low_out, low_err = low.communicate(timeout=90)
    return TwoRuns(low, low_out, low_err, low_trace, high, high_out, high_err, high_trace, ambiguous, seen)


def test_two_missions_share_one_ranger_by_priority(cluster: DaemonCluster, tmp_path: Path) -> None:
    runs = run_low_then_high(cluster, tmp_path)
    low_err, high_err, ambiguous = runs.low_err, runs.high_err, runs.ambiguous
    assert runs.high.returncode == 0, (high_err[-2000:], cluster.log("controller")[-3000:])
    assert runs.low.returncode == 0, (low_err[-2000:], cluster.log("controller")[-3000:])
    # `missionctl stop` without an id, two missions running: it names them and stops neither
    assert ambiguous.returncode == 2 and "2 missions run" in ambiguous.stderr, ambiguous.stderr
    assert "--all" in ambiguous.stderr
    high_report, low_report = json.loads(runs.high_out), json.loads(runs.low_out)
    assert high_report["outcome"] == low_report["outcome"] == "success"
    assert "priority 1" in high_err and "priority 2" in low_err  # each run says the rank it got
    # the joining run is told its --speed is not the world's, and its report has the world's pace (not a cluster
    # that fell behind the 8x it asked)
    assert "--speed 8 not applied" in high_err, high_err[-2000:]
    assert high_report["speed"] == low_report["speed"] == 4
    assert_queued_behind_the_other(runs.seen, low_report, high_report)
    # the patrol's progress line said it was suspended while High drove (it said `active Patrol`: audit D7)
    assert "suspended FollowCorridor" in low_err, low_err[-2000:]
    low_recs, high_recs = read_trace(runs.low_trace), read_trace(runs.high_trace)
    assert {r["mission"] for r in low_recs} == {low_report["id"]}, "each trace holds its own mission"
    assert {r["mission"] for r in high_recs} == {high_report["id"]}
    assert_checked_together(cluster, runs.low_trace, runs.high_trace)
    assert_high_drove_between(low_recs + high_recs, low_report["id"], high_report["id"])


def assert_queued_behind_the_other(seen: list[tuple[Any, dict[str, list[str]]]], low_report: dict[str, Any],
                                   high_report: dict[str, Any]) -> None:
    """status's queues come from the manager's claims: the waiter stands in ranger1's queue, ranked by its
    mission's priority, blocked by the other mission's holder, which holds ranger1 (multi-mission audit D2)."""
    waiter, queues = seen[0]
    mine, other = (low_report, high_report) if waiter.mission == low_report["id"] else (high_report, low_report)
    assert waiter.mission_priority == mine["priority"]
    assert [b.holder.split("/", 1)[0] for b in waiter.blocked_by] == [other["id"]], waiter
    # the blocker holds ranger1 whole (`ranger: ranger1`, when the patrol blocks High) or its drive (when High, which
    # needs the drive, blocks the preempted patrol): whichever waits first
    assert set(waiter.blocked_by[0].holds.values()) & {"ranger1", "ranger1.drive"}, waiter
    assert waiter.holder in queues["ranger1.drive"], queues


def assert_checked_together(cluster: DaemonCluster, low_trace: Path, high_trace: Path) -> None:
    """The outside check: only the holder moved a device, no double hold, everything released."""
    check = subprocess.run([*MISSIONCTL, "check-trace", "--together", str(low_trace), str(high_trace), "--config",
                            str(cluster.hosts_file), "--json"], cwd=ROOT, capture_output=True, text=True,
                           timeout=60, check=False)
    assert check.returncode == 0, check.stdout + check.stderr
    [together] = json.loads(check.stdout)
    assert together["ok"] and together["accepted"] > 0 and together["grants"] >= 3


def assert_high_drove_between(records: list[dict[str, Any]], low: str, high: str) -> None:
    """Read in causal order: the patrol's drive is revoked for High, High drives, then the patrol resumes."""
    merged = sorted(records, key=lambda r: r["seq"])
    drive = "ranger1.drive"
    revoked = next(i for i, r in enumerate(merged) if r["kind"] == "revoked" and drive in r["resources"])
    assert merged[revoked]["mission"] == low
    assert "High" in merged[revoked]["reason"], merged[revoked]
    high_grant = next(i for i, r in enumerate(merged)
                      if r["kind"] == "granted" and r["mission"] == high and drive in r["epochs"])
    assert high_grant > revoked, "the drive is granted to High only after the patrol lost it"
    high_done = next(i for i, r in enumerate(merged) if r["kind"] == "released" and drive in r["resources"]
                     and r["mission"] == high)
    resumed = next(i for i, r in enumerate(merged) if r["kind"] == "resumed" and r["mission"] == low)
    assert high_grant < high_done < resumed
    window = merged[high_grant:high_done]
    moved = [r for r in window if r["kind"] == "command" and r["device"] == drive and r["accepted"]]
    assert moved and all(r["mission"] == high for r in moved), \
        "while High held the drive, only High moved it"
    assert [r for r in merged[resumed:] if r["kind"] == "command" and r["device"] == drive and r["accepted"]
            and r["mission"] == low], "the patrol drove again once resumed"


def blocked_waiter(client: Any, seen: list[tuple[Any, dict[str, list[str]]]]) -> bool:
    """Whether the manager has a waiter that another mission's holder blocks: kept in `seen`, with each unit's
    queue."""
    reply = client.resources()
    for w in reply.queue:
        if any(b.holder.split("/", 1)[0] != w.mission and not b.waiting for b in w.blocked_by):
            seen.append((w, {u.id: u.queue for u in reply.units}))
            return True
    return False


def robot_distance(cluster: DaemonCluster, robot: str, x: float, y: float) -> float:
    """How far the simulated robot stands from (x, y), asked of the simulator itself (the robot's side)."""
    from drd.sim.service import SimReply, SimRequest, decode_value

    reply = cluster.client().bus.call(f"drd/{cluster.name}/sim", SimRequest("call", "odometry", [robot]), timeout=5)
    assert isinstance(reply, SimReply) and reply.error == "", reply
    pose = decode_value(reply.value)
    px, py = pose.x, pose.y
    return math.hypot(px - x, py - y)


def run_traced(cluster: DaemonCluster, tmp_path: Path, text: str) -> tuple[int, dict[str, Any], list[dict[str, Any]]]:
    mission, trace = tmp_path / "c.mission", tmp_path / "c.jsonl"
    mission.write_text(text)
    r = cluster.missionctl("run", str(mission), "--config", str(cluster.hosts_file), "--speed", "8", "--json",
                           "--trace", str(trace), timeout=120)
    assert r.stdout, (r.stderr[-2000:], cluster.log("controller")[-3000:])
    return r.returncode, json.loads(r.stdout), read_trace(trace)


def test_a_constraint_is_enforced_on_the_robots_host_and_stops_it_at_the_fence(cluster: DaemonCluster,
                                                                              tmp_path: Path) -> None:
    rc, report, recs = run_traced(cluster, tmp_path, CONSTRAINED)
    assert rc == 1 and report["outcome"] == "failure", report
    assert "constraint home violated" in report["reason"], report["reason"]
    # refused at ranger1's own gate (the controller's monitor does not refuse commands, it unbinds)
    refused = [r for r in recs if r["kind"] == "command" and not r["accepted"]]
    assert refused and "constraint home" in refused[0]["reason"], refused[:3]
    assert any(r["kind"] == "event" and r["name"] == "violation" and r["fields"]["name"] == "home" for r in recs)
    distance = robot_distance(cluster, "ranger1", 1.0, 0.0)
    assert 5.4 < distance <= 6.1, distance  # stopped at the fence: not before it, not past it


def test_a_violation_handler_on_a_cluster_takes_over_and_drives_back(cluster: DaemonCluster, tmp_path: Path) -> None:
    rc, report, recs = run_traced(cluster, tmp_path, HANDLED)
    assert rc == 0 and report["outcome"] == "success", report
    taken = [(r["path"], r["target"]) for r in recs if r["kind"] == "taken" and r["trigger"] == "event"]
    assert taken == [("Fenced/Out", "Fenced/Home")], taken
    home = [r for r in recs if r["kind"] == "command" and r["path"] == "Fenced/Home"]
    assert home and all(r["accepted"] for r in home)  # driving back in breaks nothing
    assert robot_distance(cluster, "ranger1", 1.0, 0.0) < 1.0  # home again


LIVE_GUARD = """\
mission Reach {
    needs ranger: Ranger
    start -> Out
    FollowCorridor(speed: 0.5) as Out
    Out -> done when ranger.x > 4
}
"""


def test_a_guard_reads_the_robots_live_pose_on_a_cluster(cluster: DaemonCluster, tmp_path: Path) -> None:
    rc, report, recs = run_traced(cluster, tmp_path, LIVE_GUARD)
    assert rc == 0 and report["outcome"] == "success", report
    taken = [r for r in recs if r["kind"] == "taken" and r["label"] == "when ranger.x > 4"]
    assert taken and 5.9 < taken[0]["at"] < 9.0, taken  # 3 m at 0.5 m/s from x = 1, read live each cycle
    x = robot_distance(cluster, "ranger1", 0.0, 0.0)
    assert 4.0 < x < 4.6, x
