"""On a cluster, only the arbitration's winner reaches a device, and a component whose state exited commands
nothing (safety audit 8, D1 and D2), as in a dry-run. The Creator executed every fenced setpoint at once and
relied on the next one overwriting it: the lower-ranked sibling's command reached the driver every cycle (a ROS 2
robot got 0.6 then -0.3 m/s, alternately) and the trace recorded it as accepted. And a component that goes on
commanding from a thread of its own after its state exited was admitted at its ancestor's grant and epoch. Checked
from the trace of `missionctl run --trace` against the dry-run's."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from cluster_support import corridor_hosts, running_cluster, user_kit

from tests.conftest import ROOT

MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
KIT = '''import threading
import time

from drd.runtime.component import Component, Status


class Cruise(Component):
    """Drives straight at its speed each step."""

    def step(self, now):
        self.device("drive").set_velocity(float(self.ctx.params["speed"]), 0.0)
        return Status.RUNNING


class Rogue(Component):
    """Commands its drive from a thread of its own, every 50 ms for 8 s, whatever its state."""

    def start(self):
        drive = self.device("drive")

        def loop():
            for _ in range(160):
                try:
                    drive.set_velocity(0.6, 0.0)
                except Exception:
                    pass
                time.sleep(0.05)
        threading.Thread(target=loop, daemon=True).start()

    def step(self, now):
        return Status.RUNNING
'''
MANIFEST = """name: {name}
kind: behavior
description: A drive's user.
entry_point: arbkit:{name}
params:
  speed: {{type: float, default: 0.3, min: -1, max: 1, description: forward speed.}}
needs:
  drive: {{type: Drive, of: [Ranger], description: the base.}}
interfaces: [Drive]
"""
#: `Top` is declared last: it wins the drive each cycle (subsumption); `Cruise` never reaches it.
SUBSUME = ("mission Subsume {\n    needs rov: Ranger\n"
           "    parallel any { Cruise(speed: 0.6); Cruise(speed: -0.3) as Top; Wait(duration: 3s) }\n}\n")
#: `R` exits at 2 s; its thread goes on commanding while `D` drives.
ROGUE = ("mission RogueFight {\n    needs rov: Ranger\n    start -> R\n    Rogue as R\n    R -> D after 2s\n"
         "    Cruise(speed: -0.3) as D\n    D -> done after 4s\n}\n")


@pytest.fixture
def kit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    user_kit(tmp_path, monkeypatch, "arbkit", KIT, {n: MANIFEST.format(name=n) for n in ("Cruise", "Rogue")})
    (tmp_path / "subsume.mission").write_text(SUBSUME)
    (tmp_path / "rogue.mission").write_text(ROGUE)
    return tmp_path


def commands(trace: Path) -> list[dict[str, object]]:
    records = [json.loads(line) for line in trace.read_text().splitlines() if line.strip()]
    return [r for r in records if r["kind"] == "command"]


def accepted_by(trace: Path) -> Counter[str]:
    return Counter(str(c["path"]).split("/", 1)[1] for c in commands(trace) if c["accepted"])


def test_only_the_winner_and_no_exited_component_reach_the_drive_on_a_cluster(kit: Path) -> None:
    for mission in ("subsume", "rogue"):
        r = subprocess.run([*MISSIONCTL, "dry-run", str(kit / f"{mission}.mission"), "--config",
                            str(ROOT / "hosts.yaml"), "--trace", str(kit / f"{mission}.dry.jsonl"), "--speed", "1"],
                           cwd=kit, capture_output=True, text=True, timeout=120, check=False)
        assert r.returncode == 0, r.stderr[-2000:]
    with running_cluster(kit, ["controller", "ranger1"]) as c:
        c.hosts_file.write_text(corridor_hosts(c))
        c.start_all()
        c.wait_ready()
        c.wait_up()
        for mission in ("subsume", "rogue"):
            r = c.missionctl("run", str(kit / f"{mission}.mission"), "--config", str(c.hosts_file), "--trace",
                             str(kit / f"{mission}.cluster.jsonl"), timeout=120)
            assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-2000:])
    for run in ("dry", "cluster"):
        won = accepted_by(kit / f"subsume.{run}.jsonl")
        assert set(won) == {"Top"} and won["Top"] >= 20, (run, won)  # Cruise's never reached the drive
        rogue = commands(kit / f"rogue.{run}.jsonl")
        exited = [c for c in rogue if c["path"] == "RogueFight/R" and float(str(c["at"])) > 2.0]
        assert exited and not any(c["accepted"] for c in exited), (run, exited[:3])
        assert {str(c["reason"]).split(" (")[0] for c in exited} == {"not bound to a grant"}, (run, exited[:3])
