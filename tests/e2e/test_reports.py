"""Reports that explain (issue #12): the failure chain down to the leaf that failed and its own reason, the
mission's `log` lines, and what a run stopped at `--until` left active and waiting, in text and JSON. Real
dry-runs of small missions with the standard components (and, where a leaf must fail in its own words, a
test component in their place)."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from rich.console import Console  # noqa: TID251 - rendering the text report at a chosen width

from drd.cli.report import print_report
from drd.dryrun import DryRun, run
from drd.hosts import load_hosts
from drd.runtime.component import Component, Status
from drd.sim.world import load_world
from dsl import compile_text
from dsl.catalog import Catalog

ROOT = Path(__file__).resolve().parents[2]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]

TIMES_OUT = """\
mission Survey {
    Room
}

behavior Room {
    start -> Hide
    Hide -> done
}

behavior Hide {
    Wait(duration: 1min)
    Wait -> fail after 2s
}
"""

LOOKOUTS = """\
mission Pair {
    Lookout[1..2] as lookouts
}

behavior Lookout {
    needs scout: Scout
    plan { Go }
    Go -> fail after 3s
}

behavior Go {
    Wait(duration: 10s)
}
"""

LOGS = """\
mission Logged {
    var laps: int = 3
    Wait(duration: 1s)
    Wait -> done / log "waited, {laps} laps to go"
}
"""

BUSY = """\
mission Busy {
    parallel {
        First
        Second
    }
}

behavior First {
    needs ranger: Ranger
    Wait(duration: 100s)
}

behavior Second {
    needs ranger: Ranger
    Wait(duration: 1s)
}
"""

GIVES_UP = """\
mission Patrol {
    start -> Leg
    Leg -> fail on error
}

