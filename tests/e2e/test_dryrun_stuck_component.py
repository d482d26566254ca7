"""A component call that never returns in `missionctl dry-run` (wedge audit D4): a step in a busy loop, a `start`
asleep. The dry-run runs components in its own process, so the run hung for ever, `--until` (sim time) never came,
the first Ctrl-C did nothing and the second gave no report. Now the call is interrupted after 5 s of wall time
(`drd.stuck`): its state fails naming the line it was stuck at, and the run ends with its report. The real
command, in a process of its own (signals need its main thread); bounded by a timeout, nothing timed."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
KIT = '''import threading
import time
from drd.runtime.component import Component, Status


class Spinner(Component):
    def start(self):
        self.drive, self.steps = self.device("drive"), 0

    def step(self, now):
        self.drive.set_velocity(0.3, 0.0)
        self.steps += 1
        while self.steps > 3:  # stuck here
            pass  # stuck here
        return Status.RUNNING


class Blocker(Component):
    def start(self):
        time.sleep(1e9)  # stuck here

    def step(self, now):
        return Status.RUNNING


class Waiter(Component):
    def step(self, now):
        threading.Event().wait()  # stuck here
        return Status.RUNNING


class Retrier(Component):
    def step(self, now):
        while True:
            try:
                time.sleep(0.05)  # stuck here
            except Exception:  # a retry loop: it swallowed the first interruption and went on for ever
                self.ctx.log("retrying")
'''
MANIFEST = "name: {name}\nkind: behavior\ndescription: Never returns.\nentry_point: stuckkit:{name}\n"
NEEDS = "needs:\n  drive: {type: Drive, of: [Ranger], description: base}\ninterfaces: [Drive]\n"


@pytest.fixture
def kit(tmp_path: Path) -> Path:
    (tmp_path / "stuckkit.py").write_text(KIT)
    for name, extra in (("Spinner", NEEDS), ("Blocker", ""), ("Waiter", ""), ("Retrier", "")):
        (tmp_path / "comps" / name).mkdir(parents=True)
        (tmp_path / "comps" / name / "manifest.yaml").write_text(MANIFEST.format(name=name) + extra)
    return tmp_path


@pytest.mark.parametrize(("mission", "call"), [
    ("mission SpinOut {\n    needs ranger: Ranger\n    Spinner\n}\n", "step"),
    ("mission BlockOut {\n    Blocker\n}\n", "start"),
    ("mission WaitOut {\n    Waiter\n}\n", "step"),  # in the standard library's code, under the component's
    ("mission RetryOut {\n    Retrier\n}\n", "step"),  # `except Exception` does not catch it (reverify 7, D-d)
])
def test_a_component_call_that_never_returns_fails_its_state_and_the_run_reports(kit: Path, mission: str,
                                                                                 call: str) -> None:
    (kit / "m.mission").write_text(mission)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(kit), str(ROOT)])}
    r = subprocess.run([*MISSIONCTL, "dry-run", str(kit / "m.mission"), "-C", str(kit / "comps"), "--config",
                        str(ROOT / "hosts.yaml"), "--until", "60", "--json", "--trace", str(kit / "t.jsonl")],
                       cwd=kit, env=env, capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 1, (r.stdout[-1500:], r.stderr[-1500:])
    report = json.loads(r.stdout)
    assert report["outcome"] == "failure", report["reason"]
    reason = report["reason"]
    assert f"ComponentStuck: {call} did not return within 5 s of wall time" in reason, reason
    line = int(reason.rsplit("stuckkit.py:", 1)[1].split(",")[0])
    assert KIT.splitlines()[line - 1].endswith("# stuck here"), reason
    assert report["sim_time"] < 60, "the run ended with the failure, not at --until"
    kinds = [json.loads(x)["kind"] for x in (kit / "t.jsonl").read_text().splitlines()]
    assert kinds[-1] == "finished"


@pytest.mark.parametrize(("raising", "said"), [("sys.exit(3)", "SystemExit: 3"),
                                               ("raise GeneratorExit('done')", "GeneratorExit: done")])
def test_a_component_that_calls_sys_exit_fails_its_state_and_on_error_catches_it(tmp_path: Path, raising: str,
                                                                                said: str) -> None:
    """Users audit 12, D4: `sys.exit(3)` in a step ended `missionctl dry-run` with exit 3, no report, no message;
    reverify audit 14, D5: a `GeneratorExit` printed a traceback."""
    (tmp_path / "quitkit.py").write_text("import sys\nfrom drd.runtime.component import Component\n\n\n"
                                         "class Quitter(Component):\n    def step(self, now):\n"
                                         f"        {raising}  # a library that exits on a fatal condition\n")
    (tmp_path / "comps" / "Quitter").mkdir(parents=True)
    (tmp_path / "comps" / "Quitter" / "manifest.yaml").write_text(
        "name: Quitter\nkind: behavior\ndescription: Exits.\nentry_point: quitkit:Quitter\n")
    (tmp_path / "m.mission").write_text("mission Quit {\n    start -> Q\n    Quitter as Q\n"
                                        "    Q -> Recover on error / log \"caught\"\n"
                                        "    Wait(duration: 1s) as Recover\n}\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    r = subprocess.run([*MISSIONCTL, "dry-run", str(tmp_path / "m.mission"), "-C", str(tmp_path / "comps"),
                        "--config", str(ROOT / "hosts.yaml"), "--json"],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 0, (r.stdout[-1500:], r.stderr[-1500:])
    report = json.loads(r.stdout)
    assert report["outcome"] == "success"
    q = next(t for t in report["timeline"] if t["path"] == "Quit/Q")
    assert q["status"] == "failure"
    logs = json.dumps(report["logs"])
    assert f"component raised {said} (at quitkit.py:7, in step)" in logs and '"caught"' in logs, logs
