"""A stopped dry-run on a generated building (scale audit D3, D4): each waiter names at most `BLOCKERS_SHOWN`
blockers, all holding now what they are said to hold, and counts the rest; the text report folds the waiters and
keeps every line within 80 columns."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

from drd.explain import BLOCKERS_SHOWN
from tests.conftest import ROOT

MISSION = "missions/corridor_surveillance.mission"


def missionctl(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["missionctl", *args], cwd=ROOT, capture_output=True, text=True, timeout=300, check=False,
                          env={**os.environ, "COLUMNS": "80"})


def test_waiters_name_current_blockers_and_stay_bounded(tmp_path: Path) -> None:
    r = missionctl("world", "generate", "--wings", "3", "--scouts", "20", "--out", str(tmp_path / "b"))
    assert r.returncode == 0, r.stderr
    hosts = str(tmp_path / "b" / "hosts.yaml")
    r = missionctl("dry-run", MISSION, "--hosts", hosts, "--until", "15", "--json")
    assert r.returncode == 1, r.stderr  # stopped by --until
    report = json.loads(r.stdout)
    waiting = report["waiting"]
    assert len(waiting) > 20  # 60 RoomSurveillances for 3 Rangers: most wait
    # held at the stop: the rows the stop's shutdown ended
    open_holds = {h["path"]: h["resources"] for h in report["holds"] if h["to"] == report["sim_time"]}
    rangers_held = {p for p, units in open_holds.items() if "ranger" in units}
    assert rangers_held
    for w in waiting:
        assert len(w["blocked_by"]) <= BLOCKERS_SHOWN
        assert w["blockers"] >= len(rangers_held)  # every Ranger's holder now is in its way
        for b in w["blocked_by"]:
            assert b["path"] in open_holds, f"{b['path']} holds nothing now"  # current, not those of 0 s
            assert set(b["holds"].values()) <= set(open_holds[b["path"]].values())
        assert {b["path"] for b in w["blocked_by"]} <= rangers_held | set(open_holds)
    assert {w["blocked_by"][0]["path"] for w in waiting} <= rangers_held  # the Rangers' holders come first

    r = missionctl("dry-run", MISSION, "--hosts", hosts, "--until", "15")
    lines = r.stdout.splitlines()
    start = lines.index(next(line for line in lines if line.startswith("still active when it stopped")))
    section = lines[start:lines.index(next(line for line in lines[start:] if line.startswith("timeline")))]
    assert max(len(line) for line in section) <= 80  # the still-active rows (other parts are not this test's)
    still = [line for line in section if "waiting since" in line]
    assert 0 < len(still) < len(waiting) // 4  # folded: `RoomSurveillance[a..b] (n)`