behavior Leg {
    Wait(duration: 5s)
}
"""


def dry_run_cli(tmp_path: Path, text: str, *args: str) -> tuple[subprocess.CompletedProcess[str], Path]:
    mission = tmp_path / "m.mission"
    mission.write_text(text)
    r = subprocess.run([*MISSIONCTL, "dry-run", str(mission), *args], cwd=ROOT, capture_output=True, text=True,
                       timeout=300, check=False)
    return r, mission


def dry_run(text: str, catalog: Catalog, **options: Any) -> DryRun:
    result = compile_text(text, catalog, "m.mission")
    assert result.ok and result.statechart is not None, [d.message for d in result.diagnostics]
    return run(result.statechart, load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" /
               "corridor.yaml"), catalog, **options)


def text_of(report: DryRun, width: int = 80) -> str:
    buf = io.StringIO()
    print_report(report, console=Console(file=buf, width=width, force_terminal=True, color_system=None))
    return buf.getvalue()


# --- the failure chain ----------------------------------------------------------------------------------


def test_a_leaf_that_times_out_is_named_with_its_timeout(tmp_path: Path) -> None:
    r, _ = dry_run_cli(tmp_path, TIMES_OUT, "--json")
    assert r.returncode == 1, r.stderr
    report = json.loads(r.stdout)
    assert report["outcome"] == "failure"
    chain = report["failure_chain"]
    assert [c["path"] for c in chain] == ["Survey", "Survey/Room", "Survey/Room/Hide", "Survey/Room/Hide/Wait"]
    assert chain[0]["reason"] == report["reason"]
    assert chain[-1] == {"path": "Survey/Room/Hide/Wait", "reason": "timed out after 2s", "leaf": True}
    assert [c["leaf"] for c in chain] == [False, False, False, True]
    r, _ = dry_run_cli(tmp_path, TIMES_OUT)
    assert r.returncode == 1
    lines = r.stdout.splitlines()
    assert lines[2] == "why it failed" and lines[3] == "  Room/Hide/Wait: timed out after 2s", r.stdout


class GivesUp(Component):
    """A leaf that fails in its own words, as DetectDoor does at the end of the corridor."""

    def step(self, now: float) -> Status:
        assert self.ctx is not None
        self.ctx.log("no door in sight")
        return Status.FAILURE


def test_a_failed_leaf_gives_its_own_last_log_line(catalog: Catalog) -> None:
    report = dry_run(GIVES_UP, catalog, registry={"Wait": GivesUp})
    assert report.outcome == "failure"
    chain = report.failure_chain()
    assert [c["path"] for c in chain] == ["Patrol", "Patrol/Leg", "Patrol/Leg/Wait"]
    assert chain[1]["reason"] == "Wait failed"
    assert chain[-1] == {"path": "Patrol/Leg/Wait", "reason": "no door in sight", "leaf": True}
    assert "  Leg/Wait: no door in sight" in text_of(report)


def test_a_multiplicity_that_fails_points_to_each_failed_instance(tmp_path: Path) -> None:
    """`only 0 of at least 1 instances of lookouts can succeed`: one instance lost its Scout, the other timed
    out; each is named with its own reason, not `(last failure: failed)`."""
    r, _ = dry_run_cli(tmp_path, LOOKOUTS, "--json", "--inject", "lose scout1 at 1s")
    assert r.returncode == 1, r.stderr
    report = json.loads(r.stdout)
    assert "only 0 of at least 1 instances of lookouts can succeed" in report["reason"]
    leaves = {c["path"]: c["reason"] for c in report["failure_chain"] if c["leaf"]}
    assert leaves == {"Pair/lookouts[0]": "lost scout1 (resource lost)",
                      "Pair/lookouts[1]/Go": "timed out after 3s (while Wait ran)"}, report["failure_chain"]
    multi = next(c for c in report["failure_chain"] if c["path"] == "Pair/lookouts")
    assert multi["reason"].startswith("only 0 of at least 1 instances of lookouts can succeed")
    r, _ = dry_run_cli(tmp_path, LOOKOUTS, "--inject", "lose scout1 at 1s")
    why = r.stdout[r.stdout.index("why it failed"):r.stdout.index("timeline")]
    assert "lookouts[0]: lost scout1 (resource lost)" in why and "lookouts[1]/Go: timed out after 3s" in why


def test_no_failure_chain_when_the_mission_succeeds(catalog: Catalog) -> None:
    report = dry_run(LOGS, catalog)
    assert report.outcome == "success" and report.failure_chain() == []
    assert "why it failed" not in text_of(report)


# --- log lines ---------------------------------------------------------------------------------------------


def test_the_missions_log_lines_are_in_the_report(tmp_path: Path) -> None:
    r, _ = dry_run_cli(tmp_path, LOGS, "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["logs"] == [{"at": 1.0, "path": "Logged", "text": "waited, 3 laps to go"}]
    r, _ = dry_run_cli(tmp_path, LOGS)
    assert "log: 1 line" in r.stdout
    assert "    1.0 s  Logged: waited, 3 laps to go" in r.stdout


# --- a run stopped at --until ------------------------------------------------------------------------------


def test_a_run_stopped_at_until_says_what_was_active_and_who_waited_for_whom(tmp_path: Path) -> None:
    r, _ = dry_run_cli(tmp_path, BUSY, "--until", "5", "--json")
    assert r.returncode == 1, r.stderr
    report = json.loads(r.stdout)
    assert (report["outcome"], report["reason"]) == ("stopped", "sim time limit of 5 s reached")
    assert report["sim_time"] == 5.0 or abs(report["sim_time"] - 5.0) < 1e-6
    assert report["still_active"] == [{"path": "Busy/First/Wait", "since": 0.0, "state": "running"},
                                      {"path": "Busy/Second", "since": 0.0, "state": "waiting"}]
    assert report["waiting"] == [{"path": "Busy/Second", "since": 0.0, "needs": ["ranger: Ranger"],
                                  "blocked_by": [{"path": "Busy/First", "holds": {"ranger": "ranger1"}}],
                                  "blockers": 1}]
    assert report["failure_chain"] == []
    r, _ = dry_run_cli(tmp_path, BUSY, "--until", "5")
    lines = r.stdout.splitlines()
    start = lines.index("still active when it stopped: 2")
    assert lines[start + 1].split() == ["First/Wait", "running", "since", "0.0", "s"]
    assert lines[start + 2].split()[:5] == ["Second", "waiting", "since", "0.0", "s"]
    assert lines[start + 2].endswith("for ranger: Ranger, held by First (ranger1)")


def test_nothing_is_said_to_be_still_active_when_the_mission_ended_by_itself(catalog: Catalog) -> None:
    report = dry_run(TIMES_OUT, catalog)
    assert report.still_active() == [] and report.waiting() == []


# --- readable at 80 columns --------------------------------------------------------------------------------


def test_the_text_report_fits_80_columns_and_says_why_first(catalog: Catalog) -> None:
    report = dry_run(LOOKOUTS, catalog, until=60.0)
    text = text_of(report)
    lines = text.splitlines()
    assert max(len(line) for line in lines) <= 80, text
    order = [text.index(s) for s in ("mission Pair", "sim time", "why it failed", "timeline", "resource holds",
                                     "log:")]
    assert order == sorted(order), text
    corridor = compile_text((ROOT / "missions" / "corridor_surveillance.mission").read_text(), catalog, "c.mission")
    assert corridor.statechart is not None
    long = run(corridor.statechart, load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" /
               "corridor.yaml"), catalog, until=60.0)
    text = text_of(long)
    assert max(len(line) for line in text.splitlines()) <= 80
    assert "…" in text, "long paths are cut from the middle"
    assert "RoomSurveillance[0]/FindNewDoor/DetectDoor" in text, "paths are shown below the mission"
    assert "still active when it stopped" in text
