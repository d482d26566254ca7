"""`missionctl run` on a real 3-daemon cluster (controller + simulator, ranger1, a spare worker) on loopback.

One cluster serves the module's tests, in file order: an invalid mission (exit 2, located error), a detached
run seen by `status --json` and stopped, Ctrl-C on a run, and last a kill -9 of ranger1 mid-mission (exit 1
with the reason, within lease + a few seconds). The corridor mission to its end, with the simulator where the
repository's hosts.yaml puts it, is in `test_cluster_sim_host.py`. Every process is ours and killed by pid
(`tests/cluster_support.py`).
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

import psutil
import pytest
from cluster_support import MISSIONCTL, ROOT, DaemonCluster, eventually, serving_cluster

NAMES = ["controller", "ranger1", "spare"]
MISSION = "missions/corridor_surveillance.mission"


def corridor_hosts(cluster: DaemonCluster, *, simulator: str = "controller") -> str:
    """The repository's hosts.yaml (controller, ranger1 with six Scouts) on our free ports, plus a spare worker,
    with the test lease. The simulator runs on `simulator`: on the controller by default (the repository puts it
    on ranger1, for speed), so that killing ranger1 tests the loss of a Ranger's host, not of the world."""
    text = (ROOT / "hosts.yaml").read_text()
    if simulator == "controller":
        text = text.replace("roles: [worker, simulator]", "roles: [worker]")
        text = text.replace("roles: [controller]", "roles: [controller, simulator]")
    ports = dict(zip(NAMES, cluster.ports, strict=True))
    text = text.replace("name: corridor", f"name: {cluster.name}").replace("lease: 3s", "lease: 1000ms")
    text = text.replace("127.0.0.1:7447", f"127.0.0.1:{ports['controller']}")
    text = text.replace("127.0.0.1:7448", f"127.0.0.1:{ports['ranger1']}")
    return text.replace("  ranger1:\n", f"  spare:\n    endpoint: tcp/127.0.0.1:{ports['spare']}\n"
                        "    roles: [worker]\n\n  ranger1:\n", 1)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    with serving_cluster(tmp_path_factory.mktemp("cluster_run"), NAMES, corridor_hosts) as c:
        yield c


def missionctl(c: DaemonCluster, *args: str, timeout: float = 90.0) -> subprocess.CompletedProcess[str]:
    return c.missionctl(*args, "--config", str(c.hosts_file), timeout=timeout)


def test_an_invalid_mission_is_refused_by_the_controller_with_a_located_error(cluster: DaemonCluster,
                                                                              tmp_path: Path) -> None:
    bad = tmp_path / "bad.mission"
    bad.write_text("mission Bad {\n    FollowCorridor(sped: 0.5)\n}\n")
    r = missionctl(cluster, "run", str(bad))
    assert r.returncode == 2, r.stderr
    assert "bad.mission:2:" in r.stderr and "sped" in r.stderr  # file:line:col, the message, the caret
    assert "not run" in r.stderr
    # under --json, the diagnostics `validate --json` gives (users audit 15, D6: no code, end_line, end_column)
    as_json = missionctl(cluster, "run", str(bad), "--json")
    [validated] = json.loads(missionctl(cluster, "validate", str(bad), "--json").stdout)
    assert as_json.returncode == 2 and json.loads(as_json.stderr)["diagnostics"] == validated["diagnostics"]
    assert {"code", "end_line", "end_column"} <= set(validated["diagnostics"][0])


def test_a_valid_mission_too_large_to_send_is_refused_as_input_not_as_a_crash(cluster: DaemonCluster,
                                                                             tmp_path: Path) -> None:
    """A mission under the 1 MB source limit whose JSON is over 1 MiB (its quotes escaped) validates, and `run` says it
    cannot be sent (exit 2), not "internal error" (exit 70)."""
    big = tmp_path / "big.mission"
    big.write_text("".join(f'# {chr(34) * 80}\n' for _ in range(7000)) + (ROOT / MISSION).read_text(), encoding="utf-8")
    assert big.stat().st_size < 1_000_000
    assert missionctl(cluster, "validate", str(big)).returncode == 0
    r = missionctl(cluster, "run", str(big))
    assert r.returncode == 2, r.stderr
    assert "cannot send this request: too large" in r.stderr and "internal error" not in r.stderr


def test_a_submission_its_client_gave_up_on_never_starts(cluster: DaemonCluster) -> None:
    """All or nothing (issue #18): a request whose client stopped waiting is refused, and nothing runs later."""
    from drd.daemon.missions import RunMission, RunReply, run_key

    client = cluster.client(timeout=5.0)
    source = (ROOT / MISSION).read_text(encoding="utf-8")
    late = RunMission(source, "late.mission", speed=10.0, give_up_at=time.time() - 1.0)
    reply = client.bus.call(run_key(cluster.name), late, timeout=15.0)
    assert isinstance(reply, RunReply) and not reply.ok and reply.mission == ""
    assert "not started: the client stopped waiting" in reply.diagnostics[0]
    time.sleep(2.0)  # a mission started behind the refusal would show by now
    assert [m for m in client.missions() if m.get("outcome") is None] == []
    in_time = RunMission("mission Quick {\n    Wait(duration: 1s)\n}\n", "quick.mission", speed=10.0,
                         give_up_at=time.time() + 30.0)
    reply = client.bus.call(run_key(cluster.name), in_time, timeout=15.0)
    assert isinstance(reply, RunReply) and reply.ok and reply.mission.startswith("Quick-")
    eventually(lambda: any(m.get("id") == reply.mission and m.get("outcome") == "success"
                           for m in client.missions()), "the mission sent in time to succeed", timeout=30.0)


