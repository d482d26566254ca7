"""The dry-run models a standby controller (issue #16): with two controller hosts and `cluster.store: {etcd: ...}`
(no etcd is needed: the dry-run models the election), killing the acting controller makes the standby take over once
the election's lease ran out, and the mission resumes from the journal, as on a cluster."""

from __future__ import annotations

import contextlib
import json
import subprocess
from pathlib import Path
from typing import Any

import pytest

from drd.restart import ControllerLife
from tests.conftest import ROOT

MISSION = "missions/corridor_surveillance.mission"


@pytest.fixture(scope="module")
def standby_hosts() -> Path:
    """The repository's hosts.standby.yaml: hosts.yaml with a replicated store and a second controller host,
    controller2 (a standby: the first controller of the file acts)."""
    return ROOT / "hosts.standby.yaml"


def dry_run(hosts: Path, *args: str) -> tuple[int, dict[str, Any], str]:
    r = subprocess.run(["missionctl", "dry-run", MISSION, "--json", "--config", str(hosts), *args], cwd=ROOT,
                       capture_output=True, text=True, timeout=300, check=False)
    return r.returncode, (json.loads(r.stdout) if r.stdout.strip() else {}), r.stderr


def test_the_standby_takes_over_after_the_election_lease_and_the_mission_resumes(standby_hosts: Path,
                                                                                   tmp_path: Path) -> None:
    trace = tmp_path / "run.jsonl"
    code, report, err = dry_run(standby_hosts, "--inject", "kill controller at 60s", "--trace", str(trace))
    assert code == 0 and report["outcome"] == "success", err
    [effect] = [i["effect"] for i in report["injections"]]
    assert "wait for standby controller2" in effect and "election's lease of 3 s" in effect, effect
    assert "at 63.0 s standby controller controller2 elected: 1 mission(s) resumed" in effect, effect
    records = [json.loads(line) for line in trace.read_text().splitlines()]
    [restored] = [r for r in records if r["kind"] == "restored"]
    assert restored["at"] == pytest.approx(63.0, abs=0.11) and restored["since"] == pytest.approx(60.0, abs=0.11)
    assert not [r for r in records if 60.05 < r["at"] < 62.95], "nobody acts before the election"


def test_a_standby_lost_changes_nothing_and_then_the_acting_one_is_lost_for_good(standby_hosts: Path) -> None:
    code, report, err = dry_run(standby_hosts, "--inject", "kill controller2 at 30s", "--inject",
                                "kill controller at 60s")
    assert code == 1 and report["outcome"] == "stopped", err
    effects = [i["effect"] for i in report["injections"]]
    assert effects[0].endswith("a standby controller is gone; controller acts"), effects
    assert effects[1].endswith("every mission stopped, every robot with it"), effects
    assert report["sim_time"] == pytest.approx(60.0, abs=0.11)


def test_a_controller_started_again_is_a_standby_and_takes_over_in_turn(standby_hosts: Path) -> None:
    code, report, err = dry_run(standby_hosts, "--inject", "kill controller at 60s", "--inject",
                                "restart controller at 61s", "--inject", "kill controller2 at 100s")
    assert code == 0 and report["outcome"] == "success", err
    effects = [i["effect"] for i in report["injections"]]
    assert "a standby controller again (controller2 acts)" in effects[1], effects
    assert "at 103.0 s standby controller controller elected" in effects[2], effects


def test_with_every_controller_lost_the_one_started_again_resumes() -> None:
    """Pure: both controllers die; the one started again before the last one's lease ran out waits for it."""
    made: list[object] = []

    class Executive:
        missions: dict[str, object] = {}
        gates = None
        pool = None

        def abandon(self) -> None:
            pass

        def highest_number(self) -> int:  # what the next one numbers its records and grants its epochs above
            return 0

        def continue_records(self, after: int) -> None:
            pass

        def together(self) -> contextlib.nullcontext[None]:  # missions resumed at once ask as one
            return contextlib.nullcontext()

    def make(_gone: object) -> Executive:
        made.append(Executive())
        return made[-1]  # type: ignore[return-value]

    life = ControllerLife(Executive(), make, [], controllers=["c1", "c2"], election=3.0)  # type: ignore[arg-type]
    life._properties = {}
    assert "wait for standby c2" in life.kill(10.0, "c1", False)
    assert life.tick(12.0) is None and life.tick(13.0) is not None and life.acting == "c2"
    life.kill(20.0, "c2", True)
    assert life.executive is None and life.takeover is None
    assert "elected once the lost controller's lease runs out, at 23" in life.restart(21.0, "c1")
    assert life.tick(22.9) is None and life.tick(23.0) is not None and life.acting == "c1"
    assert len(made) == 2
