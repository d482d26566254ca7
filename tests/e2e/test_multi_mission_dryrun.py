"""A dry-run of several missions, as a user runs it (multi-mission audit D1, D3, D4): `missionctl dry-run A B
--until T --trace --json`. At --until every mission stops as one: none is granted a robot nor enters a state in
that stop, and a mission that waited says whom for, with that mission's id and what it held. Two missions of
one name name each other by id in the trace (blocked_by, the revoked reason)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]

HOG = """\
mission Hog priority 1 {
    HoldIt
}
behavior HoldIt {
    needs ranger: Ranger where ranger.id == "ranger1"
    Observe(duration: 10min)
}
"""

STARVED = """\
mission Starved priority 3 {
    WantIt
}
behavior WantIt {
    needs ranger: Ranger where ranger.id == "ranger1"
    Observe(duration: 5s)
}
"""

GUARD = """\
mission Guard priority 2 {
    Post
}
behavior Post {
    needs ranger: Ranger where ranger.id == "ranger1" for 5s
    Observe(duration: 1min)
}
"""


def dry_run(tmp_path: Path, missions: dict[str, str], until: str) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The JSON reports and the trace's records of `missionctl dry-run` of these missions (file name -> text)."""
    files = []
    for name, text in missions.items():
        (tmp_path / name).write_text(text)
        files.append(str(tmp_path / name))
    trace = tmp_path / "trace.jsonl"
    r = subprocess.run([*MISSIONCTL, "dry-run", *files, "--until", until, "--trace", str(trace), "--json"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 1, r.stderr  # stopped at --until
    check = subprocess.run([*MISSIONCTL, "check-trace", str(trace)], cwd=ROOT, capture_output=True, text=True,
                           timeout=300)
    assert check.returncode == 0, check.stdout + check.stderr
    return json.loads(r.stdout), [json.loads(line) for line in trace.read_text().splitlines() if line.strip()]


def test_the_end_at_until_grants_nothing_to_a_mission_it_stops_and_keeps_whom_it_waited_for(tmp_path: Path) -> None:
    """Hog holds ranger1 and Starved waits for it. Before the fix, Hog's stop gave ranger1 to Starved, which
    entered its Observe in the stop; its report then said `waiting: []` and a hold from 3.0 to 3.0."""
    reports, records = dry_run(tmp_path, {"hog.mission": HOG, "starve.mission": STARVED}, "3")
    by_name = {r["mission"]: r for r in reports}
    hog, starved = by_name["Hog"]["id"], by_name["Starved"]["id"]
    mine = [r for r in records if r["mission"] == starved]
    assert [r for r in mine if r["kind"] == "granted"] == []
    assert [r["path"] for r in mine if r["kind"] == "entered"] == ["Starved", "Starved/WantIt"]
    report = by_name["Starved"]
    assert report["outcome"] == "stopped" and report["holds"] == []
    assert report["still_active"] == [{"path": "Starved/WantIt", "since": 0.0, "state": "waiting"}]
    assert report["waiting"] == [{"path": "Starved/WantIt", "since": 0.0, "needs": ["ranger: Ranger"],
                                  "blocked_by": [{"path": f"{hog}/Hog/HoldIt", "mission": hog,
                                                  "holds": {"ranger": "ranger1"}}], "blockers": 1}]
    waits = [r for r in mine if r["kind"] == "waiting" and r["blocked_by"]]
    assert [(w["blocked_by"], w["holds"]) for w in waits] == [
        ([f"{hog}/Hog/HoldIt"], {f"{hog}/Hog/HoldIt": {"ranger": "ranger1"}})]


def test_two_missions_of_one_name_name_each_other_by_id(tmp_path: Path) -> None:
    """Two Guards share ranger1 in 5 s slices. Before the fix, the second's blocker and the first's preemptor
    were both `Guard/Post`: each read as blocked (or preempted) by itself."""
    (tmp_path / "b").mkdir()
    reports, records = dry_run(tmp_path, {"guard.mission": GUARD, "b/guard.mission": GUARD}, "7")
    first, second = (r["id"] for r in reports)
    assert first != second
    blocked = [(r["mission"], r["blocked_by"]) for r in records if r["kind"] == "waiting" and r["blocked_by"]]
    # the second waits for the first; preempted at the slice's end, the first waits again, for the second
    assert blocked == [(second, [f"{first}/Guard/Post"]), (first, [f"{second}/Guard/Post"])]
    revoked = [(r["mission"], r["reason"]) for r in records if r["kind"] == "revoked"]
    assert revoked == [(first, f"preempted by {second}/Guard/Post")]
