"""`missionctl replay` rebuilds the run's report from the recording alone (issue #13): the corridor mission, a
mission that fails on its own and one an injection makes fail (the corridor mission with an injected loss is in
`test_record.py`); and a recording whose process was killed mid-run replays up to where it was cut."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
CORRIDOR = str(ROOT / "missions" / "corridor_surveillance.mission")
HOSTS = str(ROOT / "hosts.yaml")
#: A mission that fails on its own: its one behavior runs out of time.
DEADLINE = "mission Deadline {\n    needs ranger: Ranger\n    start -> FollowCorridor\n" \
           "    FollowCorridor -> fail after 10s\n}\n"


def missionctl(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False)


@pytest.mark.parametrize(("mission", "extra", "outcome"), [
    (CORRIDOR, [], "success"),
    ("deadline.mission", [], "failure"),
    (CORRIDOR, ["--inject", "lose ranger1 at 5s"], "failure"),
], ids=["corridor", "fails-on-its-own", "fails-by-injection"])
def test_replay_json_is_the_runs_json(tmp_path: Path, mission: str, extra: list[str], outcome: str) -> None:
    (tmp_path / "deadline.mission").write_text(DEADLINE)
    run = missionctl("dry-run", mission, "--config", HOSTS, *extra, "--record", "run.mcap", "--json", cwd=tmp_path)
    assert run.returncode == (0 if outcome == "success" else 1), run.stderr[-2000:]
    report = json.loads(run.stdout)
    assert report["outcome"] == outcome and (outcome == "success" or report["failure_chain"])
    (tmp_path / "elsewhere").mkdir()  # no hosts file, no world, no mission: the recording alone
    replay = missionctl("replay", str(tmp_path / "run.mcap"), "--json", cwd=tmp_path / "elsewhere")
    assert replay.returncode == run.returncode, replay.stderr[-2000:]
    assert json.loads(replay.stdout) == report


def test_a_run_killed_mid_way_replays_up_to_where_its_recording_ends(tmp_path: Path) -> None:
    """SIGKILL, not a clean stop: no summary, no index at the end; what the chunks flushed each second hold."""
    proc = subprocess.Popen([*MISSIONCTL, "dry-run", CORRIDOR, "--config", HOSTS, "--speed", "10", "--record",
                             "run.mcap", "--trace", "run.jsonl"], cwd=tmp_path, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        recording = tmp_path / "run.mcap"
        while not (recording.exists() and recording.stat().st_size > 400_000):  # some 40 s of the run
            assert proc.poll() is None and time.monotonic() < deadline, "the run ended before it could be cut"
            time.sleep(0.05)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    replay = missionctl("replay", "run.mcap", "--json", "--trace", "again.jsonl", cwd=tmp_path)
    assert replay.returncode == 1, replay.stderr[-2000:]
    report = json.loads(replay.stdout)
    assert report["outcome"] == "unfinished" and report["reason"].startswith("the recording ends at ")
    assert 10 < report["sim_time"] < 180 and report["timeline"][0]["path"] == "CorridorSurveillance"
    replayed = (tmp_path / "again.jsonl").read_text().splitlines()
    traced = (tmp_path / "run.jsonl").read_text().splitlines()
    n = min(len(replayed), len(traced) - 1)  # the trace's last line may be cut too
    assert n > 100 and replayed[:n] == traced[:n]  # the same records, in the same order, up to the cut
    at = missionctl("replay", "run.mcap", "--at", f"{report['sim_time'] - 1:.1f}", "--json", cwd=tmp_path)
    assert at.returncode == 0 and json.loads(at.stdout)["robots"]["ranger1"]["x"] > 2, at.stderr[-2000:]
