"""Missions resumed after their controller was lost get back what they held by priority (safety audit 7, D2, D3).
The controller entered them again one by one, in the order they had started, and the first one entered took the
Ranger at once, though a mission of a better priority had held it when the controller died: the worse mission
drove it until the next slice, and the trace had double holds (the better mission's `released (controller lost)`
was written only when it was entered, after the other's grant). Checked from the outside, on the trace of the
real `missionctl dry-run --inject`, and with `missionctl check-trace` (double holds)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.conftest import ROOT

MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
#: Started first, priority 2: it waits for the Ranger the priority-1 mission takes at t=0.
LOW = "mission Lesser {\n    needs r: Ranger\n    Wait(duration: 30s)\n}\n"
HIGH = "mission Better {\n    needs r: Ranger\n    Wait(duration: 30s)\n}\n"


def test_missions_resumed_together_get_their_robots_back_by_priority(tmp_path: Path) -> None:
    (tmp_path / "low.mission").write_text(LOW)
    (tmp_path / "high.mission").write_text(HIGH)
    trace = tmp_path / "t.jsonl"
    r = subprocess.run([*MISSIONCTL, "dry-run", str(tmp_path / "low.mission"), str(tmp_path / "high.mission"),
                        "--priority", "2", "--priority", "1", "--config", str(ROOT / "hosts.yaml"),
                        "--inject", "kill controller at 8s", "--inject", "restart controller at 10s",
                        "--trace", str(trace), "--until", "120"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=120, check=False)
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-2000:])
    records = [json.loads(line) for line in trace.read_text().splitlines() if line.strip()]
    grants = [(g["at"], g["mission"].rpartition("-")[0]) for g in records if g["kind"] == "granted"]
    assert grants[0] == (0.0, "Better"), grants
    after = [g for g in grants if g[0] >= 10.0]
    assert after[0] == (10.0, "Better"), grants  # it held the Ranger when the controller died: it gets it back
    assert [at for at, name in grants if name == "Lesser"] == [30.0], grants  # when Better is done, not before
    check = subprocess.run([*MISSIONCTL, "check-trace", str(trace), "--config", str(ROOT / "hosts.yaml")],
                           capture_output=True, text=True, timeout=60, check=False)
    assert check.returncode == 0 and "0 breaches" in check.stdout, check.stdout[-2000:]  # no double hold either