def test_params_set_the_missions_variables_on_the_controller(cluster: DaemonCluster, tmp_path: Path) -> None:
    choose = tmp_path / "choose.mission"
    choose.write_text("mission Choose {\n    var ok: bool = false\n    Wait(duration: 1s)\n"
                      "    Wait -> done [ok]\n    Wait -> fail [not ok]\n}\n")
    r = missionctl(cluster, "run", str(choose), "--speed", "10", "--param", "ok=true", "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["outcome"] == "success", r.stderr[-2000:]
    r = missionctl(cluster, "run", str(choose), "--param", "ok=maybe")
    assert r.returncode == 2 and "ok is a bool, and 'maybe' is not one" in r.stderr, r.stderr


def test_a_cluster_run_records_and_replays_to_the_same_report(cluster: DaemonCluster, tmp_path: Path) -> None:
    """`missionctl run --record` (issue #13): the records the client followed, replayed without any cluster."""
    mission = tmp_path / "short.mission"
    mission.write_text("mission Short {\n    start -> first\n    Wait(duration: 2s) as first\n"
                       "    Wait(duration: 1s) as second\n    first -> second\n}\n")
    r = missionctl(cluster, "run", str(mission), "--speed", "10", "--record", str(tmp_path / "run.mcap"), "--json")
    assert r.returncode == 0, r.stderr[-2000:]
    replay = subprocess.run([*MISSIONCTL, "replay", str(tmp_path / "run.mcap"), "--json"], cwd=tmp_path,
                            capture_output=True, text=True, timeout=60, check=False)
    assert replay.returncode == 0, replay.stderr[-2000:]
    ran, replayed = json.loads(r.stdout), json.loads(replay.stdout)
    assert replayed == ran
    assert [row["path"] for row in replayed["timeline"]] == ["Short", "Short/first", "Short/second"]
    # `mission` and `id` mean what a dry-run's report means by them: the mission's name, the mission's id
    assert ran["mission"] == "Short" and re.fullmatch(r"Short-\d+", ran["id"]), (ran["mission"], ran["id"])
    text = missionctl(cluster, "run", str(mission), "--speed", "10")
    assert text.returncode == 0, text.stderr[-2000:]
    rows = [line.split("│")[1].strip() for line in text.stdout.splitlines() if line.count("│") == 5]
    assert rows == ["Short", "first", "second"], text.stdout  # paths below the mission, as the dry-run's


def test_detach_then_status_shows_the_active_states_then_stop(cluster: DaemonCluster) -> None:
    r = missionctl(cluster, "run", MISSION, "--detach", "--speed", "5", "--json")
    assert r.returncode == 0, r.stderr
    started = json.loads(r.stdout)  # one strict JSON object under --json, the id in it
    mid = started["mission"]
    assert mid.startswith("CorridorSurveillance-") and started["speed"] == 5 and started["world"]

    def active() -> list[str]:
        s = missionctl(cluster, "status", "--json")
        assert s.returncode == 0, s.stderr
        missions = {m["id"]: m for m in json.loads(s.stdout)["missions"]}
        tree = missions[mid]["tree"]
        out, stack = [], [tree] if tree else []
        while stack:
            n = stack.pop()
            out.append(f"{n['path']}:{n['phase']}")
            stack.extend(n["children"])
        return out

    eventually(lambda: any("FollowCorridor:active" in p for p in active()), "FollowCorridor to be active", 20)
    # `time` is the world's clock, which the world's missions share; the mission began at `started`
    shown = {m["id"]: m for m in json.loads(missionctl(cluster, "status", "--json").stdout)["missions"]}[mid]
    assert 0.0 <= shown["started"] <= shown["time"], shown
    client = cluster.client()
    tokens = f"drd/{cluster.name}/instance/**"
    mine = re.compile(rf"drd/{cluster.name}/instance/ranger1/0/CorridorSurveillance/"  # slot 0: no other run
                      r"RoomSurveillance\[\d\]/FindNewDoor/FollowCorridor")
    eventually(lambda: any(mine.fullmatch(k) for k in client.bus.alive(tokens)), "FollowCorridor's liveliness token",
               10, poll=0.05)
    pids = {i.pid for i in client.components().instances if i.host == "ranger1"}
    assert pids and all(isinstance(p, int) and psutil.pid_exists(p) and p != cluster.pid("ranger1") for p in pids), \
        "each instance names the worker process that runs it"
    r = missionctl(cluster, "stop", mid)
    assert r.returncode == 0, r.stderr
    assert "stopped" in r.stdout
    eventually(lambda: not client.bus.alive(tokens), "the instances' tokens to vanish with the mission", 10, 0.05)
    s = json.loads(missionctl(cluster, "status", "--json").stdout)
    assert {m["id"]: m["outcome"] for m in s["missions"]}[mid] == "stopped"


@pytest.mark.parametrize(("signals", "said"), [
    ([signal.SIGINT], "Ctrl-C"), ([signal.SIGTERM], "SIGTERM"),
    ([signal.SIGTERM] * 3, "SIGTERM"),  # as timeout(1) or job control send them: the second one killed the client
    ([signal.SIGINT] * 2, "Ctrl-C"),  # one Ctrl-C to `timeout ... missionctl run` comes twice (cluster audit 17, D3)
], ids=["ctrl-c", "sigterm", "sigterm-burst", "ctrl-c-twice"])
def test_ctrl_c_on_run_stops_the_mission_and_prints_how_it_ended(cluster: DaemonCluster, tmp_path: Path,
                                                                  signals: list[int], said: str) -> None:
    """A SIGTERM (safety audit 8) as a Ctrl-C: it killed the client, leaving the mission driving and the trace
    empty. Several SIGTERMs 10 ms apart (cluster audit 10, D2): the next ones are ignored while it stops."""
    trace = tmp_path / "t.jsonl"
    cmd = [*MISSIONCTL, "run", MISSION, "--config", str(cluster.hosts_file), "--speed", "5", "--json", "--trace",
           str(trace)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        client = cluster.client()
        eventually(lambda: any(m.get("outcome") is None  # its world ticked: `time` is the executive's clock,
                               and float(m.get("time") or 0.0) - float(m.get("started") or 0.0) > 0.2  # shared by
                               for m in client.missions()), "the mission to run", 30, 0.05)  # the missions before
        for i, signum in enumerate(signals):
            if i:
                time.sleep(0.01)
            proc.send_signal(signum)
        out, err = proc.communicate(timeout=30)
        left = [m["id"] for m in client.missions() if m.get("outcome") is None]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=10)
        if any(m.get("outcome") is None for m in cluster.client().missions()):
            missionctl(cluster, "stop", "--all")  # so that a failure here does not fail the next test too
    assert proc.returncode == 1, err[-2000:]
    assert f"{said}: stopping mission" in err and "Traceback" not in err
    kinds = [json.loads(line)["kind"] for line in trace.read_text().splitlines()]
    assert kinds and kinds[0] == "entered" and kinds[-1] == "finished", (kinds[-3:], err[-3000:], out[-500:])
    report = json.loads(out)
    assert report["outcome"] == "stopped" and report["reason"] == "stopped by operator"
    assert report["timeline"][0]["entered"] == 0.0, "the report keeps what came before the Ctrl-C"
    assert 0 < report["wall_time"] < 30 and report["sim_time"] > 0
    assert not left, "nothing left running on the cluster"


def test_a_worker_daemon_keeps_no_thread_per_mission(cluster: DaemonCluster) -> None:
    """Soak audit defect 1: every world left a `drd-telemetry` thread (and its world's drivers) in each worker
    daemon, forever. The daemon's own threads (not its children's) after mission 2 and after mission 4 are the
    same: what a world starts ends with it."""
    daemon = psutil.Process(cluster.pid("ranger1"))
    counts: list[int] = []
    for _ in range(4):
        r = missionctl(cluster, "run", MISSION, "--speed", "10", "--until", "5")
        assert r.returncode in (0, 1) and "Traceback" not in r.stderr, r.stderr[-2000:]
        counts.append(daemon.num_threads())
    # a thread of the last mission's end may still be finishing (a retired worker's reaper, a late start's
    # terminate): a leak never goes, a passing thread does
    eventually(lambda: daemon.num_threads() <= counts[1], "the daemon's threads to be as after mission 2", 15,
               poll=0.2, explain=lambda: f"{counts} now {daemon.num_threads()}: {[t.id for t in daemon.threads()]}")


def test_kill_9_of_the_ranger_host_mid_mission_fails_the_mission(cluster: DaemonCluster) -> None:
    cmd = [*MISSIONCTL, "run", MISSION, "--config", str(cluster.hosts_file), "--speed", "10"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        client = cluster.client()

        def running() -> bool:
            assert proc.poll() is None, proc.communicate()
            for m in client.missions():
                stack = [m["tree"]] if m.get("outcome") is None and m.get("tree") else []
                while stack:
                    n = stack.pop()
                    if n["path"].endswith("FollowCorridor") and n["phase"] == "active":
                        return True
                    stack.extend(n["children"])
            return False

        eventually(running, "the mission's Ranger to follow the corridor", 30, poll=0.1)
        time.sleep(1.0)
        os.kill(cluster.pid("ranger1"), signal.SIGKILL)
        killed = time.monotonic()
        out, err = proc.communicate(timeout=1.0 + 10.0)  # lease + a few seconds
        assert time.monotonic() - killed < 11.0
        assert proc.returncode == 1, err[-3000:]
        assert "failure" in out
        assert "ranger1" in out or "host" in out
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=10)
