"""What the audit of user-written missions found in the CLI, as a user meets it (real console scripts, a real
2-daemon cluster on loopback for `stop`): `plan` never cuts a line silently, `check-trace` refuses what is not a
trace at its line (exit 2, never 70 nor a pass), `stop` does not call an ended mission stopped nor list it as
running, and `--help` lists `--version`."""

from __future__ import annotations

import json
import os
import pty
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from cluster_support import DRD, MISSIONCTL, DaemonCluster, corridor_hosts, serving_cluster

LONG = """mission LongLabels {
    var sightings: int = 0
    Wait(duration: 1s) as first
    Wait(duration: 1s) as second
    start -> first
    first -> second / set sightings = sightings + 1; log "sighting number {sightings} of the long watch, in full"
    second -> done
}
"""
ACTION = 'set sightings = sightings + 1; log "sighting number {sightings} of the long watch, in full"'
GOOD_TRACE = [
    '{"kind":"granted","at":0,"path":"M/a","resources":{"d":"d1"},"epochs":{"d1":1},"mission":"M-1"}',
    '{"kind":"command","at":1,"path":"M/a","device":"d1","method":"stop","epoch":1,"accepted":true,"reason":"",'
    '"mission":"M-1"}',
    '{"kind":"released","at":2,"path":"M/a","resources":["d1"],"reason":"exit","mission":"M-1"}',
    '{"kind":"finished","at":2,"path":"M","outcome":"success","reason":"","mission":"M-1"}',
]


def missionctl(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args], capture_output=True, text=True, timeout=60, cwd=cwd, check=False)


def test_plan_to_a_pipe_or_a_file_keeps_every_line_whole(tmp_path: Path) -> None:
    mission = tmp_path / "long.mission"
    mission.write_text(LONG)
    piped = missionctl("plan", str(mission))
    assert piped.returncode == 0, piped.stderr
    [line] = [x for x in piped.stdout.splitlines() if "→ second" in x]
    assert line.endswith(f"/ {ACTION}") and len(line) > 100, line  # was cut at 80 columns, mid-action
    written = missionctl("plan", str(mission), "-o", str(tmp_path / "plan.txt"))
    assert written.returncode == 0, written.stderr
    assert (tmp_path / "plan.txt").read_text() == piped.stdout


def test_plan_on_a_terminal_ends_a_cut_line_with_an_ellipsis(tmp_path: Path) -> None:
    mission = tmp_path / "long.mission"
    mission.write_text(LONG)
    master, slave = pty.openpty()
    try:
        proc = subprocess.Popen([*MISSIONCTL, "plan", str(mission)], stdout=slave, stderr=slave,
                                env={**os.environ, "COLUMNS": "60", "TERM": "xterm"})
        os.close(slave)
        shown = b"".join(read_all(master)).decode()
        assert proc.wait(timeout=60) == 0, shown
    finally:
        os.close(master)
    lines = [re.sub(r"\x1b\[[0-9;]*m", "", x) for x in shown.splitlines()]
    [line] = [x for x in lines if "→ second" in x]
    assert line.endswith("…") and len(line) <= 60, line


def read_all(fd: int) -> Iterator[bytes]:
    """A pty's output until the other side closed (Linux says EIO then)."""
    while True:
        try:
            chunk = os.read(fd, 65536)
        except OSError:
            return
        if not chunk:
            return
        yield chunk


@pytest.mark.parametrize(("lines", "where", "message"), [
    ([GOOD_TRACE[0], '{"kind":"command","at":"x","path":"M/a"}'], 2, '`at` is "x", not a number'),
    ([GOOD_TRACE[0], '{"kind":"command"}'], 2, "`command` record without `at`"),
    ([*GOOD_TRACE[:2], '{"kind": "released", "at": 2'], 3,
     "not a JSON record: Expecting ',' delimiter (column 29)"),
    (['{"kind":"command","at":1,"path":"M/a","method":"stop","epoch":1,"accepted":true,"reason":""}'], 1,
     "`command` record without `device`"),
])
def test_check_trace_refuses_a_bad_record_at_its_line(tmp_path: Path, lines: list[str], where: int,
                                                      message: str) -> None:
    trace = tmp_path / "bad.jsonl"
    trace.write_text("\n".join(lines) + "\n")
    r = missionctl("check-trace", "bad.jsonl", cwd=tmp_path)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert f"error: bad.jsonl:{where}: " in r.stderr and message in r.stderr, r.stderr
    assert "internal error" not in r.stderr and "✓" not in r.stdout
    as_json = missionctl("check-trace", "bad.jsonl", "--json", cwd=tmp_path)
    assert as_json.returncode == 2 and json.loads(as_json.stderr)["error"].startswith(f"bad.jsonl:{where}: ")


def test_check_trace_of_an_empty_file_has_nothing_to_check_and_a_good_one_passes(tmp_path: Path) -> None:
    (tmp_path / "empty.jsonl").write_text("\n")
    r = missionctl("check-trace", "empty.jsonl", cwd=tmp_path)
    assert r.returncode == 2 and "empty.jsonl: no records: there is nothing to check" in r.stderr, r.stderr
    (tmp_path / "good.jsonl").write_text("\n".join(GOOD_TRACE) + "\n")
    ok = missionctl("check-trace", "good.jsonl", cwd=tmp_path)
    assert ok.returncode == 0 and "1 accepted commands of 1" in ok.stdout, ok.stderr


@pytest.mark.parametrize("tool", [MISSIONCTL, DRD])
def test_help_lists_version(tool: list[str]) -> None:
    r = subprocess.run([*tool, "--help"], capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 0 and re.search(r"^\s+--version\s+Print the installed drd's version", r.stdout, re.M)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    folder = tmp_path_factory.mktemp("stop_ended")
    with serving_cluster(folder, ["controller", "ranger1"],
                         lambda c: corridor_hosts(c, simulator_on_controller=True)) as c:
        yield c


def test_stop_of_an_ended_mission_says_it_had_ended_and_an_unknown_id_lists_only_running_ones(
        cluster: DaemonCluster, tmp_path: Path) -> None:
    quick = tmp_path / "quick.mission"
    quick.write_text("mission Quick {\n    Wait(duration: 1s)\n}\n")
    config = ("--config", str(cluster.hosts_file))
    ran = cluster.missionctl("run", str(quick), *config, "--speed", "5", "--json")
    assert ran.returncode == 0, ran.stderr
    report = json.loads(ran.stdout)
    mid = report.get("id") or report["mission"]  # the report's id (before the audit's item 6: its `mission`)
    assert mid.startswith("Quick-"), report
    unknown = cluster.missionctl("stop", "NoSuch-1", *config)
    assert unknown.returncode == 2, unknown.stderr
    assert "no mission NoSuch-1; running: none; 1 ended mission known" in unknown.stderr
    assert mid not in unknown.stderr, "an ended mission was listed as running"
    ended = cluster.missionctl("stop", mid, *config)
    assert ended.returncode == 0, ended.stderr
    assert f"{mid}: had already ended (success): nothing to stop" in ended.stdout
    as_json = json.loads(cluster.missionctl("stop", mid, *config, "--json").stdout)
    assert as_json["stopped"] == [] and [m["id"] for m in as_json["ended"]] == [mid]
    assert as_json["ended"][0]["outcome"] == "success"
