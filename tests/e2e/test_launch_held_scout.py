"""A launcher throws only a Scout its behavior holds (safety audit 7, D1). A behavior holding ranger1's launcher
alone threw scout1 while another mission held scout1, in the dry-run and on a cluster, and both trace checkers
passed (the trace names only the launcher). Now the launcher declares that `launch` moves the Scout its first
argument names (`MOVES`), and the gate refuses it from a behavior not bound to that Scout: the trace shows the
refusal, and the Scout stays in the magazine. Checked from the outside: the trace's command records and the
mission's report, with the real `missionctl` and real daemons."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from cluster_support import corridor_hosts, running_cluster, user_kit

from tests.conftest import ROOT

MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
KIT = '''from drd.runtime.component import Component, Status


class Thrower(Component):
    """Holds a launcher only, and throws the Scout its parameter names."""

    def start(self):
        self.thrown = False

    def step(self, now):
        if self.thrown:
            return Status.SUCCESS
        self.thrown = True
        try:
            self.device("launcher").launch(str(self.ctx.params["scout"]), 0.0, 3.0)
            self.ctx.log("thrown")
        except Exception as e:
            self.ctx.log(f"refused: {type(e).__name__}")
        return Status.RUNNING
'''
MANIFEST = """name: Thrower
kind: behavior
description: Throws a named Scout, holding only a launcher.
entry_point: throwkit:Thrower
params:
  scout: {type: str, default: scout1, description: the Scout to throw.}
needs:
  launcher: {type: Launcher, of: [Ranger], description: the launcher.}
interfaces: [Launcher]
"""
HOLD = 'mission HoldScout {\n    needs s: Scout where s.id == "scout1"\n    Wait(duration: 20s)\n}\n'
THROW = "mission ThrowOnly {\n    start -> Wait\n    Wait(duration: 2s)\n    Wait -> Thrower\n}\n"
REFUSED = "it does not hold scout1, which launch moves"


@pytest.fixture
def kit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    user_kit(tmp_path, monkeypatch, "throwkit", KIT, {"Thrower": MANIFEST})
    (tmp_path / "hold.mission").write_text(HOLD)
    (tmp_path / "throw.mission").write_text(THROW)
    return tmp_path


def launches(trace: Path) -> list[dict[str, object]]:
    records = [json.loads(line) for line in trace.read_text().splitlines() if line.strip()]
    return [r for r in records if r.get("kind") == "command" and r.get("method") == "launch"]


def test_a_launch_of_a_scout_the_behavior_does_not_hold_is_refused_in_the_dry_run(kit: Path) -> None:
    trace = kit / "t.jsonl"
    r = subprocess.run([*MISSIONCTL, "dry-run", str(kit / "hold.mission"), str(kit / "throw.mission"), "--config",
                        str(ROOT / "hosts.yaml"), "--trace", str(trace), "--until", "60", "--json"], cwd=kit,
                       capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode in (0, 1), r.stderr[-2000:]
    (launch,) = launches(trace)
    assert launch["accepted"] is False and launch["reason"] == REFUSED, launch
    assert launch["device"] == "ranger1.launcher", launch
    assert '"ScoutLaunched"' not in trace.read_text()


def test_a_launch_of_a_scout_the_behavior_does_not_hold_is_refused_on_a_cluster(kit: Path) -> None:
    with running_cluster(kit, ["controller", "ranger1"]) as c:
        c.hosts_file.write_text(corridor_hosts(c))
        c.start_all()
        c.wait_ready()
        c.wait_up()
        config = ["--config", str(c.hosts_file)]
        r = c.missionctl("run", str(kit / "hold.mission"), *config, "--detach", "--speed", "4", timeout=60)
        assert r.returncode == 0, r.stderr[-2000:]
        trace = kit / "cluster.jsonl"
        r = c.missionctl("run", str(kit / "throw.mission"), *config, "--trace", str(trace), timeout=120)
        assert r.returncode in (0, 1), (r.stdout[-2000:], r.stderr[-2000:])
        (launch,) = launches(trace)
        assert launch["accepted"] is False and launch["reason"] == REFUSED, launch
        assert "refused: NotHolder" in r.stdout + trace.read_text(), r.stdout[-2000:]
